"""The backfitting of a base and its terms: weights re-solved with the structure kept, and the
accelerated alternation, each against the plain computation on small data."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from hysteresis.discrepancy.bases import PlaySumModel
from hysteresis.discrepancy.effects import CANDIDATES, ComposedModel, Term, _Anderson
from hysteresis.discrepancy.inject import NOISE_MM, injected_runs
from hysteresis.discrepancy.workflow import base_factory_for
from hysteresis.gamma import GammaModel, solve_play_weights


def _record() -> tuple[np.ndarray, np.ndarray]:
    run = injected_runs("gamma", kinds=("sine_decay",))[0]
    return run.u[:600], run.y[:600]


@pytest.mark.parametrize("params", [
    {"constraint": "sum_to_one", "fit_offset": False},
    {"constraint": "free", "fit_offset": True},
    {"constraint": "nonneg", "fit_offset": True},
])
def test_gamma_weights_re_solved_with_the_setup_kept_are_the_least_squares(params) -> None:
    u, y = _record()
    m = GammaModel(**params).fit(u, y)
    p, pos, w0 = m.thresholds_.copy(), m.start_position_, m.weights_.copy()
    y2 = y + 0.05 * np.sin(np.linspace(0.0, 9.0, y.size))
    m.refit_weights(u, y2)
    assert np.array_equal(m.thresholds_, p) and m.start_position_ == pos
    # the reference: the play design of the fitted setup, solved in full
    a = m.design_matrix(u)
    if params["fit_offset"]:
        a = np.column_stack([a, np.ones(u.size)])
    x, _ = solve_play_weights(a, y2, n_weights=p.size, constraint=m.constraint_)
    assert np.allclose(m.weights_, x[:p.size], atol=1e-8)
    assert np.allclose(m.predict(u), a @ x, atol=1e-8)
    assert m.sse_ == pytest.approx(float(np.sum((a @ x - y2) ** 2)), rel=1e-8)
    m.refit_weights(u, y)  # and back: the fit's own weights
    assert np.allclose(m.weights_, w0, atol=1e-8)


def test_play_sum_weights_re_solved_match_a_fresh_fit() -> None:
    u, y = _record()
    m = PlaySumModel().fit(u, y)
    y2 = 1.3 * y + 0.2
    m.refit_weights(u, y2)
    fresh = PlaySumModel().fit(u, y2)
    assert np.allclose(m.predict(u), fresh.predict(u), atol=1e-8)


def test_anderson_reaches_a_slow_contractions_fixed_point_in_far_fewer_steps() -> None:
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(12, 12)))
    a = q @ np.diag(np.linspace(0.3, 0.8, 12)) @ q.T  # contracts by 0.8 at worst
    b = rng.normal(size=12)
    fixed = np.linalg.solve(np.eye(12) - a, b)

    def step(x: np.ndarray) -> tuple[np.ndarray, float]:
        out = a @ x + b
        return out, float(np.sum((out - fixed) ** 2))

    x = np.zeros(12)
    plain = 0
    while np.max(np.abs(x - fixed)) > 1e-6:
        x, plain = a @ x + b, plain + 1
    # a third of the plain iteration's steps reach the same accuracy
    got = _Anderson(step, plain // 3, 0.0).solve(np.zeros(12))
    assert np.max(np.abs(got - fixed)) < 1e-6, plain


def test_anderson_returns_the_best_step_when_the_error_climbs() -> None:
    errors = iter([5.0, 3.0, 4.0, 6.0, 7.0])
    seen: list[float] = []

    def step(x: np.ndarray) -> tuple[np.ndarray, float]:
        e = next(errors, 9.0)
        seen.append(float(x[0]))
        return x + 1.0, e

    out = _Anderson(step, 10, 1e-9).solve(np.zeros(1))
    # the best error (3.0) came from the second step's input; it is run again last
    assert seen[-1] == seen[1] and float(out[0]) == seen[1] + 1.0


def test_anderson_steps_on_from_the_best_step_after_an_overshoot() -> None:
    # x -> x / 2 + 1: the second mixed point is the fixed point 2 itself; the scripted errors
    # call it worse, and the next step starts from the best step's output (1.5), not from it
    errors = iter([5.0, 3.0, 4.0, 2.0, 1.0])
    seen: list[float] = []

    def step(x: np.ndarray) -> tuple[np.ndarray, float]:
        seen.append(float(x[0]))
        return 0.5 * x + 1.0, next(errors, 0.5)

    _Anderson(step, 4, 0.0).solve(np.zeros(1))
    assert seen[:3] == pytest.approx([0.0, 1.0, 2.0])
    assert seen[3] == pytest.approx(1.5)


def test_a_known_tanh_stop_is_fitted_exactly_by_the_accelerated_backfitting() -> None:
    # a term reading the base's prediction couples the two fits: the plain alternation
    # contracts by about 0.8 a round, and 8 plain rounds left this stop 11 % short
    run = injected_runs("gamma", kinds=("sine_decay",))[0]
    run = run.segment(0, 750, role=run.role, suffix="head")
    factory = base_factory_for("gamma", constraint="free", fit_offset=True)
    y0 = ComposedModel(factory).fit(run).predict(run)
    sat = CANDIDATES["saturation"]
    ctx = sat.context(replace(run, y=y0))
    big_y = 1.2 * ctx["half"]
    y = ctx["centre"] + big_y * np.tanh((y0 - ctx["centre"]) / big_y)
    obs = replace(run, y=y)
    theta = ("tanh", big_y / sat.context(obs)["half"])
    m = ComposedModel(factory, [Term(sat, theta, tuple(sorted(sat.context(obs).items())))])
    m.fit(obs)
    assert np.allclose(m.coef_, -1.0, atol=0.01)  # the shortfall x - Y tanh(x / Y), taken off
    assert np.sqrt(np.mean((m.predict(obs) - y) ** 2)) < 1e-3 * ctx["half"]


def _smooth_record(start: str = "rest", plant: str = "bouc_wen_loop"
                   ) -> tuple[np.ndarray, np.ndarray]:
    run = injected_runs(plant, start=start, kinds=("sine_decay",))[0]
    return run.u[:900], run.y[:900]


@pytest.mark.parametrize(("family", "plant"), [
    ("bouc_wen", "bouc_wen_loop"), ("coleman_hodgdon", "bouc_wen_loop"), ("preisach", "preisach")])
def test_a_warm_refit_lands_where_a_fresh_fit_does(family, plant) -> None:
    # a backfitting round refits the base on an output that differs by a small term: from
    # the last round's shape (one local search) it must find the fresh fit's loop
    u, y = _smooth_record(plant=plant)
    factory = base_factory_for(family, screen=False)
    m = factory().fit(u, y)
    y2 = y + 0.04 * np.sin(np.linspace(0.0, 7.0, y.size)) + 0.01 * u
    m.refit_warm(u, y2)
    fresh = factory().fit(u, y2)
    warm_rmse = np.sqrt(np.mean((m.predict(u) - y2) ** 2))
    fresh_rmse = np.sqrt(np.mean((fresh.predict(u) - y2) ** 2))
    assert warm_rmse <= 1.02 * fresh_rmse, (warm_rmse, fresh_rmse)


def test_a_preisach_warm_refit_reuses_the_relay_rows_of_the_same_input(monkeypatch) -> None:
    # the relay states depend on the input and the plane only: a second warm refit on the
    # same input must not run them again, and lands where one without the kept rows does
    import hysteresis.preisach as preisach

    u, y = _smooth_record(plant="preisach")
    factory = base_factory_for("preisach", screen=False)
    calls = []
    real = preisach.relay_states
    monkeypatch.setattr(preisach, "relay_states", lambda *a: calls.append(1) or real(*a))
    m = factory().fit(u, y)
    for k in (1, 2, 3):
        m.refit_warm(u, y + 0.01 * k * np.sin(np.linspace(0.0, 7.0, y.size)))
    assert len(calls) == 2  # the fit, and the first warm refit; the next two reuse its rows
    m.refit_warm(u[:-50], y[:-50])  # another input: computed again
    assert len(calls) == 3
    m.refit_warm(u, y)
    twin = copy.deepcopy(m)
    del twin._relay_cache
    y3 = y + 0.03 * np.sin(np.linspace(0.0, 7.0, y.size))
    m.refit_warm(u, y3)
    twin.refit_warm(u, y3)
    assert len(calls) == 5  # the input changed back once (m), and the twin had no rows kept
    assert np.allclose(m.predict(u), twin.predict(u), rtol=0, atol=1e-9 * np.ptp(y))


def test_a_warm_refit_keeps_a_loaded_start_chosen_on_the_record() -> None:
    u, y = _smooth_record("loaded")
    m = base_factory_for("bouc_wen", screen=False)().fit(u, y)
    assert m.start_ == "loaded"
    m.refit_warm(u, y + 0.02)
    assert m.start_ == "loaded"
    assert np.sqrt(np.mean((m.predict(u) - y - 0.02) ** 2)) < 2.0 * NOISE_MM


def test_backfitting_from_the_last_shape_matches_the_fits_from_the_grid(monkeypatch) -> None:
    # the rounds after the first start from the last round's shape: the model found (a
    # Bouc-Wen base and a linear creep) is the one that searching the grid every round finds,
    # with one grid search instead of one a round
    from hysteresis import bouc_wen
    from hysteresis.discrepancy import effects

    run = injected_runs("bouc_wen_loop", {"drift:linear": 2.0}, kinds=("sine_decay",))[0]
    factory = base_factory_for("bouc_wen", screen=False)
    drift = CANDIDATES["drift"]
    theta = ("linear", 0.0)
    term = Term(drift, theta, tuple(sorted(drift.context(run).items())))
    grids = []
    real = bouc_wen.BoucWenModel._fit_varpro

    def counted(self, *args, **kwargs):
        grids.append(kwargs.get("warm") is None)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(bouc_wen.BoucWenModel, "_fit_varpro", counted)
    warm = ComposedModel(factory, [term]).fit(run)
    warm_grids = sum(grids)
    grids.clear()
    monkeypatch.setattr(effects, "WARM_BACKFIT", False)
    cold = ComposedModel(factory, [term]).fit(run)
    assert warm_grids == 1 < sum(grids)
    rmse = [np.sqrt(np.mean((m.predict(run) - run.y) ** 2)) for m in (warm, cold)]
    assert rmse[0] <= 1.02 * rmse[1] and rmse[0] < 2.0 * NOISE_MM, rmse
