"""ROS bags of the ``tsm-rig-log/1`` format (rig-log-format.md section 2), via ``rosbags``.

:func:`write_bag` turns a :class:`RawRun` into a rosbag1 ``.bag`` file or a rosbag2 folder
(``sqlite3`` or ``mcap`` storage) with the format's topics and SI units; :func:`read_bag`
reads any of them through ``rosbags.highlevel.AnyReader`` and gives back a
:class:`~rig_io.calibrate.PhysicalRun` in the manifest's units, so a bag and a run folder of
the same run reach ingest as the same thing.

Beyond the format's table, the writer puts a tracker stream on ``/rig/tracker/value`` (same
message layout as ``/rig/camera/value``); readers of the format ignore unknown topics.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from functools import cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from rig_io import checks
from rig_io.calibrate import (
    PhysicalRun,
    calibrate_raw_run,
    encoder_unit,
    si_factor,
    vision_unit,
)
from rig_io.errors import RigIOError
from rig_io.manifest import check_manifest, parse_manifest
from rig_io.run import EVENT_KINDS, RawRun

Storage = Literal["rosbag1", "sqlite3", "mcap"]

T_MANIFEST = "/rig/manifest"
T_JOINTS = "/rig/joints"
T_LOAD_IN = "/rig/load/input"
T_LOAD_OUT = "/rig/load/output"
T_CAMERA = "/rig/camera/value"
T_TRACKER = "/rig/tracker/value"  # extension: same layout as the camera topic
T_EVENTS = "/rig/events"
REQUIRED_TOPICS = (T_JOINTS,)

MSG_STRING = "std_msgs/msg/String"
MSG_JOINTS = "sensor_msgs/msg/JointState"
MSG_WRENCH = "geometry_msgs/msg/WrenchStamped"


@cache
def _store(ros1: bool) -> Typestore:
    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


# ----------------------------------------------------------------------------------- writing

def write_bag(run: RawRun, path: str | os.PathLike[str], *, storage: Storage = "rosbag1",
              compress: bool = False) -> Path:
    """Write ``run`` as a bag at ``path`` (a ``.bag`` file for rosbag1, else a folder).

    Positions go out in metres or radians, tensions in newtons, the manifest as JSON on
    ``/rig/manifest``. The bag is built under a temporary name and renamed into place.
    """
    target = Path(path)
    if storage not in ("rosbag1", "sqlite3", "mcap"):
        raise RigIOError(f"unknown bag storage {storage!r}", run=run.run_id, file=str(target))
    phys = calibrate_raw_run(run)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        inner = tmpdir / target.name
        if storage == "rosbag1":
            _write_ros1(phys, inner, compress=compress)
        else:
            plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
            _write_ros2(phys, inner, plugin=plugin)
        if target.is_dir():
            old = target.with_name(f".{target.name}.old")
            if old.exists():
                shutil.rmtree(old)
            os.replace(target, old)
            os.replace(inner, target)
            shutil.rmtree(old)
        else:
            os.replace(inner, target)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return target


def _messages(phys: PhysicalRun, ros1: bool) -> list[tuple[str, str, int, Any]]:
    """(topic, msgtype, t_ns, message) for the whole run, in SI units."""
    ts = _store(ros1)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    String, JointState = T[MSG_STRING], T[MSG_JOINTS]
    Wrench, WrenchStamped, Vector3 = (T["geometry_msgs/msg/Wrench"], T[MSG_WRENCH],
                                      T["geometry_msgs/msg/Vector3"])
    empty = np.zeros(0, dtype=np.float64)
    seq = [0]

    def header(t: int) -> Any:
        stamp = Time(sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        seq[0] += 1
        if ros1:
            return Header(seq=seq[0], stamp=stamp, frame_id="rig")
        return Header(stamp=stamp, frame_id="rig")

    m = phys.manifest
    msgs: list[tuple[str, str, int, Any]] = []
    t0 = int(phys.encoder["t_ns"].iloc[0])
    msgs.append((T_MANIFEST, MSG_STRING, t0, String(data=json.dumps(m))))
    k = si_factor(encoder_unit(m), run=phys.run_id)
    t = phys.encoder["t_ns"].to_numpy(dtype=np.int64)
    inp = phys.encoder["input"].to_numpy(dtype=float) * k
    out = phys.encoder["output"].to_numpy(dtype=float) * k
    has_out = bool(np.isfinite(out).any())
    names = ["input", "output"] if has_out else ["input"]
    for i in range(t.size):
        pos = np.array([inp[i], out[i]] if has_out else [inp[i]], dtype=np.float64)
        msgs.append((T_JOINTS, MSG_JOINTS, int(t[i]),
                     JointState(header=header(int(t[i])), name=names, position=pos,
                                velocity=empty, effort=empty)))
    if phys.loadcell is not None:
        tl = phys.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for topic, col in ((T_LOAD_IN, "tension_in_n"), (T_LOAD_OUT, "tension_out_n")):
            f = phys.loadcell[col].to_numpy(dtype=float)
            zero = Vector3(x=0.0, y=0.0, z=0.0)
            for i in range(tl.size):
                w = Wrench(force=Vector3(x=float(f[i]), y=0.0, z=0.0), torque=zero)
                msgs.append((topic, MSG_WRENCH, int(tl[i]),
                             WrenchStamped(header=header(int(tl[i])), wrench=w)))
    for topic, stream in ((T_CAMERA, "camera"), (T_TRACKER, "tracker")):
        frame = getattr(phys, stream)
        if frame is None:
            continue
        unit = vision_unit(m, stream)
        kv = si_factor(unit, run=phys.run_id)
        name = "tip_angle" if unit == "deg" else "output"
        tv = frame["t_ns"].to_numpy(dtype=np.int64)
        val = frame["value"].to_numpy(dtype=float) * kv
        conf = frame["confidence"].to_numpy(dtype=float)
        for i in range(tv.size):
            msgs.append((topic, MSG_JOINTS, int(tv[i]),
                         JointState(header=header(int(tv[i])), name=[name],
                                    position=np.array([val[i]]), velocity=empty,
                                    effort=np.array([conf[i]]))))
    if phys.events is not None:
        for te, ev, detail in zip(phys.events["t_ns"], phys.events["event"],
                                  phys.events["detail"], strict=True):
            text = f"{ev}:{detail}" if isinstance(detail, str) and detail else str(ev)
            msgs.append((T_EVENTS, MSG_STRING, int(te), String(data=text)))
    msgs.sort(key=lambda x: x[2])  # stable: the manifest stays first
    return msgs


def _write_ros1(phys: PhysicalRun, path: Path, *, compress: bool) -> None:
    ts = _store(True)
    writer = Writer1(path)
    if compress:
        writer.set_compression(Writer1.CompressionFormat.LZ4)
    with writer:
        conns: dict[str, Any] = {}
        for topic, typ, t, msg in _messages(phys, ros1=True):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
            writer.write(conns[topic], t, ts.serialize_ros1(msg, typ))


def _write_ros2(phys: PhysicalRun, path: Path, *, plugin: StoragePlugin) -> None:
    ts = _store(False)
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        conns: dict[str, Any] = {}
        for topic, typ, t, msg in _messages(phys, ros1=False):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
            writer.write(conns[topic], t, ts.serialize_cdr(msg, typ))


# ----------------------------------------------------------------------------------- reading

def is_bag(path: str | os.PathLike[str]) -> bool:
    """A rosbag1 file (``.bag``) or a rosbag2 folder (with ``metadata.yaml``)."""
    p = Path(path)
    return (p.is_file() and p.suffix == ".bag") or (p.is_dir() and (p / "metadata.yaml").exists())


def sidecar_manifest(path: str | os.PathLike[str]) -> Path:
    """Where a bag's manifest lives when the bag has no ``/rig/manifest``."""
    p = Path(path)
    return p.with_name(f"{p.name}.manifest.json")


def read_bag(path: str | os.PathLike[str], *, check: bool = True) -> PhysicalRun:
    """Read a bag into a :class:`PhysicalRun` in the manifest's units.

    Raises :class:`RigIOError` for a truncated or corrupt bag, a missing required topic, a
    missing manifest (neither ``/rig/manifest`` nor ``<bag>.manifest.json``) and, with
    ``check``, the value checks (timestamps, gaps, saturation, e-stop, camera confidence).
    """
    p = Path(path)
    file = str(p)
    hint = p.name.removesuffix(".bag")
    if not p.exists():
        raise RigIOError("bag does not exist", run=hint, file=file)
    streams: dict[str, list[tuple[int, Any]]] = {}
    last_t: int | None = None
    try:
        with AnyReader([p], default_typestore=_store(p.suffix == ".bag")) as reader:
            topics = set(reader.topics)
            wanted = [c for c in reader.connections
                      if c.topic in (T_MANIFEST, T_JOINTS, T_LOAD_IN, T_LOAD_OUT, T_CAMERA,
                                     T_TRACKER, T_EVENTS)]
            for conn, t, raw in reader.messages(connections=wanted):
                msg = reader.deserialize(raw, conn.msgtype)
                streams.setdefault(conn.topic, []).append((int(t), msg))
                last_t = int(t)
    except RigIOError:
        raise
    except Exception as err:  # rosbags raises many types for damaged storage
        where = f" after the message at t={last_t} ns" if last_t is not None else ""
        raise RigIOError(f"truncated or corrupt bag{where}: {type(err).__name__}: {err}",
                         run=hint, file=file, t_ns=last_t) from None

    manifest = _bag_manifest(streams, p, hint)
    run_id = str(manifest["run_id"])
    present = [s for s, t in (("camera", T_CAMERA), ("tracker", T_TRACKER)) if t in topics]
    check_manifest(manifest, file=file, streams=present, si_units=True, run_hint=hint)
    for topic in REQUIRED_TOPICS:
        if not streams.get(topic):
            raise RigIOError(f"required topic {topic} is missing or empty "
                             f"(topics: {', '.join(sorted(topics)) or 'none'})",
                             run=run_id, file=file)
    phys = PhysicalRun(manifest=manifest, encoder=_joints(streams[T_JOINTS], manifest,
                                                          run_id, file),
                       files={s: file for s in ("encoder", "loadcell", "camera", "tracker",
                                                "events")})
    if T_LOAD_IN in streams or T_LOAD_OUT in streams:
        phys.loadcell = _loads(streams.get(T_LOAD_IN, []), streams.get(T_LOAD_OUT, []))
    for stream, topic in (("camera", T_CAMERA), ("tracker", T_TRACKER)):
        if topic in streams:
            setattr(phys, stream, _vision(streams[topic], manifest, stream, run_id, file))
    if T_EVENTS in streams:
        phys.events = _events(streams[T_EVENTS], run_id, file)
    if check:
        checks.check_physical_run(phys, rows=False)
    return phys


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _bag_manifest(streams: dict[str, list[tuple[int, Any]]], p: Path,
                  hint: str) -> dict[str, Any]:
    msgs = streams.get(T_MANIFEST, [])
    if msgs:
        return parse_manifest(str(msgs[0][1].data), run=hint, file=f"{p}:{T_MANIFEST}")
    side = sidecar_manifest(p)
    if not side.is_file():
        raise RigIOError(f"required topic {T_MANIFEST} is missing and there is no "
                         f"{side.name} beside the bag", run=hint, file=str(p))
    try:
        text = side.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise RigIOError(f"unreadable manifest: {err}", run=hint, file=str(side)) from None
    return parse_manifest(text, run=hint, file=str(side))


def _joints(msgs: list[tuple[int, Any]], manifest: dict[str, Any], run: str,
            file: str) -> pd.DataFrame:
    k = si_factor(encoder_unit(manifest), run=run, file=file)
    n = len(msgs)
    t = np.empty(n, dtype=np.int64)
    inp = np.empty(n)
    out = np.full(n, np.nan)
    for i, (_, msg) in enumerate(msgs):
        t[i] = _stamp(msg)
        names = list(msg.name)
        try:
            inp[i] = msg.position[names.index("input")]
        except (ValueError, IndexError):
            raise RigIOError(f"{T_JOINTS} message has no 'input' position (names {names})",
                             run=run, file=file, t_ns=int(t[i])) from None
        if "output" in names:
            j = names.index("output")
            if j < len(msg.position):
                out[i] = msg.position[j]
    return pd.DataFrame({"t_ns": t, "input": inp / k, "output": out / k})


def _loads(msgs_in: list[tuple[int, Any]], msgs_out: list[tuple[int, Any]]) -> pd.DataFrame:
    def frame(msgs: list[tuple[int, Any]], col: str) -> pd.DataFrame:
        return pd.DataFrame({"t_ns": np.array([_stamp(m) for _, m in msgs], dtype=np.int64),
                             col: np.array([m.wrench.force.x for _, m in msgs], dtype=float)})

    a, b = frame(msgs_in, "tension_in_n"), frame(msgs_out, "tension_out_n")
    if len(a) == len(b) and np.array_equal(a["t_ns"].to_numpy(), b["t_ns"].to_numpy()):
        a["tension_out_n"] = b["tension_out_n"].to_numpy()
        return a
    merged = a.merge(b, on="t_ns", how="outer").sort_values("t_ns", kind="stable")
    return merged.reset_index(drop=True)


def _vision(msgs: list[tuple[int, Any]], manifest: dict[str, Any], stream: str, run: str,
            file: str) -> pd.DataFrame:
    k = si_factor(vision_unit(manifest, stream), run=run, file=file)
    n = len(msgs)
    t = np.empty(n, dtype=np.int64)
    val = np.full(n, np.nan)
    conf = np.zeros(n)
    for i, (_, msg) in enumerate(msgs):
        t[i] = _stamp(msg)
        if len(msg.position):
            val[i] = msg.position[0] / k
        if len(msg.effort):
            conf[i] = msg.effort[0]
    return pd.DataFrame({"t_ns": t, "frame": np.arange(n, dtype=np.int64), "value": val,
                         "confidence": conf})


def _events(msgs: list[tuple[int, Any]], run: str, file: str) -> pd.DataFrame:
    t, ev, detail = [], [], []
    for stamp, msg in msgs:
        kind, _, rest = str(msg.data).partition(":")
        if kind not in EVENT_KINDS:
            raise RigIOError(f"unknown event {kind!r} on {T_EVENTS}", run=run, file=file,
                             t_ns=stamp)
        t.append(stamp)
        ev.append(kind)
        detail.append(rest)
    return pd.DataFrame({"t_ns": np.array(t, dtype=np.int64),
                         "event": np.array(ev, dtype=object),
                         "detail": np.array(detail, dtype=object)})

