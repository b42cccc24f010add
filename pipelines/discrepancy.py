"""Stage ``discrepancy``: find where model and measurement disagree, name the missing effect,
add it, show the gap shrink (method in ``docs/discrepancy.md``).

    python -m pipelines.discrepancy source=<dir of raw runs or bags> report=<file.json>

The source is ingested into a temporary folder with the ingest stage's functions (so a source
of raw runs, bags or foreign logs all work and nothing is written next to them), the runs are
grouped by configuration, the base family is fitted on the identification excitation and
judged on the held-out ones by :func:`hysteresis.discrepancy.workflow.run_workflow`. Outputs:
the report JSON (atomic), before/after plots beside it, one MLflow run with the metrics, the
plots and the report.
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from hysteresis.base import HysteresisError
from hysteresis.discrepancy.runs import (
    RunData,
    check_one_rig,
    describe_mix,
    split_single_runs,
)
from hysteresis.discrepancy.workflow import (
    WorkflowSettings,
    base_factory_for,
    run_workflow,
    strip_private,
)
from hysteresis.roles import manifest_role, run_role
from pipelines import schemas
from rig_io.atomic import (
    atomic_path,
    check_output,
    clean_leftovers,
    clean_owned_temp,
    contained,
    owned_prefix,
    write_text_atomic,
)
from rig_io.errors import RigIOError

log = logging.getLogger(__name__)
#: Work folders in the temp dir: ``tsm-discrepancy-<host>-<pid>-*`` (leaks of killed runs
#: are removed when the stage starts).
TEMP_TAG = "tsm-discrepancy"


class DiscrepancyError(Exception):
    """Bad source or configuration for the discrepancy stage."""


# -- data ---------------------------------------------------------------------------------

def ingest_source(source: str | Path, workdir: Path, *, mapping: Mapping[str, Any] | None = None,
                  progress: bool = False) -> tuple[pd.DataFrame, dict[str, dict[str, Any]],
                                                   dict[str, Any]]:
    """Ingest ``source`` into ``workdir``; return (rows, per-run metadata, ingest report)."""
    from pipelines.ingest import run_ingest
    from rig_io.dataset import read_dataset, read_runs

    src = Path(source)
    if not src.exists():
        raise DiscrepancyError(f"source {src} does not exist")
    rep = run_ingest(src, workdir, mapping=dict(mapping) if mapping else None, progress=progress)
    if not rep["n_accepted"]:
        reasons = "; ".join(r["reason"] for r in rep["rejected"][:5])
        raise DiscrepancyError(f"no run of {src} could be ingested ({reasons or 'no runs found'})")
    return read_dataset(workdir), read_runs(workdir), rep


def rows_from_raw(raw_runs: list[Any]) -> tuple[pd.DataFrame, dict[str, dict[str, Any]]]:
    """In-memory ingest of :class:`rig_io.run.RawRun` objects (calibrate, synchronise,
    normalise: the ingest stage's pure functions); returns (rows, per-run metadata)."""
    from rig_io.calibrate import calibrate_raw_run
    from rig_io.process import process_run

    frames, meta = [], {}
    for raw in raw_runs:
        frame, info = process_run(calibrate_raw_run(raw))
        frames.append(frame)
        meta[raw.run_id] = {**info, "manifest": raw.manifest}
    return pd.concat(frames, ignore_index=True), meta


def _role(run_id: str, meta: Mapping[str, Any], kind: str, identify: set[str]) -> str:
    try:
        return run_role(manifest_role(meta, run_id=run_id), kind, identify)
    except HysteresisError as err:
        raise DiscrepancyError(str(err)) from None


#: A channel with at most this share of its samples missing (a stream that ends a sample or
#: two early, a short dropout) is filled by interpolation in time; beyond it, it is dropped.
MAX_FILLED_FRACTION = 0.01


def channel_values(col: pd.Series, t: np.ndarray) -> tuple[np.ndarray | None, str]:
    """A channel's values and what was done to them: used as recorded, short gaps filled
    (linear in time, the ends held) within :data:`MAX_FILLED_FRACTION` of the samples, or
    dropped with the reason. One missing sample must not switch off a whole load cell."""
    arr = col.to_numpy(dtype=float)
    ok = np.isfinite(arr)
    n, missing = arr.size, int((~ok).sum())
    if missing == 0:
        return arr, "used (complete)"
    if missing == n:
        return None, "absent"
    edges = np.flatnonzero(np.diff(np.r_[0, (~ok).astype(np.int8), 0]))
    longest = int(np.max(edges[1::2] - edges[::2]))
    limit = max(1, int(MAX_FILLED_FRACTION * n))
    if missing > limit:
        return None, (f"dropped: {missing} of {n} samples missing (longest gap {longest}); "
                      f"at most {limit} ({MAX_FILLED_FRACTION:.0%}) are filled")
    filled = np.interp(t, t[ok], arr[ok])
    return filled, (f"used ({missing} of {n} samples missing, longest gap {longest}: "
                    "filled by interpolation in time)")


def output_kind(meta: Mapping[str, Any]) -> tuple[str, str, str]:
    """(rig, output unit, output quantity) of one ingested run's metadata: the quantity is
    the camera's or tracker's ``quantity`` (``tip_angle_deg``, ``output_mm``) when that is
    the output, else ``output_<unit>`` for the output encoder."""
    manifest = meta.get("manifest") or {}
    rig = str(meta.get("rig") or manifest.get("rig") or "")
    unit = str((meta.get("units") or {}).get("output") or "")
    source = str(meta.get("output_source") or "encoder")
    channel = (manifest.get("channels") or {}).get(source) or {}
    quantity = str(channel.get("quantity") or f"output_{unit}") if source != "encoder" \
        else f"output_{unit}"
    return rig, unit, quantity


def check_one_kind(meta: Mapping[str, Mapping[str, Any]]) -> None:
    """A source whose runs come from several rigs, or measure the output in several units or
    as several quantities (mm of tendon and degrees of tip angle), is refused before the
    analysis: one RMSE over mm and deg means nothing, and an effect of one group is lost in
    the other's. The message names each group and its runs."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for run_id in sorted(meta):
        rig, unit, quantity = output_kind(meta[run_id])
        shown = "" if quantity == f"output_{unit}" else quantity
        groups.setdefault((rig, unit, shown), []).append(str(run_id))
    mix = describe_mix(groups, ("rigs", "output units", "output quantities"))
    if mix is not None:
        raise DiscrepancyError(mix)


def runs_from_dataset(rows: pd.DataFrame, meta: Mapping[str, Mapping[str, Any]], *,
                      identify_excitations: list[str], input_col: str = "input",
                      output_col: str = "output",
                      rate_hz: float | None = None,
                      channels: dict[str, dict[str, str]] | None = None) -> list[RunData]:
    """The processed rows as :class:`RunData` (configuration, role, tension, decimation);
    ``channels`` (if given) receives, per run, what was done to each tension channel."""
    for c in (input_col, output_col):
        if c not in rows:
            raise DiscrepancyError(f"dataset has no column {c!r}")
    check_one_kind(meta)
    out = []
    identify = set(identify_excitations)
    for run_id, df in rows.groupby("run_id", sort=True):
        kind = str(df["excitation"].iloc[0])
        config: dict[str, Any] = {"rig": str(df["rig"].iloc[0])}
        for c in ("curve_angle_deg", "radius_mm"):
            v = float(df[c].iloc[0])
            if math.isfinite(v):
                config[c] = v
        t = df["t_s"].to_numpy(float)
        notes: dict[str, str] = {}
        tension, notes["tension_in_n"] = channel_values(df["tension_in_n"], t)
        if tension is None and "tension_proxy" in df:
            tension, notes["tension_proxy"] = channel_values(df["tension_proxy"], t)
        tension_out, notes["tension_out_n"] = channel_values(df["tension_out_n"], t)
        if channels is not None:
            channels[str(run_id)] = notes
        run = RunData(
            run_id=str(run_id), t=t, u=df[input_col].to_numpy(float),
            y=df[output_col].to_numpy(float), tension=tension,
            tension_out=tension_out, config=config, excitation=kind,
            role=_role(str(run_id), meta.get(str(run_id), {}), kind, identify),
        )
        if rate_hz:
            run = run.decimated(max(1, int(round(1.0 / (rate_hz * run.dt)))))
        out.append(run)
    return out


# -- base family ----------------------------------------------------------------------------

def choose_base(runs: list[RunData], families: Mapping[str, Mapping[str, Any]]
                ) -> tuple[str, dict[str, Any], dict[str, float]]:
    """The family of ``families`` with the lowest held-out RMSE (the best standard family)."""
    name, params, scores, _ = rank_bases(runs, families)
    return name, params, scores


def pick_base(results: Sequence[tuple[str, dict[str, Any]]], *, min_gain: float
              ) -> tuple[str, dict[str, Any]]:
    """Of the workflow's results on several bases (best plain base first), the one whose final
    model predicts the held-out runs best. A later base must beat the first by ``min_gain``
    (the bar a term must clear) so a near tie keeps the best plain family, and one that adds
    terms where the first found nothing to add is not taken: a family that fits the source
    worse may name its own misfit."""
    first_label, first = results[0]
    best_label, best = first_label, first
    for label, res in results[1:]:
        if not res["effects"] and first["effects"]:
            continue
        if first["verdict"] == "no_missing_effect":
            break
        after = float(res["summary"]["heldout_rmse_after"])
        if after < (1.0 - min_gain) * float(best["summary"]["heldout_rmse_after"]):
            best_label, best = label, res
    return best_label, best


def rank_bases(runs: list[RunData], families: Mapping[str, Mapping[str, Any]]
               ) -> tuple[str, dict[str, Any], dict[str, float],
                          dict[str, tuple[str, dict[str, Any]]]]:
    """Every family of ``families`` scored by its plain held-out RMSE: (best family, its
    parameters, scores by label, (family, parameters) by label)."""
    from hysteresis.discrepancy.effects import ComposedModel
    from hysteresis.discrepancy.workflow import evaluate, group_runs

    groups = group_runs(runs)
    scores: dict[str, float] = {}
    specs: dict[str, tuple[str, dict[str, Any]]] = {}
    for label, spec in families.items():
        params = dict(spec or {})
        name = str(params.pop("family", label))
        try:
            factory = base_factory_for(name, **params)
            models = {g.key: ComposedModel(factory).fit(g.ident) for g in groups}
            _, e_h = evaluate(models, groups).errors(groups)
            score = float(np.sqrt(np.mean(e_h**2)))
        except Exception as err:  # a family that cannot fit this data is simply not chosen
            log.warning("base family %s skipped: %s", label, err)
            continue
        if math.isfinite(score):
            scores[label] = score
            specs[label] = (name, params)
    if not scores:
        raise DiscrepancyError("no base family could be fitted to this source")
    best = min(scores, key=scores.__getitem__)
    return specs[best][0], specs[best][1], scores, specs


# -- seed 000 model error --------------------------------------------------------------------

def ukf_model_error(runs: list[RunData]) -> dict[str, np.ndarray]:
    """f_h of seed 000's active-modelling UKF around a Coleman-Hodgdon reference model, per
    configuration's identification record (the signal the winner's term is regressed on)."""
    from hysteresis.coleman_hodgdon import ColemanHodgdonModel
    from hysteresis.discrepancy.workflow import group_runs
    from hysteresis.ukf import ActiveModelUKF

    out: dict[str, np.ndarray] = {}
    for g in group_runs(runs):
        ch = ColemanHodgdonModel(method="varpro").fit(g.ident.u, g.ident.y)
        res = ActiveModelUKF(ch, dt=g.ident.dt).run(g.ident.u, g.ident.y)
        out[g.ident.run_id] = np.asarray(res.f_h, dtype=np.float64)
    return out


# -- plots ----------------------------------------------------------------------------------

def _breaks(starts: Sequence[int]) -> Callable[[Any], npt.NDArray[np.float64]]:
    """A function inserting NaN before every record start after the first (line breaks)."""
    idx = [int(i) for i in starts if int(i) > 0]

    def cut(x: Any) -> npt.NDArray[np.float64]:
        arr = np.asarray(x, dtype=np.float64)
        return np.insert(arr, idx, np.nan) if idx else arr

    return cut


def _fixed_margins(fig: Any, rows: int, *, left: float = 0.75, right: float = 0.15,
                   bottom: float = 0.5, top: float = 0.7, row_gap: float = 0.8,
                   col_gap: float = 0.7) -> None:
    """Margins and gaps in inches (tick labels, axis labels, the titles and the suptitle's
    strip) whatever the number of rows. A measured layout (tight_layout) draws every figure
    once more and took as long as the discrepancy analysis itself."""
    w, h = fig.get_figwidth(), fig.get_figheight()
    axes_h = (h - bottom - top - (rows - 1) * row_gap) / rows
    axes_w = (w - left - right - col_gap) / 2
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h,
                        top=1.0 - top / h, hspace=row_gap / axes_h, wspace=col_gap / axes_w)


def plot_report(report: Mapping[str, Any], out_dir: Path) -> list[Path]:
    """Before/after loops and residuals per held-out run, located segments shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    evs = report["_evaluations"]
    first, last = evs[0], evs[-1]
    segs = report["located"][0]["segments"] if report["located"] else []
    files: list[Path] = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for g in report["_groups"]:
        runs = [g.ident, *g.heldout]
        fig, axes = plt.subplots(len(runs), 2, figsize=(12, 3.2 * len(runs)), squeeze=False)
        for ax, run in zip(axes, runs, strict=True):
            p0 = first.ident_pred.get(run.run_id, first.held_pred.get(run.run_id))
            p1 = last.ident_pred.get(run.run_id, last.held_pred.get(run.run_id))
            # Several identification records are one concatenated run: break every line at a
            # record start so no stroke joins the end of one record to the start of the next.
            cut = _breaks(run.starts)
            u, y, ts = cut(run.u), cut(run.y), cut(run.ts)
            ax[0].plot(u, y, "k", lw=0.8, label="measured")
            ax[0].plot(u, cut(p0), "C0", lw=0.8, label="base")
            ax[0].plot(u, cut(p1), "C3", lw=0.8, ls="--", label="base + effects")
            ax[0].set_xlabel("input")
            ax[0].set_ylabel("output")
            parts = run.run_id.split("+")
            name = parts[0] if len(parts) == 1 else f"{len(parts)} records ({parts[0]}, ...)"
            ax[0].set_title(f"{name} ({run.role})", fontsize=9)
            ax[0].legend(fontsize=7)
            ax[1].plot(ts, y - cut(p0), "C0", lw=0.7, label="residual, base")
            ax[1].plot(ts, y - cut(p1), "C3", lw=0.7, label="residual, base + effects")
            for s in segs:
                if s["run_id"] == run.run_id:
                    ax[1].axvspan(s["t_start_s"], s["t_end_s"], color="orange", alpha=0.2)
            ax[1].set_xlabel("time since start (s)")
            ax[1].legend(fontsize=7)
        names = [e["name"] for e in report["effects"]] or ["no missing effect"]
        fig.suptitle(f"{report['base_family']} + {', '.join(names)} | {g.key}", fontsize=10)
        _fixed_margins(fig, len(runs))
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in g.key)
        path = contained(out_dir, f"discrepancy_{safe}.png")
        with atomic_path(path, suffix=".png", folder=False) as tmp:
            fig.savefig(tmp, dpi=90, format="png")
        plt.close(fig)
        files.append(path)
    return files


# -- the stage ------------------------------------------------------------------------------

def workflow_settings(workflow: Mapping[str, Any] | None, *, progress: bool = False
                      ) -> WorkflowSettings:
    """The workflow's knobs: :class:`WorkflowSettings` (the one place of their defaults) with
    the given fields replaced; an unknown field is an error, never ignored."""
    values = dict(workflow or {})
    known = {f.name for f in fields(WorkflowSettings)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise DiscrepancyError(f"unknown workflow setting(s) {unknown}; known: {sorted(known)}")
    if values.get("candidates") is not None:
        values["candidates"] = tuple(values["candidates"])
    values["progress"] = progress
    return replace(WorkflowSettings(), **values)


def analyse(runs: list[RunData], *, base_family: str = "auto",
            base_params: Mapping[str, Any] | None = None,
            auto_families: Mapping[str, Mapping[str, Any]],
            settings: WorkflowSettings | None = None, ukf_evidence: bool = False,
            base_check: bool = True, base_misfit_factor: float = 1.5,
            base_misfit_fallback: bool = True, max_bases: int = 2,
            base_retry_factor: float = 1.5,
            ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The stage's computation, no I/O: choose the base, run the workflow, check a given
    base against the auto families. Returns ``(report, full)``: the JSON-ready report and the
    workflow's full result (with the evaluations and groups the plots need).

    ``auto``: the workflow runs on the best of ``auto_families`` (plain held-out RMSE), and
    again on the next best, up to ``max_bases``, while the result is neither clean nor
    explained to within ``base_retry_factor`` x the noise floor; the base whose model with
    its terms predicts the held-out runs best is kept (:func:`pick_base`). The plain ranking
    alone confounds the effect with the family: a family that bends to a hidden drift or stop
    wins plain and then leaves half of it, where the family that matches the mechanism plus
    the term explains it.

    A given base is checked against the best of ``auto_families`` (``base_check``): with
    ``base_misfit_fallback`` by :func:`second_opinion` (the best family answers when its model
    with its terms predicts clearly better; ``given_base`` keeps the given base's answer),
    else by :func:`base_misfit` (flagged only). Terms added to a base that cannot take the
    loop's shape stand in for the base's misfit, and the answer would depend on the base and
    not on the source."""
    st = settings or WorkflowSettings()
    try:
        check_one_rig(runs)
    except HysteresisError as err:
        raise DiscrepancyError(str(err)) from None
    model_error = None
    if ukf_evidence:
        try:
            model_error = ukf_model_error(runs)
        except HysteresisError as err:  # evidence only: never fatal
            log.warning("UKF model-error evidence skipped: %s", err)

    def workflow(name: str, params: Mapping[str, Any]) -> dict[str, Any]:
        try:
            factory = base_factory_for(name, **params)
        except HysteresisError as err:
            raise DiscrepancyError(str(err)) from None
        return run_workflow(runs, factory, base_name=name, settings=st, model_error=model_error)

    auto_scores: dict[str, float] = {}
    tried: list[dict[str, Any]] = []
    if base_family == "auto":
        _, _, auto_scores, specs = rank_bases(runs, auto_families)
        results: list[tuple[str, dict[str, Any]]] = []
        for label in sorted(auto_scores, key=auto_scores.__getitem__)[:max(1, max_bases)]:
            res = workflow(*specs[label])
            results.append((label, res))
            tried.append({"base": label, "verdict": res["verdict"],
                          "effects": [e["name"] for e in res["effects"]],
                          "heldout_rmse_after": res["summary"]["heldout_rmse_after"],
                          "rmse_over_noise": res["residual"]["rmse_over_noise"]})
            if res["verdict"] == "no_missing_effect" \
                    or res["residual"]["rmse_over_noise"] <= base_retry_factor:
                break
        label, full = pick_base(results, min_gain=st.min_relative_gain)
        base, params = specs[label]
    else:
        base, params = base_family, dict(base_params or {})
        full = workflow(base, params)
    report = strip_private(full)
    report["base_params"] = params
    report["base_selection"] = auto_scores or None
    report["bases_tried"] = tried or None
    if auto_scores:
        best_plain = min(auto_scores.values())
        after = float(report["summary"]["heldout_rmse_after"])
        report["summary"]["heldout_rmse_best_plain"] = best_plain
        report["summary"]["heldout_reduction_vs_best_plain"] = \
            1.0 - after / best_plain if best_plain > 0 else 0.0
    report["base_misfit"] = None
    report["given_base"] = None
    if not auto_scores and base_check and base_misfit_fallback:
        report, full = second_opinion(
            runs, report, full, workflow, auto_families, base=base, params=params,
            factor=base_misfit_factor, retry_factor=base_retry_factor,
            min_gain=st.min_relative_gain)
    elif not auto_scores and base_check:
        report["base_misfit"] = base_misfit(runs, report, auto_families,
                                            factor=base_misfit_factor)
    report["headline"] = headline(report)
    return report, full


def asks_best_family(report: Mapping[str, Any], *, plain_ratio: float, factor: float,
                     retry_factor: float) -> bool:
    """Whether a given base's answer (``report``) is checked on the best family: the base
    fits ``factor`` x worse plain (``plain_ratio``), or its answer is neither clean nor within
    ``retry_factor`` x the noise floor."""
    unexplained = (report["verdict"] != "no_missing_effect"
                   and float(report["residual"]["rmse_over_noise"]) > retry_factor)
    return plain_ratio > factor or unexplained


def best_family_answers(own_after: float, best_after: float, *, min_gain: float) -> bool:
    """Whether the best family's model with its terms predicts the held-out runs ``min_gain``
    better than the given base's with its terms (held-out RMSEs after the terms)."""
    return best_after < (1.0 - min_gain) * own_after


def second_opinion(runs: list[RunData], report: dict[str, Any], full: dict[str, Any],
                   workflow: Callable[[str, Mapping[str, Any]], dict[str, Any]],
                   families: Mapping[str, Mapping[str, Any]], *, base: str,
                   params: Mapping[str, Any], factor: float, retry_factor: float,
                   min_gain: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """A given base checked against the best family plain (``base_misfit_fallback``).

    When the base fits ``factor`` x worse plain than the best family, or its answer is neither
    clean nor explained to within ``retry_factor`` x the noise floor (what makes ``auto`` try
    a second base), the workflow runs on the best family too; that family answers when its
    model with its terms predicts the held-out runs ``min_gain`` better than the given base's
    with its terms, and ``given_base`` keeps the given base's answer. Otherwise the given
    base's answer stands: a base that fits worse plain only because it lacked the effect
    predicts as well once the term is in."""
    try:
        _, _, scores = choose_base(runs, families)
    except DiscrepancyError:
        return report, full
    label = min(scores, key=scores.__getitem__)
    best_params = dict(families[label])
    best = str(best_params.pop("family", label))
    own_plain = float(report["summary"]["heldout_rmse_before"])
    own_after = float(report["summary"]["heldout_rmse_after"])
    ratio = own_plain / scores[label] if scores[label] > 0 else float("inf")
    if (best, best_params) == (base, dict(params)) or not asks_best_family(
            report, plain_ratio=ratio, factor=factor, retry_factor=retry_factor):
        return report, full
    best_full = workflow(best, best_params)
    best_after = float(best_full["summary"]["heldout_rmse_after"])
    if not best_family_answers(own_after, best_after, min_gain=min_gain):
        return report, full
    given = {"base": base, "base_params": dict(params), "verdict": report["verdict"],
             "effects": [e["name"] for e in report["effects"]],
             "heldout_rmse_after": own_after,
             "rmse_over_noise": report["residual"]["rmse_over_noise"]}
    misfit = {"base": base, "heldout_rmse": own_plain, "best_family": label,
              "best_heldout_rmse": scores[label], "ratio": ratio,
              "ratio_with_terms": own_after / best_after if best_after > 0 else float("inf"),
              "scores": scores}
    log.warning("base %s with its terms predicts this source %.1fx worse held out than %s with "
                "its own: %s answers", base, misfit["ratio_with_terms"], label, label)
    out = strip_private(best_full)
    out.update(base_params=best_params, base_selection=None, bases_tried=None,
               base_misfit=misfit, given_base=given)
    out["summary"]["heldout_rmse_best_plain"] = scores[label]
    return out, best_full


def run(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """Run the stage from a plain config mapping; returns the JSON report (also written).

    ``cfg``: a composed ``conf/discrepancy.yaml`` or a hand-written mapping; settings it
    leaves out take their defaults from :class:`pipelines.schemas.DiscrepancyConfig`.
    The edges: ingest the source, :func:`analyse`, then plots, the report file and MLflow."""
    t0 = time.perf_counter()
    cfg = schemas.with_defaults(schemas.DiscrepancyConfig, cfg)
    if not cfg.get("source"):
        raise DiscrepancyError("source=<dir of raw runs or bags> is required")
    if not cfg.get("report"):
        raise DiscrepancyError("report=<file.json> is required")
    # never resolved: a link given as the report is refused, not followed to what it names
    report_path = Path(os.path.abspath(os.path.expanduser(str(cfg["report"]))))
    plots_dir = report_path.parent / f"{report_path.stem}_plots"
    try:  # before any work: a wrong kind of output path fails now, not after the analysis
        check_output(report_path, folder=False)
        if cfg["plots"]:
            check_output(plots_dir, folder=True)
    except RigIOError as err:
        raise DiscrepancyError(f"report={cfg['report']}: {err}") from None
    clean_leftovers(report_path.parent, recursive=False)  # temporaries of a killed run
    clean_leftovers(plots_dir)
    progress = bool(cfg["progress"])
    settings = workflow_settings(cfg["workflow"], progress=progress)
    clean_owned_temp(TEMP_TAG)  # work folders of killed runs
    with tempfile.TemporaryDirectory(prefix=owned_prefix(TEMP_TAG)) as tmp:
        rows, meta, ingest_rep = ingest_source(cfg["source"], Path(tmp),
                                               mapping=cfg["importer"], progress=progress)
    channels: dict[str, dict[str, str]] = {}
    runs = runs_from_dataset(
        rows, meta, identify_excitations=list(cfg["identify_excitations"]),
        input_col=str(cfg["signals"]["input"]), output_col=str(cfg["signals"]["output"]),
        rate_hz=cfg["analysis_rate_hz"], channels=channels)
    for run_id, notes in channels.items():
        for name, note in notes.items():
            if note not in ("used (complete)", "absent"):
                log.info("discrepancy: %s: %s %s", run_id, name, note)
    # one run per configuration (a common way to record): its head identifies, its tail judges
    try:
        runs, run_choice = split_single_runs(
            runs, heldout_fraction=float(cfg["single_run_heldout_fraction"]))
    except HysteresisError as err:
        raise DiscrepancyError(str(err)) from None
    for key, note in run_choice.items():
        log.info("discrepancy: %s: %s", key, note)
    report, full = analyse(
        runs, base_family=str(cfg["base_family"]), base_params=cfg["base_params"],
        auto_families=cfg["auto_families"], settings=settings,
        ukf_evidence=bool(cfg["ukf_evidence"]), base_check=bool(cfg["base_check"]),
        base_misfit_factor=float(cfg["base_misfit_factor"]),
        base_misfit_fallback=bool(cfg["base_misfit_fallback"]), max_bases=int(cfg["max_bases"]),
        base_retry_factor=float(cfg["base_retry_factor"]))
    report["run_choice"] = run_choice or None
    report["channels"] = channels
    report["source"] = str(Path(str(cfg["source"])).resolve())
    report["ingest"] = {"accepted": ingest_rep["n_accepted"], "rejected": ingest_rep["rejected"]}
    plots = plot_report(full, plots_dir) if cfg["plots"] else []
    report["plots"] = [str(p) for p in plots]
    report["elapsed_s"] = round(time.perf_counter() - t0, 3)
    write_text_atomic(report_path, json.dumps(report, indent=1, default=_json_default) + "\n")
    _track(cfg, report, report_path, plots, meta)
    log.info("%s", report["headline"])
    return report


def base_misfit(runs: list[RunData], report: Mapping[str, Any],
                families: Mapping[str, Mapping[str, Any]], *,
                factor: float) -> dict[str, Any] | None:
    """A chosen base that, *with the terms the workflow added*, still predicts the held-out
    runs ``factor`` x worse than the best standard family does plain: the base cannot take the
    loop's shape, and its terms may stand in for that misfit (a sum-to-one play sum on a
    Bouc-Wen-shaped loop gets an "asymmetry"). Judged after the terms, so a base that only
    lacked the effect (thesis Gamma on a drifting source, worse plain than a family that bends
    to the drift) is not flagged once the term is in. ``None`` if it fits. The check without
    a second workflow (``base_misfit_fallback=false``); :func:`second_opinion` is the one
    with."""
    try:
        _, _, scores = choose_base(runs, families)
    except DiscrepancyError:
        return None
    best = min(scores, key=scores.__getitem__)
    own = float(report["summary"]["heldout_rmse_after"])
    ratio = own / scores[best] if scores[best] > 0 else float("inf")
    if ratio <= factor:
        return None
    log.warning("base %s with its terms fits this source %.1fx worse held out than %s plain "
                "(%.4g vs %.4g): the effects named may stand in for the base's misfit",
                report["base_family"], ratio, best, own, scores[best])
    return {"base": report["base_family"], "heldout_rmse": own, "best_family": best,
            "best_heldout_rmse": scores[best], "ratio": ratio, "scores": scores}


def headline(report: Mapping[str, Any]) -> str:
    """One sentence: which effect was added and by how much it cut the held-out error (and
    which effects the load cells show that the model already reproduces)."""
    measured = [m["name"] for m in report.get("measured_within_reach", [])]
    also = (f"; the load cells also show {', '.join(measured)}, already reproduced by the "
            "model (named, not added)") if measured else ""
    tried = report.get("bases_tried") or []
    if len(tried) > 1 and report.get("base_selection"):
        plain = min(report["base_selection"], key=report["base_selection"].__getitem__)
        others = "; ".join(" + ".join([t["base"], *t["effects"]])
                           + f" {t['heldout_rmse_after']:.4g}" for t in tried)
        also += (f"; base chosen with its terms (best plain family: {plain}; held-out RMSE "
                 f"after the terms: {others})")
    misfit = report.get("base_misfit")
    given = report.get("given_base")
    if misfit and given:
        named = ", ".join(given["effects"]) or given["verdict"].replace("_", " ")
        also += (f"; answered with {misfit['best_family']} because the given base "
                 f"{misfit['base']} fits this source {misfit['ratio']:.1f}x worse held out "
                 f"plain and {misfit['ratio_with_terms']:.1f}x worse with its terms (with it: "
                 f"{named}, which may be its own misfit)")
    elif misfit:
        also += (f"; caution: base {misfit['base']} with its terms fits this source "
                 f"{misfit['ratio']:.1f}x worse held out than {misfit['best_family']} plain, so "
                 "what is named may be the base's misfit (base_family=auto picks the best)")
    if not report["effects"]:
        ratio = float(report["residual"]["rmse_over_noise"])
        rmse = f"held-out RMSE {report['summary']['heldout_rmse_before']:.4g}, {ratio:.1f}x " \
               "the noise floor"
        reach = report.get("within_base_reach") or []
        absorbed = (f"; within the base's reach (it absorbs them, so these runs cannot tell "
                    f"them apart from it): {', '.join(reach)}") if reach else ""
        if report["verdict"] == "unexplained":
            tried_terms = ", ".join(s["name"] for s in (report.get("rankings") or [[]])[0])
            return (f"unexplained: the base {report['base_family']} leaves a residual no "
                    f"candidate term reduces ({rmse}; tried: {tried_terms or 'none'}); see the "
                    f"located segments{absorbed}{also}")
        return (f"no missing effect: no candidate term beats the noise on the held-out runs "
                f"(base {report['base_family']}, {rmse}){absorbed}{also}")
    parts = []
    ident = report.get("identifiability")
    for i, e in enumerate(report["effects"]):
        cut = 1.0 - e["heldout_rmse_after"] / e["heldout_rmse_before"]
        name = f"{e['name']} ({e['form']})" if e.get("form") else e["name"]
        if i == 0 and ident:
            name = ident["statement"]
        parts.append(f"{name} (held-out RMSE {e['heldout_rmse_before']:.4g} -> "
                     f"{e['heldout_rmse_after']:.4g}, -{100 * cut:.1f} %)")
    return f"base {report['base_family']} is missing: " + "; then ".join(parts) + also


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def _track(cfg: Mapping[str, Any], report: Mapping[str, Any], report_path: Path,
           plots: list[Path], runs: Mapping[str, Mapping[str, Any]] | None = None) -> None:
    from pipelines import lineage
    from pipelines.tracking import StageRun, stage_tracker

    tracker = stage_tracker(cfg)
    if tracker is None:
        return
    # the measured runs it analysed: on the analysis run and on its stage's own parent
    data = lineage.source_input(str(cfg["source"]), runs or {}, context="analysis")
    with StageRun(tracker, "discrepancy") as stage:
        with tracker.run(f"discrepancy {Path(str(report['source'])).name}",
                         parent_id=stage.parent_id, note=str(report["headline"]),
                         tags={"stage": "discrepancy", "kind": "analysis",
                               "verdict": report["verdict"]}) as run_id:
            lineage.log_input(tracker, [run_id, stage.parent_id if stage.owns else None],
                              data)
            s = report["summary"]
            metrics = {
                "before.rmse": s["rmse_before"], "after.rmse": s["rmse_after"],
                "before.heldout_rmse": s["heldout_rmse_before"],
                "after.heldout_rmse": s["heldout_rmse_after"],
                "heldout_reduction": s["heldout_reduction"],
                "n_effects": float(len(report["effects"])),
            }
            for i, e in enumerate(report["effects"]):
                metrics[f"effect{i + 1}.heldout_rmse_after"] = e["heldout_rmse_after"]
            if report.get("base_misfit"):
                metrics["base_misfit_ratio"] = report["base_misfit"]["ratio"]
            params = {"source": report["source"], "base_family": report["base_family"],
                      "base_params": json.dumps(report["base_params"]),
                      "effects": ",".join(e["name"] for e in report["effects"]) or "none",
                      "measured_within_reach": ",".join(
                          m["name"] for m in report.get("measured_within_reach", [])) or "none",
                      **{f"workflow.{k}": v for k, v in cfg["workflow"].items()}}
            if report.get("given_base"):
                params["given_base"] = report["given_base"]["base"]
                params["given_base.effects"] = ",".join(report["given_base"]["effects"]) \
                    or "none"
            tracker.log(run_id, params=params,
                        metrics={k: float(v) for k, v in metrics.items() if math.isfinite(v)})
            tracker.log_artifact(run_id, report_path, "reports")
            for p in plots:
                tracker.log_artifact(run_id, p, "plots")


def _main() -> None:
    import hydra
    from omegaconf import DictConfig

    from pipelines.common import run_stage, to_container

    @hydra.main(config_path="../conf", config_name="discrepancy", version_base="1.3")
    def main(cfg: DictConfig) -> None:
        rep = run_stage("discrepancy", lambda: run(to_container(cfg)),
                        errors=(DiscrepancyError,))
        print(rep["headline"])

    main()


if __name__ == "__main__":
    from pipelines.cli import guard

    guard("discrepancy")
    _main()
