"""One calibrated run -> its rows of the processed dataset (pure; no files).

:func:`process_run` synchronises every stream onto the encoder time base, picks the output
channel (output encoder, else tracker, else camera), removes start offsets, normalises by the
maximum input amplitude and returns the rows (schema in :mod:`rig_io.schema`) plus the run's
metadata (units, offsets, latency used and how, ...).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from rig_io.calibrate import PhysicalRun, encoder_unit, vision_unit
from rig_io.checks import check_moves
from rig_io.errors import RigIOError
from rig_io.manifest import excitation_name
from rig_io.normalise import normalise
from rig_io.schema import COLUMNS
from rig_io.synchronise import SyncOptions, synchronise

#: Bumped whenever the processing changes what a run's rows are (part of the cache key).
INGEST_VERSION = "1.2.0"


def process_run(run: PhysicalRun, *, sync: SyncOptions | None = None
                ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The dataset rows of ``run`` and its metadata."""
    synced = synchronise(run, sync)
    ch = synced.channels
    m = run.manifest
    if np.isfinite(ch["output_encoder"]).any():
        output, source, out_unit = ch["output_encoder"], "encoder", encoder_unit(m)
    elif "tracker" in ch and np.isfinite(ch["tracker"]).any():
        output, source, out_unit = ch["tracker"], "tracker", vision_unit(m, "tracker")
    elif "camera" in ch and np.isfinite(ch["camera"]).any():
        output, source, out_unit = ch["camera"], "camera", vision_unit(m, "camera")
    else:
        raise RigIOError("no output channel: no output encoder, tracker or camera values",
                         run=run.run_id, file=run.file("encoder"))
    # Keep the span where the output is measured (a tracker may start late or stop early).
    finite = np.flatnonzero(np.isfinite(output) & np.isfinite(ch["input"]))
    if finite.size < 2:
        raise RigIOError("fewer than two samples with both input and output",
                         run=run.run_id, file=run.file("encoder"))
    lo, hi = int(finite[0]), int(finite[-1]) + 1
    keep = slice(lo, hi)
    if np.isnan(output[keep]).any():
        i = lo + int(np.flatnonzero(np.isnan(output[keep]))[0])
        raise RigIOError(f"output ({source}) missing inside the run", run=run.run_id,
                         file=run.file(source if source != "encoder" else "encoder"),
                         t_ns=int(synced.info["t0_ns"] + round(synced.t_s[i] * 1e9)))
    # a channel that never moves holds no hysteresis (a stuck encoder "fits" perfectly)
    counts = float((m.get("channels") or {}).get("encoder", {}).get("counts_per_unit") or 0.0)
    count = 1.0 / counts if counts > 0 else 0.0
    check_moves(ch["input"][keep], channel="input (encoder)", key="input", unit=encoder_unit(m),
                resolution=count, run=run.run_id, file=run.file("encoder"))
    check_moves(output[keep], channel=f"output ({source})", key="output", unit=out_unit,
                resolution=count if source == "encoder" else 0.0, run=run.run_id,
                file=run.file(source))
    t_s = synced.t_s[keep] - synced.t_s[lo]
    # encoders count relative to their first sample (the format says so); a tracker or a
    # camera measures an absolute quantity, whose level at the start is part of the state
    norm = normalise(ch["input"][keep], output[keep], rezero_output=source == "encoder")
    amp = float(norm["input_amplitude"])
    if not np.isfinite(amp) or amp <= 0:
        raise RigIOError("the input never moves (maximum input amplitude is 0)",
                         run=run.run_id, file=run.file("encoder"))
    n = t_s.size
    config = m.get("configuration") or {}

    def col(name: str) -> np.ndarray:
        arr = ch.get(name)
        return np.full(n, np.nan) if arr is None else np.asarray(arr[keep], dtype=float)

    def num(value: Any) -> float:
        return float(value) if value is not None else float("nan")

    frame = pd.DataFrame({
        "run_id": pd.Series([run.run_id] * n, dtype="str"),
        "rig": pd.Series([str(m.get("rig", ""))] * n, dtype="str"),
        "curve_angle_deg": np.full(n, num(config.get("curve_angle_deg"))),
        "radius_mm": np.full(n, num(config.get("radius_mm"))),
        "excitation": pd.Series([excitation_name(m["excitation"])] * n, dtype="str"),
        "t_s": t_s,
        "input": norm["input"],
        "output": norm["output"],
        "input_norm": norm["input_norm"],
        "output_norm": norm["output_norm"],
        "tension_in_n": col("tension_in_n"),
        "tension_out_n": col("tension_out_n"),
        "camera": col("camera"),
        "tracker": col("tracker"),
        "tension_proxy": col("tension_proxy"),
    }, columns=list(COLUMNS))
    info = dict(synced.info)
    enc_applied: dict[str, Any] = dict(run.applied.get("encoder") or {})
    info.update(
        run_id=run.run_id,
        rig=m.get("rig"),
        excitation=m.get("excitation"),
        configuration=config,
        ingest_version=INGEST_VERSION,
        n_samples=int(n),
        duration_s=float(t_s[-1]),
        trimmed_samples=int(synced.t_s.size - n),
        t0_ns=int(synced.info["t0_ns"] + round(synced.t_s[lo] * 1e9)),
        output_source=source,
        units={"input": encoder_unit(m), "output": out_unit,
               "camera": vision_unit(m, "camera") if run.camera is not None else None,
               "tracker": vision_unit(m, "tracker") if run.tracker is not None else None,
               "tension": "N"},
        # The whole offset between the recorded reading and the dataset's value: the counter's
        # start reading (encoder channels) plus the re-zeroing at the run's first sample.
        input_offset=float(norm["input_offset"]) + float(enc_applied.get("input_start_removed",
                                                                          0.0)),
        output_offset=float(norm["output_offset"]) + (
            float(enc_applied.get("output_start_removed", 0.0)) if source == "encoder" else 0.0),
        rezeroed={"input": float(norm["input_offset"]), "output": float(norm["output_offset"])},
        calibration=run.applied,
        input_amplitude=amp,
    )
    return frame, info
