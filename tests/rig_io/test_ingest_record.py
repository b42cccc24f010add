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


@pytest.mark.parametrize("drop", [("input",), ("input", "output"), ("output",)])
def test_a_load_cell_without_zero_and_gain_is_kept_raw_and_flagged(
        drop: tuple[str, ...]) -> None:
    import numpy as np

    raw = make_raw_run("uncal")
    cells = raw.manifest["channels"]["loadcell"]
    calibrated = {side: dict(cells[side]) for side in ("input", "output")}
    for side in drop:
        for key in ("zero_mv_per_v", "newton_per_mv_per_v"):
            cells[side].pop(key)
    frame, info = process_run(calibrate_raw_run(raw))
    record = info["calibration"]["loadcell"]
    for side, col in (("input", "tension_in_n"), ("output", "tension_out_n")):
        if side in drop:
            # never newtons: the column is empty and the record says why
            assert frame[col].isna().all()
            assert record[side]["calibrated"] is False and record[side]["unit"] == "mV/V"
        else:
            assert frame[col].notna().all()
            assert record[side] == {k: calibrated[side][k]
                                    for k in ("zero_mv_per_v", "newton_per_mv_per_v")}
    if "input" in drop:
        # the input cell's raw mV/V is kept as the tension proxy, on the encoder's time base
        proxy = frame["tension_proxy"].to_numpy()
        assert np.isfinite(proxy).all()
        mv = raw.loadcell["input_mv_per_v"].to_numpy()
        assert mv.min() - 1e-9 <= proxy.min() and proxy.max() <= mv.max() + 1e-9
        assert record["input"]["raw"].startswith("tension_proxy")
    else:
        assert frame["tension_proxy"].isna().all()


def test_half_a_load_cell_calibration_is_refused_with_the_missing_key() -> None:
    from rig_io.errors import RigIOError
    from rig_io.manifest import check_manifest

    raw = make_raw_run("half")
    raw.manifest["channels"]["loadcell"]["output"].pop("zero_mv_per_v")
    with pytest.raises(RigIOError, match="zero_mv_per_v"):
        check_manifest(raw.manifest, file="manifest.json", streams=["encoder", "loadcell"])


def test_ingest_accepts_a_run_folder_whose_load_cells_have_no_calibration(tmp_path) -> None:
    import json

    from pipelines.ingest import run_ingest
    from rig_io.folder import write_run_folder

    raw = make_raw_run("uncal_folder")
    for side in ("input", "output"):
        raw.manifest["channels"]["loadcell"][side] = {}
    write_run_folder(raw, tmp_path / "raw")
    rep = run_ingest(tmp_path / "raw", tmp_path / "out", progress=False)
    assert rep["n_accepted"] == 1, rep["rejected"]
    runs = json.loads((tmp_path / "out" / "runs.json").read_text())["runs"]
    assert runs["uncal_folder"]["calibration"]["loadcell"]["output"]["calibrated"] is False
