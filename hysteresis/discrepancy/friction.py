"""Friction read straight from the two load cells: independent evidence for friction hypotheses.

While the whole tendon slides, capstan friction sets the tension ratio across the sheath:
``ln(T_in / T_out) = +mu Theta`` pulling and ``-mu Theta`` releasing (Theta = the path's total
turning, plus the contact terms). So ``sign(v) ln(T_in / T_out)`` is a friction reading that does
not go through the output position at all. Two candidates claim that friction itself changes:

* ``rate_dependence``: friction grows with sliding speed, so the reading is larger on the fast
  parts of a stroke than on the slow ones (``speed_ratio`` > 1);
* ``asymmetry``: friction differs between pulling and releasing (``direction_ratio`` != 1).

Every other candidate (a latency of the output measurement, a drift, extra stretch, a stop, an
actuator-side dead zone) leaves the friction reading alone (the dead zone has a reading of its
own, :mod:`.backlash`; :mod:`.evidence` says which candidate claims what). The workflow uses
these ratios to keep a friction hypothesis from standing in for a latency or a stretch that
shapes the loop the same way: a friction candidate is only accepted when the load cells show
the change it claims.

Only samples of *full* sliding count: after a reversal the slip front needs some travel to run
through the sheath (the ratio swings from one sign to the other meanwhile), so samples within
``plateau_fraction`` x the run's input span of the last reversal are left out.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.effects import speed
from hysteresis.discrepancy.runs import RunData

#: Evidence thresholds: a friction claim needs the reading to change by at least this factor.
#: On clean virtual-rig runs both ratios stay within 0.93-1.00 (texture and load-cell noise);
#: the weakest effects tried (rate_dependence 0.5, asymmetry 0.5) give 1.18 and 1.30.
MIN_SPEED_RATIO = 1.08
MIN_DIRECTION_RATIO = 1.12


def travel_since_reversal(u: FloatArray, v: FloatArray) -> FloatArray:
    """Input travel since the last change of the direction of motion."""
    out = np.zeros(u.size)
    last = float(u[0])
    cur = 0.0
    for i in range(1, u.size):
        s = float(np.sign(v[i])) or cur
        if s != cur:
            last = float(u[i - 1])
            cur = s
        out[i] = abs(float(u[i]) - last)
    return out


def follower_slides(run: RunData, *, fraction: float = 0.5) -> npt.NDArray[np.bool_]:
    """Samples where the output follows the input at no less than ``fraction`` of its usual
    rate (same direction): the whole tendon slides. Against an end-of-stroke stop the input
    keeps pulling while the follower stands, and the tension ratio then reads the stop's
    reaction, not friction."""
    du = np.diff(run.u, prepend=run.u[0])
    dy = np.diff(run.y, prepend=run.y[0])
    den = float(np.dot(du, du))
    if den == 0.0:
        return np.zeros(run.n, dtype=bool)
    gain = float(np.dot(du, dy)) / den  # the output's usual rate per unit input
    return np.asarray(dy * np.sign(gain) * np.sign(du) >= fraction * abs(gain) * np.abs(du),
                      dtype=np.bool_)


def friction_reading(run: RunData, *, plateau_fraction: float = 0.3,
                     t_floor: float = 0.05) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """``(reading, speed, direction)`` on the fully sliding samples of ``run``, or ``None``
    when the run has no tension at both ends."""
    if run.tension is None or run.tension_out is None:
        return None
    v = speed(run)  # the speed the rate term uses
    moving = np.abs(v) > 0.05 * float(np.percentile(np.abs(v), 99))
    travel = travel_since_reversal(run.u, np.where(moving, v, 0.0))
    full = moving & (travel > plateau_fraction * float(np.ptp(run.u))) & follower_slides(run)
    if int(full.sum()) < 30:
        return None
    ratio = np.log(np.maximum(run.tension, t_floor) / np.maximum(run.tension_out, t_floor))
    sgn = np.sign(v[full])
    return ratio[full] * sgn, np.abs(v[full]), sgn


def friction_ratios(run: RunData, **kwargs: Any) -> dict[str, float] | None:
    """``speed_ratio`` (mean reading in the fastest third / slowest third of the sliding
    samples, within each direction, geometric mean of the two) and ``direction_ratio``
    (pulling / releasing, within each speed third, geometric mean of the three); ``None``
    without both tensions. Comparing within strata keeps one effect out of the other's ratio
    (pulls and releases of a decaying sine do not sample the speeds alike)."""
    got = friction_reading(run, **kwargs)
    if got is None:
        return None
    reading, speed, sgn = got
    by_speed, slow_v, fast_v = [], [], []
    for d in (1.0, -1.0):
        sp, rd = speed[sgn == d], reading[sgn == d]
        if sp.size < 30:
            return None
        lo, hi = np.percentile(sp, [100 / 3, 200 / 3])
        by_speed.append(_ratio(float(rd[sp >= hi].mean()), float(rd[sp <= lo].mean())))
        slow_v.append(float(np.median(sp[sp <= lo])))
        fast_v.append(float(np.median(sp[sp >= hi])))
    edges = np.percentile(speed, [0, 100 / 3, 200 / 3, 100])
    by_dir = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        band = (speed >= a) & (speed <= b)
        pull, rel = reading[band & (sgn > 0)], reading[band & (sgn < 0)]
        if min(pull.size, rel.size) < 5:
            continue
        by_dir.append(_ratio(float(pull.mean()), float(rel.mean())))
    if not by_dir:
        return None
    return {"speed_ratio": _geomean(by_speed), "direction_ratio": _geomean(by_dir),
            "n_samples": float(reading.size),
            "speed_slow_mm_s": float(np.mean(slow_v)), "speed_fast_mm_s": float(np.mean(fast_v))}


def _geomean(x: list[float]) -> float:
    a = np.asarray(x, dtype=float)
    return float(np.exp(np.mean(np.log(a)))) if np.all(a > 0) else float("nan")


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 and a > 0 else float("nan")
