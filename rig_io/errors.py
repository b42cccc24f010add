"""The one error class of :mod:`rig_io` (as rosbags does: one error class per package), and
its one refinement, :class:`WriteError`, that a stage must not treat as a bad run."""

from __future__ import annotations

from typing import Any

#: The reason part of a message is cut here: a bad file must never put megabytes into a
#: report (a NUL "header" of a 1 GiB file once did).
MAX_REASON_CHARS = 200
#: A quoted value (a cell, a header, a manifest value) is cut here.
MAX_VALUE_CHARS = 60


def short(value: Any, limit: int = MAX_VALUE_CHARS) -> str:
    """``repr(value)``, cut to ``limit`` characters with its full length noted (numpy
    scalars shown as the Python number they hold)."""
    if type(value).__module__ == "numpy" and hasattr(value, "item"):
        value = value.item()
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} chars)"


def _cap(text: str, limit: int) -> str:
    return text if len(text) <= limit else f"{text[:limit]}... [{len(text) - limit} more chars]"


class RigIOError(Exception):
    """Any problem reading, writing or importing a rig run.

    The message always names what it can of: the run, the file, the key (a manifest key or
    a column), and the row or time, so that a researcher can go straight to the offending
    line of a raw log. The reason is capped at :data:`MAX_REASON_CHARS` characters.
    """

    def __init__(
        self,
        message: str,
        *,
        run: str | None = None,
        file: str | None = None,
        key: str | None = None,
        row: int | None = None,
        t_ns: int | None = None,
    ) -> None:
        self.run = run if run is None else _cap(str(run), 2 * MAX_VALUE_CHARS)
        self.file = file if file is None else _cap(str(file), 4 * MAX_REASON_CHARS)
        self.key = key if key is None else _cap(str(key), MAX_VALUE_CHARS)
        self.row = row
        self.t_ns = t_ns
        where = []
        if self.run is not None:
            where.append(f"run {self.run!r}")
        if self.file is not None:
            where.append(f"file {self.file!r}")
        if self.key is not None:
            where.append(f"key {self.key}")
        if row is not None:
            where.append(f"row {row}")
        if t_ns is not None:
            where.append(f"t={t_ns} ns ({t_ns / 1e9:.3f} s)")
        self.reason = _cap(str(message), MAX_REASON_CHARS)
        super().__init__(f"{', '.join(where)}: {self.reason}" if where else self.reason)


class WriteError(RigIOError):
    """An output could not be written (disk full, no permission, read-only file system...).

    A failure of the stage, never a reject of the run being processed: a stage that meets it
    stops without pruning or removing anything, since the input was fine and only the
    output could not be stored. It is a :class:`RigIOError`, so callers that catch the
    package's error still catch it; those that reject runs re-raise it first.
    """
