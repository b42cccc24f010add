"""Small hand-built raw runs for tests and examples (no physics: see ``rig_io.virtual``).

:func:`make_raw_run` writes exactly the raw columns a rig logs: encoder counts (optionally
starting near the counter's wrap-around), load cells in mV/V, a delayed noisy camera, a
tracker and events, from a known output law so tests can check calibration and latency.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from rig_io.calibrate import newton_to_mv_per_v
from rig_io.run import FORMAT, RawRun


def make_manifest(run_id: str, *, rig: str = "tsm-bench", curve_angle_deg: float | None = 90,
                  radius_mm: float | None = 30, unit: str = "mm",
                  counts_per_unit: float = 10000, counter_bits: int = 32,
                  camera_latency_ms: float = 45.0, quantity: str = "output_mm",
                  frequency_hz: float = 0.5) -> dict[str, Any]:
    """A complete manifest (format section 1) for a sine excitation."""
    cell = {"newton_per_mv_per_v": 9.81, "zero_mv_per_v": 0.012, "range_n": 20.0}
    return {
        "format": FORMAT,
        "run_id": run_id,
        "rig": rig,
        "started_at": "2026-03-02T10:15:00Z",
        "configuration": {"curve_angle_deg": curve_angle_deg, "radius_mm": radius_mm},
        "excitation": {"kind": "sine", "amplitude": 3.0, "offset": 0.0,
                       "frequency_hz": frequency_hz},
        "channels": {
            "encoder": {"unit": unit, "counts_per_unit": counts_per_unit,
                        "counter_bits": counter_bits, "input_sign": 1, "output_sign": -1},
            "loadcell": {"input": dict(cell), "output": {**cell, "zero_mv_per_v": -0.004}},
            "camera": {"quantity": quantity, "source": "camera",
                       "nominal_latency_ms": camera_latency_ms, "rate_hz": 30},
            "tracker": {"quantity": quantity, "source": "tracker"},
        },
        "notes": "synthetic",
    }


def make_raw_run(run_id: str = "synthetic_0001", *, duration_s: float = 10.0,
                 amplitude: float = 3.0, frequency_hz: float = 0.5,
                 counts_start: int = 0, counter_bits: int = 32,
                 camera_latency_ms: float = 45.0, with_output_encoder: bool = True,
                 with_loadcell: bool = True, with_camera: bool = True,
                 with_tracker: bool = False, with_events: bool = True,
                 seed: int = 0, **manifest_kw: Any) -> RawRun:
    """A deterministic raw run: input a sine, output = 0.8 x input lagged by a backlash-free
    first-order filter, tensions proportional to |velocity|, camera = output delayed."""
    rng = np.random.default_rng(seed)
    cpu = 10000.0
    t_ns = np.arange(int(round(duration_s * 100)), dtype=np.int64) * 10_000_000
    t = t_ns / 1e9
    u = amplitude * np.sin(2 * np.pi * frequency_hz * t)
    y = 0.8 * amplitude * np.sin(2 * np.pi * frequency_hz * t - 0.2)
    y = y - y[0]
    modulus = 1 << counter_bits
    half = modulus >> 1

    def wrap(c: np.ndarray) -> np.ndarray:
        return ((c + half) % modulus - half).astype(np.int64)

    in_counts = wrap(counts_start + np.round(u * cpu).astype(np.int64))
    # output_sign is -1 in the manifest: the counter counts the other way.
    out_counts = wrap(counts_start - np.round(y * cpu).astype(np.int64))
    encoder = pd.DataFrame({
        "t_ns": t_ns, "input_counts": in_counts,
        "output_counts": pd.array(out_counts if with_output_encoder else [pd.NA] * t.size,
                                  dtype="Int64"),
    })
    manifest = make_manifest(run_id, counter_bits=counter_bits,
                             camera_latency_ms=camera_latency_ms, frequency_hz=frequency_hz,
                             **manifest_kw)
    if not with_output_encoder:
        manifest["rig"] = "bending-joint"
    loadcell = None
    if with_loadcell:
        tl = np.arange(int(round(duration_s * 1000)), dtype=np.int64) * 1_000_000
        vel = np.abs(np.cos(2 * np.pi * frequency_hz * tl / 1e9))
        f_in = 5.0 + 3.0 * vel + 0.01 * rng.standard_normal(tl.size)
        f_out = 4.0 + 2.0 * vel + 0.01 * rng.standard_normal(tl.size)
        cells = manifest["channels"]["loadcell"]
        loadcell = pd.DataFrame({
            "t_ns": tl,
            "input_mv_per_v": newton_to_mv_per_v(f_in, **_cal(cells["input"])),
            "output_mv_per_v": newton_to_mv_per_v(f_out, **_cal(cells["output"])),
        })
    camera = tracker = None
    if with_camera:
        tc = np.arange(0.0, duration_s, 1 / 30.0)
        tc = tc + rng.uniform(0, 0.004, tc.size)
        true = np.interp(tc - camera_latency_ms / 1e3, t, y)
        value = true + 0.02 * amplitude * rng.standard_normal(tc.size)
        conf = rng.uniform(0.5, 1.0, tc.size)
        conf[::17] = 0.0
        camera = pd.DataFrame({"t_ns": np.round(tc * 1e9).astype(np.int64),
                               "frame": np.arange(tc.size, dtype=np.int64),
                               "value": value, "confidence": conf})
    if with_tracker:
        tt = t_ns[::2]
        tracker = pd.DataFrame({"t_ns": tt, "frame": np.arange(tt.size, dtype=np.int64),
                                "value": np.interp(tt / 1e9, t, y),
                                "confidence": np.ones(tt.size)})
    events = None
    if with_events:
        events = pd.DataFrame({"t_ns": np.array([0, int(t_ns[-1])], dtype=np.int64),
                               "event": np.array(["start", "stop"], dtype=object),
                               "detail": np.array(["", "done"], dtype=object)})
    return RawRun(manifest=manifest, encoder=encoder, loadcell=loadcell, camera=camera,
                  tracker=tracker, events=events,
                  extras={"true_output": y, "true_input": u - u[0]})


def _cal(cell: dict[str, Any]) -> dict[str, float]:
    return {"zero_mv_per_v": float(cell["zero_mv_per_v"]),
            "newton_per_mv_per_v": float(cell["newton_per_mv_per_v"])}
