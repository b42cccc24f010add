"""Stage ``fit``: every model family x every configuration, identified on the
identification excitation (default ``sine_decay``) of the processed dataset.

    python -m pipelines.fit
    python -m pipelines.fit family=gamma config.curve_angle_deg=90
    python -m pipelines.fit -m family=gamma,bouc_wen config.curve_angle_deg=15,90

Fitted models are written as JSON to ``${paths.models}/<family>/<configuration>__<kind>.json``
(with the content key that produced them); a model whose data, configuration and family code
are unchanged is read back instead of being fitted again.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import hydra
import pandas as pd

from pipelines import cache, schemas, stages
from pipelines.artifacts import load_models, save_models
from pipelines.common import (
    CONF_DIR,
    Paths,
    dataset_hash,
    dataset_units,
    hydra_output_dir,
    hydra_sweep_dir,
    identification_plan,
    read_processed,
    run_stage,
    stage_columns,
    to_container,
)
from pipelines.stages import FamilySpec, FitTask, PipelineError
from rig_io.atomic import clean_leftovers

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------
# families from config
# --------------------------------------------------------------------------------------


def instantiate_family(config: Mapping[str, Any]) -> Any:
    """Hydra ``instantiate`` of a family config (``_target_`` + hyper-parameters)."""
    from hydra.utils import instantiate

    from hysteresis.base import HysteresisModel

    model = instantiate(dict(config), _convert_="all")
    if not isinstance(model, HysteresisModel):
        raise PipelineError(f"{config.get('_target_')!r} is not a HysteresisModel")
    return model


def _target_class(target: str) -> type:
    from hydra.utils import get_class

    return get_class(target)


def family_file_config(name: str, *, conf_dir: Path = CONF_DIR) -> dict[str, Any]:
    """``conf/family/<name>.yaml`` as a dict; the registered class alone if there is none."""
    from omegaconf import OmegaConf

    path = conf_dir / "family" / f"{name}.yaml"
    if path.is_file():
        data = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
        assert isinstance(data, dict)
        data.pop("defaults", None)
        if "_target_" in data:
            return {str(k): v for k, v in data.items()}
    from hysteresis.base import family_class

    cls = family_class(name)
    return {"_target_": f"{cls.__module__}.{cls.__qualname__}"}


def family_specs(cfg: Mapping[str, Any], *, conf_dir: Path = CONF_DIR) -> list[FamilySpec]:
    """The families this invocation fits.

    A selected ``family`` group (``family=gamma``) gives exactly that family with its
    (possibly overridden) hyper-parameters; otherwise every name in ``families``
    (``all`` = :func:`hysteresis.family_names`), each from ``conf/family/<name>.yaml`` with
    ``family_overrides.<name>`` merged on top.
    """
    cfg = schemas.with_defaults(schemas.FitConfig, cfg)
    selected = cfg["family"]
    if selected:
        fam = dict(selected)
        if "_target_" not in fam:
            raise PipelineError(f"family config has no _target_: {fam}")
        cls = _target_class(str(fam["_target_"]))
        name = str(getattr(cls, "family", cls.__name__))
        return [FamilySpec(name, fam, instantiate_family, cache.source_hash(cls))]
    wanted = cfg["families"]
    if wanted in (None, "all"):
        from hysteresis.base import family_names

        names = family_names()
    else:
        names = [str(n) for n in ([wanted] if isinstance(wanted, str) else wanted)]
    overrides = cfg["family_overrides"]
    specs = []
    for name in names:
        fam = family_file_config(name, conf_dir=conf_dir)
        fam.update(dict(overrides.get(name) or {}))
        cls = _target_class(str(fam["_target_"]))
        specs.append(FamilySpec(name, fam, instantiate_family, cache.source_hash(cls)))
    if not specs:
        raise PipelineError("no model family registered or selected")
    return specs


# --------------------------------------------------------------------------------------
# model files
# --------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------
# the stage
# --------------------------------------------------------------------------------------


#: Identification runs from this many samples on are announced before fitting: each such
#: fit takes minutes rather than seconds.
LARGE_RUN = 200_000


def joblib_runner(n_jobs: int, *, progress: bool) -> Callable[..., list[dict[str, Any]]]:
    """Map ``fit_task`` over tasks with joblib processes (a tqdm bar as results come back).

    Each finished fit is logged with its time and the elapsed total (INFO without the bar,
    DEBUG beside it), and fits on large runs are announced first, so a long stage never
    runs silent."""

    def run(fn: Callable[[FitTask], dict[str, Any]],
            tasks: Sequence[FitTask]) -> list[dict[str, Any]]:
        done = _progress_log(tasks, progress=progress)
        if n_jobs == 1 or len(tasks) == 1:
            items = tasks
            if progress:
                from tqdm import tqdm

                items = tqdm(tasks, desc="fit", unit="model")
            return [done(fn(t)) for t in items]
        from joblib import Parallel, delayed

        # Slow families first, so the last task to start is a quick one.
        order = sorted(range(len(tasks)), key=lambda i: _expected_cost(tasks[i]), reverse=True)
        par = Parallel(n_jobs=n_jobs, return_as="generator", batch_size=1)
        gen = par(delayed(fn)(tasks[i]) for i in order)
        if progress:
            from tqdm import tqdm

            gen = tqdm(gen, total=len(tasks), desc="fit", unit="model")
        out: list[dict[str, Any]] = [{}] * len(tasks)
        for i, r in zip(order, gen, strict=True):
            out[i] = done(r)
        return out

    return run


def _progress_log(tasks: Sequence[FitTask], *, progress: bool
                  ) -> Callable[[dict[str, Any]], dict[str, Any]]:
    """Announce fits on large runs; return the callback logging each finished fit."""
    def longest(t: FitTask) -> stages.RunSignal:
        return max(t.runs, key=lambda r: r.u.size)

    large = [t for t in tasks if longest(t).u.size >= LARGE_RUN]
    if large:
        big = longest(max(large, key=lambda t: longest(t).u.size))
        log.info("fit: %d of %d models identify on runs of %d samples or more (largest: %s, "
                 "%d samples); each may take minutes", len(large), len(tasks), LARGE_RUN,
                 big.run_id, big.u.size)
    start = time.perf_counter()
    level = logging.DEBUG if progress else logging.INFO
    count = [0]

    def done(row: dict[str, Any]) -> dict[str, Any]:
        count[0] += 1
        config = stages.Configuration(str(row["rig"]), stages._num(row["curve_angle_deg"]),
                                      stages._num(row["radius_mm"]))
        log.log(level, "fit %d/%d: %s %s %s, %d samples: %.1f s%s (elapsed %.1f s)",
                count[0], len(tasks), row["family"], config.label, row["fit_excitation"],
                row["n_samples"], row["fit_seconds"], " FAILED" if row.get("error") else "",
                time.perf_counter() - start)
        return row

    return done


_COST_HINT = {"coleman_hodgdon": 4, "bouc_wen": 3, "preisach": 2, "gamma": 1, "linear": 0}


def _expected_cost(task: FitTask) -> int:
    return _COST_HINT.get(task.family.name, 2)


def run(cfg: Mapping[str, Any], *, dataset: pd.DataFrame | None = None) -> pd.DataFrame:
    """Hydra-free core of the stage: config (plain mapping) in, fits table out.

    Reads the processed dataset (unless given), fits what is not cached, writes model files.
    """
    cfg = schemas.with_defaults(schemas.FitConfig, cfg)
    paths = Paths.from_config(cfg["paths"])
    clean_leftovers(paths.models)  # temporaries of a killed fit
    if dataset is None:
        dataset = read_processed(paths.processed, stage_columns(cfg["signals"]))
    input_col, output_col = str(cfg["signals"]["input"]), str(cfg["signals"]["output"])
    sel = cfg["config"]
    configs = stages.configurations(dataset, rig=sel["rig"],
                                    curve_angle_deg=sel["curve_angle_deg"],
                                    radius_mm=sel["radius_mm"])
    plan = identification_plan(cfg, dataset, paths)
    tasks = stages.plan_fits(plan.dataset, family_specs(cfg), configs,
                             fit_excitations=plan.fit_excitations, fit_runs=plan.chosen,
                             marked=plan.marked, input_col=input_col, output_col=output_col,
                             max_samples=int(cfg["max_samples"]))
    previous = load_models(paths.models) if cfg["cache"] else None
    progress = bool(cfg["progress"])
    n_jobs = int(cfg["n_jobs"])
    if hydra_sweep_dir() is not None:
        n_jobs = 1  # the multirun launcher already runs jobs in parallel
    start = time.perf_counter()
    fits = stages.fit_models(tasks, previous=previous,
                             runner=joblib_runner(n_jobs, progress=progress))
    save_models(fits, paths.models)
    fresh = int((~fits["cached"]).sum())
    log.info("fit: %d models (%d fitted, %d cached) in %.1f s", len(fits), fresh,
             len(fits) - fresh, time.perf_counter() - start)
    for row in fits[fits["error"].notna()].to_dict("records"):
        log.warning("fit failed: %s %s phi=%s r=%s: %s", row["family"], row["rig"],
                    row["curve_angle_deg"], row["radius_mm"], row["error"])
    return fits


def fit_metrics(fits: pd.DataFrame, dataset: pd.DataFrame, cfg: Mapping[str, Any]
                ) -> pd.DataFrame:
    """In-sample metrics (split ``fit``) of the given fits, for the stage's own MLflow runs."""
    sig = cfg["signals"]
    frames = []
    located = stages.ConfigurationRows(dataset)
    for _, group in fits.groupby(["rig", "curve_angle_deg", "radius_mm"], dropna=False):
        first = group.iloc[0]
        config = stages.Configuration(str(first["rig"]), stages._num(first["curve_angle_deg"]),
                                      stages._num(first["radius_mm"]))
        signals = stages.run_signals(located.rows(config),
                                     input_col=str(sig["input"]), output_col=str(sig["output"]))
        metrics, _, _ = stages.evaluate_configuration(group, signals, heldout=[], cross=False)
        frames.append(metrics)
    return pd.concat(frames, ignore_index=True) if frames else stages.metrics_frame([])


def main_cfg(cfg: Any) -> pd.DataFrame:
    """What ``python -m pipelines.fit`` does with its composed config (also MLflow)."""
    from pipelines import tracking

    started = time.time()  # its own parent run spans the work, not only the logging
    plain = to_container(cfg)
    paths = Paths.from_config(plain["paths"])
    settings = tracking.settings_from_config(plain["tracking"], root=paths.root)
    tracker = tracking.Tracker(settings)
    if tracker.enabled:
        tracker.init_store()  # a locked or damaged store stops the stage before the fits
    dataset = read_processed(paths.processed)
    fits = run(plain, dataset=dataset)
    if tracker.enabled:
        # a model this store already holds (same key: data, config and code) is not logged
        # again: a re-run that changes nothing adds no run
        fresh = fits[~fits["key"].astype(str).isin(tracker.logged_model_keys("fit"))]
        if fresh.empty:
            log.info("fit: every model is already in the MLflow store; nothing new logged")
            return fits
        _track_fits(tracker, plain, paths, dataset, fresh, started)
    return fits


def _track_fits(tracker: Any, plain: dict[str, Any], paths: Paths, dataset: pd.DataFrame,
                fits: pd.DataFrame, started: float) -> None:
    """The stage's parent run and one child run per model in ``fits``."""
    from pipelines import tracking

    with tracking.StageRun(tracker, "fit", sweep_dir=hydra_sweep_dir(),
                            start_time=started) as stage_run:
        assert stage_run.parent_id is not None
        base = tracking.flatten({k: v for k, v in plain.items()
                                 if k not in ("family", "family_overrides", "tracking")})
        hydra_dir = hydra_output_dir()
        plan = identification_plan(plain, dataset, paths)
        if plan.notes:
            tracker.log_text(stage_run.parent_id, json.dumps(dict(plan.notes), indent=1),
                             "identification_plan.json")
        ids = tracking.log_model_runs(
            tracker, stage_run.parent_id, fits=fits,
            metrics=fit_metrics(fits, plan.dataset, plain), base_params=base,
            tags={"dataset_hash": dataset_hash(paths.processed)},
            hydra_dir=hydra_dir / ".hydra" if hydra_dir else None, stage="fit",
            units=dataset_units(paths.processed),
        )
        from pipelines import lineage

        lineage.log_model_inputs(tracker, ids, fits, None, processed=paths.processed,
                                 dataset=dataset)


@hydra.main(config_path="../conf", config_name="fit", version_base="1.3")
def main(cfg: Any) -> None:
    run_stage("fit", lambda: main_cfg(cfg))


if __name__ == "__main__":
    from pipelines.cli import guard

    guard("fit")
    main()
