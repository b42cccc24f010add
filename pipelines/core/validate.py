"""The core of stage ``validate`` (no Hydra, no MLflow; its command
is :mod:`pipelines.validate`; the command line is in its docstring).

Metrics for every (family, configuration, fit excitation, evaluation excitation) go to
``${paths.reports}/metrics.parquet`` and ``metrics.csv`` (columns
:data:`pipelines.stages.METRICS_COLUMNS`); the predictions, one parquet file per
configuration under ``${paths.predictions}``, feed the report's plots. A configuration whose
models and data are unchanged is read back from its predictions file instead of recomputed.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from pipelines import artifacts, schemas, stages
from pipelines.artifacts import (
    load_models,
    prediction_path,
    read_prediction_meta,
    write_predictions,
)
from pipelines.common import (
    Paths,
    hydra_sweep_dir,
    identification_plan,
    read_processed,
    stage_columns,
)
from pipelines.stages import Configuration, RunSignal
from rig_io.atomic import clean_leftovers, write_text_atomic

log = logging.getLogger("pipelines.validate")  # the stage's name, as its command logs


def validate_configuration(
    fits: pd.DataFrame,
    signals: Mapping[str, list[RunSignal]],
    *,
    heldout: Sequence[str],
    cross: bool,
    key: str,
    path: Path,
    config: Configuration,
) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """Evaluate one configuration and write its predictions file (a joblib task):
    (pooled metrics, per-run metrics, errors)."""
    metrics, preds, errors = stages.evaluate_configuration(fits, signals, heldout=heldout,
                                                           cross=cross)
    by_run = stages.run_metrics(preds, metrics, config)
    for col in ("family", "fit_excitation", "eval_excitation", "run_id"):
        if col in preds:
            preds[col] = preds[col].astype("category")
    record = {"key": key, "metrics": metrics.to_dict("records"),
              "run_metrics": by_run.to_dict("records"), "errors": errors}
    write_predictions(path, preds, record)
    return metrics, by_run, errors


def select_fits(fits: pd.DataFrame, configs: Sequence[Configuration],
                fit_excitations: Sequence[str]) -> pd.DataFrame:
    labels = {c.label for c in configs}
    keep = fits.apply(
        lambda r: Configuration(str(r["rig"]), stages._num(r["curve_angle_deg"]),
                                stages._num(r["radius_mm"])).label in labels, axis=1
    ) if not fits.empty else pd.Series([], dtype=bool)
    out = fits[keep.astype(bool) & fits["fit_excitation"].isin(list(fit_excitations))]
    return out.reset_index(drop=True)


def run(settings: Any, *, dataset: pd.DataFrame | None = None,
        fits: pd.DataFrame | None = None) -> tuple[pd.DataFrame, list[str]]:
    """Hydra-free core: settings (:class:`schemas.ValidateConfig`, or a mapping of its
    fields) in, (metrics table, error messages) out; writes the files.

    ``fits`` defaults to every model file under ``${paths.models}`` in the selection.
    """
    s = schemas.settings(schemas.ValidateConfig, settings)
    paths = Paths.from_config(s.paths)
    clean_leftovers(paths.predictions)  # temporaries of a killed validate
    clean_leftovers(paths.reports, recursive=False)
    if dataset is None:
        dataset = read_processed(paths.processed, stage_columns(s.signals))
    plan = identification_plan(s, dataset, paths)
    dataset = plan.dataset
    stages.check_dataset(dataset, signals=(s.signals.input, s.signals.output))
    configs = stages.configurations(dataset, rig=s.config.rig,
                                    curve_angle_deg=s.config.curve_angle_deg,
                                    radius_mm=s.config.radius_mm)
    fits = select_fits(load_models(paths.models) if fits is None else fits, configs,
                       list(plan.fit_excitations))
    if fits.empty:
        raise stages.PipelineError(
            f"no fitted model for the selected configurations and fit excitations "
            f"{list(plan.fit_excitations)} under {paths.models}; run `make fit` first"
        )
    heldout = list(plan.heldout)
    start = time.perf_counter()
    done, todo = _cached_configurations(s, fits, configs, dataset, heldout, paths)
    n_jobs = 1 if hydra_sweep_dir() is not None else s.n_jobs
    done += _run_tasks(todo, heldout=heldout, cross=s.cross, n_jobs=n_jobs,
                       progress=s.progress)
    metrics = _write_outputs(done, paths, heldout)
    errors = [e for _, _, errs in done for e in errs]
    log.info("validate: %d configurations (%d recomputed), %d metric rows in %.1f s",
             len(done), len(todo), len(metrics), time.perf_counter() - start)
    for e in errors:
        log.warning("validate: %s", e)
    return metrics, errors


_Task = tuple[pd.DataFrame, dict[str, list[RunSignal]], str, Path, Configuration]
_Done = tuple[pd.DataFrame, pd.DataFrame, list[str]]


def _config_label(row: Mapping[str, Any]) -> str:
    return Configuration(str(row["rig"]), stages._num(row["curve_angle_deg"]),
                         stages._num(row["radius_mm"])).label


def _cached_configurations(s: schemas.ValidateConfig, fits: pd.DataFrame,
                           configs: Sequence[Configuration], dataset: pd.DataFrame,
                           heldout: list[str], paths: Paths
                           ) -> tuple[list[_Done], list[_Task]]:
    """Each configuration's results read back from its predictions file where its key (the
    models, the runs and the settings) is unchanged, else a task to compute them."""
    keyed = {"heldout": heldout, "cross": s.cross,
             "signals": [s.signals.input, s.signals.output]}
    done: list[_Done] = []
    todo: list[_Task] = []
    by_label = {c.label: c for c in configs}
    located = stages.ConfigurationRows(dataset)
    for label, group in fits.groupby(fits.apply(_config_label, axis=1), sort=True):
        config = by_label[str(label)]
        signals = stages.run_signals(located.rows(config), input_col=s.signals.input,
                                     output_col=s.signals.output)
        key = stages.validation_key(group, signals, keyed)
        path = prediction_path(paths.predictions, config)
        meta = read_prediction_meta(path) if s.cache and path.exists() else None
        if meta is not None and meta.get("key") == key and "run_metrics" in meta:
            done.append((stages.metrics_frame(meta["metrics"]),
                         stages.run_metrics_frame(meta["run_metrics"]),
                         list(meta.get("errors", []))))
        else:
            todo.append((group, signals, key, path, config))
    return done, todo


def _write_outputs(done: Sequence[_Done], paths: Paths, heldout: Sequence[str]
                   ) -> pd.DataFrame:
    """metrics, metrics_by_run and validate_errors.json from every configuration's results."""
    frames = [m for m, _, _ in done]
    metrics = stages.sort_metrics(pd.concat(frames, ignore_index=True)) if frames else \
        stages.metrics_frame([])
    metrics = stages.metrics_frame(metrics.to_dict("records"))
    write_metrics(metrics, paths)
    by_run = [r for _, r, _ in done]
    runs_table = stages.run_metrics_frame(
        pd.concat(by_run, ignore_index=True).to_dict("records") if by_run else [])
    artifacts.write_table_pair(runs_table, paths.reports / artifacts.METRICS_BY_RUN)
    _warn_if_nothing_held_out(metrics, heldout)
    errors = [e for _, _, errs in done for e in errs]
    write_text_atomic(paths.reports / "validate_errors.json", json.dumps(errors, indent=1))
    return metrics


def _warn_if_nothing_held_out(metrics: pd.DataFrame, heldout: Sequence[str]) -> None:
    """Every score in-sample is worth a loud line: a champion would be chosen on how well a
    model fits its own identification data."""
    if metrics.empty or (metrics["split"] == "heldout").any():
        return
    log.warning(
        "validate: NOTHING HELD OUT WAS SCORED: every metric is in-sample (split 'fit'). "
        "No run has a held-out excitation kind %s and no run is marked held out; list the "
        "kinds with heldout=[...] or give runs `role: held_out` in their manifest or mapping",
        list(heldout))


def _run_tasks(todo: Sequence[tuple[pd.DataFrame, dict[str, list[RunSignal]], str, Path,
                                    Configuration]], *,
               heldout: Sequence[str], cross: bool, n_jobs: int, progress: bool
               ) -> list[tuple[pd.DataFrame, pd.DataFrame, list[str]]]:
    if not todo:
        return []
    if n_jobs == 1 or len(todo) == 1:
        items: Any = todo
        if progress:
            from tqdm import tqdm

            items = tqdm(todo, desc="validate", unit="config")
        return [validate_configuration(g, s, heldout=heldout, cross=cross, key=k, path=p,
                                       config=c)
                for g, s, k, p, c in items]
    from joblib import Parallel, delayed

    gen: Any = Parallel(n_jobs=n_jobs, return_as="generator")(
        delayed(validate_configuration)(g, s, heldout=heldout, cross=cross, key=k, path=p,
                                        config=c)
        for g, s, k, p, c in todo)
    if progress:
        from tqdm import tqdm

        gen = tqdm(gen, total=len(todo), desc="validate", unit="config")
    return list(gen)


def write_metrics(metrics: pd.DataFrame, paths: Paths) -> None:
    """``metrics.parquet`` and ``metrics.csv``, atomically, only when the content changed."""
    artifacts.write_table_pair(metrics, paths.reports / artifacts.METRICS)
