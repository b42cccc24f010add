"""The standard campaign of seed 001 (chapter 3.1.1): 24 configurations x 3 excitations,
plus the two evaluation-only excitations of :data:`EVALUATION_EXCITATIONS`."""

from __future__ import annotations

import copy
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from rig_io.virtual.excitations import EVALUATION_EXCITATIONS

CURVE_ANGLES_DEG = (15, 30, 45, 60, 75, 90)
RADII_MM = (30, 45, 60, 75)
AMPLITUDES_MM = [6.0, 4.5, 3.0, 1.5]
STANDARD_EXCITATIONS: tuple[dict[str, Any], ...] = (
    {"kind": "sine_decay", "amplitudes_mm": AMPLITUDES_MM, "periods_per_amplitude": 5,
     "frequency_hz": 0.25},
    {"kind": "triangle_decay", "amplitudes_mm": AMPLITUDES_MM, "periods_per_amplitude": 5,
     "slope_mm_s": 6.0},
    {"kind": "trapezoid_decay", "amplitudes_mm": AMPLITUDES_MM, "periods_per_amplitude": 5,
     "slope_mm_s": 6.0, "dwell_s": 0.5},
    *EVALUATION_EXCITATIONS,
)
_START = datetime(2026, 3, 2, 9, 0, tzinfo=UTC)


def run_seed(campaign_seed: int, index: int) -> int:
    """Seed of run ``index`` of a campaign: independent streams, reproducible from the seed."""
    return int(np.random.SeedSequence([int(campaign_seed), int(index)]).generate_state(1)[0])


def standard_campaign(seed: int = 0, *, rig: str = "tsm-bench",
                      curve_angles_deg: Any = CURVE_ANGLES_DEG, radii_mm: Any = RADII_MM,
                      excitations: Any = STANDARD_EXCITATIONS,
                      effects: dict[str, float] | None = None,
                      sensors: dict[str, Any] | None = None,
                      minutes_per_run: float = 3.0) -> list[dict[str, Any]]:
    """Run specs (keyword arguments of :func:`simulate_run`) of the standard campaign.

    Order: curve angle, then radius, then excitation; run ids
    ``phi090_r030_sine_decay_0001`` with the 1-based campaign index. All effects are off
    unless ``effects`` says otherwise.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"campaign seed must be a non-negative integer, got {seed!r}")
    specs: list[dict[str, Any]] = []
    index = 0
    for phi in curve_angles_deg:
        for r in radii_mm:
            for exc in excitations:
                exc = copy.deepcopy(dict(exc))
                if "kind" not in exc:
                    raise ValueError(f"campaign excitation without 'kind': {exc!r}")
                index += 1
                started = _START + timedelta(minutes=minutes_per_run * (index - 1))
                spec: dict[str, Any] = {
                    "run_id": f"phi{int(phi):03d}_r{int(r):03d}_{exc['kind']}_{index:04d}",
                    "rig": rig,
                    "curve_angle_deg": phi,
                    "radius_mm": r,
                    "excitation": exc,
                    "effects": dict(effects or {}),
                    "seed": run_seed(int(seed), index),
                    "started_at": started.strftime("%Y-%m-%dT%H:%M:%SZ"),
                }
                if sensors:
                    spec["sensors"] = dict(sensors)
                specs.append(spec)
    return specs
