"""``make pipeline``: generate -> ingest -> fit -> validate -> unseen_shape -> report, then MLflow.

    python -m pipelines.run_all
    python -m pipelines.run_all +experiment=quick
    python -m pipelines.run_all paths.root=/tmp/cold-run          # everything in another folder

Every stage runs in this process through its Hydra-free function (``run_generate``,
``run_ingest``, and the ``run`` of fit/validate/report), each with its own composed stage
config (``conf/generate.yaml``, ``conf/ingest.yaml``, ``conf/fit.yaml`` ...) plus
``overrides.<stage>`` and the shared values of ``conf/pipeline.yaml`` (paths first). Every
stage skips what its content hashes say is unchanged. MLflow: one parent run per invocation
and a child run per (family, configuration); when nothing changed at all, nothing new is
logged (the log names the run that already holds the identical results); when only the
report or the shape study changed, one parent run points at that run (``same_as`` tag) and
holds the new files instead of 120 copies of the models.
Per-stage wall times go to ``${paths.reports}/pipeline_timing.json`` and the parent run.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hydra
import pandas as pd

from pipelines import cache, schemas
from pipelines.common import (
    CONF_DIR,
    REPO_ROOT,
    Paths,
    dataset_hash,
    hydra_output_dir,
    identification_plan,
    read_processed,
    run_stage,
    stage_columns,
    to_container,
)
from pipelines.stages import PipelineError
from rig_io.atomic import write_text_atomic

log = logging.getLogger(__name__)
EXTERNAL_STAGES = ("generate", "ingest")
OWN_STAGES = ("fit", "validate", "unseen_shape", "report")


@dataclass
class PipelineResult:
    timings: dict[str, float] = field(default_factory=dict)
    fits: pd.DataFrame | None = None
    metrics: pd.DataFrame | None = None
    unseen_shape: Any = None
    report: Any = None
    parent_run_id: str | None = None
    up_to_date: bool = False
    ingest_report: dict[str, Any] | None = None
    generate_report: dict[str, Any] | None = None


def compose_stage(name: str, overrides: Sequence[str] = ()) -> dict[str, Any]:
    """A stage's own config (``conf/<name>.yaml``) composed with overrides, as a plain dict."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import MissingConfigException

    gh = GlobalHydra.instance()
    if gh.is_initialized():  # inside a Hydra app (run_all's own): its search path is conf/
        try:
            return to_container(compose(config_name=name, overrides=list(overrides)))
        except MissingConfigException:
            # initialised on another config folder (e.g. left over by a test): start clean
            gh.clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name=name, overrides=list(overrides))
    return to_container(cfg)


def path_overrides(pipeline: Mapping[str, Any]) -> list[str]:
    """The pipeline's (resolved, absolute) ``paths`` as overrides for a stage's own config."""
    paths = Paths.from_config(pipeline["paths"])
    out = []
    for key in Paths.__dataclass_fields__:
        value = str(getattr(paths, key))
        if "'" in value:
            raise PipelineError(f"paths.{key} may not contain a quote: {value!r}")
        out.append(f"paths.{key}='{value}'")
    return out


def stage_overrides(name: str, pipeline: Mapping[str, Any]) -> list[str]:
    """The pipeline's paths, then ``overrides.<name>`` (``pipeline``: the pipeline config with
    its defaults, composed or through :func:`schemas.with_defaults`)."""
    return [*path_overrides(pipeline), *list(pipeline["overrides"][name])]


def _identified(plan: Any, pipeline: Mapping[str, Any]) -> str:
    """The excitation the models of this pipeline identify on: the first configured one, or,
    when the data has none of those, the first the identification rule added."""
    configured = list(pipeline["fit_excitations"])
    if plan.marked:  # runs a manifest or mapping marks for identification decide
        ds = plan.dataset
        kinds = ds.loc[ds["run_id"].astype(str).isin(plan.marked), "excitation"].astype(str)
        return str(kinds.value_counts().index[0])
    added = [k for k in plan.fit_excitations if k not in configured]
    present = set(plan.dataset["excitation"].astype(str))
    return str(configured[0] if configured[0] in present or not added else added[0])


def stage_config(name: str, pipeline: Mapping[str, Any]) -> dict[str, Any]:
    """``conf/<name>.yaml`` + ``overrides.<name>`` + the pipeline's shared values
    (:class:`pipelines.schemas.PipelineConfig`)."""
    pipeline = schemas.with_defaults(schemas.PipelineConfig, pipeline)
    cfg = compose_stage(name, stage_overrides(name, pipeline))
    cfg["paths"] = dict(pipeline["paths"])
    cfg["tracking"] = dict(pipeline.get("tracking") or {})
    shared = ("config", "fit_excitations", "fit_runs", "single_run_heldout_fraction", "signals",
              "n_jobs", "cache")
    if name in ("fit", "validate"):
        for key in shared:
            cfg[key] = pipeline[key]
    if name == "validate":
        for key in ("heldout", "cross"):
            cfg[key] = pipeline[key]
    # what the identification rule decided (run_pipeline sets it from the fit stage's plan)
    identified = pipeline.get("identified_excitation") or next(iter(pipeline["fit_excitations"]),
                                                                None)
    if identified is None:
        raise PipelineError("fit_excitations is empty and no identification run was found; "
                            "name the excitation that identifies, e.g. "
                            "fit_excitations=[sine_decay]")
    if name == "unseen_shape":
        cfg["fit_excitation"] = identified
        for key in ("config", "signals", "n_jobs", "cache"):
            cfg[key] = pipeline[key]
        heldout = pipeline.get("planned_heldout") or pipeline["heldout"]
        if heldout:
            cfg["eval_excitations"] = list(heldout)
    if name == "report":
        cfg["fit_excitation"] = identified
        for key in ("n_jobs", "cache"):
            cfg[key] = pipeline[key]
    cfg["progress"] = bool(pipeline["progress"])
    return cfg


def run_external(stage: str, overrides: Sequence[str], *, root: Path) -> None:
    """Run ``python -m pipelines.<stage>`` in ``root`` (relative data paths land there)."""
    cmd = [sys.executable, "-m", f"pipelines.{stage}", *overrides,
           f"hydra.run.dir='{root / 'outputs' / 'run_all' / stage}'"]
    env = {**os.environ, "HYDRA_FULL_ERROR": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO_ROOT),
                                                       os.environ.get("PYTHONPATH")]))}
    log.info("run_all: %s", " ".join(cmd))
    proc = subprocess.run(cmd, cwd=root, env=env, check=False)
    if proc.returncode != 0:
        raise PipelineError(f"stage {stage!r} failed with exit code {proc.returncode} "
                            f"(command: {' '.join(cmd)})")


def run_generate_stage(pipeline: Mapping[str, Any]) -> dict[str, Any]:
    """The virtual-rig campaign in this process through ``pipelines.generate`` (as its CLI)."""
    from pipelines.generate import run_generate, specs_from_config

    gcfg = compose_stage("generate", stage_overrides("generate", pipeline))
    report: dict[str, Any] = run_generate(
        specs_from_config(gcfg), str(gcfg["out"]), fmt=str(gcfg["format"]),
        compress=bool(gcfg["compress"]), n_jobs=int(gcfg["n_jobs"]),
        overwrite=bool(gcfg["overwrite"]), progress=bool(gcfg["progress"]))
    log.info("generate: %d runs written, %d unchanged -> %s", len(report["written"]),
             len(report["skipped"]), report["out"])
    return report


def run_ingest_stage(pipeline: Mapping[str, Any]) -> dict[str, Any]:
    """Ingest in this process through ``pipelines.ingest.run_ingest`` (as its CLI does).

    Rejected runs are reported and left out; the pipeline goes on with the accepted ones
    (``python -m pipelines.ingest`` alone exits 1 instead).
    """
    from pipelines.ingest import run_ingest
    from rig_io.limits import ReadLimits
    from rig_io.synchronise import SyncOptions

    icfg = compose_stage("ingest", stage_overrides("ingest", pipeline))
    if own_data(pipeline):
        if not pipeline.get("source"):
            raise PipelineError(
                f"importer {_importer_name(pipeline)!r} is set but no source: name the folder "
                f"of your logs, e.g. source=../shared/real-data/tendon-catheter")
        icfg["source"] = str(pipeline["source"])
        icfg["importer"] = pipeline.get("importer")
    report: dict[str, Any] = run_ingest(
        str(icfg["source"]), str(icfg["out"]), mapping=icfg["importer"],
        sync=SyncOptions(**icfg["sync"]), force=bool(icfg["force"]), prune=bool(icfg["prune"]),
        progress=bool(icfg["progress"]), limits=ReadLimits.from_mapping(icfg["limits"]))
    for rej in report.get("rejected", []):
        log.warning("ingest rejected %s: %s", rej.get("source"), rej.get("reason"))
    if not report.get("n_accepted"):
        raise PipelineError(f"ingest accepted no run from {icfg['source']}")
    return report


def own_data(cfg: Mapping[str, Any]) -> bool:
    """True when the pipeline runs on the user's logs (``importer=...`` and/or
    ``source=...``) instead of the virtual campaign."""
    return bool(cfg.get("importer") or cfg.get("source"))


def _importer_name(cfg: Mapping[str, Any]) -> str:
    imp = cfg.get("importer")
    return str(imp.get("name", "?")) if isinstance(imp, Mapping) else "none (tsm-rig-log/1)"


def run_pipeline(cfg: Mapping[str, Any]) -> PipelineResult:
    """Hydra-free core of ``make pipeline`` (cfg = composed ``conf/pipeline.yaml``, or a
    mapping whose missing settings take :class:`pipelines.schemas.PipelineConfig`'s defaults)."""
    from pipelines import tracking

    cfg = schemas.with_defaults(schemas.PipelineConfig, cfg)
    paths = Paths.from_config(cfg["paths"])
    paths.root.mkdir(parents=True, exist_ok=True)
    result = PipelineResult()
    wanted = list(cfg["stages"])
    if own_data(cfg) and "generate" in wanted:
        log.info("run_all: your own data (importer %s, source %s): no virtual campaign is "
                 "generated", _importer_name(cfg), cfg.get("source"))
        wanted.remove("generate")
    unknown = [s for s in wanted if s not in (*EXTERNAL_STAGES, *OWN_STAGES)]
    if unknown:
        raise PipelineError(f"unknown stage(s) {unknown}; known: "
                            f"{[*EXTERNAL_STAGES, *OWN_STAGES]}")
    tracker = tracking.Tracker(tracking.settings_from_config(cfg.get("tracking") or {},
                                                             root=paths.root))
    state = _Progress()
    try:
        return _run_stages(cfg, paths, tracker, result, wanted, state)
    except BaseException as exc:
        _end_failed(tracker, state, exc)
        raise


@dataclass
class _Progress:
    """Where a pipeline is: the stage running and the parent run once it exists."""

    stage: str = "start"
    parent: str | None = None


def _end_failed(tracker: Any, state: _Progress, exc: BaseException) -> None:
    """A pipeline that failed (a stage raised, a write failed, it was interrupted) leaves a
    FAILED parent run naming the stage and the error: its own when it had one, else a new
    one, so the failure is in MLflow and no run is left RUNNING."""
    if not tracker.enabled:
        return
    error = " ".join(str(exc).split())[:480] or type(exc).__name__
    try:
        parent = state.parent
        if parent is None:
            parent = tracker.start_run("pipeline", tags={"stage": "pipeline", "kind": "parent"})
        tracker.log(parent, tags={"failed_stage": state.stage, "error": error})
        tracker.end_run(parent, status="FAILED")
    except Exception as err:  # noqa: BLE001 - the store may be what failed; keep the cause
        log.warning("could not end the pipeline's MLflow run as FAILED: %s", err)


def _run_stages(cfg: Mapping[str, Any], paths: Paths, tracker: Any, result: PipelineResult,
                wanted: list[str], state: _Progress) -> PipelineResult:
    from pipelines import fit, report, unseen_shape, validate

    total = time.perf_counter()
    started = time.time()  # the parent run's start: its duration is the whole pipeline's
    if tracker.enabled:
        # Before any parallel worker exists: schema creation must happen exactly once.
        t0 = time.perf_counter()
        tracker.init_store()
        result.timings["tracking_init"] = time.perf_counter() - t0

    if "generate" in wanted:
        t0 = time.perf_counter()
        state.stage = "generate"
        result.generate_report = run_generate_stage(cfg)
        result.timings["generate"] = time.perf_counter() - t0
    if "ingest" in wanted:
        t0 = time.perf_counter()
        state.stage = "ingest"
        result.ingest_report = run_ingest_stage(cfg)
        result.timings["ingest"] = time.perf_counter() - t0

    dataset = planned = None
    if any(s in wanted for s in ("fit", "validate", "unseen_shape")):
        t0 = time.perf_counter()
        dataset = read_processed(paths.processed, stage_columns(cfg["signals"]))
        result.timings["read_dataset"] = time.perf_counter() - t0
    if dataset is not None:
        # the identification rule, as fit and validate apply it, for the later stages
        plan = identification_plan(stage_config("validate", cfg), dataset, paths)
        cfg = {**cfg, "identified_excitation": _identified(plan, cfg),
               "planned_heldout": list(plan.heldout)}
        planned = plan.dataset
    if "fit" in wanted:
        t0 = time.perf_counter()
        state.stage = "fit"
        result.fits = fit.run(stage_config("fit", cfg), dataset=dataset)
        result.timings["fit"] = time.perf_counter() - t0
    if "validate" in wanted:
        t0 = time.perf_counter()
        state.stage = "validate"
        # exactly the models of this invocation (not every model file left on disk)
        result.metrics, _ = validate.run(stage_config("validate", cfg), dataset=dataset,
                                         fits=result.fits)
        result.timings["validate"] = time.perf_counter() - t0
    if "unseen_shape" in wanted:
        why = unseen_shape.not_applicable(planned) if planned is not None else None
        if why is not None:
            log.warning("unseen_shape: skipped: %s", why)
        else:
            t0 = time.perf_counter()
            state.stage = "unseen_shape"
            result.unseen_shape = unseen_shape.run(stage_config("unseen_shape", cfg),
                                                   dataset=planned, fits=result.fits)
            result.timings["unseen_shape"] = time.perf_counter() - t0
    # MLflow's child runs are logged in a background thread while the report draws (its
    # figures render in worker processes); the figures are attached to the runs afterwards.
    tracking_state: TrackState | None = None
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="mlflow") as pool:
        # (Hydra's compose is not thread-safe: the fit config is composed here, not there.)
        fit_cfg = stage_config("fit", cfg) if tracker.enabled else {}
        pending = (pool.submit(_track_start, tracker, cfg, fit_cfg, paths, result, state,
                               started) if tracker.enabled else None)
        if "report" in wanted:
            t0 = time.perf_counter()
            state.stage = "report"
            result.report = report.run(stage_config("report", cfg), metrics=result.metrics,
                                       fits=result.fits)
            result.timings["report"] = time.perf_counter() - t0
        if pending is not None:
            t0 = time.perf_counter()
            state.stage = "tracking"
            tracking_state = pending.result()
            if tracking_state.parent is None and _outputs_changed(result):
                tracking_state.parent = _open_parent(
                    tracker, cfg, paths, result, state, started,
                    tags={**tracking_state.tags, "up_to_date": "true",
                          "same_as": tracking_state.same_as})
            if tracking_state.parent is not None:
                _track_finish(tracker, tracking_state, result)
            else:
                log.info("tracking: nothing changed since MLflow run %s (same data, models, "
                         "metrics, report and shape study): nothing new logged",
                         tracking_state.same_as)
            result.parent_run_id = tracking_state.parent
            result.up_to_date = tracking_state.up_to_date
            # time spent on MLflow beyond the stages it overlapped with
            result.timings["tracking"] = time.perf_counter() - t0
            result.timings["tracking_overlapped"] = tracking_state.seconds
    if tracker.enabled:
        from pipelines import registry

        t0 = time.perf_counter()
        state.stage = "registry"
        registry.register_pipeline(tracker, cfg, fits=result.fits, metrics=result.metrics,
                                   processed=paths.processed)
        result.timings["registry"] = time.perf_counter() - t0
    result.timings["total"] = time.perf_counter() - total
    write_text_atomic(paths.reports / "pipeline_timing.json",
                      json.dumps({k: round(v, 3) for k, v in result.timings.items()}, indent=1))
    if tracker.enabled and result.parent_run_id:
        tracker.log(result.parent_run_id, metrics={
            f"stage_seconds.{k}": v for k, v in result.timings.items()})
        tracker.end_run(result.parent_run_id)
        state.parent = None  # ended: nothing left to mark FAILED
    log.info("pipeline: %s", ", ".join(f"{k} {v:.1f} s" for k, v in result.timings.items()))
    return result


@dataclass
class TrackState:
    #: the parent run; None while nothing changed since ``same_as`` (nothing is logged)
    parent: str | None
    up_to_date: bool
    #: child run ids with the configuration label each one shows
    children: list[tuple[str, str]] = field(default_factory=list)
    seconds: float = 0.0
    #: the run that already holds these results, when nothing changed
    same_as: str = ""
    #: what identifies the results (dataset hash, pipeline key): every parent run carries it
    tags: dict[str, str] = field(default_factory=dict)


def _outputs_changed(result: PipelineResult) -> bool:
    """Whether the report or the shape study was made anew (the models and metrics being
    the same as an earlier run's): their files then need a run to live on."""
    return any(r is not None and not r.cached for r in (result.report, result.unseen_shape))


def _track_start(tracker: Any, cfg: Mapping[str, Any], fit_cfg: Mapping[str, Any],
                 paths: Paths, result: PipelineResult, progress: _Progress,
                 started: float | None = None) -> TrackState:
    """Parent run + one child per fitted model; nothing when nothing changed (``same_as``
    names the run that holds the same results).
    ``started`` (epoch seconds): when the pipeline began, the parent run's start time."""
    from pipelines import lineage, tracking
    from pipelines.common import dataset_units
    from pipelines.stages import Configuration

    start = time.perf_counter()
    fits, metrics = result.fits, result.metrics
    data_hash = dataset_hash(paths.processed)
    key = cache.combine({
        "stage": "pipeline", "dataset": data_hash,
        "models": sorted(fits["key"].astype(str)) if fits is not None else [],
        "metrics": cache.hash_frame(metrics) if metrics is not None else "",
    })  # no git commit: the model keys already cover the code that matters
    tags = {"dataset_hash": data_hash, "pipeline_key": key}
    if result.ingest_report is not None:
        tags["ingest_rejected"] = str(result.ingest_report.get("n_rejected", 0))
    previous = tracker.find_runs(
        f"tags.pipeline_key = '{key}' and tags.complete = 'true'")
    if previous:  # nothing new to log, unless the report or the shape study changed
        return TrackState(None, True, seconds=time.perf_counter() - start,
                          same_as=previous[0].info.run_id, tags=tags)
    parent = _open_parent(tracker, cfg, paths, result, progress, started, tags=tags)
    state = TrackState(parent, False, tags=tags)
    units = dataset_units(paths.processed)
    hydra_dir = hydra_output_dir()
    if fits is not None:
        base = tracking.flatten({k: v for k, v in fit_cfg.items()
                                 if k not in ("family", "family_overrides", "tracking",
                                              "families")})
        ids = tracking.log_model_runs(
            tracker, parent, fits=fits, metrics=metrics, base_params=base, tags=tags,
            hydra_dir=hydra_dir / ".hydra" if hydra_dir else None, plots=None,
            stage="pipeline", progress=bool(cfg["progress"]), units=units,
        )
        lineage.log_model_inputs(tracker, ids, fits, metrics, processed=paths.processed)
        labels = [Configuration(str(r["rig"]), tracking.finite_or_none(r["curve_angle_deg"]),
                                tracking.finite_or_none(r["radius_mm"])).label
                  for r in fits.to_dict("records")]
        state.children = list(zip(ids, labels, strict=True))
    state.seconds = time.perf_counter() - start
    return state


def _open_parent(tracker: Any, cfg: Mapping[str, Any], paths: Paths, result: PipelineResult,
                 progress: _Progress, started: float | None, *,
                 tags: Mapping[str, str]) -> str:
    """The pipeline's parent run, started at ``started``, with its params, data and tables;
    ``tags`` carry the dataset hash and the pipeline key (hashed once, by the caller)."""
    from pipelines import lineage, tracking

    fits, metrics = result.fits, result.metrics
    params = tracking.flatten({k: v for k, v in cfg.items() if k != "tracking"})
    parent = tracker.start_run("pipeline", tags={"stage": "pipeline", "kind": "parent",
                                                 **tags},
                               note=_pipeline_note(cfg, fits, paths), start_time=started)
    progress.parent = parent  # from here on a failure anywhere ends this run FAILED
    tracker.log(parent, params=params)
    if paths.processed.is_dir():  # the unseen-shape study and the report read all of it
        lineage.log_input(tracker, [parent],
                          lineage.processed_input(paths.processed, context="evaluation"))
        # what ingest did to every run (calibration, offsets, rejections)
        for name in ("runs.json", "ingest_report.json"):
            if (paths.processed / name).is_file():
                tracker.log_artifact(parent, paths.processed / name, "ingest")
    if metrics is not None:
        tracker.log_table(parent, metrics, "tables/metrics.json")
        tracker.log_artifact(parent, paths.metrics_csv, "tables")
    hydra_dir = hydra_output_dir()
    if hydra_dir is not None:
        tracker.log_artifact(parent, hydra_dir / ".hydra", ".hydra")
    return str(parent)


def _pipeline_note(cfg: Mapping[str, Any], fits: pd.DataFrame | None, paths: Paths) -> str:
    """The pipeline parent run's description."""
    source = (f"your logs ({_importer_name(cfg)}, {cfg.get('source')})" if own_data(cfg)
              else "the virtual rig's campaign")
    n = 0 if fits is None else len(fits)
    families = "" if fits is None or fits.empty else ", ".join(
        sorted(fits["family"].astype(str).unique()))
    return (f"make pipeline on {source}: ingest -> fit -> validate -> unseen_shape -> "
            f"report. {n} fitted models ({families}) as child runs, each with its training "
            f"and validation data; the report and the leave-one-configuration-out summary "
            f"are this run's artifacts. Data: {paths.processed.name}.")


def _track_finish(tracker: Any, state: TrackState, result: PipelineResult) -> None:
    """After the report: its files on the parent, each configuration's figures on its runs."""
    from pipelines import report as report_mod
    from pipelines import unseen_shape

    if state.parent is None:
        return
    if result.unseen_shape is not None:
        unseen_shape.log_result(tracker, state.parent, result.unseen_shape)
    rep = result.report
    if rep is not None and (not state.up_to_date or not rep.cached):
        report_mod.log_report(tracker, state.parent, rep)
    if rep is not None:
        for run_id, label in state.children:
            for fig in rep.config_plots.get(label, []):
                tracker.log_artifact(run_id, fig, "plots")
    if not state.up_to_date:
        tracker.log(state.parent, tags={"complete": "true"})


@hydra.main(config_path="../conf", config_name="pipeline", version_base="1.3")
def main(cfg: Any) -> None:
    run_stage("pipeline", lambda: run_pipeline(to_container(cfg)))


if __name__ == "__main__":
    from pipelines.cli import guard

    guard("pipeline")
    main()
