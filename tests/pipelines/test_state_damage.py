"""Damaged state is recomputed or named, never trusted: a model file without its hash, a
predictions file with damaged pages under an intact footer, a truncated run index, a locked
or truncated MLflow store."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from pipelines import artifacts, cache, tracking
from pipelines.common import run_stage
from pipelines.core import fit as fit_stage
from pipelines.core import report as report_stage
from pipelines.core import validate as validate_stage
from pipelines.ingest import run_ingest
from pipelines.stages import Configuration, PipelineError
from rig_io.dataset import RUNS, read_dataset
from rig_io.errors import RigIOError
from rig_io.folder import write_run_folder
from rig_io.synthetic import make_raw_run
from tests.pipelines.pipeline_data import make_dataset, mlflow_store, stage_cfg

REPO = Path(__file__).resolve().parents[2]
LABEL = Configuration("tsm-bench", 90.0, 30.0).label


def test_a_model_file_without_its_hash_is_refitted_not_trusted(tmp_path: Path) -> None:
    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    cfg = stage_cfg(tmp_path)
    first = fit_stage.run(cfg, dataset=data)
    path = tmp_path / f"data/interim/models/gamma/{LABEL}__sine_decay.json"
    record = json.loads(path.read_text())
    # an edit that drops the hash: the model no longer matches the stored metrics
    del record["model_sha256"]
    edited = json.dumps(record["model"]).replace("0.", "0.0", 1)
    assert edited != json.dumps(record["model"])
    record["model"] = json.loads(edited)
    path.write_text(json.dumps(record))
    second = fit_stage.run(cfg, dataset=data)
    again = second.set_index("family")
    assert not bool(again.loc["gamma", "cached"]) and bool(again.loc["linear", "cached"])
    rewritten = json.loads(path.read_text())
    assert rewritten["model_sha256"] == cache.hash_json(rewritten["model"])
    assert rewritten["model"] == json.loads(
        first.set_index("family").loc["gamma", "model_json"])


def _damage_pages(path: Path) -> None:
    """Flip bytes inside the column data; the footer (schema, cache record) stays intact."""
    raw = bytearray(path.read_bytes())
    footer = int.from_bytes(raw[-8:-4], "little") + 8
    lo, hi = 8, len(raw) - footer
    assert hi - lo > 64
    for i in range(lo + (hi - lo) // 3, lo + (hi - lo) // 3 + 32):
        raw[i] ^= 0xFF
    path.write_bytes(bytes(raw))


def test_a_predictions_file_with_damaged_pages_is_not_reused_by_validate_or_report(
        tmp_path: Path) -> None:
    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    cfg = stage_cfg(tmp_path, families=["linear", "gamma"], heldout=["triangle_decay"])
    fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run(cfg, dataset=data)
    rcfg = {**cfg, "exemplary": {"rig": "tsm-bench", "curve_angle_deg": 90, "radius_mm": 30},
            "fit_excitation": "sine_decay", "metric": "rmse",
            "plots": {"per_configuration": True, "dpi": 30, "max_points": 200},
            "formats": ["md"]}
    drawn = report_stage.run(rcfg)
    assert not drawn.cached and LABEL in drawn.config_plots
    pred = artifacts.prediction_path(tmp_path / "data/interim/predictions",
                                          Configuration("tsm-bench", 90.0, 30.0))
    whole = pred.read_bytes()
    _damage_pages(pred)
    # the footer still reads: without the hash of the bytes this file passes for up to date
    assert artifacts.pq.read_schema(pred).metadata is not None
    assert artifacts.read_prediction_meta(pred) is None

    # the report does not draw from it (and is not "up to date" on it)
    damaged = report_stage.run(rcfg)
    assert not damaged.cached and LABEL not in damaged.config_plots

    # validate recomputes it: the same bytes as before the damage, the same metrics
    again, _ = validate_stage.run(cfg, dataset=data)
    assert pred.read_bytes() == whole
    assert artifacts.read_prediction_meta(pred) is not None
    assert again.equals(metrics)
    assert LABEL in report_stage.run(rcfg).config_plots

    # a predictions file without a recorded hash (older layout) is recomputed too
    cache.digest_path(pred).unlink()
    assert artifacts.read_prediction_meta(pred) is None
    validate_stage.run(cfg, dataset=data)
    assert cache.digest_matches(pred)


def test_a_truncated_run_index_names_the_fix_and_force_rebuilds_it(tmp_path: Path) -> None:
    src, out = tmp_path / "src", tmp_path / "out"
    for i in range(2):
        write_run_folder(make_raw_run(f"run{i}", duration_s=3.0, seed=i + 1), src)
    run_ingest(src, out, progress=False)
    rows = read_dataset(out)
    index = out / RUNS
    text = index.read_text()
    index.write_text(text[: len(text) // 2])  # e.g. a disk that filled up mid-write
    with pytest.raises(RigIOError) as err:
        run_ingest(src, out, progress=False)
    msg = str(err.value)
    assert str(index) in msg and "force=true" in msg and f"delete {RUNS}" in msg
    # force repairs it: every run reprocessed, the index whole again, no data lost
    report = run_ingest(src, out, progress=False, force=True)
    assert report["n_accepted"] == 2 and report["removed"] == []
    assert set(json.loads(index.read_text())["runs"]) == {"run0", "run1"}
    assert read_dataset(out).equals(rows)
    # and the next ingest without force reuses it
    again = run_ingest(src, out, progress=False)
    assert {a["status"] for a in again["accepted"]} == {"unchanged"}


def test_a_truncated_mlflow_store_ends_in_one_line_naming_it(tmp_path: Path) -> None:
    db = mlflow_store(tmp_path)
    db.write_bytes(db.read_bytes()[: db.stat().st_size // 3])
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    with pytest.raises(PipelineError) as err:
        tracker.init_store()
    msg = str(err.value)
    assert str(db.resolve()) in msg and "damaged" in msg and "mv " in msg
    assert "\n" not in msg
    # the entry point prints that line alone (no traceback) and exits 2
    proc = subprocess.run(
        [sys.executable, "-m", "pipelines.validate", f"paths.root={tmp_path}",
         "hydra.run.dir=" + str(tmp_path / "hydra"), "hydra/job_logging=disabled"],
        cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert lines == [f"validate: {msg}"], proc.stderr[-2000:]


def test_a_locked_mlflow_store_at_start_is_named_with_the_fix(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    db = mlflow_store(tmp_path)
    monkeypatch.setattr(tracking.time, "sleep", lambda s: None)  # the retries, without waits
    holder = sqlite3.connect(db, timeout=0.1)
    holder.execute("BEGIN EXCLUSIVE")  # another process in the middle of a write
    try:
        tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
        with pytest.raises(SystemExit) as ended:
            run_stage("fit", tracker.init_store)
    finally:
        holder.rollback()
        holder.close()
    assert ended.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fit: MLflow store ") and "\n" not in err
    assert str(db.resolve()) in err and "locked by another process" in err
    assert "fuser" in err
    # once the other writer is done, the same store opens
    assert tracking.Tracker(tracking.settings_from_config({}, root=tmp_path)).experiment_id
