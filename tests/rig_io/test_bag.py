"""ROS bags: round trip against the calibrated run folder, and the bag bad-input cases."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from rig_io.bag import read_bag, sidecar_manifest, write_bag
from rig_io.calibrate import calibrate_raw_run
from rig_io.errors import RigIOError
from rig_io.synthetic import make_raw_run

STORAGES = ["rosbag1", "sqlite3", "mcap"]


def _name(storage: str) -> str:
    return "run.bag" if storage == "rosbag1" else f"run_{storage}"


@pytest.mark.parametrize("storage", STORAGES)
def test_round_trip_matches_calibrated_folder(tmp_path: Path, storage: str) -> None:
    run = make_raw_run("bag_0001", duration_s=2.0, with_tracker=True, counts_start=2**31 - 300)
    path = write_bag(run, tmp_path / _name(storage), storage=storage)  # type: ignore[arg-type]
    assert path.exists()
    if storage != "rosbag1":
        suffix = ".db3" if storage == "sqlite3" else ".mcap"
        assert (path / "metadata.yaml").exists() and (path / f"{path.name}{suffix}").exists()
    back = read_bag(path)
    ref = calibrate_raw_run(run)
    assert back.manifest == run.manifest
    for stream, cols in (("encoder", ["t_ns", "input", "output"]),
                         ("loadcell", ["t_ns", "tension_in_n", "tension_out_n"]),
                         ("camera", ["t_ns", "value", "confidence"]),
                         ("tracker", ["t_ns", "value", "confidence"])):
        a = getattr(ref, stream)[cols].to_numpy(dtype=float)
        b = getattr(back, stream)[cols].to_numpy(dtype=float)
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12, err_msg=stream)
    assert list(back.events["event"]) == ["start", "stop"]
    assert list(back.events["detail"]) == ["", "done"]
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporaries left


@pytest.mark.parametrize("storage", ["rosbag1", "mcap"])
def test_bending_joint_has_input_only(tmp_path: Path, storage: str) -> None:
    run = make_raw_run("bj_0001", duration_s=1.0, with_output_encoder=False, with_tracker=True,
                       quantity="tip_angle_deg", unit="deg")
    back = read_bag(write_bag(run, tmp_path / _name(storage), storage=storage))  # type: ignore[arg-type]
    assert back.encoder["output"].isna().all()
    np.testing.assert_allclose(back.tracker["value"], run.tracker["value"], rtol=1e-12)


def _truncate(path: Path) -> None:
    files = [path] if path.is_file() else [p for p in path.iterdir() if p.suffix != ".yaml"]
    for f in files:
        data = f.read_bytes()
        f.write_bytes(data[: len(data) // 2])


def _corrupt(path: Path) -> None:
    files = [path] if path.is_file() else [p for p in path.iterdir() if p.suffix != ".yaml"]
    for f in files:
        data = bytearray(f.read_bytes())
        rng = np.random.default_rng(1)
        for i in rng.integers(0, len(data), 400):
            data[i] ^= 0xFF
        data[:16] = b"\x00" * 16
        f.write_bytes(bytes(data))


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("damage", [_truncate, _corrupt], ids=["truncated", "corrupt"])
def test_damaged_bag_is_a_clear_error(tmp_path: Path, storage: str, damage: object) -> None:
    run = make_raw_run("dmg_0001", duration_s=1.0)
    path = write_bag(run, tmp_path / _name(storage), storage=storage)  # type: ignore[arg-type]
    damage(path)  # type: ignore[operator]
    with pytest.raises(RigIOError, match="truncated or corrupt bag") as err:
        read_bag(path)
    assert str(path) in str(err.value)


def _ros2_bag(path: Path, topics: dict[str, list[tuple[int, object, str]]]) -> Path:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for topic, msgs in topics.items():
            conn = w.add_connection(topic, msgs[0][2], typestore=ts)
            for t, msg, typ in msgs:
                w.write(conn, t, ts.serialize_cdr(msg, typ))
    return path


def _manifest_msg(run_id: str) -> tuple[int, object, str]:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    man = make_raw_run(run_id, duration_s=0.1).manifest
    return (0, ts.types["std_msgs/msg/String"](data=json.dumps(man)), "std_msgs/msg/String")


def test_missing_required_topic(tmp_path: Path) -> None:
    path = _ros2_bag(tmp_path / "nojoints", {"/rig/manifest": [_manifest_msg("nj_0001")]})
    with pytest.raises(RigIOError, match=r"run 'nj_0001'.*required topic /rig/joints is missing"):
        read_bag(path)


def test_manifest_from_sidecar_or_error(tmp_path: Path) -> None:
    run = make_raw_run("side_0001", duration_s=1.0)
    path = write_bag(run, tmp_path / "side.bag", storage="rosbag1")
    # Rebuild the bag without the manifest topic by filtering through rosbags' reader.
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer as Writer1
    ts = get_typestore(Stores.ROS1_NOETIC)
    stripped = tmp_path / "stripped.bag"
    with AnyReader([path]) as r, Writer1(stripped) as w:
        conns = {}
        for c, t, raw in r.messages():
            if c.topic == "/rig/manifest":
                continue
            if c.topic not in conns:
                conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=ts)
            w.write(conns[c.topic], t, raw)
    with pytest.raises(RigIOError, match=r"/rig/manifest is missing.*stripped.bag.manifest.json"):
        read_bag(stripped)
    sidecar_manifest(stripped).write_text(json.dumps(run.manifest))
    back = read_bag(stripped)
    assert back.run_id == "side_0001" and len(back.encoder) == 100


def test_bag_value_checks(tmp_path: Path) -> None:
    run = make_raw_run("est_0001", duration_s=1.0)
    run.events.loc[1, "event"] = "estop"  # type: ignore[union-attr]
    path = write_bag(run, tmp_path / "e.bag", storage="rosbag1")
    with pytest.raises(RigIOError, match=r"est_0001.*e.bag.*t=990000000 ns.*emergency stop"):
        read_bag(path)


@pytest.mark.parametrize("storage", STORAGES)
def test_bulk_decoding_equals_message_by_message(tmp_path: Path, storage: str,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import rig_io.bag as bag

    run = make_raw_run("bulk_0001", duration_s=2.0, with_tracker=True)
    path = write_bag(run, tmp_path / _name(storage), storage=storage)  # type: ignore[arg-type]
    calls = []
    real = bag._layout

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        out = real(*args, **kwargs)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(bag, "_layout", spy)
    fast = read_bag(path)
    assert calls and all(calls)  # joints, both load cells, camera, tracker took the bulk path
    monkeypatch.setattr(bag, "_layout", lambda *a, **k: None)
    slow = read_bag(path)
    for stream in ("encoder", "loadcell", "camera", "tracker", "events"):
        pd.testing.assert_frame_equal(getattr(fast, stream), getattr(slow, stream),
                                      check_exact=True, obj=stream)


def test_joint_names_that_vary_fall_back_to_per_message(tmp_path: Path) -> None:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    msgs = []
    for i, names in enumerate([["input", "output"], ["input", "outpux"], ["input", "output"]]):
        stamp = T["builtin_interfaces/msg/Time"](sec=i, nanosec=0)
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id="rig")
        msg = T["sensor_msgs/msg/JointState"](header=header, name=names,
                                              position=np.array([0.001 * i, 0.002 * i]),
                                              velocity=np.zeros(0), effort=np.zeros(0))
        msgs.append((i * 1_000_000_000, msg, "sensor_msgs/msg/JointState"))
    path = _ros2_bag(tmp_path / "vary", {"/rig/manifest": [_manifest_msg("vary_0001")],
                                         "/rig/joints": msgs})
    back = read_bag(path, check=False)
    np.testing.assert_allclose(back.encoder["input"], [0.0, 1.0, 2.0])
    assert np.isnan(back.encoder["output"].iloc[1]) and back.encoder["output"].iloc[2] == 4.0


@pytest.mark.parametrize("storage", ["rosbag1", "sqlite3"])
def test_bulk_serialisation_equals_message_by_message(tmp_path: Path, storage: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import rig_io.bag as bag

    run = make_raw_run("ser_0001", duration_s=2.0, with_tracker=True, counts_start=2**31 - 99)
    ros1 = storage == "rosbag1"
    fast = [(t, topic, data) for topic, _, t, data in bag._messages(calibrate_raw_run(run), ros1)]
    first = {topic: data for _, topic, data in reversed(fast)}
    assert bag._layout(bag.MSG_WRENCH, first["/rig/load/input"], cdr=not ros1) is not None
    for topic in ("/rig/joints", "/rig/camera/value", "/rig/tracker/value"):
        assert bag._layout(bag.MSG_JOINTS, first[topic], cdr=not ros1) is not None
    monkeypatch.setattr(bag, "_layout", lambda *a, **k: None)
    slow = [(t, topic, data) for topic, _, t, data in bag._messages(calibrate_raw_run(run), ros1)]
    assert len(fast) == len(slow) > 1000
    assert fast == slow  # byte for byte


def test_compressed_rosbag1_chunks_are_read_within_the_decompression_limit(
        tmp_path: Path) -> None:
    from rig_io.limits import ReadLimits

    run = make_raw_run("lz4_0001", duration_s=5.0)
    path = write_bag(run, tmp_path / "run.bag", compress=True)
    np.testing.assert_allclose(read_bag(path).encoder["input"],
                               read_bag(write_bag(run, tmp_path / "plain.bag")).encoder["input"])
    with pytest.raises(RigIOError, match="max_decompressed_mb") as err:
        read_bag(path, limits=ReadLimits(max_decompressed_mb=0.01))
    assert err.value.file == str(path)


def test_a_bz2_bomb_chunk_is_refused_not_decompressed(tmp_path: Path) -> None:
    # 64 MB of zeros in one chunk compress to a few dozen bytes of bz2; rosbags alone would
    # inflate it whole. The default limit (40 MB) stops it.
    from rosbags.rosbag1 import Writer as Writer1

    store = get_typestore(Stores.ROS1_NOETIC)
    string = store.types["std_msgs/msg/String"]
    path = tmp_path / "bomb.bag"
    writer = Writer1(path)
    writer.set_compression(Writer1.CompressionFormat.BZ2)
    with writer:
        conn = writer.add_connection("/rig/manifest", "std_msgs/msg/String", typestore=store)
        writer.write(conn, 1, store.serialize_ros1(string(data="\0" * (64 << 20)),
                                                   "std_msgs/msg/String"))
    assert path.stat().st_size < 1 << 20
    with pytest.raises(RigIOError, match="decompresses to more than 40 MB"):
        read_bag(path)
