"""The linear baseline: gain, offset, delay; trivial inverse."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import HysteresisError, make_family
from hysteresis.gamma import sine_decay, triangle_decay
from hysteresis.linear import LinearModel

U = sine_decay()


def test_recovers_gain_and_offset() -> None:
    rng = np.random.default_rng(0)
    y = 0.93 * U - 0.21 + rng.normal(0, 0.01, U.size)
    m = LinearModel().fit(U, y)
    assert m.gain_ == pytest.approx(0.93, abs=1e-3)
    assert m.offset_ == pytest.approx(-0.21, abs=1e-3)
    assert m.delay_ == 0
    assert m.sse_ / U.size == pytest.approx(1e-4, rel=0.1)


def test_recovers_delay_when_searched() -> None:
    y = np.concatenate([np.full(7, U[0]), U[:-7]]) * 1.1 + 0.5
    m = LinearModel(max_delay=20).fit(U, y)
    assert m.delay_ == 7
    assert m.gain_ == pytest.approx(1.1, abs=1e-12)
    np.testing.assert_allclose(m.predict(U), y, atol=1e-12)
    fixed = LinearModel(delay=3).fit(U, y)
    assert fixed.delay_ == 3 and fixed.sse_ > m.sse_


def test_a_lag_of_seconds_is_found_by_default_and_none_is_invented() -> None:
    # 1.2 s at 50 Hz behind a slow sine that starts mid-stroke: the default search reaches
    # it from the data (the old fixed-zero default left a 6x larger error)
    t = np.arange(0.0, 80.0, 0.02)
    u = 31.5 + 28.0 * np.sin(2 * np.pi * 0.1 * t)
    lag = 60
    y = 1.8 * np.concatenate([np.full(lag, u[0]), u[:-lag]]) - 4.0
    m = LinearModel().fit(u, y)
    assert m.delay_ == lag and m.gain_ == pytest.approx(1.8, rel=1e-9)
    assert LinearModel(delay=0).fit(u, y).sse_ > 100 * max(m.sse_, 1e-9)
    # a plant with no lag keeps none
    assert LinearModel().fit(u, 1.8 * u - 4.0).delay_ == 0


def test_predict_invert_and_state() -> None:
    m = LinearModel(delay=5).fit(U, np.concatenate([np.zeros(5), U[:-5]]) * 2.0 + 1.0)
    tri = triangle_decay()
    yd = 2.0 * tri + 1.0
    u = m.invert(yd)
    # the first `delay` outputs depend on the past only: beyond reach
    np.testing.assert_allclose(m.predict(u)[5:], yd[5:], atol=1e-12)
    y1, s1 = m.simulate(tri[:100])
    y2, _ = m.simulate(tri[100:], s1)
    np.testing.assert_allclose(np.concatenate([y1, y2]), m.predict(tri), atol=1e-12)
    v, st = m.invert_step(3.0, m.initial_state(0.0))
    assert v == pytest.approx(1.0) and st.history[-1] == pytest.approx(1.0)
    y, _ = m.step(0.5, m.initial_state(0.5))
    assert y == pytest.approx(2.0)


def test_fits_sine_predicts_triangle_of_a_linear_system() -> None:
    tri = triangle_decay()
    m = make_family("linear").fit(U, 0.8 * U + 0.1)
    np.testing.assert_allclose(m.predict(tri), 0.8 * tri + 0.1, atol=1e-12)


def test_bad_input() -> None:
    with pytest.raises(HysteresisError, match="delay"):
        LinearModel(delay=-1).fit(U, U)
    with pytest.raises(HysteresisError, match="non-finite"):
        LinearModel().fit(np.array([0.0, np.nan, 1.0]), np.zeros(3))
    m = LinearModel().fit(U, np.zeros(U.size))
    m.gain_ = 0.0  # a flat response (lstsq may leave a ~1e-17 gain)
    with pytest.raises(HysteresisError, match="zero gain"):
        m.invert(U)
