"""Each probe of the hardening review, on a copy of the committed sample run: what must be
rejected is rejected with file and key or row named, what is legal still goes through."""

from __future__ import annotations

import gzip
import json
import os
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rig_io.bag import read_bag
from rig_io.errors import MAX_REASON_CHARS, RigIOError
from rig_io.folder import read_run_folder, read_stream_csv
from rig_io.limits import ReadLimits
from rig_io.sources import discover, hash_files
from tests.rig_io.hardening_util import (
    SAMPLE_BAG,
    assert_names_where,
    assert_sound,
    folder_source,
    ingest_one,
    plain_copy,
)


def _manifest(folder: Path) -> dict[str, Any]:
    out: dict[str, Any] = json.loads((folder / "manifest.json").read_text())
    return out


def _set(folder: Path, path: str, value: Any) -> None:
    m = _manifest(folder)
    d = m
    keys = path.split(".")
    for k in keys[:-1]:
        d = d[k]
    d[keys[-1]] = value
    (folder / "manifest.json").write_text(json.dumps(m))


def _reject(folder: Path, *, limits: ReadLimits | None = None) -> RigIOError:
    with pytest.raises(RigIOError) as info:
        ingest_one(folder_source(folder), limits=limits)
    assert_names_where(info.value)
    return info.value


def _cell(folder: Path, stream: str, row: int, col: str, value: str) -> None:
    """Replace one cell (``row`` is the 1-based file line)."""
    path = folder / f"{stream}.csv"
    lines = path.read_text().split("\n")
    header = lines[0].split(",")
    fields = lines[row - 1].split(",")
    fields[header.index(col)] = value
    lines[row - 1] = ",".join(fields)
    path.write_text("\n".join(lines))


def test_sample_copy_is_accepted(tmp_path: Path) -> None:
    frame = ingest_one(folder_source(plain_copy(tmp_path)))
    assert_sound(frame)
    assert len(frame) == 201  # 2 s at 100 Hz, both ends


@pytest.mark.parametrize("run_id", ["../../escape", "/abs", "sub/dir", "..", ".hidden",
                                    "", "a" * 129, "nul\x00byte", 7])
def test_unsafe_run_id_rejected(tmp_path: Path, run_id: Any) -> None:
    folder = plain_copy(tmp_path)
    _set(folder, "run_id", run_id)
    err = _reject(folder)
    assert err.key == "run_id"


def test_rig_names(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    _set(folder, "rig", "../outside")
    assert _reject(folder).key == "rig"
    # A foreign lab's rig with a safe name is accepted and recorded as given.
    _set(folder, "rig", "other-lab.rig_2")
    frame = ingest_one(folder_source(folder))
    assert set(frame["rig"]) == {"other-lab.rig_2"}


@pytest.mark.parametrize(("key", "value", "says"), [
    ("excitation.kind", "zigzag", "'sine_decay'"),
    ("channels.encoder.unit", "furlong", "'mm' or 'deg'"),
    ("channels.camera.quantity", "speed", "'tip_angle_deg' or 'output_mm'"),
    ("channels.camera.source", "radar", "'camera' or 'tracker'"),
    ("channels.encoder.counts_per_unit", 1e-300, "greater than"),
    ("channels.encoder.counts_per_unit", 0, "greater than"),
    ("channels.encoder.input_sign", 5, "1 or -1"),
    ("channels.encoder.output_sign", True, "integer"),
    ("channels.encoder.counter_bits", 64, "less than"),
    ("channels.encoder.counter_bits", "32", "integer"),
    ("channels.loadcell.input.newton_per_mv_per_v", float("nan"), "finite"),
    ("channels.loadcell.output.range_n", -1, "greater than"),
    ("configuration.curve_angle_deg", float("nan"), "finite"),
    ("configuration.curve_angle_deg", True, "number"),
    ("configuration.radius_mm", float("inf"), "finite"),
    ("configuration.radius_mm", -30, "greater than"),
    ("excitation.frequency_hz", -0.5, "greater than"),
])
def test_bad_manifest_values_rejected(tmp_path: Path, key: str, value: Any, says: str) -> None:
    folder = plain_copy(tmp_path)
    _set(folder, key, value)
    err = _reject(folder)
    assert err.key == key
    assert says in str(err)
    assert err.file is not None and err.file.endswith("manifest.json")


def test_null_configuration_is_legal(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    _set(folder, "configuration", {"curve_angle_deg": None, "radius_mm": None})
    assert_sound(ingest_one(folder_source(folder)))


@pytest.mark.parametrize("value", ["1e30", str(2**63), str(2**63 + 5), "-1e19",
                                   str(2**32), "1.5"])
def test_count_cell_out_of_counter_range_rejected(tmp_path: Path, value: str) -> None:
    folder = plain_copy(tmp_path)
    _cell(folder, "encoder", 50, "input_counts", value)
    err = _reject(folder)
    assert err.key == "input_counts" and err.row == 50
    assert err.file is not None and err.file.endswith("encoder.csv")


def test_counter_bits_inconsistent_with_counts(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    _set(folder, "channels.encoder.counter_bits", 8)
    err = _reject(folder)
    assert err.key in ("input_counts", "output_counts") and err.row is not None
    assert "8-bit counter" in str(err)


def test_corrupt_count_inside_the_counter_range_is_a_jump(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    lines = (folder / "encoder.csv").read_text().split("\n")
    count = int(lines[79].split(",")[1])
    _cell(folder, "encoder", 80, "input_counts", str(count + 2**22))  # 419 mm in 10 ms
    err = _reject(folder)
    assert err.key == "input" and err.row == 80
    assert "jumps" in str(err)


def test_decimal_comma_rejected_naming_row_and_column(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    _cell(folder, "loadcell", 7, "input_mv_per_v", "0,5")
    err = _reject(folder)
    assert err.row == 7 and err.key == "input_mv_per_v"
    assert "decimal comma" in str(err)


def test_quoted_comma_in_events_is_accepted(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    (folder / "events.csv").write_text(
        't_ns,event,detail\n0,start,\n1000000000,note,"tension 5 N, slack"\n'
        '2000000000,stop,\n')
    back = read_run_folder(folder)
    assert back.events is not None
    assert list(back.events["detail"]) == ["", "tension 5 N, slack", ""]
    assert_sound(ingest_one(folder_source(folder)))


def test_unquoted_comma_in_events_is_rejected(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    (folder / "events.csv").write_text(
        "t_ns,event,detail\n0,start,\n1000000000,note,a, b\n2000000000,stop,\n")
    err = _reject(folder)
    assert err.row == 3 and "4 fields, expected 3" in str(err)


@pytest.mark.parametrize(("stream", "col", "value"), [
    ("loadcell", "output_mv_per_v", "nan"), ("loadcell", "input_mv_per_v", ""),
    ("loadcell", "input_mv_per_v", "1e9"), ("camera", "confidence", "1.5"),
    ("camera", "confidence", "nan"), ("camera", "frame", "-3"), ("camera", "value", "1e30"),
    ("encoder", "t_ns", "1e30"),
])
def test_bad_cells_rejected_naming_row_and_column(tmp_path: Path, stream: str, col: str,
                                                  value: str) -> None:
    folder = plain_copy(tmp_path)
    _cell(folder, stream, 5, col, value)
    err = _reject(folder)
    assert err.row == 5 and err.key == col, str(err)


def test_boolean_column_rejected(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    lines = (folder / "camera.csv").read_text().rstrip("\n").split("\n")
    rows = [",".join([*line.split(",")[:3], "True"]) for line in lines[1:]]
    (folder / "camera.csv").write_text("\n".join([lines[0], *rows]) + "\n")
    err = _reject(folder)
    assert err.key == "confidence" and err.row == 2


def test_one_row_loadcell_rejected(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    lines = (folder / "loadcell.csv").read_text().split("\n")
    (folder / "loadcell.csv").write_text("\n".join(lines[:2]) + "\n")
    err = _reject(folder)
    assert "at least 2" in str(err) and err.file is not None
    assert err.file.endswith("loadcell.csv")


@pytest.mark.parametrize("stream", ["camera", "loadcell"])
def test_stream_on_another_clock_rejected(tmp_path: Path, stream: str) -> None:
    folder = plain_copy(tmp_path)
    path = folder / f"{stream}.csv"
    lines = path.read_text().rstrip("\n").split("\n")
    shifted = [lines[0]]
    for line in lines[1:]:
        t, rest = line.split(",", 1)
        shifted.append(f"{int(t) + 3600 * 10**9},{rest}")
    path.write_text("\n".join(shifted) + "\n")
    err = _reject(folder)
    assert "do not overlap the encoder" in str(err) and err.file.endswith(f"{stream}.csv")


def test_size_limit_and_gzip_bomb(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    tiny = ReadLimits(max_file_mb=0.01)
    err = _reject(folder, limits=tiny)
    assert "limits.max_file_mb" in str(err)
    # 64 MB of zeros compress to ~64 kB: stopped at the decompression limit, not read whole.
    enc = folder / "encoder.csv"
    bomb = gzip.compress(b"t_ns,input_counts,output_counts\n" + b"0" * (64 << 20), 9)
    enc.unlink()
    (folder / "encoder.csv.gz").write_bytes(bomb)
    err = _reject(folder, limits=ReadLimits(max_decompressed_mb=4))
    assert "limits.max_decompressed_mb" in str(err)


def test_nul_header_error_is_capped(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    (folder / "encoder.csv").write_bytes(b"\0" * (2 << 20) + b"\n0,0,0\n")
    err = _reject(folder)
    assert len(str(err)) < MAX_REASON_CHARS + 300


def test_huge_header_line_error_is_capped(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    (folder / "camera.csv").write_text("x" * (3 << 20) + "\n1,2,3,4\n")
    err = _reject(folder)
    assert len(str(err)) < MAX_REASON_CHARS + 300 and err.row == 1


def _with_timeout(fn: Any, seconds: float = 10.0) -> Any:
    result: dict[str, Any] = {}

    def target() -> None:
        try:
            result["value"] = fn()
        except BaseException as err:  # handed to the test thread
            result["error"] = err

    th = threading.Thread(target=target, daemon=True)
    th.start()
    th.join(seconds)
    assert not th.is_alive(), "reader hung"
    if "error" in result:
        raise result["error"]
    return result.get("value")


def test_fifo_is_refused_without_hanging(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path / "src")
    (folder / "events.csv").unlink()
    os.mkfifo(folder / "events.csv")
    sources = _with_timeout(lambda: discover(tmp_path / "src"))
    assert len(sources) == 1
    _with_timeout(lambda: hash_files(sources[0].files, root=tmp_path / "src"))
    with pytest.raises(RigIOError, match="FIFO"):
        _with_timeout(lambda: ingest_one(sources[0]))


@pytest.mark.parametrize("target", ["/dev/zero", "outside"])
def test_symlink_out_of_the_run_folder_refused(tmp_path: Path, target: str) -> None:
    folder = plain_copy(tmp_path / "src")
    outside = tmp_path / "outside.csv"
    outside.write_text((folder / "events.csv").read_text())
    (folder / "events.csv").unlink()
    (folder / "events.csv").symlink_to(outside if target == "outside" else Path(target))
    with pytest.raises(RigIOError, match="outside the run folder") as info:
        _with_timeout(lambda: ingest_one(folder_source(folder)))
    assert_names_where(info.value, whole_file_ok=("symlink",))


def test_symlink_inside_the_run_folder_is_followed(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    (folder / "events.csv").rename(folder / "events_real.txt")
    (folder / "events.csv").symlink_to("events_real.txt")
    assert_sound(ingest_one(folder_source(folder)))


def test_device_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RigIOError, match="character device"):
        _with_timeout(lambda: read_stream_csv(Path("/dev/zero"), "events", run="x",
                                              base=Path("/dev")))


def test_symlink_loop_in_source_terminates(tmp_path: Path) -> None:
    plain_copy(tmp_path / "src" / "a")
    (tmp_path / "src" / "a" / "loop").symlink_to(tmp_path / "src")
    sources = _with_timeout(lambda: discover(tmp_path / "src"))
    assert [s.path.name for s in sources] == ["run_0001"]


@pytest.mark.parametrize("cut", [0, 13, 4096, 100_000, -1])
def test_truncated_bag_names_the_file(tmp_path: Path, cut: int) -> None:
    data = SAMPLE_BAG.read_bytes()
    bag = tmp_path / "cut.bag"
    bag.write_bytes(data[:cut] if cut >= 0 else data[:-7])
    with pytest.raises(RigIOError) as info:
        read_bag(bag)
    assert info.value.file == str(bag)
    assert len(info.value.reason) <= MAX_REASON_CHARS + 40


def test_bag_size_limit(tmp_path: Path) -> None:
    with pytest.raises(RigIOError, match="limits.max_bag_mb"):
        read_bag(SAMPLE_BAG, limits=ReadLimits(max_bag_mb=0.1))
    phys = read_bag(SAMPLE_BAG)
    assert np.isfinite(phys.encoder["input"].to_numpy()).all()


def test_limits_from_config() -> None:
    assert ReadLimits.from_mapping({"max_file_mb": 5}).max_file_mb == 5
    with pytest.raises(RigIOError, match="unknown limits key"):
        ReadLimits.from_mapping({"max_files": 5})
    with pytest.raises(RigIOError, match="positive"):
        ReadLimits.from_mapping({"max_bag_mb": -1})


def test_ingest_batch_with_hostile_runs_writes_nothing_outside(tmp_path: Path) -> None:
    from pipelines.ingest import run_ingest

    src = tmp_path / "src"
    good = plain_copy(src, "good")
    escape = plain_copy(src, "escape")
    _set(escape, "run_id", "../../escaped")
    fifo = plain_copy(src, "fifo")
    (fifo / "events.csv").unlink()
    os.mkfifo(fifo / "events.csv")
    _set(fifo, "run_id", "fifo_run")
    _set(good, "run_id", "good_run")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    report = _with_timeout(lambda: run_ingest(src, tmp_path / "out", progress=False), 60)
    assert report["n_accepted"] == 1 and report["n_rejected"] == 2
    reasons = " | ".join(r["reason"] for r in report["rejected"])
    assert "key run_id" in reasons and "FIFO" in reasons
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")
                   if not p.is_relative_to(tmp_path / "out"))
    assert after == [p for p in before if p != Path("out")]
    assert [p.name for p in (tmp_path / "out" / "samples").iterdir()] == ["good_run.parquet"]


def test_bag_with_repeated_load_stamps_is_rejected_before_merging(tmp_path: Path) -> None:
    from dataclasses import replace

    from rig_io.bag import write_bag
    from rig_io.synthetic import make_raw_run

    run = make_raw_run("rep_0001", duration_s=2.0, with_camera=False)
    assert run.loadcell is not None
    lc = run.loadcell.copy()
    lc["t_ns"] = 0  # every message at one stamp: an outer merge would square the rows
    bag = write_bag(replace(run, loadcell=lc), tmp_path / "rep.bag")
    with pytest.raises(RigIOError, match="repeats") as info:
        read_bag(bag)
    assert info.value.file is not None and info.value.file.startswith(str(bag))
    assert info.value.t_ns == 0


@pytest.mark.parametrize(("override", "key"), [
    ({"run_id": "../{stem}"}, "run_id"), ({"rig": "a/b"}, "rig"),
    ({"excitation": {"kind": "zigzag"}}, "excitation.kind"),
])
def test_importer_manifests_meet_the_schema(tmp_path: Path, override: dict[str, Any],
                                            key: str) -> None:
    from rig_io.importer import load_mapping
    from rig_io.sources import Source, load

    mapping = load_mapping(Path(__file__).resolve().parents[2] / "conf" / "importer"
                           / "tendon_catheter.yaml")
    log = tmp_path / "data_1_1.txt"
    log.write_text("Time,Tendon Disp.,Motor Curr.,Pos x,Pos y,Pos z,Angle x,Angle y,Angle z\n"
                   + "".join(f"{i * 0.002:.6f},{np.sin(i / 50):.5f},60,0,0,0,"
                             f"{30 + 10 * np.sin(i / 50):.4f},0,0\n" for i in range(200)))
    src = Source("import", log, (log,))
    assert load(src, mapping=mapping).run_id == "catheter_data_1_1"
    mapping = {**mapping, **override, "files": []}
    with pytest.raises(RigIOError) as info:
        load(src, mapping=mapping)
    assert info.value.key == key and info.value.file == str(log)


def test_deeply_nested_manifest_rejected(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path)
    deep: dict[str, Any] = {}
    cur = deep
    for _ in range(60):
        cur["x"] = {}
        cur = cur["x"]
    _set(folder, "notes_extra", deep)
    assert "nested more than 50" in str(_reject(folder))
    (folder / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    assert "manifest" in str(_reject(folder))


def test_a_single_run_as_source_is_refused(tmp_path: Path) -> None:
    folder = plain_copy(tmp_path / "src")
    with pytest.raises(RigIOError, match="source is itself a run"):
        discover(folder)
    with pytest.raises(RigIOError, match="single bag file"):
        discover(SAMPLE_BAG)
    assert [s.path for s in discover(tmp_path / "src")] == [folder]
