"""Importer mappings: the real catheter data (read in place) and foreign-log bad input."""

from __future__ import annotations

import gzip
import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from pipelines.ingest import run_ingest
from rig_io.dataset import read_dataset, read_runs
from rig_io.errors import RigIOError
from rig_io.importer import find_files, import_file, load_mapping, manifest_for
from rig_io.limits import ReadLimits

REPO = Path(__file__).resolve().parents[2]
MAPPING = REPO / "conf" / "importer" / "tendon_catheter.yaml"


def _hashes(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_catheter_mapping_records_excitations(catheter_dir: Path) -> None:
    m = load_mapping(MAPPING)
    files = find_files(m, catheter_dir)
    assert [f.name for f in files] == [f"data_{a}_{k}.txt" for a in (1, 2) for k in range(1, 6)]
    one = manifest_for(m, catheter_dir / "data_1_3.txt")
    two = manifest_for(m, catheter_dir / "data_2_5.txt")
    assert one["run_id"] == "catheter_data_1_3" and one["rig"] == "bending-joint"
    assert one["excitation"]["kind"] == "sine_decay_offset"
    assert one["excitation"]["role"] == "identification"
    assert one["excitation"]["frequency_hz"] == pytest.approx(0.3)
    assert two["excitation"]["kind"] == "sine_decay" and two["excitation"]["role"] == "held_out"
    assert two["excitation"]["frequency_hz"] == pytest.approx(0.5)
    assert one["configuration"] == {"curve_angle_deg": None, "radius_mm": None}


def test_all_ten_catheter_runs_ingest(tmp_path: Path, catheter_dir: Path) -> None:
    before = _hashes(catheter_dir)
    report = run_ingest(catheter_dir, tmp_path / "out", mapping=load_mapping(MAPPING),
                        progress=False)
    assert _hashes(catheter_dir) == before  # read in place, never written
    assert report["n_rejected"] == 0, report["rejected"]
    assert report["n_accepted"] == 10
    df = read_dataset(tmp_path / "out")
    assert df["run_id"].nunique() == 10
    runs = read_runs(tmp_path / "out")
    first = df[df.run_id == "catheter_data_1_1"]
    assert len(first) == 34061  # every logged sample, on the log's own time base
    assert first["t_s"].iloc[-1] == pytest.approx(70.0, abs=0.5)
    # Output: Angle x from the tracker, about 30 -> 93 deg, kept as measured (an absolute
    # angle: a run that starts bent must not be shifted against the others).
    assert runs["catheter_data_1_1"]["output_source"] == "tracker"
    assert runs["catheter_data_1_1"]["output_offset"] == 0.0
    assert runs["catheter_data_1_1"]["units"] == {"input": "mm", "output": "deg",
                                                  "camera": None, "tracker": "deg",
                                                  "tension": "N"}
    assert 85 < first["output"].max() < 100 and first["output"].iloc[0] == pytest.approx(30.0)
    np.testing.assert_allclose(first["tracker"], first["output"])
    assert first["input"].max() == pytest.approx(5.766304)
    assert first["input_norm"].max() == pytest.approx(1.0)
    assert first["tension_proxy"].notna().all() and first["tension_in_n"].isna().all()
    kinds = df.groupby("run_id")["excitation"].first()
    assert (kinds[kinds.index.str.contains("data_1_")] == "sine_decay_offset").all()
    assert (kinds[kinds.index.str.contains("data_2_")] == "sine_decay").all()
    # Incremental: nothing is processed again.
    again = run_ingest(catheter_dir, tmp_path / "out", mapping=load_mapping(MAPPING),
                       progress=False)
    assert again["n_processed"] == 0 and again["n_accepted"] == 10


def _foreign(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "data_1_1.txt"
    p.write_text(text)
    return p


HEADER = "Time,Tendon Disp.,Motor Curr.,Pos x,Pos y,Pos z,Angle x,Angle y,Angle z\n"


def _rows(n: int) -> str:
    return "".join(f"{i * 0.002:.6f},{np.sin(i / 50):.5f},60,0,0,0,"
                   f"{30 + 10 * np.sin(i / 50):.4f},0,0\n" for i in range(n))


def test_foreign_log_bad_input(tmp_path: Path) -> None:
    m = load_mapping(MAPPING)
    ok = import_file(m, _foreign(tmp_path, HEADER + _rows(200)))
    assert len(ok.encoder) == 200 and ok.tracker is not None
    with pytest.raises(RigIOError, match=r"catheter_data_1_1.*row 1.*missing column.*Angle x"):
        import_file(m, _foreign(tmp_path, HEADER.replace("Angle x", "Angle q") + _rows(5)))
    rows = _rows(50).splitlines(keepends=True)
    rows[20] = rows[20].replace(",60,", ",sixty,")
    with pytest.raises(RigIOError, match=r"row 22.*'sixty'.*Motor Curr"):
        import_file(m, _foreign(tmp_path, HEADER + "".join(rows)))
    rows = _rows(50).splitlines(keepends=True)
    rows[30], rows[31] = rows[31], rows[30]
    with pytest.raises(RigIOError, match=r"row 33.*goes backwards"):
        import_file(m, _foreign(tmp_path, HEADER + "".join(rows)))
    rows = _rows(100).splitlines(keepends=True)
    with pytest.raises(RigIOError, match=r"gap of .* longer than 20 sample periods"):
        import_file(m, _foreign(tmp_path, HEADER + "".join(rows[:40] + rows[70:])))
    with pytest.raises(RigIOError, match="no data rows|unreadable"):
        import_file(m, _foreign(tmp_path, HEADER))


def test_foreign_logs_are_read_within_the_limits(tmp_path: Path) -> None:
    m = load_mapping(MAPPING)
    plain = _foreign(tmp_path, HEADER + _rows(200))
    packed = tmp_path / "data_1_1.txt.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    a, b = import_file(m, plain), import_file(m, packed)
    assert b.manifest["run_id"] == a.manifest["run_id"] == "catheter_data_1_1"
    np.testing.assert_array_equal(a.encoder.to_numpy(), b.encoder.to_numpy())
    tiny = ReadLimits(max_file_mb=0.001, max_decompressed_mb=0.001)
    with pytest.raises(RigIOError, match=r"beyond the limit of 0.001 MB \(limits.max_file_mb\)"):
        import_file(m, plain, limits=tiny)
    # a gzip bomb: 80 MB of one repeated row in a few hundred kB, stopped at the default limit
    bomb = tmp_path / "data_1_2.txt.gz"
    bomb.write_bytes(gzip.compress((HEADER + _rows(1) * (2 << 20)).encode(), 9))
    with pytest.raises(RigIOError, match=r"decompresses to more than 40 MB"):
        import_file(m, bomb)
    fifo = tmp_path / "data_1_3.txt"
    os.mkfifo(fifo)
    with pytest.raises(RigIOError, match="not a regular file|special"):
        import_file(m, fifo)


def test_mapping_errors(tmp_path: Path) -> None:
    bad = tmp_path / "m.yaml"
    bad.write_text("name: x\npattern: '*.txt'\nrig: r\ntime: {column: T, unit: fortnights}\n"
                   "input: {column: a}\noutput: {column: b}\n")
    with pytest.raises(RigIOError, match="unknown time unit 'fortnights'"):
        load_mapping(bad)
    bad.write_text("name: x\npattern: '*.txt'\n")
    with pytest.raises(RigIOError, match="lacks rig, time, input, output"):
        load_mapping(bad)
