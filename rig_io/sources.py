"""Finding raw runs in a source folder, hashing them, and loading them as calibrated runs.

A source folder may mix run folders (``manifest.json`` + CSV or ``.csv.gz``), rosbag1
``.bag`` files, rosbag2 folders (``metadata.yaml`` + ``.db3``/``.mcap``) and, with an importer
mapping, foreign log files. Other folders are searched recursively; hidden names (``.x``,
temporaries of atomic writes) are skipped. Sources are only ever read.
"""

from __future__ import annotations

import hashlib
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from rig_io import checks
from rig_io.bag import is_bag, read_bag, sidecar_manifest
from rig_io.calibrate import PhysicalRun, calibrate_raw_run
from rig_io.errors import RigIOError, short
from rig_io.folder import MANIFEST, STREAMS, find_stream, read_run_folder
from rig_io.importer import import_file, matches
from rig_io.limits import DEFAULT_LIMITS, ReadLimits
from rig_io.manifest import check_manifest, is_safe_identifier

SourceKind = Literal["folder", "rosbag1", "rosbag2", "import"]


@dataclass(frozen=True)
class Source:
    """One raw run on disk."""

    kind: SourceKind
    path: Path
    #: Every file the run is made of (for hashing), sorted.
    files: tuple[Path, ...]

    def key(self, root: Path) -> str:
        """Stable name of the source relative to the source folder (the cache key)."""
        try:
            return self.path.relative_to(root).as_posix()
        except ValueError:
            return self.path.as_posix()


def _looks_like_run_folder(p: Path) -> bool:
    return os.path.lexists(p / MANIFEST) or any(
        os.path.lexists(p / f"{s}.csv") or os.path.lexists(p / f"{s}.csv.gz")
        for s in STREAMS)


def _is_regular(p: Path) -> bool:
    """A regular file (following symlinks), decided without opening it: a FIFO is never
    opened, so it can never hang discovery or hashing."""
    try:
        return stat.S_ISREG(os.stat(p).st_mode)
    except OSError:
        return False


def discover(root: str | os.PathLike[str], *,
             mapping: dict[str, Any] | None = None) -> list[Source]:
    """All raw runs under ``root`` (sorted by path)."""
    root = Path(root)
    _check_source_root(root)
    found: list[Source] = []
    seen: set[Path] = set()

    def walk(folder: Path) -> None:
        real = folder.resolve()
        if real in seen:  # a symlink loop, or the same folder linked twice
            return
        seen.add(real)
        for p in sorted(folder.iterdir()):
            if p.name.startswith("."):
                continue
            source = source_at(p, mapping)
            if source is not None:
                found.append(source)
            elif p.is_dir():
                walk(p)

    walk(root)
    return found


def _check_source_root(root: Path) -> None:
    if root.is_file() and root.suffix == ".bag":
        raise RigIOError("source is a single bag file; give the folder that holds the runs",
                         file=str(root))
    if not root.is_dir():
        raise RigIOError("source folder does not exist", file=str(root))
    # A run folder given as the source would be searched for runs inside it and give none.
    if (root / "metadata.yaml").exists() or _looks_like_run_folder(root):
        raise RigIOError("source is itself a run (it holds manifest.json, stream files or "
                         "metadata.yaml); give the folder that holds the runs",
                         file=str(root))


def source_at(p: Path, mapping: dict[str, Any] | None = None) -> Source | None:
    """The run at ``p`` (a rosbag2 or run folder, a rosbag1, a mapped foreign file), or None
    (a folder to search further, or a file that is no run)."""
    if p.is_dir():
        if (p / "metadata.yaml").exists():
            files = sorted(f for f in p.iterdir() if _is_regular(f))
            side = sidecar_manifest(p)
            return Source("rosbag2", p, tuple(files + ([side] if side.exists() else [])))
        if _looks_like_run_folder(p):
            return Source("folder", p, tuple(sorted(
                f for f in p.iterdir() if _is_regular(f) and not f.name.startswith("."))))
        return None
    if p.suffix == ".bag":
        side = sidecar_manifest(p)
        return Source("rosbag1", p, (p, side) if side.exists() else (p,))
    if mapping is not None and matches(mapping, p):
        return Source("import", p, (p,))
    return None


def hash_files(files: tuple[Path, ...], *, root: Path) -> tuple[str, dict[str, str]]:
    """sha256 of each file and one hash over all of them (names included)."""
    total = hashlib.sha256()
    each: dict[str, str] = {}
    for f in files:
        h = hashlib.sha256()
        if not _is_regular(f):
            raise OSError(f"{f} is not a regular file; refused")
        with open(os.open(f, os.O_RDONLY | os.O_NONBLOCK), "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                raise OSError(f"{f} is not a regular file; refused")
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        digest = h.hexdigest()
        try:
            name = f.relative_to(root).as_posix()
        except ValueError:
            name = f.as_posix()
        each[name] = digest
        total.update(f"{f.name}\0{digest}\n".encode())
    return total.hexdigest(), each


def load(source: Source, *, mapping: dict[str, Any] | None = None,
         limits: ReadLimits = DEFAULT_LIMITS) -> PhysicalRun:
    """Read and check one source; :class:`RigIOError` on any bad input.

    Values are checked after calibration whatever the container (finite, within physical
    ranges), and the run id and rig must be safe file names (importers build them from
    file names). Any other exception from a reader is wrapped with the source it came from.
    """
    try:
        phys = _load(source, mapping=mapping, limits=limits)
    except RigIOError:
        raise
    except (MemoryError, RecursionError, ValueError, TypeError, KeyError, IndexError,
            OverflowError, AttributeError, OSError) as err:
        raise RigIOError(f"could not be read ({type(err).__name__}: {err})",
                         run=_hint(source), file=str(source.path)) from None
    for key in ("run_id", "rig"):
        value = phys.manifest.get(key)
        if not is_safe_identifier(value):
            raise RigIOError(f"{key} {short(value)} is not a safe file name (1-128 of "
                             "A-Z a-z 0-9 . _ -, a letter or digit first, no '..')",
                             run=_hint(source), file=str(source.path), key=key)
    return phys


def _hint(source: Source) -> str:
    return source.path.name.removesuffix(".bag")


def _load(source: Source, *, mapping: dict[str, Any] | None,
          limits: ReadLimits) -> PhysicalRun:
    if source.kind == "folder":
        raw = read_run_folder(source.path, limits=limits)
        files = {}
        for s in STREAMS:
            found = find_stream(source.path, s)
            if found is not None:
                files[s] = str(found)
        phys = calibrate_raw_run(raw, files=files)
        checks.check_physical_values(phys, rows=True)
        return phys
    if source.kind in ("rosbag1", "rosbag2"):
        if not is_bag(source.path):
            raise RigIOError("not a bag", run=_hint(source), file=str(source.path))
        return read_bag(source.path, limits=limits)
    if source.kind == "import":
        if mapping is None:
            raise RigIOError("foreign log without an importer mapping", file=str(source.path))
        phys = import_file(mapping, source.path, limits=limits)
        # The mapping wrote this manifest: it meets the same schema as a rig's.
        check_manifest(phys.manifest, file=str(source.path), streams=(), si_units=True,
                       run_hint=_hint(source))
        return phys
    raise RigIOError(f"unknown source kind {source.kind!r}", file=str(source.path))
