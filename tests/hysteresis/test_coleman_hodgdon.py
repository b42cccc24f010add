"""Coleman-Hodgdon family (seed 000 eq. 10-11, GA identification eq. 26)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hysteresis import HysteresisError, HysteresisModel, make_family
from hysteresis.coleman_hodgdon import PAPER_PARAMS, ColemanHodgdonModel, ch_simulate

A, B, C = PAPER_PARAMS  # [0.95, -0.92, 18.53]: deg per mm, pull distance in mm
ORIGIN = (3.0, 55.0)  # centre of the [0, 6] mm stroke; output in degrees


def _paper_triangle(cycles: int = 3, lo: float = 0.0, hi: float = 6.0,
                    v: float = 0.125, dt: float = 0.05) -> np.ndarray:
    """Seed 000 section V-A: pull distance as a triangle at 0.125 mm/s over [0, 6] mm."""
    half = (hi - lo) / v
    t = np.arange(0.0, cycles * 2 * half + dt / 2, dt)
    ph = (t % (2 * half)) / half
    return lo + np.where(ph < 1.0, ph, 2.0 - ph) * (hi - lo)


def test_paper_parameters_reproduce_the_loop_geometry() -> None:
    """Properties of the paper's loop derivable from eq. 10 with [0.95, -0.92, 18.53]."""
    u = _paper_triangle()
    y = ch_simulate(u, A, B, C, origin=ORIGIN)
    model = ColemanHodgdonModel().fit(u, y)
    W = (C - B) / A  # half the vertical distance between the asymptotic branches
    # vertical / horizontal loop widths of the asymptotic branches
    assert model.loop_widths()[0] == pytest.approx(2 * W, rel=1e-6)
    assert 2 * W == pytest.approx(40.947, abs=1e-3)
    assert model.loop_widths()[1] == pytest.approx(2 * W / C, rel=1e-6)  # 2.21 mm of backlash
    # periodic steady state on [0, 6] mm: turning points sit W tanh(3A) from the centre line
    k = ORIGIN[1] - C * ORIGIN[0]
    half = u.size // 6  # samples per stroke
    last = slice(4 * half, None)  # third cycle
    up_turn = np.argmax(u[last]) + 4 * half
    lo_turn = 4 * half
    x = W * math.tanh(3 * A)
    assert y[up_turn] == pytest.approx(6 * C + k - x, abs=1e-6)
    assert y[lo_turn] == pytest.approx(k + x, abs=1e-6)
    # output range per cycle: 6C - 2W tanh(3A) = 70.5 deg between the turning points, and
    # the model dips after each reversal (slope 2B - C + ... < 0): the loop's extremes
    # lie beyond the turning points by the derivable dip
    span = 6 * C - 2 * x
    assert span == pytest.approx(70.51, abs=0.01)
    dip_x = math.log(A * (x + W) / C) / A  # where dy/du = 0 after the reversal at u = 0
    dip = C * dip_x + (x + W) * (math.exp(-A * dip_x) - 1.0)
    assert np.min(y[last]) == pytest.approx(y[lo_turn] + dip, abs=1e-3)
    assert dip == pytest.approx(-6.906, abs=0.001)
    # the loop closes: the start-up transient shrinks by exp(-12 A) = 1.1e-5 per cycle
    d12 = np.max(np.abs(y[:2 * half] - y[2 * half:4 * half]))
    d23 = np.max(np.abs(y[2 * half:4 * half] - y[4 * half:6 * half]))
    assert d23 == pytest.approx(d12 * math.exp(-12 * A), rel=0.05)
    assert d23 < 5e-4


def test_refit_of_own_simulation_returns_paper_parameters() -> None:
    u = _paper_triangle()
    y = ch_simulate(u, A, B, C, origin=ORIGIN)
    for method in ("ga", "varpro"):
        model = ColemanHodgdonModel(method=method).fit(u, y)
        np.testing.assert_allclose(model.params_, PAPER_PARAMS, rtol=1e-6)
        assert model.k_ == pytest.approx(ORIGIN[1] - C * ORIGIN[0], abs=1e-5)
        assert model.origin_u_ == pytest.approx(3.0)  # centre of the stroke
        assert model.origin_y_ == pytest.approx(ORIGIN[1], abs=1e-5)


def test_recovery_with_noise_and_other_parameters() -> None:
    rng = np.random.default_rng(7)
    u = np.concatenate([_paper_triangle(2), _paper_triangle(2, 0.0, 3.0),
                        _paper_triangle(2, 3.0, 6.0)])
    true = (2.0, -0.5, 10.0)
    y = ch_simulate(u, *true, origin=(3.0, 30.0)) + rng.normal(0.0, 0.3, u.size)
    model = ColemanHodgdonModel().fit(u, y)
    np.testing.assert_allclose(model.params_, true, rtol=0.03, atol=0.05)
    assert model.sse_ / model.n_samples_ < 1.05 * 0.3**2


def test_sign_constraint_and_free_variant() -> None:
    """A true backlash (flat reversal, B = C/2 > 0) needs b_sign='free'; the paper's B < 0
    fits worse, and the default (auto) sees it on the record's held-out part."""
    u = _paper_triangle(3, dt=0.1)
    y = ch_simulate(u, 3.0, 1.0, 2.0, origin=(3.0, 0.0))
    paper = ColemanHodgdonModel(b_sign="negative").fit(u, y)
    free = ColemanHodgdonModel(b_sign="free").fit(u, y)
    auto = ColemanHodgdonModel().fit(u, y)
    assert paper.B_ < 0 and paper.b_sign_ == "negative"
    np.testing.assert_allclose(free.params_, [3.0, 1.0, 2.0], rtol=1e-5)
    assert free.sse_ / free.n_samples_ < 1e-10 < paper.sse_ / paper.n_samples_
    assert auto.b_sign_ == "free"
    np.testing.assert_allclose(auto.params_, free.params_, rtol=1e-9)


def test_fit_is_scale_robust() -> None:
    u = _paper_triangle()
    y = ch_simulate(u, A, B, C, origin=ORIGIN)
    a = ColemanHodgdonModel(method="varpro").fit(u, y)
    b = ColemanHodgdonModel(method="varpro").fit(u / 25.4, np.deg2rad(y))  # inches, radians
    np.testing.assert_allclose(b.predict(u / 25.4), np.deg2rad(a.predict(u)), atol=1e-9)


def test_exact_inverse_and_step_api() -> None:
    model = ColemanHodgdonModel(method="varpro").fit(
        _paper_triangle(), ch_simulate(_paper_triangle(), A, B, C, origin=ORIGIN))
    t = np.linspace(0, 100, 2001)
    target = -50 * np.cos(np.pi / 50 * t) + 80  # seed 000 eq. 32 tracking trajectory
    u = model.invert(target)
    np.testing.assert_allclose(model.predict(u, state={"u": u[0], "y": target[0]}), target,
                               atol=1e-9)
    ys, st = [], None
    for x in u[:300]:
        yk, st = model.step(float(x), st)
        ys.append(yk)
    np.testing.assert_allclose(ys, model.predict(u[:300]), atol=1e-12)
    us, st = [], {"u": float(u[0]), "y": float(target[0])}
    for yk in target[:300]:
        uk, st = model.invert_step(float(yk), st)
        us.append(uk)
    np.testing.assert_allclose(us, u[:300], atol=1e-9)


def test_euler_scheme_matches_exact_at_fine_sampling() -> None:
    u = _paper_triangle(1, dt=0.01)
    ex = ch_simulate(u, A, B, C, origin=ORIGIN)
    eu = ch_simulate(u, A, B, C, origin=ORIGIN, scheme="euler")
    assert np.max(np.abs(ex - eu)) < 0.05  # first order in the input step (1.25 um)


def test_json_round_trip_and_errors() -> None:
    model = ColemanHodgdonModel(method="varpro").fit(
        _paper_triangle(), ch_simulate(_paper_triangle(), A, B, C, origin=ORIGIN))
    back = HysteresisModel.from_json(model.to_json())
    assert isinstance(back, ColemanHodgdonModel)
    np.testing.assert_array_equal(back.predict(_paper_triangle(1)),
                                  model.predict(_paper_triangle(1)))
    with pytest.raises(HysteresisError, match="A > 0"):
        ch_simulate([0.0, 1.0], -1.0, B, C)
    with pytest.raises(HysteresisError, match="b_sign"):
        ColemanHodgdonModel(b_sign="positive").fit(_paper_triangle(1), _paper_triangle(1))
    with pytest.raises(HysteresisError, match="constant"):
        ColemanHodgdonModel().fit(np.zeros(50), np.arange(50.0))


def test_hydra_config_instantiates() -> None:
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    cfg = OmegaConf.load(Path(__file__).parents[2] / "conf" / "family" / "coleman_hodgdon.yaml")
    model = instantiate(cfg)
    assert isinstance(model, ColemanHodgdonModel)
    assert model.get_params() == make_family("coleman_hodgdon").get_params()


def test_fits_virtual_rig_sine_and_predicts_its_triangle() -> None:
    from rig_io.calibrate import calibrate_raw_run
    from rig_io.virtual import simulate_run

    amps = [6.0, 4.5, 3.0, 1.5]
    runs = []
    for seed, e in enumerate([
        {"kind": "sine_decay", "amplitudes_mm": amps, "periods_per_amplitude": 5,
         "frequency_hz": 0.25},
        {"kind": "triangle_decay", "amplitudes_mm": amps, "periods_per_amplitude": 3,
         "slope_mm_s": 6.0},
    ], start=1):
        enc = calibrate_raw_run(simulate_run(curve_angle_deg=90.0, radius_mm=30.0,
                                             excitation=e, seed=seed)).encoder
        runs += [enc["input"].to_numpy(), enc["output"].to_numpy()]
    u, y, ut, yt = runs
    linear = make_family("linear", delay=0).fit(u, y)  # the static line
    rmse_lin = float(np.sqrt(np.mean((linear.predict(ut) - yt) ** 2)))
    for kw in ({}, {"b_sign": "free"}):
        model = ColemanHodgdonModel(**kw).fit(u, y)
        rmse = float(np.sqrt(np.mean((model.predict(ut) - yt) ** 2)))
        assert model.score(ut, yt) > 0.99, kw
        assert rmse < 0.3 * rmse_lin, kw
    target = model.predict(ut)
    np.testing.assert_allclose(model.predict(model.invert(target)), target, atol=1e-8)
