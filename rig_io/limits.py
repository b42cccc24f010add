"""Read limits and safe opening of raw files: nothing a source folder holds can hang, exhaust
memory or lead a reader outside the run it belongs to.

- Size limits (:class:`ReadLimits`, ``conf/ingest.yaml`` -> ``limits``): a stream file, its
  decompressed text, a manifest, a bag. A file beyond a limit is refused before it is read
  (gzip streams are decompressed in a bounded read, so a gzip bomb stops at the limit).
- Special files: only regular files are opened. A FIFO, a device, a socket or a symlink that
  resolves outside the run folder is refused from ``os.lstat``/``os.stat`` *before* opening
  (opening a FIFO blocks until a writer appears), and every open is non-blocking and
  re-checked with ``fstat`` so a file swapped in between cannot hang the reader either.
"""

from __future__ import annotations

import gzip
import os
import stat
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rig_io.errors import RigIOError

MB = 1024 * 1024


@dataclass(frozen=True)
class ReadLimits:
    """Upper bounds on what one run may make ingest read (``conf/ingest.yaml`` -> ``limits``).

    The defaults keep the peak memory of ingesting one run under 1 GB (measured in
    ``bench/bench_ingest.py``: a 37 MB encoder.csv, 1.45 M samples, peaks at ~0.76 GB, as the
    processed rows take ~0.35 kB per encoder sample) and still hold long runs: 40 MB is ~4 h
    of a 100 Hz encoder or ~19 min of a 1 kHz load cell. Raise them for longer runs on a
    machine with the memory.
    """

    #: One stream file (``.csv`` or ``.csv.gz``) on disk, and a foreign log file.
    max_file_mb: float = 40.0
    #: The text of one ``.csv.gz``, and one rosbag1 bz2/lz4 chunk, after decompression (a
    #: bomb stops here).
    max_decompressed_mb: float = 40.0
    #: ``manifest.json`` (and a bag's side-car manifest).
    max_manifest_mb: float = 1.0
    #: A bag (all files of a rosbag2 folder together): rosbags holds its messages in memory.
    max_bag_mb: float = 256.0

    def __post_init__(self) -> None:
        for name in ("max_file_mb", "max_decompressed_mb", "max_manifest_mb", "max_bag_mb"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    0 < float(value) < 1e7):
                raise RigIOError(f"limits.{name} must be a positive number of MB, "
                                 f"got {value!r}")

    @classmethod
    def from_mapping(cls, mapping: dict[str, Any] | None) -> ReadLimits:
        """From the ``limits`` section of a config (unknown keys are an error)."""
        if not mapping:
            return cls()
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(mapping) - known)
        if unknown:
            raise RigIOError(f"unknown limits key(s) {', '.join(unknown)} "
                             f"(known: {', '.join(sorted(known))})")
        return cls(**{str(k): v for k, v in mapping.items()})


DEFAULT_LIMITS = ReadLimits()

_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISDIR, "a directory"))


def _kind(mode: int) -> str:
    for test, name in _KINDS:
        if test(mode):
            return name
    return "not a regular file"


def check_regular(path: Path, *, base: Path | None, run: str | None) -> os.stat_result:
    """``stat`` of ``path`` if it is a regular file (or a symlink to one inside ``base``).

    Never opens the file. Raises :class:`RigIOError` for a missing file, a special file, a
    dangling or looping symlink, and a symlink that resolves outside ``base``.
    """
    file = str(path)
    try:
        st = os.lstat(path)
    except OSError as err:
        raise RigIOError(f"cannot stat: {err.strerror}", run=run, file=file) from None
    if stat.S_ISLNK(st.st_mode):
        try:
            target = path.resolve(strict=True)
        except (OSError, RuntimeError) as err:
            raise RigIOError(f"symlink does not resolve: {err}", run=run, file=file) from None
        if base is not None:
            root = base.resolve()
            if not target.is_relative_to(root):
                raise RigIOError(f"symlink points outside the run folder (to {target}); "
                                 "refused", run=run, file=file)
        try:
            st = os.stat(target)
        except OSError as err:
            raise RigIOError(f"cannot stat: {err.strerror}", run=run, file=file) from None
    if not stat.S_ISREG(st.st_mode):
        raise RigIOError(f"is {_kind(st.st_mode)}, not a regular file; refused",
                         run=run, file=file)
    return st


def read_bytes(path: Path, *, base: Path | None, run: str | None, limit_mb: float,
               limit_name: str, gunzip_limit_mb: float | None = None) -> bytes:
    """The bytes of a regular file (decompressed when ``gunzip_limit_mb`` is given), bounded.

    ``limit_name`` is the config key named in the error past the limit.
    """
    file = str(path)
    st = check_regular(path, base=base, run=run)
    limit = int(limit_mb * MB)
    if st.st_size > limit:
        raise RigIOError(f"file is {st.st_size / MB:.1f} MB, beyond the limit of "
                         f"{limit_mb:g} MB (limits.{limit_name})", run=run, file=file)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as err:
        raise RigIOError(f"cannot open: {err.strerror}", run=run, file=file) from None
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise RigIOError("is not a regular file; refused", run=run, file=file)
        if gunzip_limit_mb is None:
            data = fh.read(limit + 1)
            if len(data) > limit:
                raise RigIOError(f"file grew beyond the limit of {limit_mb:g} MB "
                                 f"(limits.{limit_name})", run=run, file=file)
            return data
        cap = int(gunzip_limit_mb * MB)
        try:
            with gzip.GzipFile(fileobj=fh, mode="rb") as gz:
                data = gz.read(cap + 1)
        except (EOFError, OSError, zlib.error) as err:
            raise RigIOError(f"unreadable or truncated gzip file: {err}", run=run,
                             file=file) from None
        if len(data) > cap:
            raise RigIOError(f"decompresses to more than {gunzip_limit_mb:g} MB "
                             "(limits.max_decompressed_mb); refused", run=run, file=file)
        return data
