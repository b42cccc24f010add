"""Physically implausible records: a position channel that never moves is rejected at ingest
by name, and a fit that reproduces a measured output exactly is refused, not stored."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipelines.core import fit as fit_stage
from pipelines.ingest import run_ingest
from rig_io.dataset import read_dataset
from rig_io.folder import write_run_folder
from rig_io.synthetic import make_raw_run
from tests.cleanroom import riglog
from tests.pipelines.pipeline_data import make_dataset, stage_cfg


def _reasons(report: dict[str, object]) -> dict[str, str]:
    rejected = report["rejected"]
    assert isinstance(rejected, list)
    return {str(r["run_id"]): str(r["reason"]) for r in rejected}


def _stuck_output(run_id: str, *, dither: bool, seed: int) -> object:
    """The project's synthetic run with its output encoder stuck (or dithering by one count)."""
    raw = make_raw_run(run_id, duration_s=4.0, seed=seed)
    n = len(raw.encoder)
    first = int(raw.encoder["output_counts"].iloc[0])
    counts = first + (np.arange(n) % 7 == 3).astype(np.int64) if dither else np.full(n, first)
    raw.encoder["output_counts"] = pd.array(counts, dtype="Int64")
    return raw


def test_ingest_rejects_a_stuck_output_encoder_by_run_and_channel(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    write_run_folder(make_raw_run("good", duration_s=4.0, seed=1), src)
    write_run_folder(_stuck_output("stuck", dither=False, seed=2), src)
    write_run_folder(_stuck_output("dither", dither=True, seed=3), src)
    report = run_ingest(src, out, progress=False)
    assert [a["run_id"] for a in report["accepted"]] == ["good"]
    reasons = _reasons(report)
    assert set(reasons) == {"stuck", "dither"}
    for run_id, reason in reasons.items():
        assert f"run {run_id!r}" in reason and "output (encoder) never moves" in reason, reason
    assert "= 0 encoder count(s)" in reasons["stuck"]
    assert "= 1 encoder count(s)" in reasons["dither"]
    assert set(read_dataset(out)["run_id"]) == {"good"}


def test_ingest_rejects_the_clean_room_stuck_channels_and_keeps_the_clean_runs(
        tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    clean = {p.name for p in riglog.write_clean_source(src, n=3)}
    ex = riglog.make_excitation("sine_decay", duration_scale=0.2)
    y, t_in, t_out = riglog.simple_tsm_plant(ex.u)
    faulty = {}
    for i, fault in enumerate(("stuck_output", "stuck_output_quantised", "stuck_input")):
        run_id = f"faulty_{fault}"
        riglog.write_run_folder(src, run_id, ex.t_s, ex.u, y, excitation=ex.manifest,
                                loadcell=(t_in, t_out), faults=[fault], seed=10 + i)
        faulty[run_id] = "input (encoder)" if fault == "stuck_input" else "output (encoder)"
    report = run_ingest(src, out, progress=False)
    assert {a["run_id"] for a in report["accepted"]} == clean
    reasons = _reasons(report)
    assert set(reasons) == set(faulty)
    for run_id, channel in faulty.items():
        assert f"run {run_id!r}" in reasons[run_id], reasons[run_id]
        assert f"{channel} never moves" in reasons[run_id], reasons[run_id]


def test_a_fit_to_an_output_that_never_moves_is_refused_not_stored(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), kinds=("sine_decay",), dt=0.1)
    data["output"] = 0.0  # a stuck output reaching fit from outside ingest
    fits = fit_stage.run(stage_cfg(tmp_path, families=["linear", "gamma"]), dataset=data)
    assert len(fits) == 2 and fits["model_json"].isna().all()
    assert all("output never moves" in str(e) for e in fits["error"]), list(fits["error"])


def test_a_fit_that_reproduces_a_quantised_output_exactly_is_refused(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), kinds=("sine_decay",), dt=0.1)
    smooth = data["input"].copy()
    count = 1e-3  # an encoder count: the output is an exact copy of the quantised input
    data["input"] = np.round(smooth / count) * count
    data["output"] = 0.5 * data["input"]
    fits = fit_stage.run(stage_cfg(tmp_path, families=["linear"]), dataset=data)
    assert fits["model_json"].isna().all()
    error = str(fits["error"].iloc[0])
    assert "in-sample RMSE" in error and "resolution (0.0005)" in error, error
    # the same exact copy off any grid (made by hand or by a model) is no sign of a fault
    data["input"], data["output"] = smooth, 0.5 * smooth
    assert fit_stage.run(stage_cfg(tmp_path / "b", families=["linear"]),
                         dataset=data)["error"].isna().all()


@pytest.mark.parametrize("fault", ["ragged_loadcell_end", "loadcell_gap"])
def test_clean_room_load_cell_faults_do_not_break_ingest(tmp_path: Path, fault: str) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    ex = riglog.make_excitation("sine_decay", duration_scale=0.2)
    y, t_in, t_out = riglog.simple_tsm_plant(ex.u)
    riglog.write_run_folder(src, "lc", ex.t_s, ex.u, y, excitation=ex.manifest,
                            loadcell=(t_in, t_out), faults=[fault])
    report = run_ingest(src, out, progress=False)
    # accepted or rejected with a reason: never an unnamed failure
    assert report["n_accepted"] + report["n_rejected"] == 1
    for r in report["rejected"]:
        assert "run 'lc'" in r["reason"] and "while processing" not in r["reason"], r
