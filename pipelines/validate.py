"""Stage ``validate``: every fitted model predicts the runs of its own configuration.

    python -m pipelines.validate
    python -m pipelines.validate cross=true            # the full cross-excitation matrix

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

import hydra
import pandas as pd
import pyarrow as pa

from pipelines import cache, schemas, stages
from pipelines.artifacts import (
    load_models,
    prediction_path,
    read_prediction_meta,
    write_predictions,
)
from pipelines.common import (
    Paths,
    dataset_hash,
    hydra_output_dir,
    hydra_sweep_dir,
    identification_plan,
    read_processed,
    run_stage,
    stage_columns,
    to_container,
)
from pipelines.stages import Configuration, RunSignal
from rig_io.atomic import atomic_path, clean_leftovers, write_text_atomic

log = logging.getLogger(__name__)


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


def run(cfg: Mapping[str, Any], *, dataset: pd.DataFrame | None = None,
        fits: pd.DataFrame | None = None) -> tuple[pd.DataFrame, list[str]]:
    """Hydra-free core: config in, (metrics table, error messages) out; writes the files.

    ``fits`` defaults to every model file under ``${paths.models}`` in the selection.
    """
    cfg = schemas.with_defaults(schemas.ValidateConfig, cfg)
    paths = Paths.from_config(cfg["paths"])
    clean_leftovers(paths.predictions)  # temporaries of a killed validate
    clean_leftovers(paths.reports, recursive=False)
    if dataset is None:
        dataset = read_processed(paths.processed, stage_columns(cfg["signals"]))
    plan = identification_plan(cfg, dataset, paths)
    dataset = plan.dataset
    input_col, output_col = str(cfg["signals"]["input"]), str(cfg["signals"]["output"])
    stages.check_dataset(dataset, signals=(input_col, output_col))
    sel = cfg["config"]
    configs = stages.configurations(dataset, rig=sel["rig"],
                                    curve_angle_deg=sel["curve_angle_deg"],
                                    radius_mm=sel["radius_mm"])
    fit_excitations = list(plan.fit_excitations)
    if fits is None:
        fits = load_models(paths.models)
    fits = select_fits(fits, configs, fit_excitations)
    if fits.empty:
        raise stages.PipelineError(
            f"no fitted model for the selected configurations and fit excitations "
            f"{fit_excitations} under {paths.models}; run `make fit` first"
        )
    heldout = list(plan.heldout)
    cross = bool(cfg["cross"])
    settings = {"heldout": heldout, "cross": cross, "signals": [input_col, output_col]}
    use_cache = bool(cfg["cache"])

    start = time.perf_counter()
    done: list[pd.DataFrame] = []
    done_runs: list[pd.DataFrame] = []
    errors: list[str] = []
    todo: list[tuple[pd.DataFrame, dict[str, list[RunSignal]], str, Path, Configuration]] = []
    by_label = {c.label: c for c in configs}
    located = stages.ConfigurationRows(dataset)
    for label, group in fits.groupby(
        fits.apply(lambda r: Configuration(str(r["rig"]), stages._num(r["curve_angle_deg"]),
                                           stages._num(r["radius_mm"])).label, axis=1),
        sort=True,
    ):
        config = by_label[str(label)]
        signals = stages.run_signals(located.rows(config), input_col=input_col,
                                     output_col=output_col)
        key = stages.validation_key(group, signals, settings)
        path = prediction_path(paths.predictions, config)
        meta = read_prediction_meta(path) if use_cache and path.exists() else None
        if meta is not None and meta.get("key") == key and "run_metrics" in meta:
            done.append(stages.metrics_frame(meta["metrics"]))
            done_runs.append(stages.run_metrics_frame(meta["run_metrics"]))
            errors.extend(meta.get("errors", []))
        else:
            todo.append((group, signals, key, path, config))
    n_jobs = 1 if hydra_sweep_dir() is not None else int(cfg["n_jobs"])
    results = _run_tasks(todo, heldout=heldout, cross=cross, n_jobs=n_jobs,
                         progress=bool(cfg["progress"]))
    for metrics, by_run, errs in results:
        done.append(metrics)
        done_runs.append(by_run)
        errors.extend(errs)
    metrics = stages.sort_metrics(pd.concat(done, ignore_index=True)) if done else \
        stages.metrics_frame([])
    metrics = stages.metrics_frame(metrics.to_dict("records"))
    write_metrics(metrics, paths)
    runs_table = stages.run_metrics_frame(
        pd.concat(done_runs, ignore_index=True).to_dict("records") if done_runs else [])
    write_table(runs_table, paths.reports / "metrics_by_run")
    _warn_if_nothing_held_out(metrics, heldout)
    write_text_atomic(paths.reports / "validate_errors.json", json.dumps(errors, indent=1))
    log.info("validate: %d configurations (%d recomputed), %d metric rows in %.1f s",
             len(done), len(todo), len(metrics), time.perf_counter() - start)
    for e in errors:
        log.warning("validate: %s", e)
    return metrics, errors


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
    write_table(metrics, paths.metrics_parquet.with_suffix(""))


def write_table(table: pd.DataFrame, stem: Path) -> None:
    """``<stem>.parquet`` and ``<stem>.csv``, atomically, only when the content changed."""

    parquet, csv = stem.with_suffix(".parquet"), stem.with_suffix(".csv")
    new_hash = cache.hash_frame(table)
    if parquet.exists() and csv.exists():
        try:
            if cache.hash_frame(pd.read_parquet(parquet)) == new_hash:
                return
        except (OSError, pa.ArrowException):
            pass
    with atomic_path(parquet) as tmp:
        table.to_parquet(tmp, index=False)
    with atomic_path(csv) as tmp:
        table.to_csv(tmp, index=False)


def main_cfg(cfg: Any) -> pd.DataFrame:
    """What ``python -m pipelines.validate`` does with its composed config (also MLflow)."""
    from pipelines import tracking

    started = time.time()  # its own parent run spans the work, not only the logging
    plain = to_container(cfg)
    paths = Paths.from_config(plain["paths"])
    tracker = tracking.Tracker(tracking.settings_from_config(plain["tracking"],
                                                             root=paths.root))
    if tracker.enabled:
        tracker.init_store()  # a locked or damaged store stops the stage before the work
    metrics, errors = run(plain)
    if tracker.enabled:
        with tracking.StageRun(tracker, "validate", sweep_dir=hydra_sweep_dir(),
                                start_time=started) as stage_run:
            assert stage_run.parent_id is not None
            tracker.log(stage_run.parent_id,
                        params=tracking.flatten({k: v for k, v in plain.items()
                                                 if k != "tracking"}),
                        tags={"dataset_hash": dataset_hash(paths.processed)})
            from pipelines import lineage

            lineage.log_stage_inputs(tracker, stage_run.parent_id, metrics,
                                     processed=paths.processed)
            tracker.log_table(stage_run.parent_id, metrics, "metrics.json")
            tracker.log_artifact(stage_run.parent_id, paths.metrics_csv, "tables")
            hydra_dir = hydra_output_dir()
            if hydra_dir is not None:
                tracker.log_artifact(stage_run.parent_id, hydra_dir / ".hydra", ".hydra")
    return metrics


@hydra.main(config_path="../conf", config_name="validate", version_base="1.3")
def main(cfg: Any) -> None:
    run_stage("validate", lambda: main_cfg(cfg))


if __name__ == "__main__":
    from pipelines.cli import guard

    guard("validate")
    main()
