"""The papers' error statistics against values computed by hand."""

import math

import numpy as np
import pytest

from hysteresis.metrics import METRIC_NAMES, error_statistics


def test_statistics_match_hand_computation() -> None:
    measured = np.array([2.0, 0.0, 5.0, 1.0])
    model = np.array([1.0, 1.0, 3.0, 1.0])
    # e = [1, -1, 2, 0]
    stats = error_statistics(measured, model)
    assert set(stats) == set(METRIC_NAMES)
    assert stats["n"] == 4
    assert stats["sse"] == pytest.approx(6.0)
    assert stats["mse"] == pytest.approx(1.5)
    assert stats["rmse"] == pytest.approx(math.sqrt(1.5))
    assert stats["mean_error"] == pytest.approx(0.5)
    # S_{n-1}: sum (e - 0.5)^2 = 0.25 + 2.25 + 2.25 + 0.25 = 5 over n-1 = 3
    assert stats["std_error"] == pytest.approx(math.sqrt(5.0 / 3.0))
    # seed 000 eq. 28 divides by N
    assert stats["var_error"] == pytest.approx(5.0 / 4.0)
    assert stats["error_range"] == pytest.approx(3.0)
    assert stats["mean_abs_error"] == pytest.approx(1.0)


def test_sign_convention_is_measured_minus_model() -> None:
    stats = error_statistics([1.0, 1.0], [0.0, 0.0])
    assert stats["mean_error"] == pytest.approx(1.0)


def test_non_finite_samples_are_dropped() -> None:
    stats = error_statistics([1.0, np.nan, 3.0], [0.0, 0.0, 1.0])
    assert stats["n"] == 2
    assert stats["sse"] == pytest.approx(5.0)


def test_shape_mismatch_and_empty_are_errors() -> None:
    with pytest.raises(ValueError, match="shape"):
        error_statistics([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="no finite"):
        error_statistics([np.nan], [1.0])
