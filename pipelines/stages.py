"""The fit -> validate -> report logic as pure functions: DataFrames in, DataFrames out.

No files, no Hydra, no MLflow here (the entry points ``pipelines/fit.py`` etc. do the I/O).
The processed dataset is the ingest contract: one row per sample with at least ``run_id``,
``rig``, ``curve_angle_deg``, ``radius_mm``, ``excitation``, ``t_s`` and the signal columns.

A *configuration* is one sheath shape on one rig: ``(rig, curve_angle_deg, radius_mm)``.
Every family is identified on the configuration's identification run(s) and evaluated on
the runs of the same configuration; the metrics table has one row per
(family, configuration, fit excitation, evaluation excitation).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.metrics import METRIC_NAMES, error_statistics
from hysteresis.roles import (
    HELDOUT,
    IDENTIFICATION,
    TAIL,
    check_heldout_fraction,
    manifest_role,
    normalise_role,
    split_note,
    tail_start,
)
from pipelines import cache

#: The columns of ``data/reports/metrics.parquet``, in order.
METRICS_COLUMNS: tuple[str, ...] = (
    "family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation", "eval_excitation",
    "split", *METRIC_NAMES,
)
log = logging.getLogger(__name__)
CONFIG_COLUMNS = ("rig", "curve_angle_deg", "radius_mm")
#: Columns of the fit results table (one row per family x configuration x fit excitation).
FIT_COLUMNS: tuple[str, ...] = (
    "family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation", "fit_run_ids",
    "n_samples", "key", "model_json", "params_json", "fit_seconds", "error", "cached",
)
#: Columns of the predictions table (long format, one row per sample and model).
PREDICTION_COLUMNS: tuple[str, ...] = (
    "family", "fit_excitation", "eval_excitation", "run_id", "t_s", "input", "output",
    "predicted",
)
REQUIRED_DATASET_COLUMNS = ("run_id", "rig", "curve_angle_deg", "radius_mm", "excitation", "t_s")


class PipelineError(Exception):
    """Bad input to a pipeline stage (missing column, unknown excitation, no data ...)."""


# --------------------------------------------------------------------------------------
# configurations and runs
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, order=True)
class Configuration:
    """One sheath shape on one rig. Angles/radii are ``None`` where the rig does not know."""

    rig: str
    curve_angle_deg: float | None
    radius_mm: float | None

    @property
    def label(self) -> str:
        """File- and MLflow-safe name, e.g. ``tsm-bench_phi090_r030``; a rig that records no
        sheath shape (a catheter, a joint) is named by its rig alone."""
        if self.curve_angle_deg is None and self.radius_mm is None:
            return self.rig
        return f"{self.rig}_phi{_fmt(self.curve_angle_deg)}_r{_fmt(self.radius_mm)}"

    @property
    def has_shape(self) -> bool:
        return self.curve_angle_deg is not None and self.radius_mm is not None

    def as_dict(self) -> dict[str, Any]:
        return {"rig": self.rig, "curve_angle_deg": self.curve_angle_deg,
                "radius_mm": self.radius_mm}


def _fmt(value: float | None) -> str:
    if value is None:
        return "NA"
    return f"{value:03.0f}" if float(value).is_integer() else f"{value:g}".replace(".", "p")


def _num(value: Any) -> float | None:
    if value is None or (isinstance(value, float) and math.isnan(value)) or value is pd.NA:
        return None
    return float(value)


def check_dataset(dataset: pd.DataFrame, *, signals: Sequence[str]) -> None:
    """Raise :class:`PipelineError` naming every required column the dataset lacks."""
    missing = [c for c in (*REQUIRED_DATASET_COLUMNS, *signals) if c not in dataset.columns]
    if missing:
        raise PipelineError(
            f"processed dataset lacks column(s) {missing}; it has {list(dataset.columns)}"
        )
    if dataset.empty:
        raise PipelineError("processed dataset is empty")


def _as_values(selector: Any) -> list[Any] | None:
    """``None`` (= all), a scalar or a list -> list of wanted values."""
    if selector is None:
        return None
    if isinstance(selector, str) or not isinstance(selector, Iterable):
        return [selector]
    values = list(selector)
    return values or None


def configurations(
    dataset: pd.DataFrame,
    *,
    rig: Any = None,
    curve_angle_deg: Any = None,
    radius_mm: Any = None,
) -> list[Configuration]:
    """The configurations present in ``dataset``, filtered by the given values (None = all)."""
    check_dataset(dataset, signals=())
    keys = dataset[list(CONFIG_COLUMNS)].drop_duplicates()
    found = sorted(
        {
            Configuration(str(r.rig), _num(r.curve_angle_deg), _num(r.radius_mm))
            for r in keys.itertuples(index=False)
        },
        key=lambda c: (c.rig, c.curve_angle_deg or -1.0, c.radius_mm or -1.0),
    )
    wanted_rig = _as_values(rig)
    wanted_phi = _as_values(curve_angle_deg)
    wanted_r = _as_values(radius_mm)
    out = [
        c for c in found
        if (wanted_rig is None or c.rig in {str(v) for v in wanted_rig})
        and (wanted_phi is None or _matches(c.curve_angle_deg, wanted_phi))
        and (wanted_r is None or _matches(c.radius_mm, wanted_r))
    ]
    if not out:
        raise PipelineError(
            f"no configuration matches rig={rig!r} curve_angle_deg={curve_angle_deg!r} "
            f"radius_mm={radius_mm!r}; the dataset has {[c.label for c in found]}"
        )
    return out


def _matches(value: float | None, wanted: list[Any]) -> bool:
    if value is None:
        return any(w is None for w in wanted)
    return any(w is not None and abs(float(w) - value) < 1e-9 for w in wanted)


def config_rows(dataset: pd.DataFrame, config: Configuration) -> pd.DataFrame:
    """The samples of one configuration (all its runs)."""
    mask = dataset["rig"].astype(str) == config.rig
    for col in ("curve_angle_deg", "radius_mm"):
        value = getattr(config, col)
        column = pd.to_numeric(dataset[col], errors="coerce")
        mask &= column.isna() if value is None else (column - value).abs() < 1e-9
    return dataset.loc[mask]


class ConfigurationRows:
    """The samples of each configuration, located in one pass over the dataset.

    :func:`config_rows` compares every row of the dataset for each configuration, so a stage
    calling it per configuration grows with the square of the map's size; this keeps only
    the row positions of each configuration (no copy of the data) and takes its rows on
    demand.
    """

    def __init__(self, dataset: pd.DataFrame) -> None:
        self.dataset = dataset
        groups = dataset.groupby(list(CONFIG_COLUMNS), sort=False, dropna=False,
                                 observed=True).indices
        self._positions = {Configuration(str(k[0]), _num(k[1]), _num(k[2])): v
                           for k, v in groups.items()}

    def rows(self, config: Configuration) -> pd.DataFrame:
        """What ``config_rows(dataset, config)`` returns."""
        positions = self._positions.get(config)
        if positions is None:  # a value that matches only within config_rows' tolerance
            return config_rows(self.dataset, config)
        return self.dataset.iloc[positions]


@dataclass(frozen=True)
class RunSignal:
    """The input/output of one run, time-ordered, with a hash of exactly these values."""

    run_id: str
    excitation: str
    t_s: np.ndarray
    u: np.ndarray
    y: np.ndarray
    data_hash: str
    #: The input before this record, when it is the held-out tail of a run: a model is run
    #: through it first, so the tail is predicted from the state the head left (the input is
    #: known; no output of the tail is used).
    lead_in: np.ndarray | None = None

    def predict(self, model: Any) -> np.ndarray:
        """``model``'s prediction of this record (from rest, or after its lead-in)."""
        if self.lead_in is None or self.lead_in.size == 0:
            return np.asarray(model.predict(self.u), dtype=np.float64)
        full = np.asarray(model.predict(np.concatenate([self.lead_in, self.u])),
                          dtype=np.float64)
        return full[self.lead_in.size:]


def run_signals(
    rows: pd.DataFrame, *, input_col: str = "input", output_col: str = "output"
) -> dict[str, list[RunSignal]]:
    """Runs of one configuration grouped by excitation kind (runs sorted by ``run_id``).

    Samples where the input or the output is missing are dropped (a bending-joint run whose
    output comes from a camera has gaps); a run left with fewer than 2 samples is skipped.
    """
    out: dict[str, list[RunSignal]] = {}
    for run_id, run in rows.groupby("run_id", sort=True, observed=True):
        run = run.sort_values("t_s", kind="stable")
        t = run["t_s"].to_numpy(dtype=np.float64)
        u = pd.to_numeric(run[input_col], errors="coerce").to_numpy(dtype=np.float64)
        y = pd.to_numeric(run[output_col], errors="coerce").to_numpy(dtype=np.float64)
        ok = np.isfinite(u) & np.isfinite(y) & np.isfinite(t)
        if ok.sum() < 2:
            warnings.warn(f"run {run_id!r}: fewer than 2 finite samples, skipped", stacklevel=2)
            continue
        t, u, y = t[ok], u[ok], y[ok]
        kind = str(run["excitation"].iloc[0])
        out.setdefault(kind, []).append(
            RunSignal(str(run_id), kind, t, u, y, cache.hash_arrays(t, u, y))
        )
    heads = {r.run_id: r for runs in out.values() for r in runs}
    for runs in out.values():
        for i, r in enumerate(runs):
            head = heads.get(r.run_id.removesuffix(TAIL)) if r.run_id.endswith(TAIL) else None
            if head is not None:
                runs[i] = dataclasses.replace(r, lead_in=head.u)
    return out


# --------------------------------------------------------------------------------------
# fit
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FamilySpec:
    """A model family as Hydra configures it: its name and its config (``_target_`` + params)."""

    name: str
    config: Mapping[str, Any]
    #: Builds an unfitted model from ``config`` (Hydra's ``instantiate`` in the entry points).
    build: Callable[[Mapping[str, Any]], HysteresisModel] = field(compare=False)
    #: Hash of the code that implements the family, so that a code change refits it.
    code_hash: str = ""


@dataclass(frozen=True)
class FitTask:
    family: FamilySpec
    config: Configuration
    fit_excitation: str
    runs: tuple[RunSignal, ...]
    key: str




@dataclass(frozen=True)
class IdentificationPlan:
    """Which data identifies and which judges, decided once for fit and validate alike.

    ``dataset`` is the processed dataset with single-run configurations split in time;
    ``fit_excitations``/``heldout`` are the configured lists extended by what the rule added;
    ``chosen`` are run ids that identify (``fit_runs`` plus manifest roles); ``notes`` say,
    per configuration the rule touched, what it did (for the log and MLflow).
    """

    dataset: pd.DataFrame
    fit_excitations: tuple[str, ...]
    heldout: tuple[str, ...]
    chosen: frozenset[str]
    notes: Mapping[str, str]
    #: Runs a manifest marks for identification: their configurations identify on them only.
    marked: frozenset[str] = frozenset()


def identification_plan(dataset: pd.DataFrame, *, fit_excitations: Sequence[str],
                        heldout: Sequence[str], fit_runs: Sequence[str] = (),
                        roles: Mapping[str, str] | None = None,
                        single_run_heldout_fraction: float = 0.3) -> IdentificationPlan:
    """The documented rule (docs/pipeline.md, "Which run identifies"), per configuration:

    1. runs whose manifest says ``excitation.role: identify`` (or named in ``fit_runs``);
    2. else runs of the ``fit_excitations`` kinds;
    3. else, for a configuration recorded in one run only, the run's head identifies and its
       last ``single_run_heldout_fraction`` (excitation ``<kind>.tail``) is held out.

    Runs marked held-out by their manifest never identify, and every one of them is scored as
    held out, whatever its excitation is called: its kind joins ``heldout`` (renamed
    ``<kind>.heldout`` where the same kind also identifies). A configuration the rule cannot
    decide is left to :func:`identification_runs`, whose error names the option to set.
    """
    try:
        given = {str(k): normalise_role(v, run_id=str(k)) for k, v in (roles or {}).items()}
        check_heldout_fraction(single_run_heldout_fraction)
    except HysteresisError as err:
        raise PipelineError(str(err)) from None
    roles = {k: v for k, v in given.items() if v is not None}
    fit_kinds, held_kinds = list(fit_excitations), list(heldout)
    configured = set(fit_kinds)
    chosen = set(map(str, fit_runs))
    all_marked: set[str] = set()
    notes: dict[str, str] = {}
    keys = ["rig", "curve_angle_deg", "radius_mm"]
    # The decisions need each run's excitation only: one row per run, not the samples (a
    # copy of every configuration's rows, then of them all, cost three datasets of memory).
    run_kinds = dataset.groupby([*keys, "run_id"], sort=True, dropna=False,
                                observed=True)["excitation"].first()
    splits: dict[Configuration, tuple[pd.DataFrame, pd.DataFrame]] = {}
    located: ConfigurationRows | None = None
    for key, kinds in _by_configuration(run_kinds):
        config = Configuration(str(key[0]), _num(key[1]), _num(key[2]))
        label = config.label
        by_run = {str(r): str(k) for r, k in kinds}
        marked = [r for r in by_run if roles.get(r) == IDENTIFICATION]
        if marked:
            chosen.update(marked)
            all_marked.update(marked)
            for r in marked:
                kind = by_run[r]
                if kind not in fit_kinds:
                    fit_kinds.append(kind)
            notes[label] = f"manifest role identify: {', '.join(marked)}"
            continue
        usable = [r for r in by_run if roles.get(r) != HELDOUT]
        has_kind = any(by_run[r] in configured for r in usable)
        if has_kind or len(by_run) != 1 or not usable or chosen.intersection(by_run):
            continue
        (run_id, _), = by_run.items()
        located = located or ConfigurationRows(dataset)
        split = _split_single_run(located.rows(config), run_id, single_run_heldout_fraction)
        if split is None:
            continue
        head, tail, notes[label] = split
        splits[config] = (head, tail)
        kind = str(head["excitation"].iloc[0])
        if kind not in fit_kinds:
            fit_kinds.append(kind)
        if kind + TAIL not in held_kinds:
            held_kinds.append(kind + TAIL)
    out = _with_splits(dataset, splits, keys)
    for col in ("run_id", "excitation"):
        if isinstance(dataset[col].dtype, pd.CategoricalDtype):
            out[col] = out[col].astype(str)
    out = _held_out_by_role(out, roles, fit_kinds, held_kinds)
    return IdentificationPlan(out, tuple(fit_kinds), tuple(held_kinds), frozenset(chosen),
                              notes, frozenset(all_marked))


def _split_single_run(rows: pd.DataFrame, run_id: str, fraction: float
                      ) -> tuple[pd.DataFrame, pd.DataFrame, str] | None:
    """A configuration's one run as (identifying head, held-out tail ``<kind>.tail``, the
    note saying so); None when the run is too short to split."""
    run = rows[rows["run_id"].astype(str) == run_id]
    run = run.sort_values("t_s", kind="stable")
    kind = str(run["excitation"].iloc[0])
    cut = tail_start(len(run), fraction)
    if cut is None:
        return None
    head, tail = run.iloc[:cut].copy(), run.iloc[cut:].copy()
    tail["run_id"] = run_id + TAIL
    tail["excitation"] = kind + TAIL
    t = run["t_s"].to_numpy(dtype=np.float64)
    return head, tail, split_note(str(run_id), t[cut] - t[0], t[-1] - t[cut], fraction,
                                  kind + TAIL)


def _with_splits(dataset: pd.DataFrame,
                 splits: Mapping[Configuration, tuple[pd.DataFrame, pd.DataFrame]],
                 keys: list[str]) -> pd.DataFrame:
    """``dataset`` with each split configuration's rows replaced by its head and tail."""
    if not splits:  # nothing split: the dataset itself (copy-on-write: no copy of its data)
        return dataset.reset_index(drop=True)
    pieces: list[pd.DataFrame] = []
    for key, rows in dataset.groupby(keys, sort=True, dropna=False, observed=True):
        split = splits.get(Configuration(str(key[0]), _num(key[1]), _num(key[2])))
        pieces += list(split) if split is not None else [rows]
    return pd.concat(pieces, ignore_index=True)


def _by_configuration(run_kinds: pd.Series) -> Iterable[tuple[tuple[Any, ...],
                                                                 list[tuple[Any, Any]]]]:
    """``(configuration key, [(run_id, excitation), ...])`` from a Series indexed by
    (rig, curve angle, radius, run id) in sorted order, one configuration at a time."""
    current: tuple[Any, ...] | None = None
    same: tuple[Any, ...] | None = None
    runs: list[tuple[Any, Any]] = []
    for (rig, phi, r, run_id), kind in run_kinds.items():
        ident = (str(rig), _num(phi), _num(r))  # NaN equals NaN here
        if ident != same:
            if current is not None:
                yield current, runs
            current, same, runs = (rig, phi, r), ident, []
        runs.append((run_id, kind))
    if current is not None:
        yield current, runs


#: Suffix of a held-out run's excitation when runs of the same kind also identify.
HELDOUT_SUFFIX = ".heldout"


def _held_out_by_role(dataset: pd.DataFrame, roles: Mapping[str, str],
                      fit_kinds: list[str], held_kinds: list[str]) -> pd.DataFrame:
    """Every run whose role is held-out is scored as held out (its kind joins
    ``held_kinds``, in place); where its kind also identifies, it is renamed
    ``<kind>.heldout`` so that it is never scored in the fit split."""
    held_runs = sorted(r for r, role in roles.items() if role == HELDOUT)
    if not held_runs:
        return dataset
    mask = dataset["run_id"].astype(str).isin(held_runs)
    if not mask.any():
        return dataset
    kinds = dataset.loc[mask, "excitation"].astype(str)
    # a kind clashes only where runs that are not held out identify with it
    others = set(dataset.loc[~mask, "excitation"].astype(str))
    clash = kinds.isin([k for k in fit_kinds if k in others])
    if clash.any():
        dataset = dataset.copy()
        if isinstance(dataset["excitation"].dtype, pd.CategoricalDtype):
            dataset["excitation"] = dataset["excitation"].astype(str)
        dataset.loc[kinds.index[clash], "excitation"] = kinds[clash] + HELDOUT_SUFFIX
        kinds = dataset.loc[mask, "excitation"].astype(str)
    for kind in sorted(set(kinds)):
        if kind not in held_kinds:
            held_kinds.append(kind)
    return dataset


def manifest_roles(runs_meta: Mapping[str, Mapping[str, Any]]) -> dict[str, str]:
    """``run_id -> role`` (:data:`~hysteresis.roles.IDENTIFICATION` or
    :data:`~hysteresis.roles.HELDOUT`) from ingest's ``runs.json``; runs without one omitted."""
    out: dict[str, str] = {}
    for run_id, meta in runs_meta.items():
        try:
            role = manifest_role(meta, run_id=str(run_id))
        except HysteresisError as err:
            raise PipelineError(str(err)) from None
        if role is not None:
            out[str(run_id)] = role
    return out


def identification_runs(runs: Sequence[RunSignal], chosen: set[str], *,
                        label: str) -> tuple[RunSignal, ...]:
    """The runs a configuration identifies on: the only candidate, or every one in
    ``chosen`` (``fit_runs`` or a manifest role), fitted jointly.

    A joint fit simulates each run from its own start (never a concatenation of records that
    each start from rest, whose seams would read as jumps); with several candidates and none
    named, nothing decides which, and the error says how to decide.
    """
    named = tuple(r for r in runs if r.run_id in chosen)
    if named:
        return named
    if len(runs) == 1:
        return (runs[0],)
    ids = ", ".join(r.run_id for r in runs)
    raise PipelineError(
        f"{label}: {len(runs)} runs could identify ({ids}); choose with "
        f"fit_runs=[<run id>, ...] (several named runs are fitted jointly), mark them "
        f"`role: identification` in the manifest or mapping, or fit on another excitation "
        f"with fit_excitations=[...]")


def plan_fits(
    dataset: pd.DataFrame,
    families: Sequence[FamilySpec],
    configs: Sequence[Configuration],
    *,
    fit_excitations: Sequence[str],
    fit_runs: Sequence[str] | frozenset[str] = (),
    marked: frozenset[str] = frozenset(),
    input_col: str = "input",
    output_col: str = "output",
    max_samples: int | None = None,
) -> list[FitTask]:
    """One task per family x configuration x identification excitation present in the data.

    Which runs identify (see :func:`identification_runs`): the one run of the excitation in
    the configuration, or every run named in ``fit_runs`` or marked by its manifest (fitted
    jointly); never a silent pick among several.

    An identification run longer than ``max_samples`` stops the stage before anything is
    fitted, naming the run, its size and the setting. It is not decimated here: the linear
    model's delay counts samples and Coleman-Hodgdon's Euler scheme steps once per sample,
    while validate scores every model on the recorded runs at their own rate.
    """
    check_dataset(dataset, signals=(input_col, output_col))
    if not families:
        raise PipelineError("no model family selected")
    if max_samples is not None and max_samples < 2:
        raise PipelineError(f"max_samples must be at least 2, got {max_samples}")
    chosen = set(map(str, fit_runs))
    too_long: list[str] = []
    tasks: list[FitTask] = []
    located = ConfigurationRows(dataset)
    for config in configs:
        by_kind = run_signals(located.rows(config), input_col=input_col,
                              output_col=output_col)
        own = {r.run_id for rs in by_kind.values() for r in rs} & set(marked)
        for kind in fit_excitations:
            runs = by_kind.get(kind)
            if own:  # the manifest says which runs identify this configuration
                runs = [r for r in runs or [] if r.run_id in own]
                if not runs:
                    continue
            if not runs:
                warnings.warn(f"{config.label}: no {kind!r} run to identify on, skipped",
                              stacklevel=2)
                continue
            chosen_runs = identification_runs(runs, chosen, label=f"{config.label} {kind!r}")
            first = chosen_runs[0].run_id
            why = ("manifest role identify" if first in own else
                   "named in fit_runs" if first in chosen else f"its only {kind} run")
            log.info("fit: %s identifies on %s (%s%s)", config.label,
                     ", ".join(r.run_id for r in chosen_runs), why,
                     f"; {len(chosen_runs)} runs fitted jointly, each from its own start"
                     if len(chosen_runs) > 1 else "")
            data = (chosen_runs[0].data_hash if len(chosen_runs) == 1
                    else [r.data_hash for r in chosen_runs])
            long_runs = [r for r in chosen_runs
                         if max_samples is not None and r.u.size > max_samples]
            if long_runs:
                too_long += [f"{config.label}: run {r.run_id} has {r.u.size} samples"
                             for r in long_runs]
                continue
            for fam in families:
                key = cache.combine({
                    "stage": "fit", "family": fam.name, "config": dict(fam.config),
                    "code": fam.code_hash, "data": data,
                    "signals": [input_col, output_col],
                })
                tasks.append(FitTask(fam, config, kind, chosen_runs, key))
    if too_long:
        shown = "; ".join(too_long[:5]) + (f"; and {len(too_long) - 5} more"
                                           if len(too_long) > 5 else "")
        raise PipelineError(
            f"identification run(s) beyond the per-run limit of the fit, max_samples="
            f"{max_samples}: {shown}. Nothing was fitted. Raise max_samples (memory and time "
            "grow with it), or identify on a shorter or resampled record (fit_runs=[...], or "
            "a lower rate at the rig or in the importer)")
    if not tasks:
        raise PipelineError(
            f"nothing to fit: no run of excitation(s) {list(fit_excitations)} in the "
            f"selected configurations {[c.label for c in configs]}"
        )
    return tasks


def fit_task(task: FitTask) -> dict[str, Any]:
    """Identify one model; a failure is recorded in the row (``error``), never raised."""
    row: dict[str, Any] = {
        "family": task.family.name, **task.config.as_dict(),
        "fit_excitation": task.fit_excitation,
        "fit_run_ids": ",".join(r.run_id for r in task.runs),
        "n_samples": int(sum(r.u.size for r in task.runs)), "key": task.key,
        "model_json": None,
        "params_json": json.dumps(dict(task.family.config), sort_keys=True, default=str),
        "fit_seconds": float("nan"), "error": None, "cached": False,
    }
    start = time.perf_counter()
    try:
        for run in task.runs:
            refused = implausible_record(run.u, run.y)
            if refused is not None:
                raise PipelineError(f"run {run.run_id}: {refused}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = task.family.build(task.family.config)
            if len(task.runs) == 1:
                model.fit(task.runs[0].u, task.runs[0].y)
            else:  # one parameter set, every run simulated from its own start
                model.fit([r.u for r in task.runs], [r.y for r in task.runs])
            refused = implausible_fit(
                np.concatenate([r.y for r in task.runs]),
                np.concatenate([model.predict(r.u) for r in task.runs]))
        if refused is not None:
            raise PipelineError(refused)
        row["model_json"] = model.to_json(indent=None)
    except Exception as exc:  # noqa: BLE001 - one bad fit must not stop the other 119
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["fit_seconds"] = time.perf_counter() - start
    return row


#: A fit whose in-sample RMSE is below this fraction of the output's quantisation step is
#: refused (a measured record cannot be reproduced that exactly).
EXACT_FIT_FRACTION = 1e-3


def implausible_record(u: np.ndarray, y: np.ndarray) -> str | None:
    """Why an identification record cannot identify a model (its output never moves while
    its input does), or None. Ingest rejects such runs; this guards data from elsewhere."""
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    if np.ptp(u) > 0 and np.ptp(y) == 0:
        return (f"the identification record's output never moves (constant {float(y[0]):.6g} "
                "while the input moves): nothing to identify, a model would fit it exactly")
    return None


def quantisation_step(y: np.ndarray) -> float | None:
    """The step of the grid a measured output sits on (an encoder count, the last digit a
    tracker writes), or None when its values are not on one grid (hand-made or model-made
    data, whose exact fit is no sign of a fault)."""
    levels = np.unique(np.asarray(y, dtype=float))
    if levels.size < 3 or not np.isfinite(levels).all():
        return None
    smallest = float(np.diff(levels).min())
    # the closest two levels may be a few steps apart (a short or fast record skips counts)
    for parts in range(1, 17):
        step = smallest / parts
        k = (levels - levels[0]) / step
        if bool(np.all(np.abs(k - np.round(k)) < 1e-3)):
            return step
    return None


def implausible_fit(y: np.ndarray, predicted: np.ndarray) -> str | None:
    """Why a fit is refused as too exact for a measured record, or None.

    A measured output is quantised (and noisy), so no model reproduces it to a small fraction
    of its quantisation step; one that does has fitted a stuck, constant or copied channel,
    and its metrics (RMSE 0) would win every comparison and be registered.
    """
    y, predicted = np.asarray(y, dtype=float), np.asarray(predicted, dtype=float)
    if y.size < 2 or predicted.shape != y.shape or not np.isfinite(predicted).all():
        return None
    resolution = quantisation_step(y)
    if resolution is None:
        return None
    rmse = float(np.sqrt(np.mean((y - predicted) ** 2)))
    if rmse < EXACT_FIT_FRACTION * resolution:
        return (f"in-sample RMSE {rmse:.3g} is below {EXACT_FIT_FRACTION:g} x the output's "
                f"resolution ({resolution:.3g}): no model fits a measured record this exactly "
                "(a stuck or copied output?); refused, not stored")
    return None


def fit_models(
    tasks: Sequence[FitTask],
    *,
    previous: pd.DataFrame | None = None,
    n_jobs: int = 1,
    progress: bool = False,
    runner: Callable[[Callable[[FitTask], dict[str, Any]], Sequence[FitTask]],
                     list[dict[str, Any]]] | None = None,
) -> pd.DataFrame:
    """Fit every task whose key is not in ``previous`` (earlier results); reuse the rest.

    ``runner`` maps ``fit_task`` over the tasks still to do (joblib in the entry point);
    by default they run in this process.
    """
    done: dict[str, dict[str, Any]] = {}
    if previous is not None and not previous.empty:
        for rec in previous.to_dict("records"):
            done[str(rec["key"])] = rec
    todo = [t for t in tasks if t.key not in done]
    if runner is not None and todo:
        fresh = runner(fit_task, todo)
    else:
        fresh = [fit_task(t) for t in _progress(todo, progress, "fit")]
    by_key = {r["key"]: r for r in fresh}
    rows = []
    for t in tasks:
        if t.key in by_key:
            rows.append(by_key[t.key])
        else:
            rows.append({**done[t.key], "cached": True})
    return fits_frame(rows)


def fits_frame(rows: Iterable[Mapping[str, Any]]) -> pd.DataFrame:
    frame = pd.DataFrame(list(rows), columns=list(FIT_COLUMNS))
    frame["n_samples"] = frame["n_samples"].astype("int64")
    frame["cached"] = frame["cached"].astype(bool)
    for col in ("curve_angle_deg", "radius_mm", "fit_seconds"):
        frame[col] = pd.to_numeric(frame[col], errors="coerce").astype("float64")
    return frame


def load_model(model_json: str) -> HysteresisModel:
    return HysteresisModel.from_json(model_json)


def _progress(items: Sequence[Any], enabled: bool, desc: str) -> Iterable[Any]:
    if not enabled:
        return items
    from tqdm import tqdm

    bar: Iterable[Any] = tqdm(items, desc=desc, unit="model")
    return bar


# --------------------------------------------------------------------------------------
# validate
# --------------------------------------------------------------------------------------


def validation_key(
    fits: pd.DataFrame, signals: Mapping[str, list[RunSignal]], settings: Mapping[str, Any]
) -> str:
    """Key of one configuration's evaluation: the models, the evaluation data, the settings."""
    return cache.combine({
        "stage": "validate",
        "models": sorted(fits["key"].astype(str)),
        "data": sorted(r.data_hash for runs in signals.values() for r in runs),
        "settings": dict(settings),
    })


def eval_excitations_for(
    fit_excitation: str, available: Iterable[str], *, heldout: Sequence[str], cross: bool
) -> list[tuple[str, str]]:
    """(evaluation excitation, split) pairs for one model.

    Always the identification excitation itself (split ``fit``); then the requested held-out
    kinds, or with ``cross`` every other kind present (the full cross-excitation matrix).
    """
    present = sorted(set(available))
    pairs = [(fit_excitation, "fit")] if fit_excitation in present else []
    others = [k for k in present if k != fit_excitation] if cross else [
        k for k in heldout if k != fit_excitation and k in present
    ]
    pairs += [(k, "heldout") for k in others]
    return pairs


def evaluate_configuration(
    fits: pd.DataFrame,
    signals: Mapping[str, list[RunSignal]],
    *,
    heldout: Sequence[str],
    cross: bool = False,
) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """Predict every run of one configuration with every fitted model of it.

    Returns (metrics rows, predictions in long format, error messages). A model predicts each
    run from the rest state; the error statistics pool the samples of all runs of one
    evaluation excitation.
    """
    metric_rows: list[dict[str, Any]] = []
    pred_frames: list[pd.DataFrame] = []
    errors: list[str] = []
    for fit in fits.to_dict("records"):
        if fit.get("model_json") is None or (isinstance(fit["model_json"], float)):
            continue
        model = load_model(str(fit["model_json"]))
        ident = {"family": fit["family"], "rig": fit["rig"],
                 "curve_angle_deg": fit["curve_angle_deg"], "radius_mm": fit["radius_mm"],
                 "fit_excitation": fit["fit_excitation"]}
        for kind, split in eval_excitations_for(
            str(fit["fit_excitation"]), signals, heldout=heldout, cross=cross
        ):
            measured, predicted = [], []
            try:
                for run in signals[kind]:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        yhat = run.predict(model)
                    measured.append(run.y)
                    predicted.append(yhat)
                    pred_frames.append(pd.DataFrame({
                        "family": fit["family"], "fit_excitation": fit["fit_excitation"],
                        "eval_excitation": kind, "run_id": run.run_id, "t_s": run.t_s,
                        "input": run.u, "output": run.y, "predicted": yhat,
                    }))
                stats = error_statistics(np.concatenate(measured), np.concatenate(predicted))
            except Exception as exc:  # noqa: BLE001 - record and go on with the others
                errors.append(f"{fit['family']} {ident['rig']} phi={ident['curve_angle_deg']} "
                              f"r={ident['radius_mm']} on {kind}: {type(exc).__name__}: {exc}")
                continue
            metric_rows.append({**ident, "eval_excitation": kind, "split": split, **stats})
    metrics = metrics_frame(metric_rows)
    preds = (pd.concat(pred_frames, ignore_index=True) if pred_frames
             else pd.DataFrame(columns=list(PREDICTION_COLUMNS)))
    return metrics, preds, errors


#: Columns of the per-run metrics table (``metrics_by_run``): one row per model and run.
RUN_METRICS_COLUMNS: tuple[str, ...] = (
    "family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation", "eval_excitation",
    "split", "run_id", *METRIC_NAMES, "max_abs_error",
)


def run_metrics(preds: pd.DataFrame, metrics: pd.DataFrame,
                config: Configuration) -> pd.DataFrame:
    """Error statistics of every run on its own (the pooled ``metrics`` pool the runs of one
    evaluation excitation): what a per-file comparison, as in a paper's table, needs."""
    if preds.empty or metrics.empty:
        return run_metrics_frame([])
    split_of = {(str(r.family), str(r.fit_excitation), str(r.eval_excitation)): str(r.split)
                for r in metrics.itertuples(index=False)}
    rows = []
    keys = ["family", "fit_excitation", "eval_excitation", "run_id"]
    for key, g in preds.groupby(keys, sort=True, observed=True):
        fam, fit_kind, kind, run_id = (str(k) for k in key)
        split = split_of.get((fam, fit_kind, kind))
        if split is None:
            continue
        y = g["output"].to_numpy(dtype=np.float64)
        yhat = g["predicted"].to_numpy(dtype=np.float64)
        stats = error_statistics(y, yhat)
        err = np.abs(y - yhat)
        rows.append({"family": fam, **config.as_dict(), "fit_excitation": fit_kind,
                     "eval_excitation": kind, "split": split, "run_id": run_id, **stats,
                     "max_abs_error": float(np.nanmax(err))})
    return run_metrics_frame(rows)


def run_metrics_frame(rows: Iterable[Mapping[str, Any]]) -> pd.DataFrame:
    frame = pd.DataFrame(list(rows), columns=list(RUN_METRICS_COLUMNS))
    for col in ("family", "rig", "fit_excitation", "eval_excitation", "split", "run_id"):
        frame[col] = frame[col].astype("string")
    frame["n"] = frame["n"].astype("int64")
    for col in ("curve_angle_deg", "radius_mm", *METRIC_NAMES[1:], "max_abs_error"):
        frame[col] = pd.to_numeric(frame[col], errors="coerce").astype("float64")
    return frame


def metrics_frame(rows: Iterable[Mapping[str, Any]]) -> pd.DataFrame:
    """Rows -> the metrics table with exactly :data:`METRICS_COLUMNS` and stable dtypes."""
    frame = pd.DataFrame(list(rows), columns=list(METRICS_COLUMNS))
    for col in ("family", "rig", "fit_excitation", "eval_excitation", "split"):
        frame[col] = frame[col].astype("string")
    frame["n"] = frame["n"].astype("int64")
    for col in ("curve_angle_deg", "radius_mm", *METRIC_NAMES[1:]):
        frame[col] = pd.to_numeric(frame[col], errors="coerce").astype("float64")
    return frame


def sort_metrics(metrics: pd.DataFrame) -> pd.DataFrame:
    split_order = metrics["split"].map({"fit": 0, "heldout": 1})
    return (metrics.assign(_s=split_order)
            .sort_values(["rig", "curve_angle_deg", "radius_mm", "family", "fit_excitation",
                          "_s", "eval_excitation"], kind="stable", na_position="first")
            .drop(columns="_s").reset_index(drop=True))


# --------------------------------------------------------------------------------------
# report tables
# --------------------------------------------------------------------------------------


def gamma_weights_table(fits: pd.DataFrame, metrics: pd.DataFrame,
                        *, family: str = "gamma") -> pd.DataFrame:
    """The seed 001 Table 4.1 equivalent: weights Q and SSE per configuration.

    Columns: rig, curve_angle_deg, radius_mm, fit_excitation, n_operators, thresholds (the
    preassigned P, as a list), q1..qn, weights_sum, sse (on the identification record).
    """
    rows = []
    ok = fits[(fits["family"] == family) & fits["model_json"].notna()]
    sse = metrics[(metrics["family"] == family) & (metrics["split"] == "fit")]
    sse_by = {(r.rig, _num(r.curve_angle_deg), _num(r.radius_mm), r.fit_excitation): r.sse
              for r in sse.itertuples(index=False)}
    width = 0
    for fit in ok.to_dict("records"):
        model = load_model(str(fit["model_json"]))
        q = np.asarray(getattr(model, "weights_", []), dtype=np.float64).ravel()
        p = np.asarray(getattr(model, "thresholds_", []), dtype=np.float64).ravel()
        width = max(width, q.size)
        key = (fit["rig"], _num(fit["curve_angle_deg"]), _num(fit["radius_mm"]),
               fit["fit_excitation"])
        row: dict[str, Any] = {
            "rig": fit["rig"], "curve_angle_deg": fit["curve_angle_deg"],
            "radius_mm": fit["radius_mm"], "fit_excitation": fit["fit_excitation"],
            "n_operators": int(q.size), "thresholds": p.tolist(),
        }
        row.update({f"q{i + 1}": float(v) for i, v in enumerate(q)})
        row["weights_sum"] = float(q.sum())
        row["sse"] = float(sse_by.get(key, float("nan")))
        rows.append(row)
    cols = ["rig", "curve_angle_deg", "radius_mm", "fit_excitation", "n_operators",
            "thresholds", *[f"q{i + 1}" for i in range(width)], "weights_sum", "sse"]
    table = pd.DataFrame(rows, columns=cols)
    return table.sort_values(["rig", "curve_angle_deg", "radius_mm", "fit_excitation"],
                             kind="stable").reset_index(drop=True)


def leaderboard(metrics: pd.DataFrame, *, metric: str = "rmse") -> pd.DataFrame:
    """Families ranked per configuration by the mean held-out ``metric`` (1 = best).

    Columns: rig, curve_angle_deg, radius_mm, fit_excitation, family, fit_<metric>,
    heldout_<metric> (mean over the held-out excitations), rank.
    """
    if metric not in METRIC_NAMES:
        raise PipelineError(f"unknown metric {metric!r}; known: {list(METRIC_NAMES)}")
    keys = ["rig", "curve_angle_deg", "radius_mm", "fit_excitation", "family"]
    m = metrics.copy()
    for col in ("curve_angle_deg", "radius_mm"):
        m[col] = m[col].fillna(-1.0)  # groupby drops NaN keys otherwise
    fit = m[m["split"] == "fit"].groupby(keys, observed=True)[metric].mean()
    held = m[m["split"] == "heldout"].groupby(keys, observed=True)[metric].mean()
    board = pd.concat({f"fit_{metric}": fit, f"heldout_{metric}": held}, axis=1).reset_index()
    score = board[f"heldout_{metric}"].fillna(board[f"fit_{metric}"])
    board["rank"] = (score.groupby([board[k] for k in keys[:-1]]).rank(method="min")
                     .astype("int64"))
    for col in ("curve_angle_deg", "radius_mm"):
        board[col] = board[col].replace(-1.0, np.nan)
    return board.sort_values([*keys[:-1], "rank", "family"], kind="stable").reset_index(drop=True)


def family_summary(board: pd.DataFrame, *, metric: str = "rmse") -> pd.DataFrame:
    """One row per family over all configurations: wins, mean rank, median errors."""
    g = board.groupby("family", observed=True)
    summary = pd.DataFrame({
        "configurations": g.size(),
        "wins": g["rank"].apply(lambda r: int((r == 1).sum())),
        "mean_rank": g["rank"].mean(),
        f"median_fit_{metric}": g[f"fit_{metric}"].median(),
        f"median_heldout_{metric}": g[f"heldout_{metric}"].median(),
    }).reset_index()
    return summary.sort_values(["mean_rank", "family"], kind="stable").reset_index(drop=True)


def headline(summary: pd.DataFrame, *, metric: str = "rmse", unit: str = "") -> str:
    """One sentence a reader takes away: who wins how many configurations, its median
    held-out error, and by how much it beats the no-hysteresis baseline (linear) or else the
    runner-up. ``summary``: :func:`family_summary`."""
    if summary.empty:
        return "No model was scored."
    col = f"median_heldout_{metric}"
    split = "held-out"
    if summary[col].isna().all():
        col, split = f"median_fit_{metric}", "in-sample (nothing held out was scored)"
    best = summary.sort_values(["wins", "mean_rank"], ascending=[False, True]).iloc[0]
    n_cfg = int(summary["configurations"].max())
    text = (f"{best['family']} wins {int(best['wins'])} of {n_cfg} configuration"
            f"{'s' if n_cfg != 1 else ''}; median {split} {metric.upper()} "
            f"{float(best[col]):.3g}{' ' + unit if unit else ''}")
    others = summary[summary["family"] != best["family"]]
    ref = others[others["family"] == "linear"]
    if ref.empty and not others.empty:
        ref = others.sort_values(col).head(1)
    if not ref.empty and float(best[col]) > 0:
        r = ref.iloc[0]
        text += (f", {float(r[col]) / float(best[col]):.2g}x below {r['family']} "
                 f"({float(r[col]):.3g}{' ' + unit if unit else ''})")
    return text + "."
