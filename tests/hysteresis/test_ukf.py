"""Active model-error estimation with the UKF (seed 000 eq. 12-18, eq. 29)."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import HysteresisError
from hysteresis.coleman_hodgdon import PAPER_PARAMS, ColemanHodgdonModel, ch_simulate
from hysteresis.ukf import (
    PAPER_P0,
    PAPER_Q0,
    PAPER_R0,
    ActiveModelUKF,
    simulate_with_model_error,
)

DT = 0.01


def _reference_model() -> tuple[ColemanHodgdonModel, np.ndarray]:
    """The paper's reference model on its [0, 6] mm triangle at 0.125 mm/s, sampled at 100 Hz."""
    half = 6.0 / 0.125
    t = np.arange(0.0, 2 * half, DT)
    ph = (t % (2 * half)) / half
    u = np.where(ph < 1.0, ph, 2.0 - ph) * 6.0
    model = ColemanHodgdonModel(method="varpro").fit(
        u, ch_simulate(u, *PAPER_PARAMS, origin=(3.0, 55.0)))
    return model, u


def test_paper_initial_values() -> None:
    assert np.array_equal(PAPER_P0, [[10, 0], [0, 10]])
    assert np.array_equal(PAPER_Q0, [[5, 0], [0, 15]])
    assert PAPER_R0 == 0.0001


def test_f_h_converges_to_an_injected_constant_error_paper_settings() -> None:
    model, u = _reference_model()
    injected = 0.8  # deg/s the real scope drifts away from the reference model
    actual = simulate_with_model_error(model, u, injected, dt=DT)
    res = ActiveModelUKF(model, dt=DT).run(u, actual)
    tail = slice(u.size // 2, None)
    np.testing.assert_allclose(res.f_h[tail], injected, atol=1e-6)
    # the enhanced estimate follows reality; the reference model alone drifts away
    assert np.max(np.abs(res.estimate - actual)) < 1e-5
    assert np.max(np.abs(res.model - actual)) > 5.0


def test_f_h_converges_with_measurement_noise_and_tuned_noise_model() -> None:
    model, u = _reference_model()
    injected = -0.5
    actual = simulate_with_model_error(model, u, injected, dt=DT)
    rng = np.random.default_rng(11)
    noise = 0.5
    measured = actual + rng.normal(0.0, noise, u.size)
    ukf = ActiveModelUKF(model, dt=DT, Q=[[1e-4, 0.0], [0.0, 1e-4]], R=noise**2)
    res = ukf.run(u, measured)
    tail = slice(u.size // 2, None)
    assert np.mean(res.f_h[tail]) == pytest.approx(injected, abs=0.05)
    assert abs(res.f_h[-1] - injected) < 3 * res.f_h_std[-1]  # calibrated posterior
    # the enhanced estimate is far closer to the truth than the raw measurement
    assert np.std(res.estimate[tail] - actual[tail]) < 0.3 * noise


def test_time_varying_error_reduces_model_error_like_tables_2_and_3() -> None:
    """Seed 000 Tables 2-4: |Err| shrinks by ~97 % and Var by > 99.5 % with the estimator."""
    model, u = _reference_model()
    t = np.arange(u.size) * DT
    f_true = 2.0 * np.sin(2 * np.pi * t / 40.0)  # slowly varying model error (deg/s)
    actual = simulate_with_model_error(model, u, f_true, dt=DT)
    measured = actual + np.random.default_rng(2).normal(0.0, 0.05, u.size)
    res = ActiveModelUKF(model, dt=DT).run(u, measured)
    err_model = actual - res.model
    err_est = actual - res.estimate
    assert np.mean(np.abs(err_est)) < 0.1 * np.mean(np.abs(err_model))
    assert np.var(err_est) < 0.005 * np.var(err_model)


def test_step_matches_run_and_missing_frames_skip_update() -> None:
    model, u = _reference_model()
    actual = simulate_with_model_error(model, u[:400], 0.3, dt=DT)
    measured = actual.copy()
    measured[100:110] = np.nan  # ten missed camera frames
    ukf = ActiveModelUKF(model, dt=DT)
    res = ukf.run(u[:400], measured)
    ukf.reset(float(u[0]))
    steps = [ukf.step(float(x), float(z)) for x, z in zip(u[:400], measured, strict=True)]
    np.testing.assert_allclose([s[0] for s in steps], res.estimate)
    np.testing.assert_allclose([s[1] for s in steps], res.f_h)
    assert np.all(np.isfinite(res.estimate))
    # without updates the covariance of f_h grows (pure prediction)
    assert res.f_h_std[109] > res.f_h_std[99]


def test_bad_arguments() -> None:
    model, u = _reference_model()
    with pytest.raises(HysteresisError, match="dt"):
        ActiveModelUKF(model, dt=0.0)
    with pytest.raises(HysteresisError, match="differ in shape"):
        ActiveModelUKF(model).run(u[:10], u[:9])
    with pytest.raises(HysteresisError, match="not fitted"):
        ActiveModelUKF(ColemanHodgdonModel())
