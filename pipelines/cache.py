"""Content hashes that decide whether a stage's output is still up to date.

A result is recomputed only when one of the things it was computed from changed: the data
(hashed by value, not by file time), the resolved configuration, or the source code of the
model family that produced it. Hashes are hex SHA-256 digests, shortened for readability.
"""

from __future__ import annotations

import hashlib
import inspect
import json
from collections.abc import Iterable, Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

#: Bump when the meaning of a cached result changes (a new metric, a new fit protocol ...).
CACHE_VERSION = "pipelines-cache/1"
_DIGEST_CHARS = 16


def _digest(h: Any) -> str:
    return str(h.hexdigest()[:_DIGEST_CHARS])


def hash_json(obj: Any) -> str:
    """Hash of a JSON-able object with sorted keys (dict order does not matter)."""
    text = json.dumps(obj, sort_keys=True, default=_json_default, separators=(",", ":"))
    return _digest(hashlib.sha256(text.encode("utf-8")))


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot hash object of type {type(obj).__name__}")


def hash_arrays(*arrays: Any) -> str:
    """Hash of the exact values (and dtypes and shapes) of some arrays."""
    h = hashlib.sha256()
    for arr in arrays:
        a = np.ascontiguousarray(np.asarray(arr))
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return _digest(h)


def hash_frame(frame: pd.DataFrame) -> str:
    """Hash of a DataFrame's values, column names and order (index ignored)."""
    h = hashlib.sha256()
    h.update(json.dumps([str(c) for c in frame.columns]).encode())
    h.update(pd.util.hash_pandas_object(frame, index=False).to_numpy().tobytes())
    return _digest(h)


def hash_files(paths: Iterable[Path]) -> str:
    """Hash of file contents (and relative names), e.g. a parquet dataset folder."""
    h = hashlib.sha256()
    for path in sorted(Path(p) for p in paths):
        h.update(path.name.encode())
        with path.open("rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    return _digest(h)


def hash_path(path: Path) -> str:
    """Content hash of a file or of every file under a folder (hidden files skipped)."""
    path = Path(path)
    if path.is_file():
        return hash_files([path])
    files = [p for p in path.rglob("*") if p.is_file() and not p.name.startswith(".")]
    h = hashlib.sha256()
    for p in sorted(files):
        h.update(str(p.relative_to(path)).encode())
        h.update(hash_files([p]).encode())
    return _digest(h)


@lru_cache(maxsize=64)
def source_hash(cls: type) -> str:
    """Hash of the source file that defines ``cls`` (a model family's code version)."""
    try:
        src = inspect.getsourcefile(cls)
    except TypeError:
        src = None
    if src is None:
        return "no-source"
    return hash_files([Path(src)])


def combine(parts: Mapping[str, Any]) -> str:
    """One key from named parts (each JSON-able), including :data:`CACHE_VERSION`."""
    return hash_json({"version": CACHE_VERSION, **parts})
