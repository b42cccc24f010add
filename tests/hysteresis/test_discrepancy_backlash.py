"""The input load cell's backlash reading (evidence for a dead zone).

Synthetic runs put a known backlash of full width ``d`` between the carriage (the encoder's
input ``u``) and the tendon's end, and give the tendon a concave tension response after every
reversal (a sum of stop operators: each contact element passes on travel until it slips, so the
stiffness is highest just after a reversal, as under capstan friction). The reading must find
``d`` and only ``d``; virtual-rig runs check that it sees the rig's dead zone and nothing else.
"""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.backlash import (
    MIN_DEAD_TRAVEL_FRACTION,
    dead_travel,
    dead_travels,
    turning_points,
)
from hysteresis.discrepancy.evidence import corroboration
from hysteresis.discrepancy.runs import RunData

DT = 0.05  # the workflow's 20 Hz


def backlash_run(d: float, *, pull: float = 1.0, noise: float = 0.0, seed: int = 0,
                 tension: bool = True, key: float = 90.0) -> RunData:
    """Decaying sine at the carriage; the tendon's end follows through a backlash of width d;
    tension = pretension + sum of stop operators of the tendon's end (concave after reversal)."""
    t = np.arange(0.0, 48.0, DT)
    amp = np.repeat([6.0, 4.5, 3.0, 1.5], t.size // 4 + 1)[: t.size]
    u = pull * amp * np.sin(2 * np.pi * 0.25 * t)
    x = play(u, 0.5 * d, z0=0.0)
    radii = np.linspace(0.1, 2.0, 12)
    tens = 4.0 + sum(0.4 * (x - play(x, r, z0=0.0)) for r in radii) * pull
    tens = tens + noise * np.random.default_rng(seed).standard_normal(t.size)
    return RunData(run_id=f"d{d}", t=t, u=u, y=u, tension=tens if tension else None,
                   config={"curve_angle_deg": key})


def test_turning_points_ignore_wiggles_smaller_than_the_tolerance():
    t = np.linspace(0.0, 4.0, 401)
    u = np.sin(2 * np.pi * 0.5 * t) + 0.01 * np.sin(2 * np.pi * 20 * t)
    turns = turning_points(u, tol=0.05)
    # the slow sine turns at 0.5, 1.5, 2.5, 3.5 s; the fast wiggle is below the tolerance
    assert np.allclose(t[turns], [0.5, 1.5, 2.5, 3.5], atol=0.06)
    assert len(turning_points(u, tol=0.001)) > 20


@pytest.mark.parametrize("d", [0.2, 0.4, 0.8])
@pytest.mark.parametrize("pull", [1.0, -1.0])
def test_the_reading_recovers_a_known_backlash(d, pull):
    got = dead_travel(backlash_run(d, pull=pull))
    assert got is not None and got["n_reversals"] >= 20
    # the chord of the concave response meets the axis a little before the end of the dead
    # travel (by 0.04 mm here, as without a backlash below)
    assert d - 0.08 < got["dead_travel"] <= d + 0.01, got
    assert got["fraction_of_span"] == pytest.approx(got["dead_travel"] / 12.0, rel=0.01)


def test_without_backlash_the_reading_is_not_positive():
    got = dead_travel(backlash_run(0.0))
    assert got is not None and -0.08 < got["dead_travel"] <= 0.0
    spread = dead_travels(backlash_run(0.0))
    assert spread is not None and np.all(spread < 0.01)


def test_load_cell_noise_does_not_make_a_backlash():
    for seed in range(3):
        clean = dead_travel(backlash_run(0.0, noise=0.01, seed=seed))
        with_dz = dead_travel(backlash_run(0.2, noise=0.01, seed=seed))
        assert clean is not None and with_dz is not None
        assert clean["fraction_of_span"] < MIN_DEAD_TRAVEL_FRACTION
        assert with_dz["fraction_of_span"] > 2 * MIN_DEAD_TRAVEL_FRACTION


def test_dead_zone_corroboration_needs_a_dead_travel_in_every_configuration():
    both = corroboration("dead_zone", [backlash_run(0.4), backlash_run(0.4, key=45.0)])
    assert both["claim"] == "dead_travel" and both["corroborated"] is True
    assert len(both["per_configuration"]) == 2
    one = corroboration("dead_zone", [backlash_run(0.4), backlash_run(0.0, key=45.0)])
    assert one["corroborated"] is False
    # without an input tension the check cannot be made: judged on the output alone
    blind = corroboration("dead_zone", [backlash_run(0.4, tension=False)])
    assert blind["corroborated"] is None and dead_travel(backlash_run(0.4, tension=False)) is None


@pytest.mark.parametrize(("effects", "dead"), [
    ({}, False),
    ({"dead_zone": 0.5}, True),
    ({"dead_zone": 1.0}, True),
    # a follower stop holds the tension still at the end of a stroke, not after a reversal
    ({"saturation": 2.0}, False),
    # the extra compliance makes the response more concave, not delayed
    ({"tendon_elongation": 12.0}, False),
    ({"asymmetry": 2.0}, False),
    ({"rate_dependence": 2.0}, False),
    ({"time_delay": 2.0}, False),
])
def test_the_rigs_input_load_cell_shows_its_dead_zone_and_nothing_else(effects, dead):
    from pipelines.discrepancy_study import STUDY_EXCITATIONS, hidden_effect_runs

    ident = hidden_effect_runs(effects, [(90.0, 30.0), (45.0, 60.0)],
                               excitations={"sine_decay": STUDY_EXCITATIONS["sine_decay"]})
    ev = corroboration("dead_zone", ident)
    assert ev["corroborated"] is dead, ev
    if effects.get("dead_zone"):
        width = 0.4 * effects["dead_zone"]  # mm, full width at strength 1
        for r in ident:
            got = dead_travel(r)
            assert got is not None and 0.7 * width < got["dead_travel"] < 1.1 * width, got
