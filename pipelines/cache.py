"""Content hashes that decide whether a stage's output is still up to date.

A result is recomputed only when one of the things it was computed from changed: the data
(hashed by value, not by file time), the resolved configuration, or the source code of the
model family that produced it (its module and every module of its package it imports).
Hashes are hex SHA-256 digests, shortened for readability.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.util
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
        _feed(h, path)
    return _digest(h)


def _feed(h: Any, path: Path) -> None:
    """Add a file's bytes to the hash ``h``, a megabyte at a time."""
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)


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


def _read_source(path: Path) -> bytes:
    """The bytes of one source file (one seam, so tests can stand in an edited file)."""
    return path.read_bytes()


def _imported_names(tree: ast.AST, module: str, *, is_package: bool) -> set[str]:
    """Absolute names of every module an ``import`` statement of ``tree`` may load
    (``from a import b`` gives ``a`` and ``a.b``: ``b`` may be a submodule)."""
    parts = module.split(".")
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = parts if is_package else parts[:-1]
                pkg = pkg[:len(pkg) - (node.level - 1)]
                base = ".".join([*pkg, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
    return {n for n in names if n}


def code_files(module: str) -> dict[str, Path]:
    """``module``'s file and the file of every module of the same top-level package that it
    imports, directly or through others (any ``import`` statement, also inside functions),
    plus the packages' ``__init__`` files that importing them runs."""
    top = module.split(".")[0]
    found: dict[str, Path] = {}
    todo = [module]
    while todo:
        name = todo.pop()
        if name in found or not (name == top or name.startswith(f"{top}.")):
            continue
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError, AttributeError):
            spec = None  # ``from pkg import function``: not a module
        if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
            continue
        path = Path(spec.origin)
        found[name] = path
        pieces = name.split(".")
        todo.extend(".".join(pieces[:i]) for i in range(1, len(pieces)))
        tree = ast.parse(_read_source(path), filename=str(path))
        todo.extend(_imported_names(tree, name,
                                    is_package=spec.submodule_search_locations is not None))
    return found


def file_digests(paths: Iterable[Path]) -> dict[str, str]:
    """``{path: content hash}`` of output files, stored beside a cache key."""
    return {str(p): hash_files([Path(p)]) for p in paths}


def files_intact(digests: Mapping[str, str]) -> bool:
    """True when every file still exists with the content hash it was recorded with; a
    truncated or edited output is then recomputed instead of trusted."""
    try:
        return all(Path(p).is_file() and hash_files([Path(p)]) == h
                   for p, h in digests.items())
    except OSError:
        return False


#: Suffix of the side-car file holding the SHA-256 of a cached file's bytes.
DIGEST_SUFFIX = ".sha256"


def sha256_file(path: Path) -> str:
    """Full hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    _feed(h, path)
    return h.hexdigest()


def digest_path(path: Path) -> Path:
    """``<file>.sha256``, beside the file it vouches for."""
    path = Path(path)
    return path.with_name(path.name + DIGEST_SUFFIX)


def write_digest(path: Path, digest: str) -> Path:
    """Record ``digest`` (of ``path``'s bytes, as just written) in its side-car, atomically.
    Written after the file itself: a crash in between leaves a side-car that does not match,
    and the file is recomputed."""
    from rig_io.atomic import write_text_atomic

    return write_text_atomic(digest_path(path), f"{digest}\n")


def digest_matches(path: Path) -> bool:
    """True only when ``path`` exists and its bytes have the SHA-256 its side-car records.
    A file without a side-car (written before it existed) is not trusted either: a file whose
    footer survives while its pages do not would still look readable."""
    try:
        recorded = digest_path(path).read_text(encoding="utf-8").strip()
        return bool(recorded) and Path(path).is_file() and sha256_file(path) == recorded
    except (OSError, UnicodeDecodeError):
        return False


@lru_cache(maxsize=64)
def source_hash(cls: type) -> str:
    """Hash of the code a model family runs: the module defining ``cls`` and every module
    of its package it imports transitively (:func:`code_files`), so that editing e.g. the
    play operator kernel refits the Gamma models."""
    files = code_files(cls.__module__)
    if not files:
        try:
            src = inspect.getsourcefile(cls)
        except TypeError:
            src = None
        if src is None:
            return "no-source"
        files = {cls.__module__: Path(src)}
    h = hashlib.sha256()
    for name in sorted(files):
        h.update(name.encode() + b"\0")
        h.update(hashlib.sha256(_read_source(files[name])).digest())
    return _digest(h)


def combine(parts: Mapping[str, Any]) -> str:
    """One key from named parts (each JSON-able), including :data:`CACHE_VERSION`."""
    return hash_json({"version": CACHE_VERSION, **parts})
