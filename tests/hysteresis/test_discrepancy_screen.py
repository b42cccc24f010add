"""The screen an iterative base searches effect parameters on: the play sum that fits the run
(started where the record starts, signed weights where the loop needs them), the form chosen
on the real base, and the point walked on it where the screen fits only roughly."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.base import HysteresisError
from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.bases import FrozenShapeModel, PlaySumModel
from hysteresis.discrepancy.effects import (
    CANDIDATES,
    ComposedModel,
    ScreenedFactory,
    _sse,
    fit_joint,
)
from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.workflow import base_factory_for

R = (0.0, 0.5, 1.0, 1.5)


def _input() -> np.ndarray:
    t = np.arange(0.0, 40.0, 0.04)
    return np.asarray(5.0 * np.sin(2 * np.pi * 0.2 * t) * np.exp(-t / 40.0))


def test_a_play_sum_with_a_negative_weight_started_after_a_pull_is_recovered() -> None:
    u = _input()
    w = np.array([1.1, 0.3, -0.25, -0.1])
    y = sum(wi * play(u, r, z0=float(u[0]) - r) for wi, r in zip(w, R, strict=True)) + 0.2
    exact = PlaySumModel(thresholds=R, signed=True, start=1.0).fit(u, y)
    np.testing.assert_allclose(exact.weights_, w, atol=1e-6)
    assert exact.offset_ == pytest.approx(0.2, abs=1e-6)
    # non-negative plays at rest cannot draw it
    rough = PlaySumModel(thresholds=R).fit(u, y)
    assert np.sqrt(np.mean((rough.predict(u) - y) ** 2)) > 0.05


def test_the_kept_pseudo_inverse_solves_as_least_squares_does() -> None:
    """The signed screen re-solves its design for each new output with the pseudo-inverse it
    kept: the weights are numpy's least-squares ones, also for a rank-deficient design (two
    equal thresholds) and after the input changes (a new design, a new inverse)."""
    u = _input()
    rng = np.random.default_rng(3)
    for thresholds in (R, (0.0, 0.5, 0.5, 1.5)):
        model = PlaySumModel(thresholds=thresholds, signed=True, start=1.0)
        model.fit(u, rng.normal(size=u.size))
        for uu in (u, 0.7 * u):
            y = sum(play(uu, r) for r in R) + rng.normal(0, 0.01, uu.size)
            model.refit_weights(uu, y)
            a = model._design(uu, model.thresholds_)
            w, *_ = np.linalg.lstsq(a, y, rcond=None)
            np.testing.assert_allclose(np.r_[model.weights_, model.offset_], w,
                                       atol=1e-9 * float(np.abs(w).max()))
            assert model._pinv_for[0] is model._design_for[1]
            # its prediction on that input reuses the columns: the same as computed afresh
            np.testing.assert_array_equal(model.predict(uu.copy()),
                                          a @ np.r_[model.weights_, model.offset_])


def test_a_start_outside_the_band_is_refused_with_its_meaning() -> None:
    u = _input()
    with pytest.raises(HysteresisError, match=r"start must lie in \[-1, 1\].*got 2"):
        PlaySumModel(start=2).fit(u, u)


def test_the_screen_is_the_play_sum_that_fits_and_the_frozen_base_where_none_does() -> None:
    runs = injected_runs("bouc_wen_loop", {}, start="rest")
    factory = base_factory_for("bouc_wen")
    assert isinstance(factory, ScreenedFactory)
    screen = factory.screen_for(runs[0])
    assert screen.func is PlaySumModel and screen.keywords["signed"]  # type: ignore[attr-defined]
    # a base far better than any play sum (here: the truth itself) screens with its own
    # plain fit, its shape frozen
    y = np.asarray(runs[0].y)
    exact = ScreenedFactory(lambda: _Replay(y), PlaySumModel)
    frozen = exact.screen_for(runs[0])
    assert frozen.func is FrozenShapeModel  # type: ignore[attr-defined]
    assert _sse(ComposedModel(frozen, []).fit(runs[0]), runs[0]) == pytest.approx(0.0, abs=1e-18)


def test_a_frozen_shape_refits_only_its_gain_and_offset() -> None:
    u = _input()
    shape = PlaySumModel(thresholds=R).fit(u, sum(play(u, r) for r in R))
    frozen = FrozenShapeModel(shape).fit(u, 2.0 * shape.predict(u) + 1.0)
    assert (frozen.gain_, frozen.offset_) == pytest.approx((2.0, 1.0), abs=1e-9)
    with pytest.raises(HysteresisError, match="needs a fitted base"):
        FrozenShapeModel().fit(u, u)


def test_a_latency_is_searched_on_the_frozen_base_where_no_play_sum_draws_the_loop() -> None:
    ident = injected_runs("bouc_wen_loop", {"time_delay": 1.0}, start="rest")[0]
    real = base_factory_for("bouc_wen")
    assert isinstance(real, ScreenedFactory)
    factory = ScreenedFactory(real.base, _Flat)  # a screen that draws no loop at all
    assert factory.screen_for(ident).func is FrozenShapeModel  # type: ignore[attr-defined]
    m = fit_joint(factory, [], CANDIDATES["time_delay"], ident)
    assert float(m.terms[-1].theta) == pytest.approx(0.12, abs=0.015)


class _Flat(PlaySumModel):
    """A 'screen' that fits a constant."""

    def fit(self, u: object, y: object, **fit_params: object) -> _Flat:
        self.weights_, self.offset_ = np.zeros(1), float(np.mean(np.asarray(y)))
        self.thresholds_ = np.zeros(1)
        return self

    def predict(self, u: object, *, state: object = None) -> np.ndarray:
        return np.full(np.asarray(u).size, self.offset_)


class _Replay(PlaySumModel):
    """A 'base' that returns the recorded output (stands for a base that fits exactly)."""

    def __init__(self, y: np.ndarray) -> None:
        super().__init__()
        self.y = y

    def fit(self, u: object, y: object, **fit_params: object) -> _Replay:
        self.weights_, self.offset_, self.thresholds_ = np.zeros(1), 0.0, np.zeros(1)
        return self

    def predict(self, u: object, *, state: object = None) -> np.ndarray:
        return self.y


@pytest.mark.parametrize(("effect", "form"), [("rate_dependence:viscous", "viscous"),
                                              ("rate_dependence:power", "power")])
def test_the_form_is_chosen_on_the_real_base(effect: str, form: str) -> None:
    # the play sum preferred a relaxation on this loop, which the Bouc-Wen then fitted 3.5x
    # worse than the viscous form
    ident = injected_runs("bouc_wen_loop", {effect: 1.0}, start="rest")[0]
    m = fit_joint(base_factory_for("bouc_wen"), [], CANDIDATES["rate_dependence"], ident)
    assert m.terms[-1].form == form


def test_a_latency_the_screen_places_a_step_off_is_walked_to_its_size() -> None:
    ident = injected_runs("bouc_wen_loop", {"time_delay": 1.0}, start="rest")[0]
    factory = base_factory_for("bouc_wen")
    m = fit_joint(factory, [], CANDIDATES["time_delay"], ident)
    assert float(m.terms[-1].theta) == pytest.approx(0.12, abs=0.015)
    plain = ComposedModel(factory, []).fit(ident)
    assert _sse(m, ident) < 0.05 * _sse(plain, ident)


def test_a_smooth_base_searches_a_backlash_in_front_of_it_itself() -> None:
    """A backlash in front of a play sum is a wider play: the play-sum screen fits every width
    alike. A textbook Bouc-Wen behind a 1 mm backlash (the injector's): the Bouc-Wen base
    searches the width itself and fits to the noise; the screen's width alone leaves far
    more."""
    ident = injected_runs("bouc_wen_loop", {"dead_zone": 2.0}, start="rest", seed=0)[0]
    dead_zone = CANDIDATES["dead_zone"]
    factory = base_factory_for("bouc_wen")
    assert isinstance(factory, ScreenedFactory) and factory.unseen["dead_zone"] == "backlash"
    own = fit_joint(factory, [], dead_zone, ident)
    assert own.terms[-1].theta == pytest.approx(1.0, abs=0.05)  # total width, mm
    assert np.sqrt(_sse(own, ident) / ident.y.size) < 0.0125  # noise sd 0.01 mm
    screened = ScreenedFactory(factory.base, PlaySumModel)
    rough = fit_joint(screened, [], dead_zone, ident)
    assert _sse(rough, ident) > 4.0 * _sse(own, ident)
