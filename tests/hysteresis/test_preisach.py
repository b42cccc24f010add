"""Preisach (seed 001 eq. 4.1-4.6): density recovery, wiping out, inverse, state, generalisation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hysteresis import HysteresisError, make_family
from hysteresis.gamma import seed001_table41, sine_decay, triangle_decay
from hysteresis.play import gamma_simulate
from hysteresis.preisach import PreisachModel

U = sine_decay()
TRI = triangle_decay()


def synthetic(density: str, theta: list[float], *, offset: float = 0.1, gain: float = 0.0,
              **kw: object) -> PreisachModel:
    """A model with a known density on the plane ``fit(U, .)`` would build."""
    m = PreisachModel(density=density, reversible=gain > 0, **kw)  # type: ignore[arg-type]
    m._check_hyper()
    m._set_plane(U)
    th = np.array(theta, dtype=float)
    m.density_params_ = th
    m.cell_weights_ = th[0] * m._shape(th)
    m.offset_ = offset
    m.reversible_gain_ = gain
    return m


@pytest.mark.parametrize(
    ("density", "theta", "free_spread", "gain"),
    [
        ("gauss_gauss", [0.8, 1.2, 0.5, 0.3, 1.0], False, 0.0),
        ("lorentzian", [0.8, 1.2, 0.5, 0.3, 1.0], False, 0.0),
        ("lognormal_gauss", [0.8, 1.2, 0.5, 0.3, 1.0], False, 0.0),
        ("gauss_gauss", [0.5, 0.6, 0.4, -0.2, 3.0], True, 0.4),
        ("lognormal_gauss", [0.5, 0.6, 0.4, -0.2, 3.0], True, 0.4),
    ],
)
def test_parametric_density_recovered_from_own_data(density: str, theta: list[float],
                                                    free_spread: bool, gain: float) -> None:
    truth = synthetic(density, theta, gain=gain)
    y = truth.predict(U)
    model = PreisachModel(density=density, free_spread=free_spread, reversible=gain > 0)
    model.fit(U, y)
    np.testing.assert_allclose(model.density_params_, theta, rtol=1e-5, atol=1e-6)
    assert model.offset_ == pytest.approx(0.1, abs=1e-6)
    assert model.reversible_gain_ == pytest.approx(gain, abs=1e-6)
    np.testing.assert_allclose(model.predict(TRI), truth.predict(TRI), atol=1e-6)


def test_parametric_recovery_with_noise() -> None:
    truth = synthetic("gauss_gauss", [0.8, 1.2, 0.5, 0.3, 1.0])
    rng = np.random.default_rng(2)
    y = truth.predict(U) + rng.normal(0, 0.01, U.size)
    model = PreisachModel(density="gauss_gauss", free_spread=False, reversible=False).fit(U, y)
    np.testing.assert_allclose(model.density_params_[:4], [0.8, 1.2, 0.5, 0.3], rtol=0.02)


def test_nonparametric_reproduces_its_own_data() -> None:
    truth = synthetic("gauss_gauss", [0.8, 1.2, 0.5, 0.3, 1.0])
    model = PreisachModel(density="nonparametric", reversible=False, fit_every=1)
    model.fit(U, truth.predict(U))
    assert np.all(model.cell_weights_ >= 0)
    assert model.density_params_.size == 0
    # cells the record never switches are unidentifiable, but the output is reproduced
    assert model.sse_ / U.size < 1e-8
    assert np.max(np.abs(model.predict(TRI) - truth.predict(TRI))) < 0.05


def staircase(points: list[float], step: float = 0.05) -> np.ndarray:
    """Piecewise-linear path through ``points`` with samples every ``step`` (exact multiples)."""
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        n = int(round(abs(b - a) / step))
        out.extend(np.round(a + np.sign(b - a) * step * np.arange(1, n + 1), 10))
    return np.array(out)


@pytest.mark.parametrize("smooth", [True, False])
def test_wiping_out_minor_loops(smooth: bool) -> None:
    """Once the input exceeds a past maximum, the minor loops inside it leave no trace."""
    m = synthetic("gauss_gauss", [0.8, 1.2, 0.6, 0.0, 2.0], smooth=smooth)
    with_loops = staircase([0.0, 4.0, -2.0, 2.0, 0.0, 3.0, 1.0, 5.5])
    without = staircase([0.0, 4.0, -2.0, 5.5])
    direct = staircase([0.0, -2.0, 5.5])  # the (4, -2) excursion wiped too once u > 4
    ya, yb, yc = m.predict(with_loops), m.predict(without), m.predict(direct)
    tail = 31  # samples of the last rise above 4.0 (4.0 -> 5.5 in 0.05 steps)
    np.testing.assert_allclose(ya[-tail:], yb[-tail:], atol=1e-12)
    np.testing.assert_allclose(ya[-tail:], yc[-tail:], atol=1e-12)
    # ... but not before: inside the big loop the minor loop's memory matters
    inside = np.flatnonzero(np.isclose(with_loops, 2.5))
    assert abs(ya[inside[-1]] - yb[np.flatnonzero(np.isclose(without, 2.5))[-1]]) > 1e-3
    # and the final states are identical
    _, sa = m.simulate(with_loops)
    _, sb = m.simulate(without)
    np.testing.assert_allclose(sa.r, sb.r, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    amps=st.lists(st.floats(-5, 5), min_size=2, max_size=5),
    freqs=st.lists(st.floats(0.05, 1.0), min_size=2, max_size=5),
)
def test_predict_invert_reproduces_reachable_targets(amps: list[float],
                                                     freqs: list[float]) -> None:
    m = synthetic("gauss_gauss", [0.5, 0.8, 0.6, 0.0, 3.0], gain=0.5)
    t = np.arange(800) * 0.01
    yd = np.asarray(sum(a * np.sin(2 * np.pi * f * t) for a, f in zip(amps, freqs,
                                                                   strict=False)), dtype=float)
    s0 = m.initial_state(0.0)
    u, end = m.invert(yd, state=s0, return_state=True)
    y, end2 = m.predict(u, state=s0, return_state=True)
    # with a reversible part every target is reachable; xtol 1e-10 in the input
    np.testing.assert_allclose(y, yd, atol=1e-8)
    np.testing.assert_allclose(end.r, end2.r, atol=1e-8)


def test_inverse_saturates_out_of_reach_without_reversible_part() -> None:
    m = synthetic("gauss_gauss", [0.5, 0.8, 0.6, 0.0, 3.0], gain=0.0)
    y_max = m.offset_ + m.cell_weights_.sum()
    yd = np.linspace(0, 2 * y_max, 300)
    s0 = m.initial_state(0.0)
    u = m.invert(yd, state=s0)
    y = m.predict(u, state=s0)
    reach = yd < y_max - 1e-6
    np.testing.assert_allclose(y[reach], yd[reach], atol=1e-8)
    assert np.all(y[~reach] <= y_max + 1e-12)
    u1, s1 = m.invert_step(float(yd[10]), s0)
    assert u1 == pytest.approx(m.invert(yd[10:11], state=s0)[0])
    y1, _ = m.step(u1, s0)
    assert y1 == pytest.approx(yd[10], abs=1e-8)


def test_state_is_carried_between_calls() -> None:
    m = synthetic("lorentzian", [0.8, 1.2, 0.5, 0.3, 1.0], gain=0.2)
    y_all = m.predict(TRI)
    y1, s1 = m.simulate(TRI[:777])
    y2, _ = m.simulate(TRI[777:], s1)
    np.testing.assert_allclose(np.concatenate([y1, y2]), y_all, atol=1e-12)


@pytest.mark.parametrize("density", ["gauss_gauss", "lognormal_gauss", "nonparametric"])
def test_fits_sine_and_predicts_triangle_of_a_tsm_like_system(density: str) -> None:
    """Data from a Gamma model with Table 4.1 weights (90 deg, 30 mm) plus noise."""
    q = np.array(seed001_table41()[20]["weights"])
    p = np.linspace(0, 2, 11)
    rng = np.random.default_rng(4)
    y, _ = gamma_simulate(U, p, q, 0.0, np.zeros(11))
    y_tri, _ = gamma_simulate(TRI, p, q, 0.0, np.zeros(11))
    model = PreisachModel(density=density).fit(U, y + rng.normal(0, 0.01, U.size))
    rmse = float(np.sqrt(np.mean((model.predict(TRI) - y_tri) ** 2)))
    assert model.score(TRI, y_tri) > 0.99
    assert rmse < 0.25  # mm, on a +-6 mm stroke
    if density != "nonparametric":
        # the paper's density alone (one width for both axes, no reversible part) is much worse
        plain = PreisachModel(density=density, free_spread=False, reversible=False).fit(U, y)
        assert plain.sse_ > 5 * model.sse_


def test_registry_and_bad_input() -> None:
    assert isinstance(make_family("preisach", n_levels=10), PreisachModel)
    with pytest.raises(HysteresisError, match="density"):
        PreisachModel(density="everett").fit(U, U)
    with pytest.raises(HysteresisError, match="constant"):
        PreisachModel().fit(np.ones(100), np.ones(100))
    with pytest.raises(HysteresisError, match="decreasing"):
        PreisachModel(reversible=False).fit(U, -U)
    m = PreisachModel(n_levels=8).fit(U, U)
    with pytest.raises(HysteresisError, match="hysterons"):
        m.predict(U, state=np.zeros(5))
