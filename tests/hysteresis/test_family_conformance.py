"""One estimator face for every registered family: a prediction continues exactly from the
state it returned, and so does stepping sample by sample."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hysteresis.base import HysteresisError, NotFittedError, family_names, make_family

T = np.arange(0.0, 20.0, 0.02)
U = 3.0 * np.sin(2 * np.pi * 0.25 * T) * np.exp(-T / 15.0)
# a loop with lag and some saturation, so every family has a state to carry
Y = 0.8 * np.sin(2 * np.pi * 0.25 * T - 0.3) * 3.0 * np.exp(-T / 15.0)
Y = np.tanh(Y / 2.5) * 2.5


@pytest.fixture(scope="module", params=family_names())
def fitted(request: pytest.FixtureRequest) -> Any:
    return make_family(request.param).fit(U, Y)


def test_every_family_is_registered() -> None:
    assert {"linear", "gamma", "preisach", "bouc_wen", "coleman_hodgdon"} <= set(family_names())


def test_a_prediction_continues_exactly_from_its_returned_state(fitted: Any) -> None:
    whole = fitted.predict(U)
    cut = 437  # mid-stroke, not at a reversal
    head, state = fitted.predict(U[:cut], return_state=True)
    tail = fitted.predict(U[cut:], state=state)
    np.testing.assert_allclose(np.concatenate([head, tail]), whole, rtol=0, atol=1e-12)


def test_every_family_is_a_stateful_model_with_a_typed_state(fitted: Any) -> None:
    from dataclasses import is_dataclass

    from hysteresis.base import StatefulModel

    assert isinstance(fitted, StatefulModel)
    _, end = fitted.predict(U[:50], return_state=True)
    for state in (fitted.initial_state(float(U[0])), end, fitted.step(float(U[0]))[1],
                  fitted.simulate(U[:50])[1]):
        assert is_dataclass(state) and type(state) is type(end), type(state)


def test_one_training_error_attribute_means_the_same_in_every_family(fitted: Any) -> None:
    # sse_: squared errors of the fitted model's own prediction summed over the whole
    # identification record (a decimated fit is still scored on every sample)
    assert fitted.n_samples_ == U.size
    assert fitted.sse_ == pytest.approx(float(np.sum((fitted.predict(U) - Y) ** 2)), rel=1e-9)
    assert not any(k.startswith("train_") for k in fitted.fitted_attributes())


def test_stepping_equals_the_record(fitted: Any) -> None:
    n = 300
    whole = fitted.predict(U[:n])
    _, state = fitted.predict(U[:1], return_state=True)
    ys = [whole[0]]
    for u_k in U[1:n]:
        y_k, state = fitted.step(float(u_k), state)
        ys.append(y_k)
    np.testing.assert_allclose(ys, whole, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", family_names())
def test_an_unknown_fit_argument_is_refused(name: str) -> None:
    with pytest.raises(HysteresisError, match="takes"):
        make_family(name).fit(U, Y, bogus=1)


@pytest.mark.parametrize("name", family_names())
def test_a_failed_fit_leaves_the_model_unfitted(name: str) -> None:
    model = make_family(name).fit(U, Y)
    assert model.is_fitted
    bad = Y.copy()
    bad[100] = np.nan
    with pytest.raises(HysteresisError):
        model.fit(U, bad)
    # no parameters of the earlier fit left to pass for a fit of the new data
    assert not model.is_fitted and model.fitted_attributes() == {}
    with pytest.raises(NotFittedError):
        model.predict(U)


def test_a_preisach_fit_that_fails_midway_leaves_no_plane() -> None:
    model = make_family("preisach")
    with pytest.raises(HysteresisError, match="no positive density"):
        model.fit(U, -Y)  # an output that falls as the input rises: no positive density
    assert not model.is_fitted


@pytest.mark.parametrize("name", ["bouc_wen", "coleman_hodgdon"])
def test_a_state_written_by_hand_is_read_and_a_wrong_one_refused(name: str) -> None:
    model = make_family(name).fit(U, Y)
    _, end = model.predict(U[:200], return_state=True)
    key = "h" if name == "bouc_wen" else "y"
    as_mapping = {"u": end.u, key: getattr(end, key)}
    np.testing.assert_array_equal(model.predict(U[200:], state=as_mapping),
                                  model.predict(U[200:], state=end))
    for bad in (42, {"u": 0.0}, {"u": 0.0, "h": "x", "y": "x"}):
        with pytest.raises(HysteresisError, match="state must be"):
            model.predict(U[:5], state=bad)


def test_capabilities_are_declared_not_probed(fitted: Any) -> None:
    """Every family declares the online face (a Steppable: initial_state, step, invert_step)
    and its own reach check; only a family linear in its weights claims the protocol."""
    from hysteresis.base import HysteresisModel, LinearInParameters, Steppable

    assert isinstance(fitted, Steppable)
    for name in ("initial_state", "invert_step", "check_reach"):
        assert getattr(type(fitted), name) is not getattr(object, name, None)
    own_reach = type(fitted).check_reach is not HysteresisModel.check_reach
    assert own_reach == (fitted.family == "gamma")
    assert isinstance(fitted, LinearInParameters) == (fitted.family == "gamma")
    if isinstance(fitted, LinearInParameters):
        a = fitted.design_matrix(U)
        np.testing.assert_allclose(a @ fitted.weights_ + fitted.offset_, fitted.predict(U),
                                   rtol=0, atol=1e-9 * np.ptp(Y))


def test_clone_is_unfitted_with_the_same_hyper_parameters(fitted: Any) -> None:
    twin = fitted.clone()
    assert type(twin) is type(fitted) and not twin.is_fitted
    assert twin.get_params() == fitted.get_params()
    assert twin.fit(U, Y).to_json() == fitted.to_json()
