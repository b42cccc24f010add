"""Forms added to the candidate library, each recovered from a known signal on small data."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysteresis.discrepancy.effects import CANDIDATES, ComposedModel, fit_with_effect
from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.workflow import base_factory_for


def _ident() -> tuple:
    # the first 30 s of the identification sine (its 6 mm and 4.5 mm blocks): enough stroke
    full = injected_runs("gamma", kinds=("sine_decay",))[0]
    run = full.segment(0, 750, role=full.role, suffix="head")
    base = ComposedModel(base_factory_for("gamma", constraint="free", fit_offset=True)).fit(run)
    return run, base.predict(run)


def test_a_tanh_stop_over_the_whole_stroke_is_told_from_a_cubic_softening() -> None:
    run, y0 = _ident()
    sat = CANDIDATES["saturation"]
    ctx = sat.context(replace(run, y=y0))
    c, half = ctx["centre"], ctx["half"]
    big_y = 1.2 * half  # 13 % short at the top of the stroke
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    for hidden, form in (("tanh", "soft"), ("cubic", "cubic")):
        x = y0 - c
        y = c + (big_y * np.tanh(x / big_y) if hidden == "tanh" else x - 0.13 * x**3 / half**2)
        m = fit_with_effect(factory, [], sat, replace(run, y=y))
        term = m.terms[-1]
        assert term.form == form
        if hidden == "tanh":
            # Y is a multiple of the recorded (stopped) half-range
            got = float(term.theta[-1]) * term.context["half"]
            assert got == pytest.approx(big_y, rel=0.02)
        assert np.sqrt(np.mean((m.predict(replace(run, y=y)) - y) ** 2)) < 0.02 * half


def test_a_push_side_gain_is_fitted_at_the_plant_rest() -> None:
    # the push side at 0.75: the recorded range's centre moves off the rest by 0.14 of the
    # half-range, and a kink held at the centre left a third of the effect
    run, y0 = _ident()
    rest = 0.5 * float(y0.max() + y0.min())
    x = y0 - rest
    y = rest + np.where(x > 0.0, x, 0.75 * x)
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    m = fit_with_effect(factory, [], CANDIDATES["asymmetry"], replace(run, y=y))
    term = m.terms[-1]
    assert term.form == "pull_push_gain"
    kink = term.context["centre"] + float(term.theta[-1]) * term.context["half"]
    assert kink == pytest.approx(rest, abs=0.07 * term.context["half"])
    assert np.sqrt(np.mean((m.predict(replace(run, y=y)) - y) ** 2)) < 0.01 * np.ptp(y)


def test_a_relaxation_of_the_output_claims_no_friction_reading() -> None:
    # a speed law of the sheath's friction raises the tension ratio the two load cells read;
    # a first-order lag of the output need not, so a flat friction reading cannot reject it
    rate = CANDIDATES["rate_dependence"]
    assert rate.claims({"speed_friction", "viscous"}) and rate.claims({"power"})
    assert not rate.claims({"relaxation"}) and not rate.claims({"viscous", "relaxation"})
    assert not CANDIDATES["dead_zone"].claims({"dead_band"})
    assert CANDIDATES["dead_zone"].claims({"backlash"})


def test_a_first_order_lag_of_the_output_is_recovered_as_a_relaxation() -> None:
    from hysteresis.discrepancy.effects import lowpass

    run, y0 = _ident()
    y = lowpass(y0, 0.4, run.dt)  # the follower's motion relaxes with 0.4 s
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    m = fit_with_effect(factory, [], CANDIDATES["rate_dependence"], replace(run, y=y))
    term = m.terms[-1]
    assert term.form == "relaxation" and term.theta[0] == "lag"
    assert float(term.theta[-1]) == pytest.approx(0.4, rel=0.05)
    assert np.sqrt(np.mean((m.predict(replace(run, y=y)) - y) ** 2)) < 0.005 * np.ptp(y)


def test_a_cubic_softening_the_record_cannot_tell_from_a_tanh_is_named_cubic() -> None:
    # a tanh stop contains a cubic softening as its scale grows: within the noise's scatter
    # of the identification error, the simpler form is the answer
    run = injected_runs("gamma", {"saturation:cubic": 1.0}, kinds=("sine_decay",))[0]
    run = run.segment(0, 750, role=run.role, suffix="head")
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    m = fit_with_effect(factory, [], CANDIDATES["saturation"], run)
    assert m.terms[-1].form == "cubic"


def test_a_loading_gain_that_turns_over_along_a_travel_is_recovered_with_its_width() -> None:
    # y' = c + (y - c)(1 + a s), s the loading state turning over along 2 w of input travel
    # after each reversal (a friction contact's direction state, not the sign of the speed)
    from hysteresis.discrepancy._ops import play

    run, y0 = _ident()
    asym = CANDIDATES["asymmetry"]
    ctx = asym.context(replace(run, y=y0))
    width = 0.06 * ctx["input_half"]
    s = (run.u - play(run.u, width)) / width
    centre = ctx["centre"]
    y = centre + (y0 - centre) * (1.0 + 0.04 * s)
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    m = fit_with_effect(factory, [], asym, replace(run, y=y))
    term = m.terms[-1]
    assert term.form == "loading_gain"
    assert float(term.theta[-1]) * term.context["input_half"] == pytest.approx(width, rel=0.2)
    # the sign of the speed alone (width 0) leaves the turn-over in the error
    sign_only = ComposedModel(factory).fit(replace(run, y=y))
    assert np.sqrt(np.mean((m.predict(replace(run, y=y)) - y) ** 2)) < \
        0.3 * np.sqrt(np.mean((sign_only.predict(replace(run, y=y)) - y) ** 2))


def _slope_backlash(x: np.ndarray, g: float, pivot: float) -> np.ndarray:
    """Tao and Kokotovic's backlash with different slopes: the output rides the branch
    1 + g while ``x`` rises and 1 - g while it falls (both through ``pivot``), held between."""
    out = np.empty_like(x)
    z = float(x[0])
    for k, xk in enumerate(x):
        up, down = xk + g * (xk - pivot), xk - g * (xk - pivot)
        z = max(z, up) if xk - x[k - 1] > 0 else z
        z = min(z, down) if xk - x[k - 1] < 0 else z
        out[k] = z
    return out


def test_a_backlash_with_different_slopes_is_recovered_as_a_held_loading_gain() -> None:
    run, y0 = _ident()
    pivot = float(y0.max())
    y = _slope_backlash(y0, 0.08, pivot)
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    m = fit_with_effect(factory, [], CANDIDATES["asymmetry"], replace(run, y=y))
    term = m.terms[-1]
    assert term.form == "loading_gain" and term.theta[:2] == ("held_gain", 1.0)
    assert float(term.theta[-1]) * float(m.coef_[0]) == pytest.approx(0.08, rel=0.15)
    assert np.sqrt(np.mean((m.predict(replace(run, y=y)) - y) ** 2)) < 0.01


def test_a_lost_motion_growing_with_the_speed_is_a_slip_on_a_base_without_plays() -> None:
    # a backlash on the input of half-width c tanh(|v| / v0) in front of a Bouc-Wen loop
    from hysteresis.discrepancy._ops import scaled_play
    from hysteresis.discrepancy.effects import speed

    full = injected_runs("bouc_wen_loop", kinds=("sine_decay",))[0]
    run = full.segment(0, 750, role=full.role, suffix="head")
    v0 = 0.5 * float(np.percentile(np.abs(run.v), 99))
    u_seen = scaled_play(run.u, 0.6 * np.tanh(np.abs(speed(run)) / v0), z0=float(run.u[0]))
    factory = base_factory_for("bouc_wen")  # searched on its play-sum screen
    plain = ComposedModel(factory).fit(run)
    y = plain.base_.predict(u_seen)
    m = fit_with_effect(factory, [], CANDIDATES["rate_dependence"], replace(run, y=y))
    term = m.terms[-1]
    assert term.form == "speed_friction" and term.theta[0] == "slip"
    assert float(term.theta[1]) == pytest.approx(v0, rel=0.01)
    assert float(term.theta[-1]) == pytest.approx(0.6, rel=0.1)
