"""Outputs that must not or cannot be written: a link or a folder at an output name is
refused before the work, and a full disk stops the stage without losing processed data."""

from __future__ import annotations

import errno
import hashlib
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from pipelines import discrepancy
from pipelines.ingest import run_ingest
from rig_io import atomic
from rig_io.dataset import read_dataset
from rig_io.errors import WriteError
from rig_io.folder import write_run_folder
from rig_io.synthetic import make_raw_run
from tests.pipelines.pipeline_data import mlflow_store

REPO = Path(__file__).resolve().parents[2]


def _digests(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}


# --------------------------------------------------------------------------------------
# a link or a folder where the report goes
# --------------------------------------------------------------------------------------


def test_a_symlinked_report_leaves_its_target_untouched_and_fails_in_one_line(
        tmp_path: Path) -> None:
    precious = tmp_path / "elsewhere" / "precious.json"
    precious.parent.mkdir()
    precious.write_bytes(b'{"keep": true}\n')
    link = tmp_path / "reports" / "discrepancy.json"
    link.parent.mkdir()
    link.symlink_to(precious)
    (tmp_path / "raw").mkdir()
    proc = subprocess.run(
        [sys.executable, "-m", "pipelines.discrepancy", f"source={tmp_path / 'raw'}",
         f"report={link}", "progress=false", "tracking=off",
         f"hydra.run.dir={tmp_path / 'hydra'}"],
        capture_output=True, text=True, timeout=120, env=_env(), cwd=tmp_path)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("discrepancy: report="), proc.stderr
    assert "symbolic link" in lines[0] and str(link) in lines[0]
    assert precious.read_bytes() == b'{"keep": true}\n'
    assert link.is_symlink()
    assert sorted(p.name for p in precious.parent.iterdir()) == ["precious.json"]
    assert sorted(p.name for p in link.parent.iterdir()) == ["discrepancy.json"]


@pytest.mark.parametrize("where", ["report", "plots"])
def test_an_existing_folder_at_a_report_path_is_refused_before_any_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    report = tmp_path / "out" / "discrepancy.json"
    blocked = report if where == "report" else report.parent / "discrepancy_plots"
    if where == "plots":  # a file where the plots folder goes
        blocked.parent.mkdir(parents=True)
        blocked.write_text("not a folder")
    else:
        (blocked / "inner").mkdir(parents=True)
    started: list[Any] = []
    monkeypatch.setattr(discrepancy, "ingest_source", lambda *a, **k: started.append(a))
    (tmp_path / "raw").mkdir()
    with pytest.raises(discrepancy.DiscrepancyError, match="where a (file|folder) is expected"):
        discrepancy.run({"source": str(tmp_path / "raw"), "report": str(report),
                         "progress": False, "tracking": {"enabled": False}})
    assert started == []
    assert (blocked / "inner").is_dir() if where == "report" else blocked.is_file()


# --------------------------------------------------------------------------------------
# a full disk during a re-ingest
# --------------------------------------------------------------------------------------


@pytest.fixture
def processed(tmp_path: Path) -> tuple[Path, Path, Path]:
    """A project root whose three raw runs are ingested once."""
    root = tmp_path / "proj"
    src, out = root / "data" / "raw" / "virtual", root / "data" / "processed" / "virtual"
    for i in range(3):
        write_run_folder(make_raw_run(f"run{i}", duration_s=4.0, seed=i + 1), src)
    report = run_ingest(src, out, progress=False)
    assert report["n_accepted"] == 3
    return root, src, out


def _fill_disk_at(monkeypatch: pytest.MonkeyPatch, victim: str) -> None:
    """ENOSPC when the atomic writer syncs the temporary of ``victim``."""
    real = atomic.fsync_tree

    def full(path: Path) -> None:
        if path.name.startswith(f".{victim}.{atomic.TMP_TAG}-"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        real(path)

    monkeypatch.setattr(atomic, "fsync_tree", full)


@pytest.mark.parametrize("victim", ["run1.parquet", "runs.json"])
def test_a_full_disk_during_a_reingest_loses_no_run_and_ends_the_parent_failed(
        processed: tuple[Path, Path, Path], monkeypatch: pytest.MonkeyPatch,
        victim: str) -> None:
    from pipelines.run_all import compose_stage, run_pipeline
    from pipelines.tracking import Tracker, TrackingSettings

    root, _, out = processed
    before = _digests(out)
    mlflow_store(root)
    _fill_disk_at(monkeypatch, victim)
    cfg = compose_stage("pipeline", [f"paths.root={root}", "stages=[ingest]", "progress=false",
                                     "overrides.ingest=['force=true','progress=false']"])
    with pytest.raises(WriteError) as info:
        run_pipeline(cfg)
    msg = str(info.value)
    assert "\n" not in msg and victim in msg and "No space left on device" in msg
    assert " free of " in msg, msg
    after = _digests(out)
    # nothing removed, the file being written is the old one, the index is the old one
    assert set(after) == set(before)
    assert after[f"samples/{victim}" if victim.endswith("parquet") else victim] == \
        before[f"samples/{victim}" if victim.endswith("parquet") else victim]
    assert after["runs.json"] == before["runs.json"]
    assert set(read_dataset(out)["run_id"]) == {"run0", "run1", "run2"}
    tracker = Tracker(TrackingSettings(root=root))
    runs = tracker.client.search_runs([tracker.experiment_id], "tags.kind = 'parent'")
    assert [r.info.status for r in runs] == ["FAILED"]
    assert runs[0].data.tags["failed_stage"] == "ingest"
    assert "No space left on device" in runs[0].data.tags["error"]


def test_the_ingest_entry_point_fails_in_one_line_naming_the_file_and_free_space(
        processed: tuple[Path, Path, Path]) -> None:
    root, src, out = processed
    before = _digests(out)
    script = (
        "import errno, os, sys\n"
        "from rig_io import atomic\n"
        "real = atomic.fsync_tree\n"
        "def full(path):\n"
        "    if path.name.startswith('.run1.parquet.'):\n"
        "        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))\n"
        "    real(path)\n"
        "atomic.fsync_tree = full\n"
        "import runpy\n"
        f"sys.argv = ['ingest', 'source={src}', 'out={out}', 'force=true', 'progress=false',\n"
        f"            'hydra.run.dir={root / 'hydra'}']\n"
        "runpy.run_module('pipelines.ingest', run_name='__main__')\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env=_env(), cwd=root)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ingest: "), proc.stderr
    assert str(out / "samples" / "run1.parquet") in lines[0] and " free of " in lines[0]
    after = _digests(out)
    assert set(after) == set(before) and after["runs.json"] == before["runs.json"]
    assert set(read_dataset(out)["run_id"]) == {"run0", "run1", "run2"}
