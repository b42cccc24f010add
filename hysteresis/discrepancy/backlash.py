"""Backlash read straight from the input load cell: independent evidence for a dead zone.

The input encoder reads the carriage; the input load cell reads the tendon's end. Without
backlash between them, the tendon's tension starts to change the moment the carriage reverses,
and fastest right then: the slip front that runs into the sheath from the input is short, so the
first newtons cost almost no travel (under capstan friction the travel grows roughly as the
square of the tension change). The curve of tension change against input travel after a
reversal is concave and passes through the origin.

With an actuator-side dead zone of width ``d`` the carriage moves ``d`` after every reversal
before it takes up the tendon again: the tension sits still for that travel, and then changes
as before. The same curve is shifted right by ``d``.

The reading fits a straight line to the *first passage* of the tension change through
``lo``-``hi`` of its swing after each reversal and takes the line's input-travel intercept: about
``d`` with a dead zone, slightly negative without one (the concave curve's chord meets the axis
before the origin). Taken on the steep part only, so a follower stop (which holds the tension
still at the end of a stroke, not at its start) or a latency of the output measurement does not
read as a dead zone. The median over reversals is reported.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.runs import RunData

#: A dead zone is read when the dead travel is at least this fraction of the input span. On
#: clean virtual-rig runs the reading is -0.08 to +0.02 mm (spans of 12 mm); the weakest dead
#: zone tried (strength 0.5, 0.2 mm) reads 0.14-0.16 mm.
MIN_DEAD_TRAVEL_FRACTION = 0.005


def turning_points(u: FloatArray, *, tol: float) -> list[int]:
    """Indices of the input's turning points: extremes after which the input comes back by more
    than ``tol`` (so that encoder noise and servo steps are not reversals)."""
    out: list[int] = []
    ext = 0
    direction = 0.0
    for i in range(1, u.size):
        if direction >= 0.0 and u[i] > u[ext]:
            ext, direction = i, direction or 1.0
        elif direction <= 0.0 and u[i] < u[ext]:
            ext, direction = i, direction or -1.0
        elif abs(float(u[i] - u[ext])) > tol:
            if direction != 0.0:
                out.append(ext)
            direction = -direction if direction != 0.0 else float(np.sign(u[i] - u[ext]))
            ext = i
    return out


def dead_travels(run: RunData, *, lo: float = 0.1, hi: float = 0.4,
                 min_travel_fraction: float = 0.04) -> FloatArray | None:
    """Dead travel after every reversal of ``run`` (input units), or ``None`` without an input
    tension. Reversals whose stroke travels less than ``min_travel_fraction`` of the span, or
    whose tension change crosses ``lo``-``hi`` of its swing in fewer than two samples, are left
    out."""
    if run.tension is None:
        return None
    u, tension = run.u, run.tension
    span = float(np.ptp(u))
    if span <= 0.0:
        return None
    turns = turning_points(u, tol=0.02 * span)
    ends = [*turns[1:], u.size - 1]
    sign = run.pull_sign
    out = []
    for i, j in zip(turns, ends, strict=True):
        du = np.abs(u[i:j + 1] - u[i])
        if du[-1] < min_travel_fraction * span:
            continue
        moving = float(np.sign(u[j] - u[i]))
        dt = sign * moving * (tension[i:j + 1] - tension[i])
        swing = float(dt.max())
        if swing <= 0.0:
            continue
        reached = np.flatnonzero(dt >= hi * swing)
        first = int(reached[0])
        sel = np.flatnonzero(dt[: first + 1] >= lo * swing)
        if sel.size < 2 or np.ptp(dt[sel]) <= 0.0:
            continue
        _, intercept = np.polyfit(dt[sel], du[sel], 1)
        out.append(float(intercept))
    return np.asarray(out, dtype=np.float64)


def dead_travel(run: RunData, **kwargs: Any) -> dict[str, float] | None:
    """``{"dead_travel": median, "fraction_of_span": ..., "n_reversals": ...}`` or ``None``
    (no input tension, or fewer than four usable reversals)."""
    d = dead_travels(run, **kwargs)
    if d is None or d.size < 4:
        return None
    med = float(np.median(d))
    return {"dead_travel": med, "fraction_of_span": med / float(np.ptp(run.u)),
            "n_reversals": float(d.size)}
