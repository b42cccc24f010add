"""Physical evidence of the discrepancy workflow: the load cells' friction reading and the
physical sign of a term's coefficients.

Synthetic runs carry a capstan tension ratio ``T_in / T_out = exp(sign(v) mu(v, dir) Theta)``
with a known friction law, so the ratios the reading reports can be checked against the law;
virtual-rig runs check that the reading sees the rig's friction effects and nothing else.
"""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy.effects import candidate
from hysteresis.discrepancy.evidence import corroboration
from hysteresis.discrepancy.friction import (
    MIN_DIRECTION_RATIO,
    MIN_SPEED_RATIO,
    follower_slides,
    friction_ratios,
    friction_reading,
    travel_since_reversal,
)
from hysteresis.discrepancy.runs import RunData

DT = 0.05
THETA = 1.5  # rad of total turning
T_OUT = 4.0


def capstan_run(*, gain: float = 0.0, asym: float = 0.0, noise: float = 0.0, seed: int = 0,
                tensions: bool = True) -> RunData:
    """Decaying sine input; tensions from a friction law mu (1 +- asym)(1 + gain tanh(|v|/5))."""
    t = np.arange(0.0, 48.0, DT)
    amp = np.repeat([6.0, 4.5, 3.0, 1.5], t.size // 4 + 1)[: t.size]
    u = amp * np.sin(2 * np.pi * 0.25 * t)
    v = np.gradient(u, t)
    mu = 0.2 * (1.0 + gain * np.tanh(np.abs(v) / 5.0)) * np.where(v > 0, 1 + asym, 1 - asym)
    rng = np.random.default_rng(seed)
    t_in = T_OUT * np.exp(np.sign(v) * mu * THETA) + noise * rng.standard_normal(t.size)
    t_out = T_OUT + noise * rng.standard_normal(t.size)
    return RunData(run_id=f"g{gain}a{asym}", t=t, u=u, y=u,
                   tension=t_in if tensions else None, tension_out=t_out if tensions else None,
                   config={"curve_angle_deg": 90.0})


def test_follower_slides_is_false_where_a_stop_holds_the_output():
    t = np.arange(0.0, 8.0, DT)
    u = 6.0 * np.sin(2 * np.pi * 0.25 * t)
    y = np.minimum(0.8 * u, 3.0)  # a stop at 3 mm on the pull side
    slides = follower_slides(RunData(run_id="s", t=t, u=u, y=y))
    at_stop = y >= 3.0
    held = at_stop & np.roll(at_stop, 1)  # at the stop since the sample before
    assert held.sum() > 20 and not slides[held].any()
    # elsewhere the output follows
    assert slides[~at_stop].all()


def test_a_follower_stop_does_not_read_as_friction_asymmetry():
    # Against the stop the input keeps pulling while the follower stands: the tension ratio
    # then reads the stop's reaction. Without the follower check, saturation 2 on these two
    # tight configurations read a pull/release ratio of 0.85 and corroborated an asymmetry.
    from pipelines.discrepancy_study import STUDY_EXCITATIONS, hidden_effect_runs

    ident = hidden_effect_runs({"saturation": 2.0}, [(90.0, 30.0), (75.0, 30.0)],
                               excitations={"sine_decay": STUDY_EXCITATIONS["sine_decay"]})
    for r in ident:
        ratios = friction_ratios(r)
        assert ratios is not None
        assert abs(np.log(ratios["direction_ratio"])) < np.log(1.06), ratios
    assert corroboration("asymmetry", ident)["corroborated"] is False


def test_travel_since_reversal_restarts_at_every_reversal():
    u = np.array([0.0, 1.0, 2.0, 3.0, 2.5, 1.0, 1.5])
    v = np.gradient(u)
    assert travel_since_reversal(u, v).tolist() == pytest.approx([0, 1, 2, 3, 0.5, 2.0, 0.5])


def test_reading_recovers_the_friction_law():
    reading, speed, sgn = friction_reading(capstan_run(gain=0.0))
    # rate-independent, symmetric friction: every full-slide sample reads mu Theta
    assert reading == pytest.approx(0.2 * THETA, rel=1e-6)
    r = friction_ratios(capstan_run(gain=1.0))
    v_slow, v_fast = r["speed_slow_mm_s"], r["speed_fast_mm_s"]
    expected = (1 + np.tanh(v_fast / 5.0)) / (1 + np.tanh(v_slow / 5.0))
    assert r["speed_ratio"] == pytest.approx(expected, rel=0.1)
    assert r["direction_ratio"] == pytest.approx(1.0, abs=0.03)
    a = friction_ratios(capstan_run(asym=0.3))
    assert a["direction_ratio"] == pytest.approx(1.3 / 0.7, rel=0.02)
    assert a["speed_ratio"] == pytest.approx(1.0, abs=0.02)


def test_corroboration_needs_the_claimed_change_in_every_configuration():
    flat, fast = capstan_run(noise=0.02), capstan_run(gain=1.0, noise=0.02)
    assert corroboration("rate_dependence", [fast])["corroborated"] is True
    assert corroboration("rate_dependence", [flat])["corroborated"] is False
    two = corroboration("rate_dependence", [fast, RunData(
        run_id="x", t=flat.t, u=flat.u, y=flat.y, tension=flat.tension,
        tension_out=flat.tension_out, config={"curve_angle_deg": 45.0})])
    assert two["corroborated"] is False and len(two["per_configuration"]) == 2
    assert corroboration("asymmetry", [capstan_run(asym=0.2)])["corroborated"] is True
    assert corroboration("asymmetry", [flat])["corroborated"] is False
    # no friction claim, or no tension at both ends: the check cannot be made
    assert corroboration("time_delay", [fast])["corroborated"] is None
    assert corroboration("rate_dependence", [capstan_run(tensions=False)])["corroborated"] is None


def test_elongation_term_can_only_shorten():
    # A stretch can only take input travel away in the direction that pulls: every stretch on
    # the term's grid moves the input the base sees against the pull, whichever way pulling
    # moves the input (no fit can use the tension as a gain standing in for something else).
    eff = candidate("tendon_elongation")
    run = capstan_run()
    for r in (run, RunData(run_id="inv", t=run.t, u=-run.u, y=-run.y, tension=run.tension,
                           tension_out=run.tension_out)):
        ctx = eff.context(r)
        # the input-side stretch (the output tension's square acts on the reading)
        grid = [th for th in eff.grid(r) if eff.side_of(th) == "input"]
        assert grid and all(th[2] > 0 for th in grid)
        for th in grid:
            loss = ctx["pull_sign"] * (r.u - eff.transform_input(r, r.u, th, ctx))
            assert np.allclose(loss, th[2] * eff.profile(r, th[0], th[1], ctx))
        # the stretch takes more travel at the highest tension than at the lowest
        loss = ctx["pull_sign"] * (r.u - eff.transform_input(r, r.u, (0.1, 1.0, 1.0), ctx))
        assert loss[int(np.argmax(r.tension))] > loss[int(np.argmin(r.tension))] + 0.5


@pytest.mark.parametrize(("effects", "speed", "direction"), [
    ({}, None, None),
    ({"time_delay": 1.0}, None, None),
    ({"tendon_elongation": 8.0}, None, None),
    ({"dead_zone": 1.0}, None, None),
    ({"rate_dependence": 0.5}, True, None),
    ({"asymmetry": 0.5}, None, True),
])
def test_the_rigs_load_cells_show_its_friction_effects_and_nothing_else(effects, speed,
                                                                          direction):
    from pipelines.discrepancy_study import hidden_effect_runs

    ident = [r for r in hidden_effect_runs(effects, [(90.0, 30.0), (30.0, 75.0)])
             if r.role == "identification"]
    ratios = [friction_ratios(r) for r in ident]
    for r in ratios:
        assert (r["speed_ratio"] >= MIN_SPEED_RATIO) == bool(speed), (effects, r)
        assert (r["direction_ratio"] >= MIN_DIRECTION_RATIO) == bool(direction), (effects, r)
        if not speed:
            assert r["speed_ratio"] < 1.03
        if not direction:
            assert abs(np.log(r["direction_ratio"])) < np.log(1.08)
