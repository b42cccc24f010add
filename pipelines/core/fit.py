"""The core of stage ``fit`` (no Hydra, no MLflow; its command
is :mod:`pipelines.fit`; the command line is in its docstring).

Fitted models are written as JSON to ``${paths.models}/<family>/<configuration>__<kind>.json``
(with the content key that produced them); a model whose data, configuration and family code
are unchanged is read back instead of being fitted again.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from pipelines import cache, schemas, stages
from pipelines.artifacts import load_models, save_models
from pipelines.common import (
    CONF_DIR,
    Paths,
    hydra_sweep_dir,
    identification_plan,
    read_processed,
    stage_columns,
)
from pipelines.stages import FamilySpec, FitTask, PipelineError
from rig_io.atomic import clean_leftovers

log = logging.getLogger("pipelines.fit")  # the stage's name, as its command logs


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


def family_specs(settings: Any, *, conf_dir: Path = CONF_DIR) -> list[FamilySpec]:
    """The families this invocation fits (``settings``: :class:`schemas.FitConfig`, or a
    mapping of its fields).

    A selected ``family`` group (``family=gamma``) gives exactly that family with its
    (possibly overridden) hyper-parameters; otherwise every name in ``families``
    (``all`` = :func:`hysteresis.family_names`), each from ``conf/family/<name>.yaml`` with
    ``family_overrides.<name>`` merged on top.
    """
    s = schemas.settings(schemas.FitConfig, settings)
    if s.family:
        fam = dict(s.family)
        if "_target_" not in fam:
            raise PipelineError(f"family config has no _target_: {fam}")
        cls = _target_class(str(fam["_target_"]))
        name = str(getattr(cls, "family", cls.__name__))
        return [FamilySpec(name, fam, instantiate_family, cache.source_hash(cls))]
    specs = []
    for name in _family_names(s.families):
        fam = family_file_config(name, conf_dir=conf_dir)
        fam.update(dict(s.family_overrides.get(name) or {}))
        cls = _target_class(str(fam["_target_"]))
        specs.append(FamilySpec(name, fam, instantiate_family, cache.source_hash(cls)))
    if not specs:
        raise PipelineError("no model family registered or selected")
    return specs


def _family_names(wanted: Any) -> list[str]:
    """``families`` as names: ``all`` (or null) = every registered family."""
    if wanted in (None, "all"):
        from hysteresis.base import family_names

        return list(family_names())
    return [str(n) for n in ([wanted] if isinstance(wanted, str) else wanted)]


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


def run(settings: Any, *, dataset: pd.DataFrame | None = None) -> pd.DataFrame:
    """Hydra-free core of the stage: settings (:class:`schemas.FitConfig`, or a mapping of
    its fields) in, fits table out.

    Reads the processed dataset (unless given), fits what is not cached, writes model files.
    """
    s = schemas.settings(schemas.FitConfig, settings)
    paths = Paths.from_config(s.paths)
    clean_leftovers(paths.models)  # temporaries of a killed fit
    if dataset is None:
        dataset = read_processed(paths.processed, stage_columns(s.signals))
    sel = s.config
    configs = stages.configurations(dataset, rig=sel.rig, curve_angle_deg=sel.curve_angle_deg,
                                    radius_mm=sel.radius_mm)
    plan = identification_plan(s, dataset, paths)
    tasks = stages.plan_fits(plan.dataset, family_specs(s), configs,
                             fit_excitations=plan.fit_excitations, fit_runs=plan.chosen,
                             marked=plan.marked, input_col=s.signals.input,
                             output_col=s.signals.output, max_samples=s.max_samples)
    previous = load_models(paths.models) if s.cache else None
    # the multirun launcher already runs jobs in parallel
    n_jobs = 1 if hydra_sweep_dir() is not None else s.n_jobs
    start = time.perf_counter()
    fits = stages.fit_models(tasks, previous=previous,
                             runner=joblib_runner(n_jobs, progress=s.progress))
    save_models(fits, paths.models)
    fresh = int((~fits["cached"]).sum())
    log.info("fit: %d models (%d fitted, %d cached) in %.1f s", len(fits), fresh,
             len(fits) - fresh, time.perf_counter() - start)
    for row in fits[fits["error"].notna()].to_dict("records"):
        log.warning("fit failed: %s %s phi=%s r=%s: %s", row["family"], row["rig"],
                    row["curve_angle_deg"], row["radius_mm"], row["error"])
    return fits


def fit_metrics(fits: pd.DataFrame, dataset: pd.DataFrame, signals: schemas.Signals
                ) -> pd.DataFrame:
    """In-sample metrics (split ``fit``) of the given fits, for the stage's own MLflow runs."""
    frames = []
    located = stages.ConfigurationRows(dataset)
    for _, group in fits.groupby(["rig", "curve_angle_deg", "radius_mm"], dropna=False):
        first = group.iloc[0]
        config = stages.Configuration(str(first["rig"]), stages._num(first["curve_angle_deg"]),
                                      stages._num(first["radius_mm"]))
        by_kind = stages.run_signals(located.rows(config), input_col=signals.input,
                                     output_col=signals.output)
        metrics, _, _ = stages.evaluate_configuration(group, by_kind, heldout=[], cross=False)
        frames.append(metrics)
    return pd.concat(frames, ignore_index=True) if frames else stages.metrics_frame([])
