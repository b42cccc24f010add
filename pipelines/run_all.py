"""``make pipeline``: generate -> ingest -> fit -> validate -> unseen_shape -> report, then MLflow.

    python -m pipelines.run_all
    python -m pipelines.run_all +experiment=quick
    python -m pipelines.run_all paths.root=../cold-run            # everything in another folder

Every stage runs in this process through its core (:mod:`pipelines.core`: ``generate``,
``ingest``, and the ``run`` of fit, validate, unseen_shape and report; never a stage's
command module), each with its own typed settings (:func:`stage_config`: ``conf/<stage>.yaml``
plus ``overrides.<stage>`` and the shared values of ``conf/pipeline.yaml``, paths first). Every
stage skips what its content hashes say is unchanged. MLflow: one parent run per invocation
and a child run per (family, configuration); when nothing changed at all, nothing new is
logged (the log names the run that already holds the identical results); when only the
report or the shape study changed, one parent run points at that run (``same_as`` tag) and
holds the new files instead of 120 copies of the models.
Per-stage wall times go to ``${paths.reports}/pipeline_timing.json`` and the parent run.
"""

from __future__ import annotations

import copy
import json
import logging
import os
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

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
    stage_columns,
)
from pipelines.core import fit as fit_core
from pipelines.core import generate as generate_core
from pipelines.core import ingest as ingest_core
from pipelines.core import report as report_core
from pipelines.core import unseen_shape as unseen_core
from pipelines.core import validate as validate_core
from pipelines.skeleton import Stage, TrackContext, tracker_for
from pipelines.stages import PipelineError
from pipelines.tracking import tracking_group
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


def compose_stage(name: str, overrides: Sequence[str] = ()) -> Any:
    """``conf/<name>.yaml`` composed with ``overrides``, as its typed settings
    (:data:`pipelines.schemas.STAGE_SCHEMAS`)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import MissingConfigException

    schema = schemas.STAGE_SCHEMAS[name]
    gh = GlobalHydra.instance()
    if gh.is_initialized():  # inside a Hydra app (run_all's own): its search path is conf/
        try:
            return schemas.settings(schema, compose(config_name=name,
                                                    overrides=list(overrides)))
        except MissingConfigException:
            # initialised on another config folder (e.g. left over by a test): start clean
            gh.clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return schemas.settings(schema, compose(config_name=name, overrides=list(overrides)))


def path_overrides(pipeline: Any) -> list[str]:
    """The pipeline's (resolved, absolute) ``paths`` as overrides for a stage's own config."""
    paths = Paths.from_config(schemas.settings(schemas.PipelineConfig, pipeline).paths)
    out = []
    for key in Paths.__dataclass_fields__:
        value = str(getattr(paths, key))
        if "'" in value:
            raise PipelineError(f"paths.{key} may not contain a quote: {value!r}")
        out.append(f"paths.{key}='{value}'")
    return out


def stage_overrides(name: str, pipeline: Any) -> list[str]:
    """The pipeline's paths, then ``overrides.<name>`` (``pipeline``: its settings,
    :class:`schemas.PipelineConfig`, or a mapping of their fields)."""
    p = schemas.settings(schemas.PipelineConfig, pipeline)
    return [*path_overrides(p), *getattr(p.overrides, name)]


@dataclass
class Decided:
    """What the identification rule decided on the data, for the stages after fit."""

    #: the excitation the models identify on (None: the first configured one)
    identified: str | None = None
    #: the kinds held out (None or empty: the configured ``heldout``)
    heldout: list[str] | None = None


def _identified(plan: Any, pipeline: schemas.PipelineConfig) -> str:
    """The excitation the models of this pipeline identify on: the first configured one, or,
    when the data has none of those, the first the identification rule added."""
    configured = list(pipeline.fit_excitations)
    if plan.marked:  # runs a manifest or mapping marks for identification decide
        ds = plan.dataset
        kinds = ds.loc[ds["run_id"].astype(str).isin(plan.marked), "excitation"].astype(str)
        return str(kinds.value_counts().index[0])
    added = [k for k in plan.fit_excitations if k not in configured]
    present = set(plan.dataset["excitation"].astype(str))
    return str(configured[0] if configured[0] in present or not added else added[0])


def stage_config(name: str, pipeline: Any, decided: Decided | None = None) -> Any:
    """The typed settings of stage ``name`` in this pipeline: ``conf/<name>.yaml`` +
    ``overrides.<name>`` + the pipeline's shared values (:class:`schemas.PipelineConfig`)
    + what the identification rule decided (``decided``)."""
    p = schemas.settings(schemas.PipelineConfig, pipeline)
    decided = decided or Decided()
    own = compose_stage(name, stage_overrides(name, p))
    identified = decided.identified or next(iter(p.fit_excitations), None)
    if identified is None:
        raise PipelineError("fit_excitations is empty and no identification run was found; "
                            "name the excitation that identifies, e.g. "
                            "fit_excitations=[sine_decay]")
    shared: dict[str, Any] = {"paths": p.paths, "tracking": p.tracking or {},
                              "n_jobs": p.n_jobs, "cache": p.cache}
    if name in ("fit", "validate"):
        shared |= {"config": p.config, "fit_excitations": p.fit_excitations,
                   "fit_runs": p.fit_runs, "signals": p.signals,
                   "single_run_heldout_fraction": p.single_run_heldout_fraction}
    if name == "validate":
        shared |= {"heldout": p.heldout, "cross": p.cross}
    if name == "unseen_shape":
        shared |= {"fit_excitation": identified, "config": p.config, "signals": p.signals}
        heldout = decided.heldout or p.heldout
        if heldout:
            shared["eval_excitations"] = list(heldout)
    if name == "report":
        shared["fit_excitation"] = identified
    if name in ("fit", "validate"):
        shared["progress"] = p.progress
    return replace(own, **copy.deepcopy(shared))


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


def run_generate_stage(pipeline: schemas.PipelineConfig) -> dict[str, Any]:
    """The virtual-rig campaign in this process, as ``python -m pipelines.generate`` does."""
    report = generate_core.generate(compose_stage("generate",
                                                  stage_overrides("generate", pipeline)))
    log.info("generate: %d runs written, %d unchanged -> %s", len(report["written"]),
             len(report["skipped"]), report["out"])
    return report


def run_ingest_stage(pipeline: schemas.PipelineConfig) -> dict[str, Any]:
    """Ingest in this process, as ``python -m pipelines.ingest`` does.

    Rejected runs are reported and left out; the pipeline goes on with the accepted ones
    (``python -m pipelines.ingest`` alone exits 1 instead).
    """
    settings = compose_stage("ingest", stage_overrides("ingest", pipeline))
    if own_data(pipeline):
        if not pipeline.source:
            raise PipelineError(
                f"importer {_importer_name(pipeline)!r} is set but no source: name the folder "
                f"of your logs, e.g. source=../shared/real-data/tendon-catheter")
        settings = replace(settings, source=str(pipeline.source), importer=pipeline.importer)
    report = ingest_core.ingest(settings)
    for rej in report.get("rejected", []):
        log.warning("ingest rejected %s: %s", rej.get("source"), rej.get("reason"))
    if not report.get("n_accepted"):
        raise PipelineError(f"ingest accepted no run from {settings.source}")
    return report


def own_data(pipeline: schemas.PipelineConfig) -> bool:
    """True when the pipeline runs on the user's logs (``importer=...`` and/or
    ``source=...``) instead of the virtual campaign."""
    return bool(pipeline.importer or pipeline.source)


def _importer_name(pipeline: schemas.PipelineConfig) -> str:
    imp = pipeline.importer
    return str(imp.get("name", "?")) if isinstance(imp, Mapping) else "none (tsm-rig-log/1)"


def run_pipeline(cfg: Any) -> PipelineResult:
    """Hydra-free core of ``make pipeline`` (``cfg``: its settings,
    :class:`pipelines.schemas.PipelineConfig`, composed or a mapping of their fields)."""
    p = schemas.settings(schemas.PipelineConfig, cfg)
    paths = Paths.from_config(p.paths)
    paths.root.mkdir(parents=True, exist_ok=True)
    wanted = list(p.stages)
    if own_data(p) and "generate" in wanted:
        log.info("run_all: your own data (importer %s, source %s): no virtual campaign is "
                 "generated", _importer_name(p), p.source)
        wanted.remove("generate")
    unknown = [s for s in wanted if s not in (*EXTERNAL_STAGES, *OWN_STAGES)]
    if unknown:
        raise PipelineError(f"unknown stage(s) {unknown}; known: "
                            f"{[*EXTERNAL_STAGES, *OWN_STAGES]}")
    tracker = tracker_for(p)
    state = _Progress()
    try:
        return _Run(p, paths, tracker, wanted, state).all()
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


@dataclass
class _Run:
    """One ``make pipeline``: the stages in order, each timed, then MLflow and the registry."""

    p: schemas.PipelineConfig
    paths: Paths
    tracker: Any
    wanted: list[str]
    state: _Progress
    result: PipelineResult = field(default_factory=PipelineResult)
    decided: Decided = field(default_factory=Decided)
    #: the rows the identification rule kept (the unseen-shape study's data)
    planned: pd.DataFrame | None = None
    dataset: pd.DataFrame | None = None
    #: the parent run's start (epoch seconds): its duration is the whole pipeline's
    started: float = field(default_factory=time.time)

    @contextmanager
    def timed(self, stage: str, *, running: bool = True) -> Iterator[None]:
        """Time ``stage`` into the result's timings (``running``: the stage a failure names)."""
        if running:
            self.state.stage = stage
        t0 = time.perf_counter()
        yield
        self.result.timings[stage] = time.perf_counter() - t0

    def settings(self, stage: str) -> Any:
        return stage_config(stage, self.p, self.decided)

    def all(self) -> PipelineResult:
        total = time.perf_counter()
        if self.tracker.enabled:
            # Before any parallel worker exists: schema creation must happen exactly once.
            with self.timed("tracking_init", running=False):
                self.tracker.init_store()
        self.data_stages()
        self.model_stages()
        self.report_and_tracking()
        if self.tracker.enabled:
            from pipelines import registry

            with self.timed("registry"):
                registry.register_pipeline(
                    self.tracker, tracking_group(self.p.tracking).registry,
                    fit_excitation=self.decided.identified or next(
                        iter(self.p.fit_excitations), "sine_decay"),
                    fits=self.result.fits, metrics=self.result.metrics,
                    processed=self.paths.processed)
        return self.finish(total)

    def data_stages(self) -> None:
        """generate and ingest, then the dataset and what the identification rule decides."""
        if "generate" in self.wanted:
            with self.timed("generate"):
                self.result.generate_report = run_generate_stage(self.p)
        if "ingest" in self.wanted:
            with self.timed("ingest"):
                self.result.ingest_report = run_ingest_stage(self.p)
        if not any(s in self.wanted for s in ("fit", "validate", "unseen_shape")):
            return
        with self.timed("read_dataset", running=False):
            self.dataset = read_processed(self.paths.processed, stage_columns(self.p.signals))
        # the identification rule, as fit and validate apply it, for the later stages
        plan = identification_plan(self.settings("validate"), self.dataset, self.paths)
        self.decided = Decided(_identified(plan, self.p), list(plan.heldout))
        self.planned = plan.dataset

    def model_stages(self) -> None:
        """fit, validate and the unseen-shape study on the dataset read once."""
        result = self.result
        if "fit" in self.wanted:
            with self.timed("fit"):
                result.fits = fit_core.run(self.settings("fit"), dataset=self.dataset)
        if "validate" in self.wanted:
            with self.timed("validate"):
                # exactly the models of this invocation (not every model file left on disk)
                result.metrics, _ = validate_core.run(self.settings("validate"),
                                                      dataset=self.dataset, fits=result.fits)
        if "unseen_shape" not in self.wanted:
            return
        why = (unseen_core.not_applicable(self.planned) if self.planned is not None
               else None)
        if why is not None:
            log.warning("unseen_shape: skipped: %s", why)
            return
        with self.timed("unseen_shape"):
            result.unseen_shape = unseen_core.run(self.settings("unseen_shape"),
                                                  dataset=self.planned, fits=result.fits)

    def report_and_tracking(self) -> None:
        """The report, while MLflow's child runs are logged in a background thread (the
        report's figures render in worker processes); the figures are attached after."""
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="mlflow") as pool:
            pending = None
            if self.tracker.enabled:
                # (Hydra's compose is not thread-safe: the fit settings are made here.)
                fit_settings = self.settings("fit")
                pending = pool.submit(_track_start, self.tracker, self.p, fit_settings,
                                      self.paths, self.result, self.state, self.started,
                                      self.decided)
            if "report" in self.wanted:
                with self.timed("report"):
                    self.result.report = report_core.run(
                        self.settings("report"), metrics=self.result.metrics,
                        fits=self.result.fits)
            if pending is not None:
                self.finish_tracking(pending)

    def finish_tracking(self, pending: Any) -> None:
        t0 = time.perf_counter()
        self.state.stage = "tracking"
        tracking_state: TrackState = pending.result()
        result = self.result
        if tracking_state.parent is None and _outputs_changed(result):
            tracking_state.parent = _open_parent(
                self.tracker, self.p, self.paths, result, self.state, self.started,
                self.decided, tags={**tracking_state.tags, "up_to_date": "true",
                                    "same_as": tracking_state.same_as})
        if tracking_state.parent is not None:
            _track_finish(self.tracker, tracking_state, result)
        else:
            log.info("tracking: nothing changed since MLflow run %s (same data, models, "
                     "metrics, report and shape study): nothing new logged",
                     tracking_state.same_as)
        result.parent_run_id = tracking_state.parent
        result.up_to_date = tracking_state.up_to_date
        # time spent on MLflow beyond the stages it overlapped with
        result.timings["tracking"] = time.perf_counter() - t0
        result.timings["tracking_overlapped"] = tracking_state.seconds

    def finish(self, total: float) -> PipelineResult:
        result = self.result
        result.timings["total"] = time.perf_counter() - total
        write_text_atomic(self.paths.reports / "pipeline_timing.json",
                          json.dumps({k: round(v, 3) for k, v in result.timings.items()},
                                     indent=1))
        if self.tracker.enabled and result.parent_run_id:
            self.tracker.log(result.parent_run_id, metrics={
                f"stage_seconds.{k}": v for k, v in result.timings.items()})
            self.tracker.end_run(result.parent_run_id)
            self.state.parent = None  # ended: nothing left to mark FAILED
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


def _track_start(tracker: Any, p: schemas.PipelineConfig, fit_settings: Any,
                 paths: Paths, result: PipelineResult, progress: _Progress,
                 started: float | None = None, decided: Decided | None = None) -> TrackState:
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
    parent = _open_parent(tracker, p, paths, result, progress, started, decided, tags=tags)
    state = TrackState(parent, False, tags=tags)
    units = dataset_units(paths.processed)
    hydra_dir = hydra_output_dir()
    if fits is not None:
        base = TrackContext.params(fit_settings, "family", "family_overrides", "families")
        ids = tracking.log_model_runs(
            tracker, parent, fits=fits, metrics=metrics, base_params=base, tags=tags,
            hydra_dir=hydra_dir / ".hydra" if hydra_dir else None, plots=None,
            stage="pipeline", progress=p.progress, units=units,
        )
        lineage.log_model_inputs(tracker, ids, fits, metrics, processed=paths.processed)
        labels = [Configuration(str(r["rig"]), tracking.finite_or_none(r["curve_angle_deg"]),
                                tracking.finite_or_none(r["radius_mm"])).label
                  for r in fits.to_dict("records")]
        state.children = list(zip(ids, labels, strict=True))
    state.seconds = time.perf_counter() - start
    return state


def _open_parent(tracker: Any, p: schemas.PipelineConfig, paths: Paths,
                 result: PipelineResult, progress: _Progress, started: float | None,
                 decided: Decided | None = None, *, tags: Mapping[str, str]) -> str:
    """The pipeline's parent run, started at ``started``, with its params, data and tables;
    ``tags`` carry the dataset hash and the pipeline key (hashed once, by the caller)."""
    from pipelines import lineage, tracking

    fits, metrics = result.fits, result.metrics
    params = {k: v for k, v in asdict(p).items() if k != "tracking"}
    if decided is not None and decided.identified is not None:
        params |= {"identified_excitation": decided.identified,
                   "planned_heldout": decided.heldout}
    parent = tracker.start_run("pipeline", tags={"stage": "pipeline", "kind": "parent",
                                                 **tags},
                               note=_pipeline_note(p, fits, paths), start_time=started)
    progress.parent = parent  # from here on a failure anywhere ends this run FAILED
    tracker.log(parent, params=tracking.flatten(params))
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


def _pipeline_note(p: schemas.PipelineConfig, fits: pd.DataFrame | None, paths: Paths) -> str:
    """The pipeline parent run's description."""
    source = (f"your logs ({_importer_name(p)}, {p.source})" if own_data(p)
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
    if state.parent is None:
        return
    if result.unseen_shape is not None:
        unseen_core.log_result(tracker, state.parent, result.unseen_shape)
    rep = result.report
    if rep is not None and (not state.up_to_date or not rep.cached):
        report_core.log_report(tracker, state.parent, rep)
    if rep is not None:
        for run_id, label in state.children:
            for fig in rep.config_plots.get(label, []):
                tracker.log_artifact(run_id, fig, "plots")
    if not state.up_to_date:
        tracker.log(state.parent, tags={"complete": "true"})


STAGE = Stage("pipeline", schemas.PipelineConfig, run=run_pipeline)


if __name__ == "__main__":
    STAGE.main()
