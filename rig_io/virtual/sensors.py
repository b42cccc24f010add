"""Sensor models of the virtual rig: what the rig's loggers would write (format section 1)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

FloatArray = npt.NDArray[np.float64]

COUNTER_BITS = 32


@dataclass(frozen=True)
class SensorConfig:
    """Sensor set-up; ``simulate_run(sensors=...)`` overrides any of these by name."""

    input_unit: str = "mm"  # "mm" of pull, or "deg" of motor angle (bending joint)
    counts_per_mm: float = 10000.0  # linear encoders (Renishaw ATOM, 0.1 um)
    counts_per_deg: float = 1000.0  # motor encoder when the input is an angle
    output_sign: int = -1  # the follower encoder counts backwards (manifest example)
    #: "random" (anywhere in the 32-bit range), "near_wrap" (crosses the wrap in the run),
    #: "zero", or an integer start value.
    counter_start: Any = "random"
    loadcell: bool = True
    loadcell_rate_hz: float = 1000.0
    newton_per_mv_per_v: float = 9.81
    loadcell_range_n: float = 20.0
    loadcell_zero_sd_mv_per_v: float = 0.01
    loadcell_noise_mv_per_v: float = 0.0008
    camera: bool = True
    camera_rate_hz: float = 30.0
    camera_latency_ms: float = 45.0  # nominal (written to the manifest)
    camera_latency_sd_ms: float = 6.0  # run-to-run spread of the true mean latency
    camera_jitter_ms: float = 3.0
    camera_drop_rate: float = 0.02
    camera_unconfident_rate: float = 0.01
    camera_noise_mm: float = 0.03
    camera_noise_deg: float = 0.5
    tracker: bool | None = None  # None: on for bending-joint, off for the bench
    tracker_rate_hz: float = 40.0
    tracker_latency_ms: float = 8.0
    tracker_noise_mm: float = 0.005
    tracker_noise_deg: float = 0.05

    @classmethod
    def from_mapping(cls, sensors: dict[str, Any] | None) -> SensorConfig:
        base = cls()
        if not sensors:
            return base
        known = set(asdict(base))
        bad = sorted(set(sensors) - known)
        if bad:
            raise ValueError(f"unknown sensor option(s) {bad}; known: {sorted(known)}")
        cfg = replace(base, **sensors)
        if cfg.input_unit not in ("mm", "deg"):
            raise ValueError(f"sensors.input_unit must be 'mm' or 'deg', got {cfg.input_unit!r}")
        if cfg.output_sign not in (1, -1):
            raise ValueError(f"sensors.output_sign must be 1 or -1, got {cfg.output_sign!r}")
        for name in ("camera_drop_rate", "camera_unconfident_rate"):
            if not 0.0 <= float(getattr(cfg, name)) < 0.5:
                raise ValueError(f"sensors.{name} must be in [0, 0.5)")
        return cfg


def wrap_counts(counts: npt.NDArray[np.int64], bits: int = COUNTER_BITS
                ) -> npt.NDArray[np.int64]:
    """Two's-complement wrap of an up/down counter of ``bits`` bits (signed values)."""
    span = 1 << bits
    half = 1 << (bits - 1)
    return ((counts + half) % span) - half


def counter_start(cfg: SensorConfig, rng: np.random.Generator, travel_counts: int) -> int:
    """Where a counter starts: the logger never zeroes it, so it starts anywhere."""
    spec = cfg.counter_start
    half = 1 << (COUNTER_BITS - 1)
    if spec == "random":
        return int(rng.integers(-half, half))
    if spec == "zero":
        return 0
    if spec == "near_wrap":
        # Close enough below the top that the run's travel crosses the wrap.
        return int(half - 1 - rng.integers(0, max(1, travel_counts // 2) + 1))
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool):
        return int(spec)
    raise ValueError(f"sensors.counter_start must be 'random', 'near_wrap', 'zero' or an int, "
                     f"got {spec!r}")


def encoder_counts(pos: FloatArray, start: int, counts_per_unit: float, sign: int
                   ) -> npt.NDArray[np.int64]:
    """Quantised, wrapping counts of a position (relative to its first sample)."""
    rel = np.rint(sign * (pos - pos[0]) * counts_per_unit).astype(np.int64)
    return wrap_counts(rel + np.int64(start))


def loadcell_raw(force_n: FloatArray, zero: float, cfg: SensorConfig, rng: np.random.Generator
                 ) -> FloatArray:
    """Bridge output in mV/V: offset, noise, and saturation at the range."""
    npm = cfg.newton_per_mv_per_v
    raw = zero + force_n / npm + rng.normal(0.0, cfg.loadcell_noise_mv_per_v, force_n.shape)
    hi = zero + cfg.loadcell_range_n / npm
    lo = zero - cfg.loadcell_range_n / npm
    return np.asarray(np.round(np.clip(raw, lo, hi), 6), dtype=np.float64)


def vision_frames(t_end_s: float, value_at: Any, *, rate_hz: float, latency_s: float,
                  jitter_s: float, drop_rate: float, unconfident_rate: float, noise: float,
                  rng: np.random.Generator, confident: bool = False) -> pd.DataFrame:
    """Frames captured at ``rate_hz``, stamped when processed (capture + latency + jitter).

    ``value_at(t_capture)`` gives the true quantity. Dropped frames leave gaps in ``frame``;
    unconfident frames have confidence 0 and an empty value.
    """
    n = int(np.floor(t_end_s * rate_hz))
    capture = np.arange(n, dtype=float) / rate_hz + rng.uniform(0.0, 1.0 / rate_hz)
    stamp = capture + latency_s + np.abs(rng.normal(0.0, jitter_s, n))
    keep = (rng.random(n) >= drop_rate) & (stamp <= t_end_s)
    frame = np.arange(n, dtype=np.int64)[keep]
    capture, stamp = capture[keep], stamp[keep]
    value = value_at(capture) + rng.normal(0.0, noise, capture.shape)
    if confident:
        conf = np.ones_like(value)
    else:
        conf = np.clip(rng.normal(0.9, 0.05, value.shape), 0.3, 1.0)
    bad = rng.random(value.shape) < unconfident_rate
    value = np.where(bad, np.nan, value)
    conf = np.where(bad, 0.0, conf)
    t_ns = np.rint(stamp * 1e9).astype(np.int64)
    t_ns = np.maximum.accumulate(t_ns)  # processing is sequential: stamps never go back
    dup = np.flatnonzero(np.diff(t_ns) <= 0)
    for i in dup:  # vanishingly rare: nudge a repeated stamp by 1 ms
        t_ns[i + 1] = t_ns[i] + 1_000_000
    return pd.DataFrame({"t_ns": t_ns, "frame": frame, "value": np.round(value, 5),
                         "confidence": np.round(conf, 3)})
