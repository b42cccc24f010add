"""In-memory form of one raw run of the ``tsm-rig-log/1`` format.

A :class:`RawRun` holds exactly what a run folder holds: the manifest and one table per
stream, with the raw columns of ``../shared/rig-log-format.md`` (integer nanosecond
timestamps, encoder counts, load-cell mV/V). Writers serialise it; the virtual rig produces
it; readers of run folders give it back. Physical units appear only after ingest.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pandas as pd

FORMAT = "tsm-rig-log/1"

#: Columns of each stream, in file order (rig-log-format.md section 1).
ENCODER_COLUMNS = ("t_ns", "input_counts", "output_counts")
LOADCELL_COLUMNS = ("t_ns", "input_mv_per_v", "output_mv_per_v")
CAMERA_COLUMNS = ("t_ns", "frame", "value", "confidence")
TRACKER_COLUMNS = CAMERA_COLUMNS
EVENTS_COLUMNS = ("t_ns", "event", "detail")

STREAM_COLUMNS: dict[str, tuple[str, ...]] = {
    "encoder": ENCODER_COLUMNS,
    "loadcell": LOADCELL_COLUMNS,
    "camera": CAMERA_COLUMNS,
    "tracker": TRACKER_COLUMNS,
    "events": EVENTS_COLUMNS,
}
REQUIRED_STREAMS = ("encoder",)
EVENT_KINDS = ("start", "stop", "estop", "note")


@dataclass(frozen=True)
class RawRun:
    """One excitation applied to one configuration, as the rig logged it.

    ``encoder`` is required; the other streams are ``None`` when the rig did not log them.
    ``output_counts`` may hold missing values (pandas ``Int64``) on a bending-joint rig
    without a distal encoder.
    """

    manifest: dict[str, Any]
    encoder: pd.DataFrame
    loadcell: pd.DataFrame | None = None
    camera: pd.DataFrame | None = None
    tracker: pd.DataFrame | None = None
    events: pd.DataFrame | None = None
    #: Free-form provenance that is not part of the format (e.g. the simulator's ground truth).
    extras: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def run_id(self) -> str:
        return str(self.manifest["run_id"])

    def streams(self) -> dict[str, pd.DataFrame]:
        """The streams present, keyed by file stem (``encoder``, ``loadcell``, ...)."""
        out: dict[str, pd.DataFrame] = {"encoder": self.encoder}
        for name in ("loadcell", "camera", "tracker", "events"):
            frame = getattr(self, name)
            if frame is not None:
                out[name] = frame
        return out
