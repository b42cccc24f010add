"""The inverse reach guard: a weighted-play model that cannot reach its targets is refused
before anything is driven, with the identification range in the message."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.base import HysteresisError, check_inverse_reach
from hysteresis.compensation import gamma_inverse, run_inverse_with_error_correction
from hysteresis.gamma import GammaModel


def _gamma(weights: list[float], plays: list[float]) -> GammaModel:
    return GammaModel.from_params(plays, weights)


def test_healthy_models_pass_and_non_play_models_are_not_judged() -> None:
    check_inverse_reach(_gamma([0.6, 0.4], [0.0, 0.5]), identified_range=(-2.0, 2.0))
    check_inverse_reach(_gamma([0.7, 0.3], [0.0, 1.0]),
                        identified_range=(0.0, 2.0), desired=np.array([0.0, 1.5]))
    check_inverse_reach(object())  # no weights: nothing to judge


def test_non_positive_total_weight_is_refused_by_the_gamma_inverse() -> None:
    model = _gamma([1.5, -2.0], [0.0, 1.0])
    with pytest.raises(HysteresisError, match=r"total weight sum\(Q\) = -0.5 <= 0.*"
                                              r"demanded outputs -1..2"):
        model.invert(np.array([-1.0, 0.0, 2.0]))
    with pytest.raises(HysteresisError, match="<= 0"):
        gamma_inverse(_gamma([1.0, -1.0], [0.0, 1.0]), np.zeros(3))


def test_thresholds_reaching_the_identification_span_are_refused() -> None:
    model = _gamma([0.5, 0.3, 0.2], [0.0, 1.5, 3.0])
    with pytest.raises(HysteresisError,
                       match=r"identified on inputs 0..2\).*thresholds up to 3 reach the "
                             r"identification range's span 2.*max_threshold < 2"):
        check_inverse_reach(model, identified_range=(0.0, 2.0))
    check_inverse_reach(model, identified_range=(-2.0, 2.0))  # span 4: identified
    # a play as wide as the span never moves from rest: refused too
    with pytest.raises(HysteresisError, match="span 3"):
        check_inverse_reach(model, identified_range=(0.0, 3.0))


def test_the_compensator_refuses_before_the_first_command() -> None:
    commands: list[float] = []

    def plant(command: float) -> dict[str, float]:
        commands.append(command)
        return {"output": command}

    bad = _gamma([0.5, 0.3, 0.2], [0.0, 1.5, 3.0])
    with pytest.raises(HysteresisError, match="identified on inputs 0..2"):
        run_inverse_with_error_correction(plant, np.linspace(0, 1, 50), bad,
                                          identified_range=(0.0, 2.0))
    with pytest.raises(HysteresisError, match="<= 0"):
        run_inverse_with_error_correction(plant, np.linspace(0, 1, 50),
                                          _gamma([1.0, -2.0], [0.0, 1.0]))
    assert commands == []
    good = _gamma([0.6, 0.4], [0.0, 0.5])
    res = run_inverse_with_error_correction(plant, np.linspace(0, 1, 50), good,
                                            identified_range=(-2.0, 2.0))
    assert len(commands) == 50 and np.all(np.isfinite(res.output))
