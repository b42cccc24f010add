"""What ingest must do with virtual-rig runs written as folders, .bag, .db3 and .mcap
ingest to the same dataset (within float tolerance), and ingest recovers the rig's truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipelines.ingest import run_ingest
from rig_io.bag import write_bag
from rig_io.dataset import read_dataset, read_runs
from rig_io.folder import write_run_folder
from rig_io.virtual import simulate_run

SINE = {"kind": "sine", "amplitude": 3.0, "offset": 0.0, "frequency_hz": 0.25,
        "duration_s": 4.0}


@pytest.fixture(scope="module")
def runs():  # type: ignore[no-untyped-def]
    bench = simulate_run(rig="tsm-bench", curve_angle_deg=90, radius_mm=30,
                         excitation=SINE, seed=1, run_id="v_bench")
    joint = simulate_run(rig="bending-joint", curve_angle_deg=60, radius_mm=45,
                         excitation={**SINE, "offset": 3.0}, seed=2, run_id="v_joint")
    return [bench, joint]


def test_every_container_ingests_to_the_same_dataset(tmp_path: Path, runs) -> None:  # type: ignore[no-untyped-def]
    datasets = {}
    metas = {}
    for kind in ("folder", "folder_gz", "rosbag1", "sqlite3", "mcap"):
        src = tmp_path / kind
        for run in runs:
            if kind.startswith("folder"):
                write_run_folder(run, src, compress=kind == "folder_gz")
            else:
                name = f"{run.run_id}.bag" if kind == "rosbag1" else run.run_id
                write_bag(run, src / name, storage=kind)  # type: ignore[arg-type]
        report = run_ingest(src, tmp_path / f"out_{kind}", progress=False)
        assert report["n_accepted"] == 2, report["rejected"]
        datasets[kind] = read_dataset(tmp_path / f"out_{kind}")
        metas[kind] = read_runs(tmp_path / f"out_{kind}")
    ref = datasets["folder"]
    for kind, frame in datasets.items():
        pd.testing.assert_frame_equal(frame, ref, check_exact=False, rtol=1e-9, atol=1e-9,
                                      obj=kind)
        for rid in ("v_bench", "v_joint"):
            assert metas[kind][rid]["camera_latency_ms"] == pytest.approx(
                metas["folder"][rid]["camera_latency_ms"], abs=1e-6)
            assert metas[kind][rid]["camera_latency_method"] == \
                metas["folder"][rid]["camera_latency_method"]


def test_ingest_recovers_the_virtual_truth(tmp_path: Path, runs) -> None:  # type: ignore[no-untyped-def]
    for run in runs:
        write_run_folder(run, tmp_path / "raw")
    run_ingest(tmp_path / "raw", tmp_path / "out", progress=False)
    df = read_dataset(tmp_path / "out")
    meta = read_runs(tmp_path / "out")
    bench = df[df.run_id == "v_bench"]
    truth = runs[0].extras["truth"]
    assert len(bench) == len(truth)
    # Encoders: counts unwrapped and scaled back to the true positions (offsets removed).
    np.testing.assert_allclose(bench["input"], truth["input_mm"] - truth["input_mm"].iloc[0],
                               atol=0.01)
    np.testing.assert_allclose(bench["output"],
                               truth["output_mm"] - truth["output_mm"].iloc[0], atol=0.01)
    # Load cells: mV/V -> N and resampled onto the encoder clock. (Row 0 is skipped: the
    # virtual rig's truth table holds the end-of-run tension there.)
    err = np.abs(bench["tension_in_n"].to_numpy()[1:] - truth["tension_in_n"].to_numpy()[1:])
    assert np.nanmax(err) < 0.5
    # Camera latency estimated against the output encoder, close to the run's true latency.
    true_latency_ms = runs[0].extras["camera_latency_s"] * 1e3
    assert meta["v_bench"]["camera_latency_method"] == "cross_correlation:output_encoder"
    assert meta["v_bench"]["camera_latency_ms"] == pytest.approx(true_latency_ms, abs=5.0)
    joint = meta["v_joint"]
    assert joint["output_source"] in ("encoder", "tracker")
    assert joint["camera_latency_method"].startswith("cross_correlation")
