"""Bouc-Wen family (seed 002 eq. 2-5): recovery, inverses, step API, JSON, scale robustness."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hysteresis import HysteresisError, HysteresisModel, NotFittedError, make_family
from hysteresis.bouc_wen import BoucWenModel, bw_simulate, canonical_params, paper_mse

TRUE = np.array([0.8, 0.5, 0.1, 2.0, 0.9, -1.5])  # [A, B, C, n, alpha, beta], a lagging loop


def _sine_decay(n: int = 8000, amp: float = 6.0, dt: float = 0.01) -> np.ndarray:
    t = np.arange(n) * dt
    return amp * np.exp(-t / 40.0) * np.sin(2 * np.pi * 0.1 * t)


def _triangle(n: int = 3000, amp: float = 5.0, period: int = 600) -> np.ndarray:
    ph = (np.arange(n) % period) / period
    return amp * (4 * np.abs(ph - 0.5) - 1.0)


def test_simulation_matches_a_fine_reference_at_any_sampling() -> None:
    """Integration in the input with sub-steps: a 50x coarser record of a triangle (turning
    points kept) gives the same outputs as the fine one, even with a sharp loop (n = 10)."""
    u_fine = _triangle(30000, amp=6.0, period=3000)
    for p in (TRUE, np.array([4.0, 3.0, 1.0, 10.0, 1.0, -0.5])):
        y_fine = bw_simulate(u_fine, p)
        y_coarse = bw_simulate(u_fine[::50], p)
        np.testing.assert_allclose(y_coarse, y_fine[::50], atol=1e-4)  # 2e-5 of the range


def test_paper_form_recovers_parameters_from_own_data() -> None:
    u = _sine_decay()
    y = bw_simulate(u, TRUE)
    model = BoucWenModel(fit_offset=False).fit(u, y)
    # eq. 2-3 are invariant under h -> s h: compare canonical forms (A = 1)
    np.testing.assert_allclose(canonical_params(model.params_), canonical_params(TRUE),
                               rtol=1e-4, atol=1e-6)
    assert model.offset_ == 0.0
    assert model.sse_ / model.n_samples_ < 1e-10


def test_recovery_with_noise_and_offset_is_close() -> None:
    u = _sine_decay()
    rng = np.random.default_rng(3)
    y = bw_simulate(u, TRUE) + 2.5 + rng.normal(0.0, 0.05, u.size)
    model = BoucWenModel().fit(u, y)
    got, want = canonical_params(model.params_), canonical_params(TRUE)
    np.testing.assert_allclose(got[[3, 4, 5]], want[[3, 4, 5]], rtol=0.05)
    assert model.offset_ == pytest.approx(2.5, abs=0.02)
    assert model.sse_ / model.n_samples_ < 1.1 * 0.05**2


def test_fit_is_scale_robust() -> None:
    """Degrees instead of mm (x 10 in, x 30 + 40 out) give the same normalised fit."""
    u = _sine_decay()
    y = bw_simulate(u, TRUE)
    a = BoucWenModel().fit(u, y)
    b = BoucWenModel().fit(10.0 * u, 30.0 * y + 40.0)
    ut = _triangle()
    np.testing.assert_allclose(b.predict(10.0 * ut), 30.0 * a.predict(ut) + 40.0, atol=1e-5)


def test_exact_inverse_reproduces_targets() -> None:
    model = BoucWenModel(fit_offset=False).fit(_sine_decay(), bw_simulate(_sine_decay(), TRUE))
    target = 0.9 * _triangle()  # any path: alpha > 0 and h bounded, so every y is reachable
    u = model.invert(target)
    np.testing.assert_allclose(model.predict(u), target, atol=1e-9)
    # the inverse is causal and stateful: continuing from a state equals one long call
    u1, st = model.simulate_inverse(target[:1000])
    u2, _ = model.simulate_inverse(target[1000:], state=st)
    np.testing.assert_allclose(np.concatenate([u1, u2]), u, atol=1e-12)


def test_feedforward_inverse_of_eq4_compensates_but_is_not_exact() -> None:
    model = BoucWenModel(fit_offset=False).fit(_sine_decay(), bw_simulate(_sine_decay(), TRUE))
    target = 0.9 * _triangle()
    naive = model.predict(target / model.alpha_) - target
    ff = model.predict(model.invert(target, method="feedforward")) - target
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    # eq. 4 halves the hysteresis error of the uncompensated (gain-only) command here...
    assert rms(ff) < 0.5 * rms(naive)
    # ...but the exact inverse is better by orders of magnitude
    exact = model.predict(model.invert(target, method="exact")) - target
    assert rms(exact) < 1e-6 * rms(ff)


def test_step_api_matches_batch_calls() -> None:
    model = BoucWenModel().fit(_sine_decay(), bw_simulate(_sine_decay(), TRUE))
    u = _triangle(500)
    ys, st = [], None
    for x in u:
        yk, st = model.step(float(x), st)
        ys.append(yk)
    np.testing.assert_allclose(ys, model.predict(u), atol=1e-12)
    target = model.predict(u)
    us, st = [], None
    for yk in target:
        uk, st = model.invert_step(float(yk), st)
        us.append(uk)
    np.testing.assert_allclose(model.predict(np.array(us)), target, atol=1e-9)


def test_json_round_trip_is_lossless() -> None:
    model = BoucWenModel(n_starts=1).fit(_sine_decay(), bw_simulate(_sine_decay(), TRUE))
    back = HysteresisModel.from_json(model.to_json())
    assert isinstance(back, BoucWenModel)
    assert back.get_params() == model.get_params()
    np.testing.assert_array_equal(back.params_, model.params_)
    ut = _triangle()
    np.testing.assert_array_equal(back.predict(ut), model.predict(ut))


def test_paper_bfgs_path_and_paper_objective() -> None:
    """method='bfgs' runs the paper's raw BFGS on eq. 5; from a near start it fits."""
    u = _sine_decay(3000)
    y = bw_simulate(u, TRUE)
    m = BoucWenModel(method="bfgs", fit_offset=False).fit(u, y, x0=TRUE * 1.1)
    assert paper_mse(u, y, m.params_) < 1e-3
    assert paper_mse(u, y, [1.0, -5.0, -5.0, 20.0, 1.0, 1.0]) == 999999.0  # blow-up penalty


def test_bad_inputs_raise_clear_errors() -> None:
    with pytest.raises(NotFittedError):
        BoucWenModel().predict([0.0, 1.0])
    with pytest.raises(HysteresisError, match="constant"):
        BoucWenModel().fit(np.ones(100), np.arange(100.0))
    with pytest.raises(HysteresisError, match="method"):
        BoucWenModel(method="newton").fit(_sine_decay(100), _sine_decay(100))
    with pytest.raises(HysteresisError, match="differ in length"):
        BoucWenModel().fit(np.arange(10.0), np.arange(11.0))
    model = BoucWenModel().fit(_sine_decay(), bw_simulate(_sine_decay(), TRUE))
    with pytest.raises(HysteresisError, match="state"):
        model.predict([0.0, 1.0], state={"x": 1.0})
    with pytest.raises(HysteresisError, match="inverse"):
        model.invert([0.0, 1.0], method="magic")


def test_registered_and_hydra_config_instantiates() -> None:
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    cfg = OmegaConf.load(Path(__file__).parents[2] / "conf" / "family" / "bouc_wen.yaml")
    model = instantiate(cfg)
    assert isinstance(model, BoucWenModel)
    assert model.get_params() == make_family("bouc_wen").get_params()


def test_fits_virtual_rig_sine_and_predicts_its_triangle(
        virtual_pair_90_30: tuple[np.ndarray, ...]) -> None:
    u, y, ut, yt = virtual_pair_90_30
    assert u.size == 8001
    model = BoucWenModel().fit(u, y)
    linear = make_family("linear", delay=0).fit(u, y)  # the static line
    rmse = float(np.sqrt(np.mean((model.predict(ut) - yt) ** 2)))
    rmse_lin = float(np.sqrt(np.mean((linear.predict(ut) - yt) ** 2)))
    assert model.score(ut, yt) > 0.99
    assert rmse < 0.3 * rmse_lin
    np.testing.assert_allclose(model.predict(model.invert(yt)), yt, atol=1e-8)
