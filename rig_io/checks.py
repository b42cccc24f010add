"""Semantic checks of one run that apply whatever container it came in (folder or bag).

Structural problems (unreadable files, missing columns, non-numeric cells) are found by the
readers; these functions look at values: timestamps, gaps, load-cell saturation, e-stops,
camera confidence (rig-log-format.md section 3) and position channels that never move. Each
raises :class:`RigIOError` naming the run, the file and the row (1-based line in the file,
header = line 1) or the time.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from rig_io.calibrate import PhysicalRun
from rig_io.errors import RigIOError

#: A gap longer than this many median sample periods rejects the run (format section 3).
MAX_GAP_PERIODS = 10.0
#: Row of the first data line in a CSV file (line 1 is the header).
FIRST_DATA_LINE = 2


def _row(i: int, rows: bool) -> int | None:
    return i + FIRST_DATA_LINE if rows else None


def check_timestamps(t_ns: npt.NDArray[np.int64], *, run: str, file: str,
                     check_gaps: bool = True, rows: bool = True,
                     max_gap_periods: float = MAX_GAP_PERIODS, min_samples: int = 1) -> None:
    """Timestamps strictly increase and have no gap longer than 10 sample periods; a
    sampled stream needs ``min_samples`` (2: one sample has no rate and cannot be resampled)."""
    if t_ns.size == 0:
        raise RigIOError("no samples", run=run, file=file, key="t_ns")
    if t_ns.size < min_samples:
        raise RigIOError(f"only {t_ns.size} sample(s); a sampled stream needs at least "
                         f"{min_samples}", run=run, file=file, row=_row(0, rows),
                         t_ns=int(t_ns[0]))
    dt = np.diff(t_ns)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        what = "repeats" if dt[bad[0]] == 0 else "goes backwards"
        raise RigIOError(f"timestamp {what} (previous sample at t={int(t_ns[i - 1])} ns)",
                         run=run, file=file, row=_row(i, rows), t_ns=int(t_ns[i]))
    if check_gaps and dt.size >= 2:
        period = float(np.median(dt))
        gaps = np.flatnonzero(dt > max_gap_periods * period)
        if gaps.size:
            i = int(gaps[0])
            raise RigIOError(
                f"gap of {dt[i] / 1e6:.1f} ms after this sample is longer than "
                f"{max_gap_periods:g} sample periods ({period / 1e6:.2f} ms)",
                run=run, file=file, row=_row(i, rows), t_ns=int(t_ns[i]))


def check_saturation(t_ns: npt.NDArray[np.int64], force_n: npt.NDArray[np.float64], *,
                     range_n: float | None, side: str, run: str, file: str,
                     rows: bool = True) -> None:
    """A load cell reading at or beyond its range is saturated and rejects the run."""
    if range_n is None:
        return
    sat = np.flatnonzero(np.abs(force_n) >= float(range_n))
    if sat.size:
        i = int(sat[0])
        raise RigIOError(
            f"{side} load cell saturated: {force_n[i]:.3f} N is at or beyond its range "
            f"{float(range_n):g} N ({sat.size} saturated samples)",
            run=run, file=file, row=_row(i, rows), t_ns=int(t_ns[i]))


def check_events(events: pd.DataFrame | None, *, run: str, file: str,
                 rows: bool = True) -> None:
    """An ``estop`` event makes the data after it invalid: the run is rejected."""
    if events is None or events.empty:
        return
    kinds = events["event"].astype(str).to_numpy()
    hits = np.flatnonzero(kinds == "estop")
    if hits.size:
        i = int(hits[0])
        detail = events["detail"].iloc[i]
        extra = f" ({detail})" if isinstance(detail, str) and detail else ""
        raise RigIOError(f"emergency stop (estop event){extra}: data after it is not valid",
                         run=run, file=file, row=_row(i, rows),
                         t_ns=int(events["t_ns"].iloc[i]))


def check_confident(frame: pd.DataFrame, *, run: str, file: str) -> None:
    """A camera or tracker stream needs at least one confident, measured frame."""
    value = pd.to_numeric(frame["value"], errors="coerce").to_numpy(dtype=float)
    conf = pd.to_numeric(frame["confidence"], errors="coerce").to_numpy(dtype=float)
    ok = np.isfinite(value) & np.isfinite(conf) & (conf > 0)
    if not ok.any():
        raise RigIOError(f"no confident frame among {len(frame)} frames "
                         "(every frame has confidence 0 or no value)", run=run, file=file,
                     key="confidence")


def check_overlap(frame: pd.DataFrame, t_encoder: npt.NDArray[np.int64], *, stream: str,
                  run: str, file: str) -> None:
    """A load cell, camera or tracker stream must share time with the encoder: at least two
    of its (confident, measured) samples lie inside the encoder's span. A stream stamped on
    another clock otherwise resamples to nothing, or (camera) to a constant."""
    t = frame["t_ns"].to_numpy(dtype=np.int64)
    if stream in ("camera", "tracker"):
        value = pd.to_numeric(frame["value"], errors="coerce").to_numpy(dtype=float)
        conf = pd.to_numeric(frame["confidence"], errors="coerce").to_numpy(dtype=float)
        t = t[np.isfinite(value) & np.isfinite(conf) & (conf > 0)]
    if t.size == 0 or t_encoder.size == 0:
        return  # reported by the confidence and timestamp checks
    lo, hi = int(t_encoder[0]), int(t_encoder[-1])
    inside = int(np.count_nonzero((t >= lo) & (t <= hi)))
    if inside < 2:
        raise RigIOError(
            f"{stream} samples (t={int(t[0]) / 1e9:.3f}..{int(t[-1]) / 1e9:.3f} s) do not "
            f"overlap the encoder (t={lo / 1e9:.3f}..{hi / 1e9:.3f} s): {inside} inside",
            run=run, file=file, key="t_ns")


#: Largest |position| accepted, by unit: 10 m of tendon or follower travel, 1000 turns of a
#: motor or joint angle. Beyond that a value is corruption, not motion.
MAX_ABS_POSITION = {"mm": 1e4, "deg": 3.6e5}
#: Fastest encoder motion accepted, by unit (per second): 10 m/s of tendon, 1e6 deg/s. A
#: corrupt count that stays inside the counter's range shows up as a jump beyond this.
MAX_SPEED = {"mm": 1e4, "deg": 1e6}
#: Largest |tension| without a declared load-cell range (N).
MAX_ABS_TENSION_N = 1e5


def check_physical_values(run: PhysicalRun, *, rows: bool = False) -> None:
    """Calibrated values are finite and within physical ranges (a corrupt count, a bit flip
    in a bag's float, a counter wrongly declared): the input everywhere, the output encoder
    where measured, tensions, camera/tracker values where measured, confidence in [0, 1]."""
    run_id = run.run_id
    channels = run.manifest.get("channels") or {}
    unit = str((channels.get("encoder") or {}).get("unit", "mm"))
    limit = MAX_ABS_POSITION.get(unit, MAX_ABS_POSITION["mm"])
    enc = run.encoder
    t = enc["t_ns"].to_numpy(dtype=np.int64)
    for col, nullable in (("input", False), ("output", True)):
        v = enc[col].to_numpy(dtype=float)
        _finite_within(v, t, limit=limit, nullable=nullable, what=f"{col} position ({unit})",
                       key=col, run=run_id, file=run.file("encoder"), rows=rows)
        _speed_within(v, t, limit=MAX_SPEED.get(unit, MAX_SPEED["mm"]), unit=unit, key=col,
                      run=run_id, file=run.file("encoder"), rows=rows)
    if run.loadcell is not None:
        tl = run.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for col in ("tension_in_n", "tension_out_n"):
            _finite_within(run.loadcell[col].to_numpy(dtype=float), tl,
                           limit=MAX_ABS_TENSION_N, nullable=True, what="tension (N)",
                           key=col, run=run_id, file=run.file("loadcell"), rows=rows)
    for name in ("camera", "tracker"):
        frame = getattr(run, name)
        if frame is None:
            continue
        tv = frame["t_ns"].to_numpy(dtype=np.int64)
        quantity = str((channels.get(name) or {}).get("quantity", "output_mm"))
        vlimit = MAX_ABS_POSITION["deg" if quantity.endswith("_deg") else "mm"]
        _finite_within(frame["value"].to_numpy(dtype=float, na_value=np.nan), tv,
                       limit=vlimit, nullable=True, what=f"{name} value", key="value",
                       run=run_id, file=run.file(name), rows=rows)
        conf = frame["confidence"].to_numpy(dtype=float, na_value=np.nan)
        bad = np.flatnonzero(~((conf >= 0.0) & (conf <= 1.0)))
        if bad.size:
            i = int(bad[0])
            raise RigIOError(f"confidence {float(conf[i])!r} outside [0, 1]", run=run_id,
                             file=run.file(name), key="confidence", row=_row(i, rows),
                             t_ns=int(tv[i]))


def _speed_within(v: npt.NDArray[np.float64], t: npt.NDArray[np.int64], *, limit: float,
                  unit: str, key: str, run: str, file: str, rows: bool) -> None:
    if v.size < 2:
        return
    dt = np.diff(t).astype(float) / 1e9
    with np.errstate(invalid="ignore", divide="ignore"):
        speed = np.abs(np.diff(v)) / dt
    fast = np.flatnonzero((dt > 0) & (speed > limit))
    if fast.size:
        i = int(fast[0]) + 1
        raise RigIOError(f"{key} jumps by {v[i] - v[i - 1]:.6g} {unit} in {dt[i - 1] * 1e3:.3g}"
                         f" ms ({speed[i - 1]:.3g} {unit}/s, beyond {limit:g}): a corrupt "
                         "value, not motion", run=run, file=file, key=key, row=_row(i, rows),
                         t_ns=int(t[i]))


def _finite_within(v: npt.NDArray[np.float64], t: npt.NDArray[np.int64], *, limit: float,
                   nullable: bool, what: str, key: str, run: str, file: str,
                   rows: bool) -> None:
    finite = np.isfinite(v)
    bad = ~finite & ~np.isnan(v) if nullable else ~finite
    with np.errstate(invalid="ignore"):
        bad |= finite & (np.abs(v) > limit)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise RigIOError(f"{what} {float(v[i])!r} is not finite or beyond +-{limit:g}",
                         run=run, file=file, key=key, row=_row(i, rows), t_ns=int(t[i]))


def check_physical_run(run: PhysicalRun, *, rows: bool = False,
                       max_gap_periods: float = MAX_GAP_PERIODS) -> None:
    """The value checks on a calibrated run (bags and importers; rows are not lines there)."""
    run_id = run.run_id
    for name in ("encoder", "loadcell", "camera", "tracker", "events"):
        frame = getattr(run, name)
        if frame is not None:
            check_timestamps(frame["t_ns"].to_numpy(dtype=np.int64), run=run_id,
                             file=run.file(name), check_gaps=name != "events", rows=rows,
                             max_gap_periods=max_gap_periods,
                             min_samples=1 if name == "events" else 2)
    if run.loadcell is not None:
        cells = run.manifest.get("channels", {}).get("loadcell") or {}
        t = run.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for side, col in (("input", "tension_in_n"), ("output", "tension_out_n")):
            cell = cells.get(side) or {}
            check_saturation(t, run.loadcell[col].to_numpy(dtype=float),
                             range_n=cell.get("range_n"), side=side, run=run_id,
                             file=run.file("loadcell"), rows=rows)
    check_events(run.events, run=run_id, file=run.file("events"), rows=rows)
    for name in ("camera", "tracker"):
        frame = getattr(run, name)
        if frame is not None:
            check_confident(frame, run=run_id, file=run.file(name))
    check_physical_values(run, rows=rows)
    t_enc = run.encoder["t_ns"].to_numpy(dtype=np.int64)
    for name in ("loadcell", "camera", "tracker"):
        frame = getattr(run, name)
        if frame is not None:
            check_overlap(frame, t_enc, stream=name, run=run_id, file=run.file(name))


def check_moves(values: npt.NDArray[np.float64], *, channel: str, key: str, unit: str,
                resolution: float, run: str, file: str) -> None:
    """A position channel must move by more than its resolution over the run (one encoder
    count; any change for a camera or tracker value, ``resolution`` 0).

    A stuck encoder (a loose coupling, a broken cable) reads one value, or dithers by one
    count around it, while the input moves: its record holds no hysteresis, and a model fitted
    to it reproduces it "perfectly". One count of change is quantisation, not motion.
    """
    finite = values[np.isfinite(values)]
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    moved = span > resolution * (1.0 + 1e-6) if resolution > 0 else span > 0.0
    if moved:
        return
    counts = (f" = {span / resolution:.3g} encoder count(s); it must move by more than its "
              f"resolution of one count ({resolution:.3g} {unit})") if resolution > 0 else ""
    raise RigIOError(f"{channel} never moves: its range over the run is {span:.6g} {unit}"
                     f"{counts}", run=run, file=file, key=key)
