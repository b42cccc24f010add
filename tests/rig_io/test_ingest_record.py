"""Ingest changes nothing silently: each offset, sign and scale it applies is in the record."""

from __future__ import annotations

import pytest

from rig_io.calibrate import calibrate_raw_run
from rig_io.process import process_run
from rig_io.synthetic import make_raw_run

CPU = 10000.0  # make_raw_run's counts per unit


def test_a_counter_that_starts_mid_stroke_is_recorded_with_its_true_offset() -> None:
    start = 27_740  # the counter reads 2.774 units when the run starts
    raw = make_raw_run("mid_stroke", counts_start=start)
    phys = calibrate_raw_run(raw)
    frame, info = process_run(phys)
    assert frame["input"].iloc[0] == 0.0
    enc = info["calibration"]["encoder"]
    assert enc["input_counter_start"] == start
    assert enc["input_start_removed"] == pytest.approx(start / CPU)
    # output_sign -1: the output counter's start reading is removed with its sign
    assert enc["output_sign"] == -1
    assert enc["output_start_removed"] == pytest.approx(-start / CPU)
    assert info["input_offset"] == pytest.approx(start / CPU + info["rezeroed"]["input"])
    assert info["input_offset"] == pytest.approx(2.774, abs=1e-3)


def test_a_counter_that_starts_at_zero_records_zero() -> None:
    _, info = process_run(calibrate_raw_run(make_raw_run("at_zero", counts_start=0)))
    assert info["calibration"]["encoder"]["input_start_removed"] == 0.0
    assert info["input_offset"] == pytest.approx(info["rezeroed"]["input"])


def test_the_load_cell_zero_and_gain_applied_are_recorded() -> None:
    raw = make_raw_run("cells")
    _, info = process_run(calibrate_raw_run(raw))
    cells = raw.manifest["channels"]["loadcell"]
    for side in ("input", "output"):
        assert info["calibration"]["loadcell"][side] == {
            "zero_mv_per_v": cells[side]["zero_mv_per_v"],
            "newton_per_mv_per_v": cells[side]["newton_per_mv_per_v"]}
