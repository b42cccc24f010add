"""The one error class of :mod:`rig_io` (as rosbags does: one error class per package)."""

from __future__ import annotations


class RigIOError(Exception):
    """Any problem reading, writing or importing a rig run.

    The message always names what it can of: the run, the file, and the row or time,
    so that a researcher can go straight to the offending line of a raw log.
    """

    def __init__(
        self,
        message: str,
        *,
        run: str | None = None,
        file: str | None = None,
        row: int | None = None,
        t_ns: int | None = None,
    ) -> None:
        self.run = run
        self.file = file
        self.row = row
        self.t_ns = t_ns
        where = []
        if run is not None:
            where.append(f"run {run!r}")
        if file is not None:
            where.append(f"file {file!r}")
        if row is not None:
            where.append(f"row {row}")
        if t_ns is not None:
            where.append(f"t={t_ns} ns ({t_ns / 1e9:.3f} s)")
        self.reason = message
        super().__init__(f"{', '.join(where)}: {message}" if where else message)
