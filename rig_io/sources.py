"""Finding raw runs in a source folder, hashing them, and loading them as calibrated runs.

A source folder may mix run folders (``manifest.json`` + CSV or ``.csv.gz``), rosbag1
``.bag`` files, rosbag2 folders (``metadata.yaml`` + ``.db3``/``.mcap``) and, with an importer
mapping, foreign log files. Other folders are searched recursively; hidden names (``.x``,
temporaries of atomic writes) are skipped. Sources are only ever read.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from rig_io.bag import is_bag, read_bag, sidecar_manifest
from rig_io.calibrate import PhysicalRun, calibrate_raw_run
from rig_io.errors import RigIOError
from rig_io.folder import MANIFEST, STREAMS, find_stream, read_run_folder
from rig_io.importer import import_file, matches

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
    return (p / MANIFEST).exists() or any(
        (p / f"{s}.csv").exists() or (p / f"{s}.csv.gz").exists() for s in STREAMS)


def discover(root: str | os.PathLike[str], *,
             mapping: dict[str, Any] | None = None) -> list[Source]:
    """All raw runs under ``root`` (sorted by path)."""
    root = Path(root)
    if not root.is_dir():
        raise RigIOError("source folder does not exist", file=str(root))
    found: list[Source] = []

    def walk(folder: Path) -> None:
        for p in sorted(folder.iterdir()):
            if p.name.startswith("."):
                continue
            if p.is_dir():
                if (p / "metadata.yaml").exists():
                    files = sorted(f for f in p.iterdir() if f.is_file())
                    side = sidecar_manifest(p)
                    found.append(Source("rosbag2", p, tuple(files + ([side] if side.exists()
                                                                      else []))))
                elif _looks_like_run_folder(p):
                    found.append(Source("folder", p, tuple(sorted(
                        f for f in p.iterdir() if f.is_file() and not f.name.startswith(".")))))
                else:
                    walk(p)
            elif p.suffix == ".bag":
                side = sidecar_manifest(p)
                found.append(Source("rosbag1", p, (p, side) if side.exists() else (p,)))
            elif mapping is not None and matches(mapping, p):
                found.append(Source("import", p, (p,)))

    walk(root)
    return found


def hash_files(files: tuple[Path, ...], *, root: Path) -> tuple[str, dict[str, str]]:
    """sha256 of each file and one hash over all of them (names included)."""
    total = hashlib.sha256()
    each: dict[str, str] = {}
    for f in files:
        h = hashlib.sha256()
        with f.open("rb") as fh:
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


def load(source: Source, *, mapping: dict[str, Any] | None = None) -> PhysicalRun:
    """Read and check one source; :class:`RigIOError` on any bad input."""
    if source.kind == "folder":
        raw = read_run_folder(source.path)
        files = {}
        for s in STREAMS:
            found = find_stream(source.path, s)
            if found is not None:
                files[s] = str(found)
        return calibrate_raw_run(raw, files=files)
    if source.kind in ("rosbag1", "rosbag2"):
        if not is_bag(source.path):
            raise RigIOError("not a bag", file=str(source.path))
        return read_bag(source.path)
    if source.kind == "import":
        if mapping is None:
            raise RigIOError("foreign log without an importer mapping", file=str(source.path))
        return import_file(mapping, source.path)
    raise RigIOError(f"unknown source kind {source.kind!r}", file=str(source.path))
