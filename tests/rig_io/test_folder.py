"""Run folders: round trip, calibration from counts, and every bad-input case of section 3."""

from __future__ import annotations

import gzip
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rig_io.calibrate import calibrate_raw_run, unwrap_counts
from rig_io.errors import RigIOError
from rig_io.folder import read_run_folder, write_run_folder
from rig_io.synthetic import make_raw_run


def _tree_hash(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.name.encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


@pytest.mark.parametrize("compress", [False, True])
def test_round_trip_every_stream(tmp_path: Path, compress: bool) -> None:
    run = make_raw_run("rt_0001", duration_s=3.0, with_tracker=True, counts_start=2**31 - 700)
    path = write_run_folder(run, tmp_path, compress=compress)
    assert path == tmp_path / "rt_0001"
    suffix = ".csv.gz" if compress else ".csv"
    assert (path / f"encoder{suffix}").exists() and (path / "events.csv").exists()
    back = read_run_folder(path)
    assert back.manifest == run.manifest
    for name, frame in run.streams().items():
        pd.testing.assert_frame_equal(getattr(back, name), frame.reset_index(drop=True),
                                      check_dtype=False)
    # Writing twice gives the same bytes (deterministic gzip), and leaves no temporaries.
    first = _tree_hash(path)
    write_run_folder(run, tmp_path, compress=compress)
    assert _tree_hash(path) == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rt_0001"]


def test_bending_joint_without_output_encoder(tmp_path: Path) -> None:
    run = make_raw_run("bj_0001", duration_s=2.0, with_output_encoder=False, with_tracker=True)
    back = read_run_folder(write_run_folder(run, tmp_path))
    assert back.encoder["output_counts"].isna().all()
    text = (tmp_path / "bj_0001" / "encoder.csv").read_text().splitlines()
    assert text[1] == "0,0,"


def test_wraparound_is_unwrapped_not_reported(tmp_path: Path) -> None:
    run = make_raw_run("wrap_0001", duration_s=4.0, counts_start=2**31 - 1000,
                       with_camera=False)
    counts = run.encoder["input_counts"].to_numpy()
    assert counts.min() < -2**30 and counts.max() > 2**30  # it really wraps
    phys = calibrate_raw_run(read_run_folder(write_run_folder(run, tmp_path)))
    np.testing.assert_allclose(phys.encoder["input"], run.extras["true_input"], atol=1e-4)
    np.testing.assert_allclose(phys.encoder["output"], run.extras["true_output"], atol=1e-4)
    # 8-bit counter wrapping many times.
    steps = np.full(1000, 37, dtype=np.int64)
    true = np.concatenate([[0], np.cumsum(steps)])
    wrapped = (true + 128) % 256 - 128
    np.testing.assert_array_equal(unwrap_counts(wrapped, 8), true)


def test_mv_per_v_to_newton(tmp_path: Path) -> None:
    run = make_raw_run("lc_0001", duration_s=1.0, with_camera=False)
    phys = calibrate_raw_run(run)
    cell = run.manifest["channels"]["loadcell"]["input"]
    raw = run.loadcell["input_mv_per_v"].to_numpy()
    expect = (raw - cell["zero_mv_per_v"]) * cell["newton_per_mv_per_v"]
    np.testing.assert_allclose(phys.loadcell["tension_in_n"], expect)
    assert 4.5 < phys.loadcell["tension_in_n"].mean() < 8.5


# ------------------------------------------------------------------------------ bad input

def _good(tmp_path: Path, **kw: object) -> Path:
    return write_run_folder(make_raw_run("bad_0001", duration_s=2.0, **kw), tmp_path)


def _edit(path: Path, fn: object) -> None:
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(fn(lines)))  # type: ignore[operator]


def _replace_line(i: int, new: str):  # type: ignore[no-untyped-def]
    def fn(lines: list[str]) -> list[str]:
        lines[i] = new
        return lines
    return fn


CASES = {
    "missing manifest": (lambda p: (p / "manifest.json").unlink(),
                         ["missing manifest.json", "manifest.json"]),
    "unreadable manifest": (lambda p: (p / "manifest.json").write_text('{"format": '),
                            ["not valid JSON", "row 1"]),
    "unknown format": (lambda p: (p / "manifest.json").write_text(json.dumps(
        {**json.loads((p / "manifest.json").read_text()), "format": "tsm-rig-log/9"})),
        ["unknown format 'tsm-rig-log/9'", "manifest.json"]),
    "missing encoder": (lambda p: (p / "encoder.csv").unlink(), ["missing required encoder"]),
    "missing column": (lambda p: _edit(p / "encoder.csv", _replace_line(0, "t_ns,input\n")),
                       ["missing required column(s) input_counts", "encoder.csv", "row 1"]),
    "non-numeric cell": (lambda p: _edit(p / "loadcell.csv",
                                         _replace_line(7, "6000000,0.5x,0.4\n")),
                         ["non-numeric value '0.5x' in column input_mv_per_v", "loadcell.csv",
                          "row 8"]),
    "truncated last line": (lambda p: (p / "encoder.csv").write_text(
        (p / "encoder.csv").read_text()[:-6]), ["truncated last line", "encoder.csv"]),
    "truncated short line": (lambda p: (p / "encoder.csv").write_text(
        (p / "encoder.csv").read_text() + "2000000000,5\n"),
        ["truncated last line", "2 fields", "row 202"]),
    "empty file": (lambda p: (p / "loadcell.csv").write_text(""),
                   ["empty file", "loadcell.csv"]),
    "header only": (lambda p: (p / "camera.csv").write_text("t_ns,frame,value,confidence\n"),
                    ["no data rows", "camera.csv"]),
    "timestamps backwards": (lambda p: _edit(p / "encoder.csv",
                                             _replace_line(51, "480000000,0,0\n")),
                             ["timestamp goes backwards", "encoder.csv", "row 52",
                              "t=480000000 ns"]),
    "timestamps repeat": (lambda p: _edit(p / "encoder.csv",
                                          _replace_line(51, "490000000,0,0\n")),
                          ["timestamp repeats", "row 52", "t=490000000 ns"]),
    "gap": (lambda p: _edit(p / "encoder.csv", lambda ls: ls[:40] + ls[60:]),
            ["gap of 210.0 ms", "10 sample periods", "encoder.csv", "row 40", "t=380000000"]),
    "saturation": (lambda p: _edit(p / "loadcell.csv", _replace_line(101, "100000000,2.1,0.4\n")),
                   ["input load cell saturated", "loadcell.csv", "row 102", "t=100000000 ns"]),
    "estop": (lambda p: (p / "events.csv").write_text(
        "t_ns,event,detail\n0,start,\n1200000000,estop,operator\n"),
        ["emergency stop", "operator", "events.csv", "row 3", "t=1200000000 ns"]),
    "unknown event": (lambda p: (p / "events.csv").write_text("t_ns,event,detail\n0,boom,\n"),
                      ["unknown event 'boom'", "row 2"]),
    "no confident frame": (lambda p: _edit(p / "camera.csv", lambda ls: [ls[0]] + [
        ",".join(line.split(",")[:3] + ["0.0\n"]) for line in ls[1:]]),
        ["no confident frame", "camera.csv"]),
    "corrupt gzip": (lambda p: (p / "tracker.csv.gz").write_bytes(b"\x1f\x8b\x08garbage"),
                     ["unreadable or truncated", "tracker.csv.gz"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_names_run_file_and_place(tmp_path: Path, case: str) -> None:
    path = _good(tmp_path, with_tracker=True)
    breaker, expected = CASES[case]
    if case == "corrupt gzip":
        (path / "tracker.csv").unlink()
    breaker(path)
    with pytest.raises(RigIOError) as err:
        read_run_folder(path)
    msg = str(err.value)
    assert "bad_0001" in msg
    for piece in expected:
        assert piece in msg, f"{piece!r} not in {msg!r}"


def test_truncated_gzip_stream(tmp_path: Path) -> None:
    path = write_run_folder(make_raw_run("gz_0001", duration_s=2.0), tmp_path, compress=True)
    data = (path / "loadcell.csv.gz").read_bytes()
    (path / "loadcell.csv.gz").write_bytes(data[: len(data) // 2])
    with pytest.raises(RigIOError, match="loadcell.csv.gz.*unreadable or truncated"):
        read_run_folder(path)


def test_gzip_of_text_truncated_mid_line(tmp_path: Path) -> None:
    path = write_run_folder(make_raw_run("gz_0002", duration_s=2.0), tmp_path, compress=True)
    text = gzip.decompress((path / "encoder.csv.gz").read_bytes())
    (path / "encoder.csv.gz").write_bytes(gzip.compress(text[:-3]))
    with pytest.raises(RigIOError, match="encoder.csv.gz.*truncated last line"):
        read_run_folder(path)
