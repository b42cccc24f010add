"""The ingest stage end to end: mixed sources, round trip across containers, bad runs in a
batch, idempotence and incrementality, raw runs untouched, the Hydra entry point."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipelines.ingest import run_ingest
from rig_io.bag import write_bag
from rig_io.dataset import read_dataset, read_runs
from rig_io.folder import write_run_folder
from rig_io.schema import COLUMNS
from rig_io.synthetic import make_raw_run

REPO = Path(__file__).resolve().parents[2]


def tree_hash(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.relative_to(folder).as_posix().encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def _run(run_id: str, **kw: object):  # type: ignore[no-untyped-def]
    kw.setdefault("duration_s", 4.0)
    return make_raw_run(run_id, **kw)  # type: ignore[arg-type]


def test_mixed_source_folder(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    write_run_folder(_run("f_plain", seed=1), src)
    write_run_folder(_run("f_gz", seed=2, counts_start=2**31 - 2000), src / "nested", compress=True)
    write_bag(_run("b_ros1", seed=3, with_tracker=True), src / "b_ros1.bag", storage="rosbag1")
    write_bag(_run("b_db3", seed=4), src / "b_db3", storage="sqlite3")
    write_bag(_run("b_mcap", seed=5, with_output_encoder=False, with_tracker=False),
              src / "b_mcap", storage="mcap")
    before = tree_hash(src)
    report = run_ingest(src, out, progress=False)
    assert report["n_rejected"] == 0, report["rejected"]
    assert sorted(a["run_id"] for a in report["accepted"]) == [
        "b_db3", "b_mcap", "b_ros1", "f_gz", "f_plain"]
    assert tree_hash(src) == before  # nothing written into raw runs
    df = read_dataset(out)
    assert tuple(df.columns) == COLUMNS
    plain = pd.read_parquet(out / "samples")
    assert len(plain) == len(df) == 5 * 400
    runs = read_runs(out)
    assert runs["b_ros1"]["camera_latency_method"] == "cross_correlation:tracker"
    assert runs["f_plain"]["camera_latency_method"] == "cross_correlation:output_encoder"
    # A bending joint with neither output encoder nor tracker: output from the camera,
    # latency from the manifest.
    assert runs["b_mcap"]["output_source"] == "camera"
    assert runs["b_mcap"]["camera_latency_method"] == "nominal"
    assert runs["b_mcap"]["camera_latency_ms"] == pytest.approx(45.0)
    for rid, meta in runs.items():
        assert meta["source_hash"] and meta["source_files"] and meta["manifest"]["run_id"] == rid
        assert meta["ingest_version"]
    one = df[df.run_id == "f_gz"]
    assert one["input_norm"].abs().max() == pytest.approx(1.0)
    assert one["input"].iloc[0] == 0.0 and one["output"].iloc[0] == 0.0
    assert one["curve_angle_deg"].iloc[0] == 90 and one["excitation"].iloc[0] == "sine"
    assert one["tension_in_n"].notna().all()
    true = make_raw_run("f_gz", duration_s=4.0, seed=2).extras["true_output"]
    np.testing.assert_allclose(one["output"], true - true[0], atol=2e-4)


def test_same_run_in_every_container_gives_the_same_dataset(tmp_path: Path) -> None:
    run = _run("rt_0001", seed=7, with_tracker=True, counts_start=2**31 - 5000)
    frames = {}
    metas = {}
    for kind in ("folder", "folder_gz", "rosbag1", "sqlite3", "mcap"):
        src = tmp_path / kind / "raw"
        if kind.startswith("folder"):
            write_run_folder(run, src, compress=kind == "folder_gz")
        else:
            name = "rt.bag" if kind == "rosbag1" else "rt"
            write_bag(run, src / name, storage=kind)  # type: ignore[arg-type]
        report = run_ingest(src, tmp_path / kind / "out", progress=False)
        assert report["n_accepted"] == 1, report["rejected"]
        frames[kind] = read_dataset(tmp_path / kind / "out")
        metas[kind] = read_runs(tmp_path / kind / "out")["rt_0001"]
    ref = frames["folder"]
    for kind, frame in frames.items():
        pd.testing.assert_frame_equal(frame, ref, check_exact=False, rtol=1e-9, atol=1e-9,
                                      obj=kind)
        assert metas[kind]["camera_latency_ms"] == pytest.approx(
            metas["folder"]["camera_latency_ms"], abs=1e-6)


def _bad_bags(src: Path) -> dict[str, str]:
    """One truncated or corrupt bag of each storage; returns {source name: expected words}."""
    expect: dict[str, str] = {}
    b = write_bag(_run("tbag"), src / "tbag.bag", storage="rosbag1")
    b.write_bytes(b.read_bytes()[:5000])
    expect["tbag.bag"] = "truncated or corrupt bag"

    b = write_bag(_run("cbag"), src / "cbag", storage="sqlite3")
    db = b / "cbag.db3"
    data = bytearray(db.read_bytes())
    data[0:100] = b"\x13" * 100
    db.write_bytes(bytes(data))
    expect["cbag"] = "truncated or corrupt bag"

    b = write_bag(_run("mbag"), src / "mbag", storage="mcap")
    data = (b / "mbag.mcap").read_bytes()
    (b / "mbag.mcap").write_bytes(data[: len(data) // 3])
    expect["mbag"] = "truncated or corrupt bag"
    return expect


def _bad_batch(src: Path) -> dict[str, str]:
    """Good runs plus one run per bad case; returns {source name: expected words}."""
    write_run_folder(_run("good_1", seed=1), src)
    write_bag(_run("good_2", seed=2), src / "good_2.bag", storage="rosbag1")
    expect: dict[str, str] = {}

    p = write_run_folder(_run("no_manifest"), src)
    (p / "manifest.json").unlink()
    expect["no_manifest"] = "missing manifest.json"

    p = write_run_folder(_run("fmt"), src)
    m = json.loads((p / "manifest.json").read_text())
    m["format"] = "tsm-rig-log/2"
    (p / "manifest.json").write_text(json.dumps(m))
    expect["fmt"] = "unknown format"

    p = write_run_folder(_run("cell"), src)
    lines = (p / "encoder.csv").read_text().splitlines(keepends=True)
    lines[10] = "90000000,abc,3\n"
    (p / "encoder.csv").write_text("".join(lines))
    expect["cell"] = "row 11"

    p = write_run_folder(_run("trunc"), src)
    (p / "loadcell.csv").write_text((p / "loadcell.csv").read_text()[:-4])
    expect["trunc"] = "truncated last line"

    p = write_run_folder(_run("empty"), src)
    (p / "camera.csv").write_text("")
    expect["empty"] = "empty file"

    p = write_run_folder(_run("backwards"), src)
    lines = (p / "encoder.csv").read_text().splitlines(keepends=True)
    lines[30], lines[31] = lines[31], lines[30]
    (p / "encoder.csv").write_text("".join(lines))
    expect["backwards"] = "goes backwards"

    p = write_run_folder(_run("gap"), src)
    lines = (p / "encoder.csv").read_text().splitlines(keepends=True)
    (p / "encoder.csv").write_text("".join(lines[:100] + lines[130:]))
    expect["gap"] = "sample periods"

    run = _run("sat")
    run.loadcell.loc[2500, "output_mv_per_v"] = 3.0  # type: ignore[union-attr]
    write_run_folder(run, src)
    expect["sat"] = "output load cell saturated"

    run = _run("estop")
    run.events.loc[1, "event"] = "estop"  # type: ignore[union-attr]
    write_run_folder(run, src)
    expect["estop"] = "emergency stop"

    run = _run("blind")
    run.camera["confidence"] = 0.0  # type: ignore[index]
    write_run_folder(run, src)
    expect["blind"] = "no confident frame"

    expect.update(_bad_bags(src))
    return expect


def test_bad_runs_are_rejected_and_good_runs_land(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    expect = _bad_batch(src)
    before = tree_hash(src)
    report = run_ingest(src, out, progress=False)
    assert tree_hash(src) == before
    assert sorted(a["run_id"] for a in report["accepted"]) == ["good_1", "good_2"]
    got = {r["source"]: r["reason"] for r in report["rejected"]}
    assert sorted(got) == sorted(expect)
    for name, words in expect.items():
        assert words in got[name], (name, got[name])
        stem = name.removesuffix(".bag")
        assert stem in got[name], (name, got[name])  # names the run (or the bag)
    on_disk = json.loads((out / "ingest_report.json").read_text())
    assert on_disk["n_rejected"] == len(expect)
    assert set(read_dataset(out)["run_id"]) == {"good_1", "good_2"}


def test_idempotent_and_incremental(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    for i in range(3):
        write_run_folder(_run(f"r{i}", seed=i), src)
    first = run_ingest(src, out, progress=False)
    assert first["n_processed"] == 3
    files = {p.name: p.stat().st_mtime_ns for p in (out / "samples").iterdir()}
    data = read_dataset(out)
    second = run_ingest(src, out, progress=False)
    assert second["n_processed"] == 0 and second["n_accepted"] == 3
    assert {p.name: p.stat().st_mtime_ns for p in (out / "samples").iterdir()} == files
    pd.testing.assert_frame_equal(read_dataset(out), data)
    # One changed run, one new run, one removed run.
    write_run_folder(_run("r1", seed=11), src)
    write_run_folder(_run("r3", seed=3), src)
    shutil.rmtree(src / "r0")
    third = run_ingest(src, out, progress=False)
    processed = sorted(a["run_id"] for a in third["accepted"] if a["status"] == "processed")
    assert processed == ["r1", "r3"]
    assert third["removed"] == ["r0"]
    assert sorted(p.stem for p in (out / "samples").iterdir()) == ["r1", "r2", "r3"]
    assert (out / "samples" / "r2.parquet").stat().st_mtime_ns == files["r2.parquet"]
    # force reprocesses everything, and gives the same rows.
    again = read_dataset(out)
    forced = run_ingest(src, out, progress=False, force=True)
    assert forced["n_processed"] == 3
    pd.testing.assert_frame_equal(read_dataset(out), again)


def test_hydra_entry_point_exit_status(tmp_path: Path) -> None:
    src, out = tmp_path / "raw", tmp_path / "out"
    write_run_folder(_run("ok_1", duration_s=3.0), src)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".venv" / "numba-cache")}
    cmd = [sys.executable, "-m", "pipelines.ingest", f"source={src}", f"out={out}",
           "progress=false", f"hydra.run.dir={tmp_path / 'hydra'}"]
    p = write_run_folder(_run("bad_1", duration_s=3.0), src)
    (p / "encoder.csv").write_text("")
    bad = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert bad.returncode == 1, bad.stderr
    assert "1 accepted (1 processed), 1 rejected" in bad.stderr
    assert "rejected bad_1" in bad.stderr and "empty file" in bad.stderr
    assert json.loads((out / "ingest_report.json").read_text())["n_accepted"] == 1


def test_bag_with_sidecar_manifest(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.typesys import Stores, get_typestore

    run = _run("side_1", duration_s=2.0)
    full = write_bag(run, tmp_path / "full.bag", storage="rosbag1")
    src = tmp_path / "raw"
    src.mkdir()
    ts = get_typestore(Stores.ROS1_NOETIC)
    with AnyReader([full]) as r, Writer1(src / "side.bag") as w:
        conns: dict[str, object] = {}
        for c, t, raw in r.messages():
            if c.topic != "/rig/manifest":
                if c.topic not in conns:
                    conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=ts)
                w.write(conns[c.topic], t, raw)  # type: ignore[arg-type]
    report = run_ingest(src, tmp_path / "out", progress=False)
    assert report["n_rejected"] == 1 and "side.bag.manifest.json" in report["rejected"][0]["reason"]
    (src / "side.bag.manifest.json").write_text(json.dumps(run.manifest))
    report = run_ingest(src, tmp_path / "out", progress=False)
    assert report["n_rejected"] == 0 and report["n_sources"] == 1
    meta = read_runs(tmp_path / "out")["side_1"]
    assert sorted(meta["source_files"]) == ["side.bag", "side.bag.manifest.json"]
