"""The delay search covers what the record can show: lags of seconds, not a fixed 0.5 s."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.discrepancy.inject import SIZES, injected_runs
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow
from hysteresis.lag import MIN_SEARCH_S, delay_grid, delay_search_max, xcorr_lag

DT = 0.04
T = np.arange(0.0, 80.0, DT)
U = np.sin(2 * np.pi * 0.1 * T) * np.exp(-T / 60.0)


@pytest.mark.parametrize("lag", [0.12, 0.8, 2.4])
def test_the_cross_correlation_lag_is_the_known_delay(lag: float) -> None:
    y = 0.7 * np.interp(T - lag, T, U, left=0.0) + 3.0  # scale and offset do not matter
    assert xcorr_lag(U, y, DT) == pytest.approx(lag, abs=DT / 2)


def test_a_periodic_record_without_lag_reads_zero_not_one_period() -> None:
    assert xcorr_lag(U, U, DT) == 0.0
    assert delay_search_max(U, U, DT) == MIN_SEARCH_S


def test_the_grid_reaches_past_a_seconds_lag_and_stays_inside_the_record() -> None:
    y = np.interp(T - 2.4, T, U, left=0.0)
    grid = delay_grid(U, y, DT)
    assert max(grid) >= 2.4 and max(grid) <= 0.25 * T[-1]
    assert grid == sorted(grid) and grid[0] == pytest.approx(DT)
    # without a lag the grid is the short one latencies of cameras need
    assert max(delay_grid(U, U, DT)) <= MIN_SEARCH_S


def test_a_two_second_latency_is_named_with_the_lag_it_recovered() -> None:
    runs = injected_runs("gamma", {"time_delay": 2.0 / SIZES["time_delay"]})
    report = run_workflow(runs, base_factory_for("gamma"), base_name="gamma")
    first = report["effects"][0]
    assert first["name"] == "time_delay"
    theta = next(iter(first["evidence"]["parameters"].values()))["theta"]
    assert theta == pytest.approx(2.0, abs=2 * runs[0].dt)
    assert first["heldout_rmse_after"] < 0.5 * first["heldout_rmse_before"]
