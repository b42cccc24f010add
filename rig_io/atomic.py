"""Atomic writes: a temporary name beside the target, then ``os.replace``.

A crash never leaves a half-written file (or folder) that looks whole.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


def _replace(src: Path, target: Path) -> None:
    """Move ``src`` onto ``target``; a folder target is moved aside first (no one-step
    replace exists for folders) and removed once ``src`` stands in its place."""
    if target.is_dir() and src.is_dir():
        old = target.with_name(f".{target.name}.old")
        if old.exists():
            shutil.rmtree(old)
        os.replace(target, old)
        os.replace(src, target)
        shutil.rmtree(old)
    else:
        os.replace(src, target)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], *, suffix: str = "",
                keep_name: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    Works for files and for folders (the caller creates what it needs at the yielded path).
    With ``keep_name`` the yielded path has ``target``'s own name, inside a hidden temporary
    folder: for writers that name inner files after their folder (rosbag2 storage files).
    On error the temporary is removed and ``target`` is left as it was.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    holder: Path | None = None
    if keep_name:
        holder = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=f"{suffix}.tmp",
                                       dir=target.parent))
        tmp = holder / target.name
    else:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f"{suffix}.tmp",
                                        dir=target.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        tmp.unlink()  # the caller decides whether this becomes a file or a folder
    try:
        yield tmp
        _replace(tmp, target)
    finally:
        for leftover in (tmp, holder):
            if leftover is None:
                continue
            if leftover.is_dir():
                shutil.rmtree(leftover, ignore_errors=True)
            elif leftover.exists():
                leftover.unlink()


def write_text_atomic(target: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``target`` atomically (UTF-8)."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)


def write_bytes_atomic(target: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)
