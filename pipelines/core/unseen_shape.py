"""The core of stage ``unseen_shape`` (no Hydra, no MLflow; its command
is :mod:`pipelines.unseen_shape`; the command line is in its docstring).

Leave-one-configuration-out over every configuration of the rig: for each configuration and
family, three predictors score the configuration's evaluation runs (``eval_excitations``):

* ``own``: the configuration's own model (identified on its own record: the reference);
* ``nearest``: the model of the nearest other configuration (scaled wrap angle x curvature);
* ``shape_aware``: :class:`hysteresis.shape_aware.ShapeAwareModel` fitted on the models of
  every *other* configuration, asked for this one.

Writes ``${paths.reports}/unseen_shape.parquet`` (columns :data:`COLUMNS`, one row per family x
configuration x predictor), ``unseen_shape_summary.csv`` (per family: median RMSE of each
predictor, the shape-aware / own ratio, in how many configurations shape-aware beats nearest,
whether the targets hold) and ``plots/unseen_shape.png``; reads only the fit stage's model
files and the processed dataset. Nothing is recomputed when its inputs are unchanged.
"""

from __future__ import annotations

import json
import logging
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.base import HysteresisModel, family_class
from hysteresis.shape_aware import (
    ShapeAwareModel,
    leave_one_out_models,
    refit_on_common_structure,
)
from pipelines import artifacts, cache, schemas, stages
from pipelines.common import (
    Paths,
    hydra_sweep_dir,
    read_processed,
    stage_columns,
)
from pipelines.skeleton import KeyFile
from pipelines.stages import Configuration, PipelineError, RunSignal
from rig_io.atomic import atomic_path

log = logging.getLogger("pipelines.unseen_shape")  # the stage's name, as its command logs
COLUMNS = ("family", "curve_angle_deg", "radius_mm", "predictor", "rmse")
PREDICTORS = ("own", "nearest", "shape_aware")
KEY_FILE = "unseen_shape_key.json"
#: The targets for the best family: shape-aware median LOO RMSE at most this times
#: the own-configuration median, and below the nearest model in this share of configurations.
RATIO_TARGET = 1.15
BELOW_NEAREST_SHARE = 20 / 24


@dataclass
class UnseenShapeResult:
    table: pd.DataFrame
    summary: pd.DataFrame
    files: list[Path] = field(default_factory=list)
    best_family: str | None = None
    cached: bool = False
    seconds: float = 0.0

    def mlflow_metrics(self) -> dict[str, float]:
        """``unseen_shape.<family>.<name>`` for every summary number (MLflow metric keys)."""
        out: dict[str, float] = {}
        for row in self.summary.to_dict("records"):
            for key, value in row.items():
                if key != "family" and isinstance(value, (int, float, np.number, bool)):
                    out[f"unseen_shape.{row['family']}.{key}"] = float(value)
        return out


def _rmse(model: HysteresisModel, runs: Sequence[RunSignal]) -> float:
    errs = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for run in runs:
            errs.append(run.y - run.predict(model))
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e * e)))


def leave_one_out(family: str, configs: Sequence[Configuration],
                  models: Sequence[HysteresisModel], runs: Mapping[str, Sequence[RunSignal]],
                  estimator: Mapping[str, Any],
                  records: Sequence[tuple[np.ndarray, np.ndarray] | None] | None = None,
                  ) -> list[dict[str, Any]]:
    """Rows (:data:`COLUMNS`) of one family: own, nearest and shape-aware per configuration.

    ``runs`` maps a configuration label to its evaluation runs. A predictor whose model
    fails to simulate scores NaN (recorded, never raised). ``records``: each configuration's
    identification ``(u, y)``; when the other configurations' models chose different
    structures (Gamma's play widths), the shape-aware model is learnt from models refitted
    on them with one common structure (the own and nearest predictors keep the fit stage's
    models).
    """
    rows: list[dict[str, Any]] = []
    shapes = [(float(c.curve_angle_deg or 0.0), float(c.radius_mm or 0.0)) for c in configs]
    n = len(configs)
    memo: dict[tuple[Any, str], HysteresisModel] = {}
    sse_memo: dict[tuple[Any, str], float] = {}

    def training(others: Sequence[int]) -> tuple[list[HysteresisModel], str | None]:
        """The fold's training models and the common structure they were refitted on."""
        train = [models[j] for j in others]
        if records is None or any(records[j] is None for j in others):
            return train, None
        refits, cand = refit_on_common_structure(
            train, [records[j] for j in others], keys=others,  # type: ignore[misc]
            memo=memo, sse_memo=sse_memo)
        return refits, (json.dumps(cand, sort_keys=True) if cand else None)

    folds = [[j for j in range(n) if j != i] for i in range(n)]
    trained = [training(others) for others in folds]
    # Folds learning from the same kind of models (the fit stage's, or refits on one common
    # structure) are one regression with one row left out each: solved once for all of them.
    closed: dict[int, tuple[HysteresisModel, int]] = {}
    for tag in dict.fromkeys(t for _, t in trained):
        members = [i for i in range(n) if trained[i][1] == tag]
        if len(members) < 2:
            continue
        full = list(models) if tag is None else _refits_on(tag, models, records, memo)
        solved = leave_one_out_models(shapes, full, base_family=family, **dict(estimator))
        closed.update({i: solved[i] for i in members if solved[i] is not None})  # type: ignore[misc]

    for i, config in enumerate(configs):
        others = folds[i]
        phi, r = shapes[i]
        if i in closed:
            model_i, near = closed[i]
            offered = {"own": models[i], "nearest": models[near], "shape_aware": model_i}
        else:  # a fold the closed form does not cover: fitted on its own
            sa = ShapeAwareModel(base_family=family, **dict(estimator))
            sa.fit([shapes[j] for j in others], trained[i][0])
            offered = {}
        for name in PREDICTORS:
            try:
                model = (offered[name] if offered
                         else _predictor(name, i, others, models, sa, phi, r))
                value = _rmse(model, runs[config.label])
            except Exception as exc:  # noqa: BLE001 - one bad prediction must not stop the rest
                log.warning("unseen_shape: %s %s %s: %s: %s", family, config.label, name,
                            type(exc).__name__, exc)
                value = float("nan")
            rows.append({"family": family, "curve_angle_deg": phi, "radius_mm": r,
                         "predictor": name, "rmse": value})
    return rows


def _refits_on(tag: str, models: Sequence[HysteresisModel],
               records: Sequence[tuple[np.ndarray, np.ndarray] | None] | None,
               memo: dict[tuple[Any, str], HysteresisModel]) -> list[HysteresisModel]:
    """Every configuration's model refitted on the structure ``tag`` (from ``memo`` where a
    fold already fitted it)."""
    assert records is not None
    cand = json.loads(tag)
    out = []
    for j, model in enumerate(models):
        if (j, tag) not in memo:
            u, y = records[j]  # type: ignore[misc]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                memo[(j, tag)] = type(model)(**{**model.get_params(), **cand}).fit(u, y)
        out.append(memo[(j, tag)])
    return out


def _predictor(name: str, i: int, others: Sequence[int], models: Sequence[HysteresisModel],
               sa: ShapeAwareModel, phi: float, r: float) -> HysteresisModel:
    """The model predictor ``name`` offers for configuration ``i`` at shape (phi, r);
    ``sa`` was fitted without it."""
    if name == "own":
        return models[i]
    if name == "nearest":
        return models[others[sa.nearest_index(phi, r)]]
    return sa.model_for(phi, r)


def summarise(table: pd.DataFrame) -> pd.DataFrame:
    """Per family: median RMSE per predictor, shape-aware / own, configurations beating nearest.

    ``meets_targets``: ratio <= :data:`RATIO_TARGET` and shape-aware below nearest in at least
    :data:`BELOW_NEAREST_SHARE` of the configurations (20 of 24).
    """
    cols = ["family", "configurations", "median_own", "median_nearest", "median_shape_aware",
            "ratio_shape_aware_to_own", "shape_aware_below_nearest", "meets_targets"]
    if table.empty:
        return pd.DataFrame(columns=cols)
    wide = table.pivot_table(index=["family", "curve_angle_deg", "radius_mm"],
                             columns="predictor", values="rmse", dropna=False).reset_index()
    rows = []
    for fam, g in wide.groupby("family", sort=True):
        n = len(g)
        med = {p: float(g[p].median()) for p in PREDICTORS}
        ratio = med["shape_aware"] / med["own"] if med["own"] > 0 else float("nan")
        below = int((g["shape_aware"] < g["nearest"]).sum())
        rows.append({"family": fam, "configurations": n, "median_own": med["own"],
                     "median_nearest": med["nearest"], "median_shape_aware": med["shape_aware"],
                     "ratio_shape_aware_to_own": ratio, "shape_aware_below_nearest": below,
                     "meets_targets": bool(ratio <= RATIO_TARGET
                                           and below >= BELOW_NEAREST_SHARE * n - 1e-9)})
    return pd.DataFrame(rows, columns=cols)


def _family_task(family: str, configs: list[Configuration], model_json: list[str],
                 runs: dict[str, list[RunSignal]], estimator: dict[str, Any],
                 records: list[tuple[np.ndarray, np.ndarray] | None] | None = None
                 ) -> list[dict[str, Any]]:
    models = [stages.load_model(j) for j in model_json]
    if type(models[0]).structure_candidates(models):
        log.info("unseen_shape: %s: the configurations' fits chose different structures; each "
                 "fold's shape-aware model learns from refits on the structure that fits its "
                 "training configurations best", family)
    return leave_one_out(family, configs, models, runs, estimator, records)


def identification_record(by_kind: Mapping[str, Sequence[RunSignal]], run_ids: str,
                          n_samples: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``(u, y)`` a fit row identified on (its first ``n_samples``: a single-run
    configuration identifies on the run's head), or None when the run is not in the data."""
    wanted = run_ids.split(",")
    found = [r for rs in by_kind.values() for r in rs if r.run_id in wanted]
    if len(found) != 1 or found[0].u.size < n_samples:
        return None
    return found[0].u[:n_samples], found[0].y[:n_samples]


#: Fewest configurations with a curve angle and a radius that a leave-one-out study needs.
MIN_SHAPED_CONFIGURATIONS = 2


def not_applicable(dataset: pd.DataFrame) -> str | None:
    """Why the stage cannot run on ``dataset`` (None when it can): it predicts a sheath shape
    from the others, so it needs configurations that record a shape."""
    configs = stages.configurations(dataset)
    shaped = [c for c in configs if c.has_shape]
    if len(shaped) >= MIN_SHAPED_CONFIGURATIONS:
        return None
    names = ", ".join(c.label for c in configs)
    return (f"it needs {MIN_SHAPED_CONFIGURATIONS} or more configurations with a curve angle "
            f"and a radius, the data has {len(shaped)} ({names})")


def run(settings: Any, *, dataset: pd.DataFrame | None = None,
        fits: pd.DataFrame | None = None) -> UnseenShapeResult:
    """Hydra-free core: settings (:class:`schemas.UnseenShapeConfig`, or a mapping of its
    fields) in, :class:`UnseenShapeResult` out; writes under reports/."""
    from pipelines.artifacts import load_models

    start = time.perf_counter()
    s = schemas.settings(schemas.UnseenShapeConfig, settings)
    paths = Paths.from_config(s.paths)
    if dataset is None:
        dataset = read_processed(paths.processed, stage_columns(s.signals))
    stages.check_dataset(dataset, signals=(s.signals.input, s.signals.output))
    configs = _study_configurations(dataset, s.config)
    models = _Models.select(load_models(paths.models) if fits is None else fits, configs, s)
    runs, signals = _evaluation_runs(dataset, configs, s)
    key = _content_key(s, models, runs)
    reports = paths.reports
    out_table = reports / "unseen_shape.parquet"
    out_summary = reports / artifacts.UNSEEN_SHAPE_SUMMARY
    plot = reports / "plots" / "unseen_shape.png"
    keyfile = KeyFile(reports / KEY_FILE, enabled=s.cache, needs=(out_table,))
    if keyfile.hit(key) is not None:
        table = pd.read_parquet(out_table)
        summary = summarise(table)
        done = [p for p in (out_table, out_summary, plot) if p.exists()]
        log.info("unseen_shape: up to date (%s)", key)
        return UnseenShapeResult(table, summary, done, _best(summary), cached=True,
                                 seconds=time.perf_counter() - start)

    tasks = _family_tasks(models, configs, runs, signals, asdict(s.estimator))
    table = _loo_table(tasks, n_jobs=1 if hydra_sweep_dir() is not None else s.n_jobs)
    summary = summarise(table)
    files: list[Path] = []
    with atomic_path(out_table) as tmp:
        table.to_parquet(tmp, index=False)
    files.append(out_table)
    with atomic_path(out_summary) as tmp:
        summary.to_csv(tmp, index=False)
    files.append(out_summary)
    if s.plot and not table.empty:
        files.append(figure(table, plot, dpi=s.dpi))
    keyfile.store(key)
    seconds = time.perf_counter() - start
    best = _best(summary)
    log.info("unseen_shape: %d families x %d configurations in %.1f s; best %s", len(tasks),
             len(configs), seconds, best)
    return UnseenShapeResult(table, summary, files, best, cached=False, seconds=seconds)


def _study_configurations(dataset: pd.DataFrame, sel: schemas.ConfigurationSelection
                          ) -> list[Configuration]:
    """The selected configurations with a shape, of the rig with the most of them."""
    configs = stages.configurations(dataset, rig=sel.rig, curve_angle_deg=sel.curve_angle_deg,
                                    radius_mm=sel.radius_mm)
    configs = [c for c in configs if c.curve_angle_deg is not None and c.radius_mm is not None]
    if not configs:
        raise PipelineError("unseen_shape needs configurations with a curve angle and a radius")
    rigs = sorted({c.rig for c in configs}, key=lambda r: -sum(c.rig == r for c in configs))
    return [c for c in configs if c.rig == rigs[0]]


@dataclass
class _Models:
    """The fit stage's models the study uses, per family and configuration label."""

    #: family -> label -> model JSON
    json: dict[str, dict[str, str]] = field(default_factory=dict)
    #: family -> label -> (identification run ids, samples identified on)
    fit_rows: dict[str, dict[str, tuple[str, int]]] = field(default_factory=dict)
    keys: list[str] = field(default_factory=list)

    @classmethod
    def select(cls, fits: pd.DataFrame, configs: Sequence[Configuration],
               s: schemas.UnseenShapeConfig) -> _Models:
        ok = fits[(fits["fit_excitation"] == s.fit_excitation) & fits["model_json"].notna()] \
            if not fits.empty else fits
        labels = {c.label for c in configs}
        out = cls()
        for rec in ok.to_dict("records"):
            c = Configuration(str(rec["rig"]), stages._num(rec["curve_angle_deg"]),
                              stages._num(rec["radius_mm"]))
            if c.label not in labels or (s.families and rec["family"] not in s.families):
                continue
            fam = str(rec["family"])
            out.json.setdefault(fam, {})[c.label] = str(rec["model_json"])
            out.fit_rows.setdefault(fam, {})[c.label] = (
                str(rec.get("fit_run_ids") or ""), int(rec.get("n_samples") or 0))
            out.keys.append(str(rec["key"]))
        return out


def _evaluation_runs(dataset: pd.DataFrame, configs: Sequence[Configuration],
                     s: schemas.UnseenShapeConfig
                     ) -> tuple[dict[str, list[RunSignal]], dict[str, dict[str, list[RunSignal]]]]:
    """Per configuration label: the runs scored, and every run by excitation kind."""
    runs: dict[str, list[RunSignal]] = {}
    signals: dict[str, dict[str, list[RunSignal]]] = {}
    located = stages.ConfigurationRows(dataset)
    for c in configs:
        by_kind = stages.run_signals(located.rows(c), input_col=s.signals.input,
                                     output_col=s.signals.output)
        signals[c.label] = by_kind
        kinds = list(s.eval_excitations) or sorted(k for k in by_kind if k != s.fit_excitation)
        runs[c.label] = [r for k in kinds for r in by_kind.get(k, [])]
    return runs, signals


def _content_key(s: schemas.UnseenShapeConfig, models: _Models,
                 runs: Mapping[str, Sequence[RunSignal]]) -> str:
    """What the study's outputs are made from: models, settings, data and code."""
    keyed = {"fit_excitation": s.fit_excitation, "eval_excitations": list(s.eval_excitations),
             "estimator": asdict(s.estimator), "families": s.families,
             "signals": [s.signals.input, s.signals.output]}
    return cache.combine({
        "stage": "unseen_shape", "models": sorted(models.keys), "settings": keyed,
        "data": sorted(r.data_hash for rs in runs.values() for r in rs),
        # the refits on a common structure run the families' own code
        "code": [cache.hash_files([Path(__file__),
                                   *cache.code_files("hysteresis.shape_aware").values()]),
                 *(cache.hash_files(cache.code_files(family_class(f).__module__).values())
                   for f in sorted(models.json))],
    })


def _family_tasks(models: _Models, configs: Sequence[Configuration],
                  runs: Mapping[str, list[RunSignal]],
                  signals: Mapping[str, Mapping[str, Sequence[RunSignal]]],
                  estimator: dict[str, Any]) -> list[tuple[Any, ...]]:
    """One leave-one-out task per family with at least 3 configurations to learn from."""
    tasks = []
    for fam, labelled in sorted(models.json.items()):
        have = [c for c in configs if c.label in labelled and runs[c.label]]
        if len(have) < 3:
            log.warning("unseen_shape: %s has %d configuration(s) with a model and evaluation "
                        "runs; leave-one-out needs 3", fam, len(have))
            continue
        tasks.append((fam, have, [labelled[c.label] for c in have],
                      {c.label: runs[c.label] for c in have}, estimator,
                      [identification_record(signals[c.label], *models.fit_rows[fam][c.label])
                       for c in have]))
    return tasks


def _loo_table(tasks: Sequence[tuple[Any, ...]], *, n_jobs: int) -> pd.DataFrame:
    """The tasks' rows (:data:`COLUMNS`), typed and sorted."""
    if n_jobs > 1 and len(tasks) > 1:
        from joblib import Parallel, delayed

        # slow simulators first, so the two workers finish together
        order = sorted(tasks, key=lambda t: t[0] not in ("preisach", "bouc_wen"))
        results = Parallel(n_jobs=n_jobs)(delayed(_family_task)(*t) for t in order)
    else:
        results = [_family_task(*t) for t in tasks]
    rows = [row for res in results for row in res]
    table = pd.DataFrame(rows, columns=list(COLUMNS))
    table["family"] = table["family"].astype("string")
    table["predictor"] = table["predictor"].astype("string")
    for col in ("curve_angle_deg", "radius_mm", "rmse"):
        table[col] = table[col].astype("float64")
    return table.sort_values(["family", "curve_angle_deg", "radius_mm", "predictor"],
                             kind="stable").reset_index(drop=True)


def _best(summary: pd.DataFrame) -> str | None:
    """The family whose shape-aware model predicts unseen shapes best (lowest median)."""
    if summary.empty or summary["median_shape_aware"].isna().all():
        return None
    return str(summary.loc[summary["median_shape_aware"].idxmin(), "family"])


def figure(table: pd.DataFrame, path: Path, *, dpi: int = 72) -> Path:
    """Per family: each configuration's RMSE under the three predictors."""
    from pipelines import plots  # sets the Agg backend before pyplot loads

    plt = plots.plt  # type: ignore[attr-defined]
    fams = sorted(table["family"].astype(str).unique())
    fig, axes = plt.subplots(len(fams), 1, figsize=(10, 2.2 * len(fams) + 0.6), squeeze=False,
                             sharex=True)
    style = {"own": ("k", "o"), "nearest": ("#d62728", "x"), "shape_aware": ("#1f77b4", "s")}
    for ax, fam in zip(axes[:, 0], fams, strict=True):
        sub = table[table["family"] == fam]
        labels: list[str] = []
        for pred in PREDICTORS:
            p = sub[sub["predictor"] == pred].sort_values(["curve_angle_deg", "radius_mm"])
            labels = [f"{a:g}/{r:g}" for a, r in zip(p["curve_angle_deg"], p["radius_mm"],
                                                     strict=True)]
            color, marker = style[pred]
            ax.plot(np.arange(len(p)), p["rmse"], marker=marker, color=color, lw=0.8,
                    label=f"{pred} (median {p['rmse'].median():.3g})")
        ax.set_ylabel("RMSE")
        ax.set_title(fam, fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
        ax.set_xticks(np.arange(len(labels)), labels, rotation=90, fontsize=6)
    axes[-1, 0].set_xlabel("held-out configuration (curve angle deg / radius mm)")
    fig.suptitle("Leave-one-configuration-out: own model vs nearest vs shape-aware", fontsize=10)
    fig.tight_layout()
    return plots._save(fig, path, dpi)


def log_result(tracker: Any, run_id: str, result: UnseenShapeResult) -> None:
    """Summary numbers as metrics, the tables and the plot as artifacts of ``run_id``."""
    tracker.log(run_id, metrics=result.mlflow_metrics(),
                tags={"unseen_shape.best_family": str(result.best_family)})
    for f in result.files:
        tracker.log_artifact(run_id, f, "unseen_shape")
