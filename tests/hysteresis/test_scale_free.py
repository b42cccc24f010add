"""Defaults come from the data, not from a unit: the same physical run recorded in mm, in deg
(input and output on different scales) or scaled by 1000 gives the same fit up to that scale,
for every registered family."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import family_names, make_family
from hysteresis.base import HysteresisError

RATE_HZ = 50.0
T = np.arange(0.0, 60.0, 1.0 / RATE_HZ)
# A decaying sine from rest, as a rig's identification run.
U_MM = 5.0 * np.sin(2 * np.pi * 0.2 * T) * np.exp(-T / 50.0)

# (input scale, output scale): mm; deg of a 8 mm pulley in, deg of a 6.5 mm joint out; x1000
SCALES = {"mm": (1.0, 1.0), "deg": (180 / np.pi / 8.0, 2 * 180 / np.pi / 6.5),
          "x1000": (1000.0, 1000.0)}


def backlash_plant(u: np.ndarray) -> np.ndarray:
    """A plant written here (not one of the families): a 0.8 mm backlash into a stiffening
    spring, with a little noise."""
    z = np.empty_like(u)
    s = float(u[0])
    for k, v in enumerate(u):
        s = min(max(s, v - 0.4), v + 0.4)
        z[k] = s
    rng = np.random.default_rng(3)
    return 0.8 * z + 0.004 * z**3 + 0.01 * rng.standard_normal(u.size)


Y_MM = backlash_plant(U_MM)


@pytest.mark.parametrize("family", family_names())
def test_a_run_in_mm_deg_or_x1000_gives_the_same_fit_up_to_scale(family: str) -> None:
    preds = {}
    for name, (a, b) in SCALES.items():
        model = make_family(family).fit(a * U_MM, b * Y_MM)
        preds[name] = np.asarray(model.predict(a * U_MM)) / b
    span = float(np.ptp(Y_MM))
    for name in ("deg", "x1000"):
        dev = float(np.max(np.abs(preds[name] - preds["mm"]))) / span
        assert dev < 1e-3, f"{family} in {name}: prediction differs by {dev:.2e} of the range"
    # and the fit is a fit: the hysteresis families follow the backlash, not only the trend
    rmse = float(np.sqrt(np.mean((preds["mm"] - Y_MM) ** 2)))
    assert rmse < (0.2 if family == "linear" else 0.06) * span, (family, rmse / span)


def test_gamma_thresholds_and_weights_carry_the_units() -> None:
    a, b = SCALES["deg"]
    mm = make_family("gamma").fit(U_MM, Y_MM)
    deg = make_family("gamma").fit(a * U_MM, b * Y_MM)
    np.testing.assert_allclose(deg.thresholds_, a * mm.thresholds_, rtol=1e-12)
    np.testing.assert_allclose(deg.weights_, b / a * mm.weights_, rtol=1e-6, atol=1e-9)
    assert deg.offset_ == pytest.approx(b * mm.offset_, rel=1e-6, abs=1e-9)


@pytest.mark.parametrize("family", family_names())
def test_a_record_that_starts_at_rest_mid_stroke_fits_as_one_that_starts_at_zero(
        family: str) -> None:
    # the same run with the input and output zeros elsewhere (a rig that rests mid-stroke when
    # the record starts): the fit is the same up to those offsets, not read as a jump from zero
    at_zero = make_family(family).fit(U_MM, Y_MM)
    shifted = make_family(family).fit(U_MM + 3.0, Y_MM + 40.0)
    dev = np.max(np.abs(shifted.predict(U_MM + 3.0) - 40.0 - at_zero.predict(U_MM)))
    assert dev < 1e-3 * float(np.ptp(Y_MM)), f"{family}: {dev:.3g}"


def test_gamma_finds_where_its_plays_start_when_the_record_starts_mid_loop() -> None:
    # a Gamma plant that settled at 3 mm before the record starts, every play in the middle
    # of its band (the thesis' zero state would have them at the bottom, as after a rise
    # from 0): the fitted start says so and the first seconds are fitted
    from hysteresis.play import gamma_simulate

    p = np.linspace(0.0, 1.0, 6)
    q = np.array([0.2, 0.3, 0.2, 0.1, 0.1, 0.1])
    u = 3.0 + U_MM
    y, _ = gamma_simulate(u, p, q, 0.0, 3.0 - 0.5 * p)
    y = np.asarray(y) + 0.005 * np.random.default_rng(1).standard_normal(u.size)
    fitted = make_family("gamma", max_threshold=1.0, n_operators=6).fit(u, y)
    thesis = make_family("gamma", max_threshold=1.0, n_operators=6, start_state="zero").fit(u, y)
    assert fitted.start_position_ == 0.5
    first = slice(0, int(3 * RATE_HZ))
    err_fit = float(np.sqrt(np.mean((fitted.predict(u)[first] - y[first]) ** 2)))
    err_zero = float(np.sqrt(np.mean((thesis.predict(u)[first] - y[first]) ** 2)))
    assert err_fit < 0.01 and err_zero > 3 * err_fit, (err_fit, err_zero)


def test_a_fixed_threshold_fraction_spans_that_share_of_the_input_range() -> None:
    a, _ = SCALES["x1000"]
    for scale in (1.0, a):
        m = make_family("gamma", threshold_fraction=0.25).fit(scale * U_MM, Y_MM)
        assert m.thresholds_.max() == pytest.approx(0.25 * scale * float(np.ptp(U_MM)))
    with pytest.raises(HysteresisError, match="threshold_fraction"):
        make_family("gamma", threshold_fraction=0.0).fit(U_MM, Y_MM)
