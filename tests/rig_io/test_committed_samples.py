"""Golden files: the committed sample run (data/samples) stays readable as it is on disk.

The folder and the rosbag1 copy of the same run were written by the rig once
(`data/samples/regenerate.py`); a reader or ingest change that can no longer read them, or reads
them differently from each other, fails here.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipelines.ingest import run_ingest
from rig_io.bag import read_bag
from rig_io.dataset import read_dataset
from rig_io.folder import read_run_folder

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
RUN_ID = "sample_phi090_r030_sine_0001"


def _tree_hash(root: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def test_committed_folder_reads_with_every_stream() -> None:
    run = read_run_folder(SAMPLES / "folder" / RUN_ID)
    assert run.run_id == RUN_ID
    assert run.manifest["format"] == "tsm-rig-log/1"
    assert run.manifest["configuration"] == {"curve_angle_deg": 90, "radius_mm": 30}
    assert run.loadcell is not None and run.camera is not None
    # 2 s at the 100 Hz encoder loop and the 1 kHz load cells (both ends inclusive or not)
    assert 195 <= len(run.encoder) <= 202
    assert 1950 <= len(run.loadcell) <= 2002
    assert np.all(np.diff(run.encoder["t_ns"].to_numpy()) > 0)


def test_committed_bag_reads_with_the_same_manifest_and_clock() -> None:
    folder = read_run_folder(SAMPLES / "folder" / RUN_ID)
    bag = read_bag(SAMPLES / "rosbag1" / f"{RUN_ID}.bag")
    assert bag.run_id == RUN_ID
    assert bag.manifest["configuration"] == folder.manifest["configuration"]
    assert bag.manifest["excitation"] == folder.manifest["excitation"]
    assert bag.loadcell is not None and bag.camera is not None
    assert len(bag.encoder) == len(folder.encoder)


@pytest.fixture(scope="module")
def ingested(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pd.DataFrame]:
    before = _tree_hash(SAMPLES)
    out = {}
    for container in ("folder", "rosbag1"):
        dst = tmp_path_factory.mktemp(f"processed_{container}")
        report = run_ingest(SAMPLES / container, dst, progress=False)
        assert [r["run_id"] for r in report["accepted"]] == [RUN_ID], report
        assert report["rejected"] == []
        out[container] = read_dataset(dst)
    assert _tree_hash(SAMPLES) == before, "ingest wrote into a raw sample"
    return out


def test_folder_and_bag_samples_ingest_to_the_same_dataset(
        ingested: dict[str, pd.DataFrame]) -> None:
    a, b = ingested["folder"], ingested["rosbag1"]
    assert len(a) == len(b)
    for col in ("t_s", "input", "output", "input_norm", "output_norm", "tension_in_n"):
        np.testing.assert_allclose(a[col].to_numpy(float), b[col].to_numpy(float),
                                   atol=1e-6, err_msg=col)


def test_sample_is_physically_plausible(ingested: dict[str, pd.DataFrame]) -> None:
    d = ingested["folder"]
    u, y = d["input"].to_numpy(float), d["output"].to_numpy(float)
    # a 6 mm sine at the input; the output falls short of it (lost motion at 90 deg)
    assert 5.5 < np.max(np.abs(u)) < 6.5
    assert np.ptp(y) < np.ptp(u)
    assert np.max(np.abs(d["input_norm"].to_numpy(float))) == pytest.approx(1.0, abs=0.02)
    # tension stays inside the load cell's 20 N range and above the follower's pretension
    t_in = d["tension_in_n"].to_numpy(float)
    assert np.nanmin(t_in) > 0.0 and np.nanmax(t_in) < 20.0
