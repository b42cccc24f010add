"""The discrepancy stages' data step: a source of raw runs (or raw runs in memory) -> the
processed rows -> :class:`~hysteresis.discrepancy.runs.RunData` (configuration, role, tension
channels, decimation), as the workflow sees them.

Shared by the discrepancy stage (a source on disk, ingested into a temporary folder), the
detection study (virtual-rig runs in memory) and the kernel compiler, so none of them imports
another's stage module.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.base import HysteresisError
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.runs import RunData, describe_mix
from hysteresis.roles import manifest_role, run_role

#: A channel with at most this share of its samples missing (a stream that ends a sample or
#: two early, a short dropout) is filled by interpolation in time; beyond it, it is dropped.
MAX_FILLED_FRACTION = 0.01


def ingest_source(source: str | Path, workdir: Path, *, mapping: Mapping[str, Any] | None = None,
                  progress: bool = False) -> tuple[pd.DataFrame, dict[str, dict[str, Any]],
                                                   dict[str, Any]]:
    """Ingest ``source`` into ``workdir``; return (rows, per-run metadata, ingest report)."""
    from pipelines.core.ingest import run_ingest
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
    identify = set(identify_excitations)
    out = []
    for run_id, df in rows.groupby("run_id", sort=True):
        run, notes = _run_data(str(run_id), df, meta.get(str(run_id), {}), identify,
                               input_col=input_col, output_col=output_col)
        if channels is not None:
            channels[str(run_id)] = notes
        if rate_hz:
            run = run.decimated(max(1, int(round(1.0 / (rate_hz * run.dt)))))
        out.append(run)
    return out


def _run_data(run_id: str, df: pd.DataFrame, meta: Mapping[str, Any], identify: set[str], *,
              input_col: str, output_col: str) -> tuple[RunData, dict[str, str]]:
    """One run's rows as :class:`RunData`, and what was done to each tension channel."""
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
    run = RunData(
        run_id=run_id, t=t, u=df[input_col].to_numpy(float),
        y=df[output_col].to_numpy(float), tension=tension,
        tension_out=tension_out, config=config, excitation=kind,
        role=_role(run_id, meta, kind, identify),
        started_at=_started_at(meta),
    )
    return run, notes


def _started_at(meta: Mapping[str, Any]) -> float | None:
    """The manifest's ``started_at`` as POSIX seconds (None when absent or unreadable: the run
    is then never taken as recorded after another)."""
    stamp = (meta.get("manifest") or {}).get("started_at")
    if not isinstance(stamp, str):
        return None
    try:
        when = datetime.fromisoformat(stamp)
    except ValueError:
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.timestamp()
