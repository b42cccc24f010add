"""Calibration: raw rig values to physical units (rig-log-format.md section 1 and 2).

The common in-memory form after calibration is :class:`PhysicalRun`: the manifest plus one
table per stream in the manifest's units (encoder ``unit``, newtons, the camera quantity's
unit). Run folders reach it through :func:`calibrate_raw_run`; bags (values in SI units) through
:func:`from_si`; importers build it directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from rig_io.errors import RigIOError
from rig_io.manifest import LOADCELL_CALIBRATION
from rig_io.run import RawRun

#: Columns of the calibrated streams.
PHYS_ENCODER = ("t_ns", "input", "output")
PHYS_LOADCELL = ("t_ns", "tension_in_n", "tension_out_n")
PHYS_VISION = ("t_ns", "frame", "value", "confidence")


@dataclass
class PhysicalRun:
    """A run in physical units; ``output`` is NaN where the rig has no output encoder."""

    manifest: dict[str, Any]
    encoder: pd.DataFrame
    loadcell: pd.DataFrame | None = None
    camera: pd.DataFrame | None = None
    tracker: pd.DataFrame | None = None
    events: pd.DataFrame | None = None
    #: File that held each stream (for error messages).
    files: dict[str, str] = field(default_factory=dict)
    #: Extra per-sample columns on the encoder time base (importers: e.g. a tension proxy).
    extra: dict[str, npt.NDArray[np.float64]] = field(default_factory=dict)
    #: What turning the raw values into these did (signs, scales, zeros, start offsets), so
    #: that ingest records every interpretation it applied with its true value.
    applied: dict[str, Any] = field(default_factory=dict)

    @property
    def run_id(self) -> str:
        return str(self.manifest["run_id"])

    def file(self, stream: str) -> str:
        return self.files.get(stream, stream)


def unwrap_counts(counts: npt.ArrayLike, bits: int) -> npt.NDArray[np.int64]:
    """Unwrap a ``bits``-bit up/down counter: counts relative to the first sample.

    Consecutive differences are folded into [-2**(bits-1), 2**(bits-1)), which is exact as
    long as the counter moves less than half its range between two samples.
    """
    c = np.asarray(counts, dtype=np.int64)
    if c.size == 0:
        return c
    modulus = np.int64(1) << np.int64(bits)
    half = modulus >> np.int64(1)
    d = np.diff(c)
    d = (d + half) % modulus - half
    out = np.empty_like(c)
    out[0] = 0
    np.cumsum(d, out=out[1:])
    return out


def counts_to_units(counts: npt.ArrayLike, *, counts_per_unit: float, bits: int,
                    sign: int) -> npt.NDArray[np.float64]:
    """Position in the encoder's unit: sign x unwrapped counts / counts_per_unit."""
    return float(sign) * unwrap_counts(counts, bits).astype(float) / float(counts_per_unit)


def mv_per_v_to_newton(raw: npt.ArrayLike, *, zero_mv_per_v: float,
                       newton_per_mv_per_v: float) -> npt.NDArray[np.float64]:
    """Bridge output in mV/V to force in N: (raw - zero) x gain."""
    return (np.asarray(raw, dtype=float) - float(zero_mv_per_v)) * float(newton_per_mv_per_v)


def newton_to_mv_per_v(force: npt.ArrayLike, *, zero_mv_per_v: float,
                       newton_per_mv_per_v: float) -> npt.NDArray[np.float64]:
    """Inverse of :func:`mv_per_v_to_newton` (the virtual rig and the bag round trip)."""
    return np.asarray(force, dtype=float) / float(newton_per_mv_per_v) + float(zero_mv_per_v)


# ------------------------------------------------------------------------------ SI <-> units

_TO_SI = {"mm": 1e-3, "m": 1.0, "deg": math.pi / 180.0, "rad": 1.0}


def si_factor(unit: str, *, run: str | None = None, file: str | None = None) -> float:
    """Multiply a value in ``unit`` by this to get SI (m or rad)."""
    try:
        return _TO_SI[unit]
    except KeyError:
        raise RigIOError(f"unknown unit {unit!r} (known: {', '.join(_TO_SI)})",
                         run=run, file=file) from None


def encoder_unit(manifest: dict[str, Any]) -> str:
    """The encoder's unit (``mm`` when a bag's manifest does not say)."""
    enc = manifest.get("channels", {}).get("encoder") or {}
    return str(enc.get("unit", "mm"))


def vision_unit(manifest: dict[str, Any], stream: str) -> str:
    """Unit of a camera/tracker ``quantity``: ``tip_angle_deg`` -> deg, ``output_mm`` -> mm."""
    ch = manifest.get("channels", {}).get(stream) or {}
    quantity = str(ch.get("quantity", "tip_angle_deg"))
    return "deg" if quantity.endswith("_deg") else "mm" if quantity.endswith("_mm") else "mm"


# ------------------------------------------------------------------------------- raw -> phys

def calibrate_raw_run(run: RawRun, *, files: dict[str, str] | None = None) -> PhysicalRun:
    """Counts to units (sign, wrap-around unwrapped), mV/V to newtons."""
    m = run.manifest
    enc = m["channels"]["encoder"]
    bits, cpu = int(enc["counter_bits"]), float(enc["counts_per_unit"])
    t = run.encoder["t_ns"].to_numpy(dtype=np.int64)
    in_counts = run.encoder["input_counts"].to_numpy(dtype=np.int64)
    inp = counts_to_units(in_counts, counts_per_unit=cpu, bits=bits,
                          sign=int(enc["input_sign"]))
    # Positions are relative to the first sample (format section 1): the counter's start
    # reading is removed here, and recorded so that no offset is removed silently.
    applied: dict[str, Any] = {"encoder": {
        "unit": encoder_unit(m), "counts_per_unit": cpu, "counter_bits": bits,
        "input_sign": int(enc["input_sign"]), "output_sign": int(enc["output_sign"]),
        "input_counter_start": int(in_counts[0]),
        "input_start_removed": int(enc["input_sign"]) * float(in_counts[0]) / cpu}}
    out_raw = run.encoder["output_counts"]
    if out_raw.isna().all():
        out = np.full(t.size, np.nan)
    else:
        out_counts = out_raw.to_numpy(dtype=np.int64)
        out = counts_to_units(out_counts, counts_per_unit=cpu, bits=bits,
                              sign=int(enc["output_sign"]))
        applied["encoder"].update(
            output_counter_start=int(out_counts[0]),
            output_start_removed=int(enc["output_sign"]) * float(out_counts[0]) / cpu)
    encoder = pd.DataFrame({"t_ns": t, "input": inp, "output": out})
    loadcell = None
    if run.loadcell is not None:
        cells = (m.get("channels") or {}).get("loadcell") or {}
        applied["loadcell"] = {}
        loadcell = pd.DataFrame({"t_ns": run.loadcell["t_ns"].to_numpy(dtype=np.int64)})
        for side, col in (("input", "tension_in_n"), ("output", "tension_out_n")):
            cell = cells.get(side) or {}
            raw_mv = run.loadcell[f"{side}_mv_per_v"].to_numpy(dtype=np.float64)
            if all(cell.get(k) is not None for k in LOADCELL_CALIBRATION):
                applied["loadcell"][side] = {
                    "zero_mv_per_v": float(cell["zero_mv_per_v"]),
                    "newton_per_mv_per_v": float(cell["newton_per_mv_per_v"])}
                loadcell[col] = mv_per_v_to_newton(
                    raw_mv, zero_mv_per_v=cell["zero_mv_per_v"],
                    newton_per_mv_per_v=cell["newton_per_mv_per_v"])
                continue
            # no zero and gain: never newtons; the input cell's raw mV/V is the tension proxy
            loadcell[col] = np.full(raw_mv.size, np.nan)
            kept = "tension_proxy (mV/V)" if side == "input" else "not kept (no raw column)"
            applied["loadcell"][side] = {"calibrated": False, "unit": "mV/V", "raw": kept}
            if side == "input":
                loadcell["tension_proxy"] = raw_mv
    return PhysicalRun(manifest=m, encoder=encoder, loadcell=loadcell,
                       camera=_vision(run.camera), tracker=_vision(run.tracker),
                       events=run.events, files=dict(files or {}), applied=applied)


def _vision(frame: pd.DataFrame | None) -> pd.DataFrame | None:
    if frame is None:
        return None
    return pd.DataFrame({
        "t_ns": frame["t_ns"].to_numpy(dtype=np.int64),
        "frame": frame["frame"].to_numpy(dtype=np.int64),
        "value": pd.to_numeric(frame["value"]).to_numpy(dtype=float, na_value=np.nan),
        "confidence": pd.to_numeric(frame["confidence"]).to_numpy(dtype=float,
                                                                  na_value=np.nan),
    })
