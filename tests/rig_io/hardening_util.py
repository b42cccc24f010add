"""Shared helpers of the hardening and fuzz tests: copies of the committed sample run (raw
samples are never modified), loading a source end to end, and the acceptance invariants."""

from __future__ import annotations

import gzip
import shutil
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

import numpy as np
import pandas as pd

from rig_io.checks import MAX_ABS_POSITION
from rig_io.dataset import run_file
from rig_io.errors import RigIOError
from rig_io.limits import ReadLimits
from rig_io.manifest import is_safe_identifier
from rig_io.process import process_run
from rig_io.schema import validate
from rig_io.sources import Source, load

REPO = Path(__file__).resolve().parents[2]
SAMPLE_FOLDER = REPO / "data" / "samples" / "folder" / "sample_phi090_r030_sine_0001"
SAMPLE_BAG = REPO / "data" / "samples" / "rosbag1" / "sample_phi090_r030_sine_0001.bag"


def plain_copy(dst_root: Path, name: str = "run_0001") -> Path:
    """The sample run folder copied under ``dst_root/name`` with every stream as plain CSV."""
    dst = dst_root / name
    dst.mkdir(parents=True)
    for f in SAMPLE_FOLDER.iterdir():
        if f.name.endswith(".gz"):
            (dst / f.name.removesuffix(".gz")).write_bytes(gzip.decompress(f.read_bytes()))
        else:
            shutil.copyfile(f, dst / f.name)
    return dst


def folder_source(folder: Path) -> Source:
    return Source("folder", folder, tuple(sorted(p for p in folder.iterdir())))


def bag_source(bag: Path) -> Source:
    return Source("rosbag1", bag, (bag,))


@contextmanager
def no_hang(seconds: float = 30.0) -> Iterator[None]:
    """Fail (``TimeoutError``, not a ``RigIOError``) if the block runs longer than ``seconds``
    (in the main thread; callers in another thread time out with a join instead)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def alarm(signum: int, frame: FrameType | None) -> None:
        raise TimeoutError(f"still running after {seconds} s: a hang")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def ingest_one(source: Source, *, limits: ReadLimits | None = None) -> pd.DataFrame:
    """Load and process one source as ingest does; the dataset rows (validated). Any run
    longer than 30 s fails the test as a hang."""
    with no_hang():
        return _ingest_one(source, limits=limits)


def _ingest_one(source: Source, *, limits: ReadLimits | None) -> pd.DataFrame:
    phys = load(source, limits=limits or ReadLimits())
    frame, info = process_run(phys)
    validate(frame, where="write", run=phys.run_id)
    assert is_safe_identifier(info["run_id"]) and is_safe_identifier(info["rig"])
    out = Path("/nonexistent/out")
    assert run_file(out, info["run_id"]).resolve().parent == (out / "samples").resolve()
    return frame


def assert_sound(frame: pd.DataFrame) -> None:
    """An accepted run holds finite values within physical ranges."""
    assert len(frame) >= 2
    for col in ("input", "output", "t_s", "input_norm", "output_norm"):
        v = frame[col].to_numpy(dtype=float)
        assert np.isfinite(v).all(), col
    assert (np.abs(frame["input"].to_numpy()) <= 2 * MAX_ABS_POSITION["deg"]).all()
    for col in ("tension_in_n", "tension_out_n", "camera", "tracker"):
        v = frame[col].to_numpy(dtype=float)
        assert not np.isinf(v).any(), col
        assert (np.abs(v[np.isfinite(v)]) <= 1e5).all(), col


#: Rejects about a whole file (its size, its kind, a corrupt container): no key or row applies.
WHOLE_FILE = ("file is ", "decompresses to more than", "bag is ", "is a ", "symlink ",
              "truncated or corrupt bag", "unreadable or truncated gzip", "corrupt bag content",
              "not valid UTF-8", "NUL byte", "manifest is nested", "manifest is not a JSON",
              "missing manifest", "missing required encoder")


def assert_names_where(err: RigIOError, *, whole_file_ok: tuple[str, ...] = WHOLE_FILE) -> None:
    """A reject names the file and a key, a row or a time (unless it is about the whole
    file: its size, its kind, a corrupt container), and stays short."""
    assert err.file, str(err)
    if not any(err.reason.startswith(p) for p in whole_file_ok):
        assert err.key is not None or err.row is not None or err.t_ns is not None, str(err)
    assert len(err.reason) <= 260, str(err)
