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

import bz2
import json
import os
import struct
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any, Literal

import lz4.frame
import numpy as np
import numpy.typing as npt
import pandas as pd
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag1 import reader as ros1_reader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from rig_io import checks
from rig_io.atomic import atomic_path
from rig_io.calibrate import (
    PhysicalRun,
    calibrate_raw_run,
    encoder_unit,
    si_factor,
    vision_unit,
)
from rig_io.errors import RigIOError
from rig_io.limits import DEFAULT_LIMITS, MB, ReadLimits, check_regular, read_bytes
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
    # keep_name: a rosbag2 writer names its storage file after the folder it writes.
    with atomic_path(target, keep_name=True) as inner:
        if storage == "rosbag1":
            _write_ros1(phys, inner, compress=compress)
        else:
            plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
            _write_ros2(phys, inner, plugin=plugin)
    return target


@dataclass
class _Topic:
    """One topic to write: stamps, a message factory, and its float columns for bulk fill."""

    topic: str
    typ: str
    t: npt.NDArray[np.int64]
    make: Callable[[int], Any]
    columns: dict[str, list[npt.NDArray[np.float64]]] = field(default_factory=dict)


def _topics(phys: PhysicalRun, ros1: bool) -> list[_Topic]:
    """Every topic of the run in SI units (the manifest first)."""
    ts = _store(ros1)
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    String, JointState = T[MSG_STRING], T[MSG_JOINTS]
    Wrench, WrenchStamped, Vector3 = (T["geometry_msgs/msg/Wrench"], T[MSG_WRENCH],
                                      T["geometry_msgs/msg/Vector3"])
    empty = np.zeros(0, dtype=np.float64)

    def header(t: int, seq: int) -> Any:
        stamp = Time(sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        if ros1:
            return Header(seq=seq, stamp=stamp, frame_id="rig")
        return Header(stamp=stamp, frame_id="rig")

    m = phys.manifest
    out: list[_Topic] = []
    t0 = np.array([int(phys.encoder["t_ns"].iloc[0])], dtype=np.int64)
    out.append(_Topic(T_MANIFEST, MSG_STRING, t0, lambda i: String(data=json.dumps(m))))
    k = si_factor(encoder_unit(m), run=phys.run_id)
    t = phys.encoder["t_ns"].to_numpy(dtype=np.int64)
    inp = phys.encoder["input"].to_numpy(dtype=float) * k
    outp = phys.encoder["output"].to_numpy(dtype=float) * k
    has_out = bool(np.isfinite(outp).any())
    names = ["input", "output"] if has_out else ["input"]
    pos_cols = [inp, outp] if has_out else [inp]

    def joint(i: int) -> Any:
        return JointState(header=header(int(t[i]), i + 1), name=names,
                          position=np.array([c[i] for c in pos_cols], dtype=np.float64),
                          velocity=empty, effort=empty)

    out.append(_Topic(T_JOINTS, MSG_JOINTS, t, joint, {"position": pos_cols, "effort": []}))
    if phys.loadcell is not None:
        tl = phys.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for topic, col in ((T_LOAD_IN, "tension_in_n"), (T_LOAD_OUT, "tension_out_n")):
            f = phys.loadcell[col].to_numpy(dtype=float)

            def wrench(i: int, f: npt.NDArray[np.float64] = f) -> Any:
                zero = Vector3(x=0.0, y=0.0, z=0.0)
                w = Wrench(force=Vector3(x=float(f[i]), y=0.0, z=0.0), torque=zero)
                return WrenchStamped(header=header(int(tl[i]), i + 1), wrench=w)

            out.append(_Topic(topic, MSG_WRENCH, tl, wrench, {"fx": [f]}))
    for topic, stream in ((T_CAMERA, "camera"), (T_TRACKER, "tracker")):
        frame = getattr(phys, stream)
        if frame is None:
            continue
        unit = vision_unit(m, stream)
        kv = si_factor(unit, run=phys.run_id)
        vname = "tip_angle" if unit == "deg" else "output"
        tv = frame["t_ns"].to_numpy(dtype=np.int64)
        val = frame["value"].to_numpy(dtype=float) * kv
        conf = frame["confidence"].to_numpy(dtype=float)

        def vision(i: int, tv: Any = tv, val: Any = val, conf: Any = conf,
                   vname: str = vname) -> Any:
            return JointState(header=header(int(tv[i]), i + 1), name=[vname],
                              position=np.array([val[i]]), velocity=empty,
                              effort=np.array([conf[i]]))

        out.append(_Topic(topic, MSG_JOINTS, tv, vision,
                          {"position": [val], "effort": [conf]}))
    if phys.events is not None:
        te = phys.events["t_ns"].to_numpy(dtype=np.int64)
        texts = [f"{ev}:{d}" if isinstance(d, str) and d else str(ev)
                 for ev, d in zip(phys.events["event"], phys.events["detail"], strict=True)]
        out.append(_Topic(T_EVENTS, MSG_STRING, te, lambda i: String(data=texts[i])))
    return out


def _serialise(topic: _Topic, ros1: bool) -> list[bytes]:
    """Serialised messages of one topic: one template message, then numpy fills the stamps
    and values of every row (checked against rosbags on the first and last row)."""
    ts = _store(ros1)

    def ser(msg: Any) -> bytes:
        return bytes(ts.serialize_ros1(msg, topic.typ) if ros1
                     else ts.serialize_cdr(msg, topic.typ))

    n = topic.t.size
    if n < 3 or not topic.columns:
        return [ser(topic.make(i)) for i in range(n)]
    template = ser(topic.make(0))
    found = _layout(topic.typ, template, cdr=not ros1)
    if found is None:
        return [ser(topic.make(i)) for i in range(n)]
    lay, fields = found
    arr = np.tile(np.frombuffer(template, dtype=np.uint8), (n, 1))

    def put(off: int, values: npt.NDArray[Any], dtype: str) -> None:
        size = np.dtype(dtype).itemsize
        arr[:, off:off + size] = np.ascontiguousarray(values, dtype=dtype).view(
            np.uint8).reshape(n, size)

    sec_off, nsec_off = lay.stamp
    put(sec_off, topic.t // 1_000_000_000, "<u4" if ros1 else "<i4")
    put(nsec_off, topic.t % 1_000_000_000, "<u4")
    if ros1:
        put(0, np.arange(1, n + 1), "<u4")  # header.seq
    if topic.typ == MSG_WRENCH:
        put(fields["fx"], topic.columns["fx"][0], "<f8")
    else:
        for key in ("position", "effort"):
            for off, col in zip(fields[key], topic.columns[key], strict=True):
                put(off, col, "<f8")
    rows = [arr[i].tobytes() for i in range(n)]
    if rows[0] != template or rows[-1] != ser(topic.make(n - 1)):
        return [ser(topic.make(i)) for i in range(n)]
    return rows


def _messages(phys: PhysicalRun, ros1: bool) -> list[tuple[str, str, int, bytes]]:
    """(topic, msgtype, t_ns, serialised message) for the whole run, in time order."""
    topics = _topics(phys, ros1)
    datas = [_serialise(tp, ros1) for tp in topics]
    t_all = np.concatenate([tp.t for tp in topics])
    which = np.concatenate([np.full(tp.t.size, j) for j, tp in enumerate(topics)])
    index = np.concatenate([np.arange(tp.t.size) for tp in topics])
    order = np.argsort(t_all, kind="stable")  # stable: the manifest stays first
    return [(topics[j].topic, topics[j].typ, int(t_all[o]), datas[j][index[o]])
            for o in order.tolist() for j in (int(which[o]),)]


def _write_ros1(phys: PhysicalRun, path: Path, *, compress: bool) -> None:
    ts = _store(True)
    writer = Writer1(path)
    if compress:
        writer.set_compression(Writer1.CompressionFormat.LZ4)
    with writer:
        conns: dict[str, Any] = {}
        for topic, typ, t, data in _messages(phys, ros1=True):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
            writer.write(conns[topic], t, data)


def _write_ros2(phys: PhysicalRun, path: Path, *, plugin: StoragePlugin) -> None:
    ts = _store(False)
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        conns: dict[str, Any] = {}
        for topic, typ, t, data in _messages(phys, ros1=False):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
            writer.write(conns[topic], t, data)


# ----------------------------------------------------------------------------------- reading

def is_bag(path: str | os.PathLike[str]) -> bool:
    """A rosbag1 file (``.bag``) or a rosbag2 folder (with ``metadata.yaml``)."""
    p = Path(path)
    return (p.is_file() and p.suffix == ".bag") or (p.is_dir() and (p / "metadata.yaml").exists())


def sidecar_manifest(path: str | os.PathLike[str]) -> Path:
    """Where a bag's manifest lives when the bag has no ``/rig/manifest``."""
    p = Path(path)
    return p.with_name(f"{p.name}.manifest.json")


_CHUNK_LOCK = threading.Lock()


def _bounded(make: Callable[[], Any], limit: int, what: str) -> Callable[[bytes], bytes]:
    """A chunk decompressor that stops past ``limit`` bytes instead of filling the memory."""

    def decompress(data: bytes) -> bytes:
        out = make().decompress(data, max_length=limit + 1)
        if len(out) > limit:
            raise RigIOError(f"a {what} chunk decompresses to more than {limit / MB:g} MB "
                             "(limits.max_decompressed_mb)")
        return bytes(out)

    return decompress


@contextmanager
def _bounded_ros1_chunks(limits: ReadLimits) -> Iterator[None]:
    """rosbags decompresses a rosbag1 chunk whole and unbounded (a few kB of bz2 can hold
    gigabytes of zeros); while a bag is read, its bz2 and lz4 chunks go through bounded
    decompressors. The table is rosbags' module-level one, hence the lock."""
    limit = int(limits.max_decompressed_mb * MB)
    table = ros1_reader.decompressors
    with _CHUNK_LOCK:
        saved = dict(table)
        table["bz2"] = _bounded(bz2.BZ2Decompressor, limit, "bz2")
        table["lz4"] = _bounded(lz4.frame.LZ4FrameDecompressor, limit, "lz4")
        try:
            yield
        finally:
            table.clear()
            table.update(saved)


def _check_bag_files(p: Path, hint: str, limits: ReadLimits) -> None:
    """Only regular files, within the size limit (rosbags holds the messages in memory)."""
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if not f.name.startswith("."))
        sizes = [check_regular(f, base=p, run=hint).st_size for f in files]
    else:
        sizes = [check_regular(p, base=None, run=hint).st_size]
    total = sum(sizes)
    if total > limits.max_bag_mb * MB:
        raise RigIOError(f"bag is {total / MB:.1f} MB, beyond the limit of "
                         f"{limits.max_bag_mb:g} MB (limits.max_bag_mb)", run=hint,
                         file=str(p))


def read_bag(path: str | os.PathLike[str], *, check: bool = True,
             limits: ReadLimits = DEFAULT_LIMITS) -> PhysicalRun:
    """Read a bag into a :class:`PhysicalRun` in the manifest's units.

    Raises :class:`RigIOError` for a truncated or corrupt bag, a missing required topic, a
    missing manifest (neither ``/rig/manifest`` nor ``<bag>.manifest.json``) and, with
    ``check``, the value checks (timestamps, gaps, saturation, e-stop, camera confidence,
    finite values in physical ranges, stream overlap). ``limits`` bounds the bag's size;
    special files are refused.
    """
    p = Path(path)
    file = str(p)
    hint = p.name.removesuffix(".bag")
    if not os.path.lexists(p):
        raise RigIOError("bag does not exist", run=hint, file=file)
    _check_bag_files(p, hint, limits)
    raw: dict[str, tuple[str, list[int], list[bytes]]] = {}
    last_t: int | None = None
    try:
        with _bounded_ros1_chunks(limits), \
                AnyReader([p], default_typestore=_store(p.suffix == ".bag")) as reader:
            topics = set(reader.topics)
            wanted = [c for c in reader.connections
                      if c.topic in (T_MANIFEST, T_JOINTS, T_LOAD_IN, T_LOAD_OUT, T_CAMERA,
                                     T_TRACKER, T_EVENTS)]
            for conn, t, data in reader.messages(connections=wanted):
                entry = raw.setdefault(conn.topic, (conn.msgtype, [], []))
                entry[1].append(int(t))
                entry[2].append(bytes(data))
                last_t = int(t)
            cdr = reader.is2
            decoded = {topic: _decode(reader, topic, typ, stamps, datas, cdr=cdr)
                       for topic, (typ, stamps, datas) in raw.items()}
    except RigIOError as err:
        if err.file is not None:
            raise
        raise RigIOError(err.reason, run=hint, file=file, key=err.key, t_ns=last_t) from None
    except Exception as err:  # rosbags raises many types for damaged storage
        where = f" after the message at t={last_t} ns" if last_t is not None else ""
        raise RigIOError(f"truncated or corrupt bag{where}: {type(err).__name__}: {err}",
                         run=hint, file=file, t_ns=last_t) from None
    try:
        return _physical(decoded, topics, p, hint, check=check, limits=limits)
    except RigIOError:
        raise
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError,
            UnicodeError) as err:  # a message that decodes but does not fit the format
        raise RigIOError(f"corrupt bag content: {type(err).__name__}: {err}", run=hint,
                         file=file) from None


def _physical(decoded: dict[str, dict[str, Any]], topics: set[str], p: Path, hint: str, *,
              check: bool, limits: ReadLimits) -> PhysicalRun:
    file = str(p)
    manifest = _bag_manifest(decoded, p, hint, limits)
    present = [s for s, t in (("camera", T_CAMERA), ("tracker", T_TRACKER)) if t in topics]
    run_id = check_manifest(manifest, file=file, streams=present, si_units=True,
                            run_hint=hint)
    for topic in REQUIRED_TOPICS:
        if topic not in decoded or not len(decoded[topic]["stamp"]):
            raise RigIOError(f"required topic {topic} is missing or empty "
                             f"(topics: {', '.join(sorted(topics)) or 'none'})",
                             run=run_id, file=file)
    phys = PhysicalRun(manifest=manifest, encoder=_joints(decoded[T_JOINTS], manifest,
                                                          run_id, file),
                       files={s: file for s in ("encoder", "loadcell", "camera", "tracker",
                                                "events")},
                       applied={"values": "SI as recorded in the bag (joint positions, "
                                          "forces); only the unit of the manifest's encoder "
                                          "applies"})
    if T_LOAD_IN in decoded or T_LOAD_OUT in decoded:
        for topic in (T_LOAD_IN, T_LOAD_OUT):
            if topic in decoded:  # ordered stamps first: merging repeats would multiply rows
                checks.check_timestamps(np.asarray(decoded[topic]["stamp"], dtype=np.int64),
                                        run=run_id, file=f"{file}:{topic}", rows=False,
                                        check_gaps=False)
        phys.loadcell = _loads(decoded.get(T_LOAD_IN), decoded.get(T_LOAD_OUT))
    for stream, topic in (("camera", T_CAMERA), ("tracker", T_TRACKER)):
        if topic in decoded:
            setattr(phys, stream, _vision(decoded[topic], manifest, stream, run_id, file))
    if T_EVENTS in decoded:
        phys.events = _events(decoded[T_EVENTS], run_id, file)
    if check:
        checks.check_physical_run(phys, rows=False)
    return phys


# ------------------------------------------------------------------------ bulk decoding

class _Layout:
    """Byte offsets of the fields ingest needs in one serialised message (ROS1 or CDR-LE).

    Bags from one logger repeat the same layout in every message of a topic (same frame id,
    same joint names, same array lengths), so the offsets of one message let numpy read all
    of them at once; :func:`_decode` checks that assumption and falls back otherwise.
    """

    def __init__(self, buf: bytes, *, cdr: bool) -> None:
        self.buf, self.cdr = buf, cdr
        self.base = 4 if cdr else 0
        self.pos = self.base
        self.f64: list[int] = []  # offsets of every float64 (values, not structure)
        self.stamp: tuple[int, int] = (0, 0)

    def _align(self, n: int) -> None:
        if self.cdr:
            self.pos = self.base + -(-(self.pos - self.base) // n) * n

    def u32(self) -> int:
        self._align(4)
        (v,) = struct.unpack_from("<I", self.buf, self.pos)
        self.pos += 4
        return int(v)

    def string(self) -> str:
        n = self.u32()
        text = self.buf[self.pos:self.pos + n].split(b"\0")[0].decode("utf-8")
        self.pos += n
        return text

    def doubles(self, n: int) -> list[int]:
        offs = []
        for _ in range(n):
            self._align(8)
            offs.append(self.pos)
            self.pos += 8
        self.f64.extend(offs)
        return offs

    def header(self) -> None:
        if not self.cdr:
            self.u32()  # seq
        sec = self.pos if not self.cdr else self.base + -(-(self.pos - self.base) // 4) * 4
        self.u32()
        nsec = self.pos
        self.u32()
        self.stamp = (sec, nsec)
        self.string()  # frame_id


def _layout(typ: str, buf: bytes, *, cdr: bool) -> tuple[_Layout, dict[str, Any]] | None:
    if cdr and (len(buf) < 4 or buf[1] != 1):  # only little-endian CDR
        return None
    lay = _Layout(buf, cdr=cdr)
    lay.header()
    if typ == MSG_WRENCH:
        offs = lay.doubles(6)
        fields: dict[str, Any] = {"fx": offs[0]}
    elif typ == MSG_JOINTS:
        names = [lay.string() for _ in range(lay.u32())]
        pos = lay.doubles(lay.u32())
        lay.doubles(lay.u32())  # velocity
        eff = lay.doubles(lay.u32())
        fields = {"names": names, "position": pos, "effort": eff}
    else:
        return None
    if lay.pos != len(buf):
        return None
    return lay, fields


def _decode(reader: AnyReader, topic: str, typ: str, stamps: list[int], datas: list[bytes],
            *, cdr: bool) -> dict[str, Any]:
    """Columns of one topic: ``stamp`` plus ``fx`` (wrench), ``input``/``output`` (joints),
    ``value``/``confidence`` (camera, tracker), ``msgs`` (strings)."""
    n = len(datas)
    fast = None
    if n and typ in (MSG_WRENCH, MSG_JOINTS) and len({len(d) for d in datas}) == 1:
        fast = _layout(typ, datas[0], cdr=cdr)
    if fast is not None:
        lay, fields = fast
        width = len(datas[0])
        arr = np.frombuffer(b"".join(datas), dtype=np.uint8).reshape(n, width)
        structure = np.ones(width, dtype=bool)
        for off in lay.f64:
            structure[off:off + 8] = False
        sec_off, nsec_off = lay.stamp
        structure[sec_off:sec_off + 4] = False
        structure[nsec_off:nsec_off + 4] = False
        if not cdr:
            structure[0:4] = False  # seq
        if np.array_equal(arr[:, structure], np.broadcast_to(arr[0, structure],
                                                             (n, int(structure.sum())))):
            def col(off: int, dtype: str) -> npt.NDArray[Any]:
                size = np.dtype(dtype).itemsize
                return np.ascontiguousarray(arr[:, off:off + size]).view(dtype).ravel()

            sec = col(sec_off, "<i4" if cdr else "<u4").astype(np.int64)
            stamp = sec * 1_000_000_000 + col(nsec_off, "<u4").astype(np.int64)
            out: dict[str, Any] = {"stamp": stamp}
            if typ == MSG_WRENCH:
                out["fx"] = col(fields["fx"], "<f8").astype(float)
            else:
                _joint_columns(out, fields["names"],
                               [col(o, "<f8") for o in fields["position"]],
                               [col(o, "<f8") for o in fields["effort"]], n)
            _verify(reader, typ, datas, out)
            return out
    # General path: deserialise message by message.
    msgs: list[Any] = [reader.deserialize(d, typ) for d in datas]
    if typ == MSG_STRING:
        return {"stamp": np.asarray(stamps, dtype=np.int64), "msgs": msgs}
    stamp = np.array([_stamp(m) for m in msgs], dtype=np.int64)
    out = {"stamp": stamp}
    if typ == MSG_WRENCH:
        out["fx"] = np.array([m.wrench.force.x for m in msgs], dtype=float)
    elif typ == MSG_JOINTS:
        _joint_rows(out, msgs)
    else:
        raise RigIOError(f"message type {typ} on {topic} is not one ingest reads "
                         f"({MSG_WRENCH} or {MSG_JOINTS})", key=topic)
    return out


def _joint_columns(out: dict[str, Any], names: list[str], pos: list[npt.NDArray[Any]],
                   eff: list[npt.NDArray[Any]], n: int) -> None:
    nan = np.full(n, np.nan)
    out["names"] = names
    for i, name in enumerate(names):
        out[name] = pos[i].astype(float) if i < len(pos) else nan
    out["value"] = pos[0].astype(float) if pos else nan
    out["confidence"] = eff[0].astype(float) if eff else np.zeros(n)


def _joint_rows(out: dict[str, Any], msgs: list[Any]) -> None:
    n = len(msgs)
    cols: dict[str, npt.NDArray[np.float64]] = {}
    value, conf = np.full(n, np.nan), np.zeros(n)
    for i, m in enumerate(msgs):
        for j, name in enumerate(m.name):
            if j < len(m.position):
                cols.setdefault(name, np.full(n, np.nan))[i] = m.position[j]
        if len(m.position):
            value[i] = m.position[0]
        if len(m.effort):
            conf[i] = m.effort[0]
    out.update(cols)
    out["names"] = sorted(cols)
    out["value"], out["confidence"] = value, conf


def _verify(reader: AnyReader, typ: str, datas: list[bytes], out: dict[str, Any]) -> None:
    """The bulk decode must agree with rosbags on the first and last message."""
    for i in (0, len(datas) - 1):
        m: Any = reader.deserialize(datas[i], typ)
        ok = _stamp(m) == int(out["stamp"][i])
        if typ == MSG_WRENCH:
            ok = ok and _same(m.wrench.force.x, out["fx"][i])
        else:
            for j, name in enumerate(m.name):
                if j < len(m.position):
                    ok = ok and _same(m.position[j], out[name][i])
        if not ok:
            raise RigIOError(f"bulk decoding of {typ} disagrees with rosbags (message {i})")


def _same(a: float, b: float) -> bool:
    return bool((np.isnan(a) and np.isnan(b)) or a == b)


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _bag_manifest(decoded: dict[str, dict[str, Any]], p: Path, hint: str,
                  limits: ReadLimits) -> dict[str, Any]:
    msgs = decoded.get(T_MANIFEST, {}).get("msgs", [])
    if msgs:
        return parse_manifest(str(msgs[0].data), run=hint, file=f"{p}:{T_MANIFEST}")
    side = sidecar_manifest(p)
    if not os.path.lexists(side):
        raise RigIOError(f"required topic {T_MANIFEST} is missing and there is no "
                         f"{side.name} beside the bag", run=hint, file=str(p))
    data = read_bytes(side, base=side.parent, run=hint, limit_mb=limits.max_manifest_mb,
                      limit_name="max_manifest_mb")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise RigIOError(f"unreadable manifest: {err}", run=hint, file=str(side)) from None
    return parse_manifest(text, run=hint, file=str(side))


def _joints(cols: dict[str, Any], manifest: dict[str, Any], run: str,
            file: str) -> pd.DataFrame:
    k = si_factor(encoder_unit(manifest), run=run, file=file)
    t = cols["stamp"]
    if "input" not in cols or np.isnan(cols["input"]).any():
        bad = 0 if "input" not in cols else int(np.flatnonzero(np.isnan(cols["input"]))[0])
        raise RigIOError(f"{T_JOINTS} message has no 'input' position "
                         f"(names {cols.get('names')})", run=run, file=file, t_ns=int(t[bad]))
    out = cols.get("output", np.full(t.size, np.nan))
    return pd.DataFrame({"t_ns": t, "input": cols["input"] / k, "output": out / k})


def _loads(c_in: dict[str, Any] | None, c_out: dict[str, Any] | None) -> pd.DataFrame:
    def frame(c: dict[str, Any] | None, col: str) -> pd.DataFrame:
        if c is None:
            return pd.DataFrame({"t_ns": np.zeros(0, dtype=np.int64), col: np.zeros(0)})
        return pd.DataFrame({"t_ns": c["stamp"], col: c["fx"]})

    a, b = frame(c_in, "tension_in_n"), frame(c_out, "tension_out_n")
    if len(a) == len(b) and np.array_equal(a["t_ns"].to_numpy(), b["t_ns"].to_numpy()):
        a["tension_out_n"] = b["tension_out_n"].to_numpy()
        return a
    merged = a.merge(b, on="t_ns", how="outer").sort_values("t_ns", kind="stable")
    return merged.reset_index(drop=True)


def _vision(cols: dict[str, Any], manifest: dict[str, Any], stream: str, run: str,
            file: str) -> pd.DataFrame:
    k = si_factor(vision_unit(manifest, stream), run=run, file=file)
    n = len(cols["stamp"])
    return pd.DataFrame({"t_ns": cols["stamp"], "frame": np.arange(n, dtype=np.int64),
                         "value": cols["value"] / k, "confidence": cols["confidence"]})


def _events(cols: dict[str, Any], run: str, file: str) -> pd.DataFrame:
    t, ev, detail = [], [], []
    for stamp, msg in zip(cols["stamp"], cols["msgs"], strict=True):
        kind, _, rest = str(msg.data).partition(":")
        if kind not in EVENT_KINDS:
            raise RigIOError(f"unknown event {kind!r} on {T_EVENTS}", run=run, file=file,
                             t_ns=int(stamp))
        t.append(int(stamp))
        ev.append(kind)
        detail.append(rest)
    return pd.DataFrame({"t_ns": np.array(t, dtype=np.int64),
                         "event": np.array(ev, dtype=object),
                         "detail": np.array(detail, dtype=object)})
