"""What the load cells say about a candidate, independently of the output fit.

Three candidates claim something the load cells can read without going through the output
position:

* ``rate_dependence``: friction grows with sliding speed (``speed_ratio`` > 1, :mod:`.friction`);
* ``asymmetry``: friction differs between pulling and releasing (``direction_ratio`` != 1,
  :mod:`.friction`);
* ``dead_zone``: after every reversal the carriage travels a while before the tendon's tension
  moves (``dead_travel`` > 0, :mod:`.backlash`).

The other candidates make no load-cell claim and are judged on the output fit alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.backlash import MIN_DEAD_TRAVEL_FRACTION, dead_travel
from hysteresis.discrepancy.friction import (
    MIN_DIRECTION_RATIO,
    MIN_SPEED_RATIO,
    friction_ratios,
)
from hysteresis.discrepancy.runs import RunData

#: Which candidate claims which reading.
CLAIMS = {"rate_dependence": "speed_ratio", "asymmetry": "direction_ratio",
          "dead_zone": "dead_travel"}


def reading(claim: str, run: RunData) -> float | None:
    """The value of ``claim`` on one identification run (None: the run cannot show it).
    ``dead_travel`` is given as a fraction of the run's input span (scale-free)."""
    if claim == "dead_travel":
        got = dead_travel(run)
        return None if got is None else got["fraction_of_span"]
    ratios = friction_ratios(run)
    if ratios is None or not np.isfinite(ratios[claim]):
        return None
    return float(ratios[claim])


def corroboration(name: str, idents: Sequence[RunData]) -> dict[str, Any]:
    """Do the load cells show what candidate ``name`` claims?

    Returns ``{"claim": ..., "per_configuration": {...}, "corroborated": True/False/None}``;
    ``None`` when the candidate makes no load-cell claim or no run carries the channels the
    reading needs (the check cannot be made, and the candidate is judged on the output alone).
    A claim holds when every configuration shows it (one sheath, one mechanism).
    """
    claim = CLAIMS.get(name)
    if claim is None:
        return {"claim": None, "per_configuration": {}, "corroborated": None}
    per: dict[str, float] = {}
    for r in idents:
        x = reading(claim, r)
        if x is not None:
            per[r.config_key] = x
    if not per:
        return {"claim": claim, "per_configuration": per, "corroborated": None}
    if claim == "speed_ratio":
        ok = all(x >= MIN_SPEED_RATIO for x in per.values())
    elif claim == "dead_travel":
        ok = all(x >= MIN_DEAD_TRAVEL_FRACTION for x in per.values())
    else:
        logs = [float(np.log(x)) for x in per.values()]
        ok = (all(abs(x) >= np.log(MIN_DIRECTION_RATIO) for x in logs)
              and len({np.sign(x) for x in logs}) == 1)  # one sheath: the same side everywhere
    return {"claim": claim, "per_configuration": per, "corroborated": bool(ok)}


#: The input tension "follows the speed" when speed terms explain at least this share of what a
#: rate-independent map of the input leaves of it.
SPEED_SHARE = 0.8


#: An output tension that an affine map of the output explains to this share of its variance
#: (R^2) carries nothing the output does not (a spring follower: ``T_out = F0 + k y``), so a
#: term on it is a static curve of the output.
FOLLOWS_OUTPUT_R2 = 0.99


def output_tension_follows(idents: Sequence[RunData]) -> float | None:
    """The least R^2 over the identification runs of the output tension regressed on
    ``a + b y`` (the output), or None without an output tension. Near 1: the follower's load is
    a function of its position alone, and the tension adds no channel to the output."""
    shares = []
    for run in idents:
        if run.tension_out is None:
            return None
        t = run.tension_out
        x = np.column_stack([np.ones(run.n), run.y])
        coef, *_ = np.linalg.lstsq(x, t, rcond=None)
        var = float(np.sum((t - t.mean()) ** 2))
        shares.append(1.0 - float(np.sum((t - x @ coef) ** 2)) / var if var > 0 else 0.0)
    return min(shares) if shares else None


def tension_speed_share(idents: Sequence[RunData], *, n_plays: int = 7) -> float | None:
    """How much of the input tension the input speed explains beyond a rate-independent map.

    On the identification runs the tension is regressed on a rate-independent basis (plays of
    the input with thresholds up to half its span, the input, a constant) and again with speed
    terms added (``v``, ``sign(v) |v|^0.5``, ``|v|``, scaled by the 99th-percentile speed);
    returns the share of the first fit's residual variance the speed terms remove (partial
    R^2), or None without an input tension. A capstan tension set by the friction state alone
    leaves little to the speed; a tension that also carries a viscous or relaxing force (a
    rate effect pulling on the tendon) leaves most of it."""
    rows_plain, rows_speed, target = [], [], []
    for run in idents:
        if run.tension is None:
            return None
        span = float(np.ptp(run.u))
        radii = np.linspace(0.0, 0.5 * span, n_plays + 1)[1:]
        plain = np.column_stack([*(play(run.u, float(r)) for r in radii), run.u,
                                 np.ones(run.n)])
        v = run.v / max(float(np.percentile(np.abs(run.v), 99)), 1e-12)
        rows_plain.append(plain)
        rows_speed.append(np.column_stack([plain, v, np.sign(v) * np.sqrt(np.abs(v)),
                                           np.abs(v)]))
        target.append(run.tension)
    t = np.concatenate(target)

    def residual(a: list[np.ndarray]) -> float:
        x = np.vstack(a)
        coef, *_ = np.linalg.lstsq(x, t, rcond=None)
        return float(np.sum((t - x @ coef) ** 2))

    plain_ss = residual(rows_plain)
    if plain_ss <= 0.0:
        return 0.0
    return float(1.0 - residual(rows_speed) / plain_ss)
