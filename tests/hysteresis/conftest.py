"""Shared fixtures of the model-family tests."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def virtual_pair_90_30() -> tuple[np.ndarray, ...]:
    """Seed 001 section 4.5 on the virtual rig at 90 deg / 30 mm, in mm: the sine-decay
    identification run and a triangle validation run, as (u, y, u_triangle, y_triangle)."""
    from rig_io.calibrate import calibrate_raw_run
    from rig_io.virtual import simulate_run

    amps = [6.0, 4.5, 3.0, 1.5]
    exc = [
        {"kind": "sine_decay", "amplitudes_mm": amps, "periods_per_amplitude": 5,
         "frequency_hz": 0.25},
        {"kind": "triangle_decay", "amplitudes_mm": amps, "periods_per_amplitude": 3,
         "slope_mm_s": 6.0},
    ]
    out: list[np.ndarray] = []
    for seed, e in enumerate(exc, start=1):
        enc = calibrate_raw_run(simulate_run(curve_angle_deg=90.0, radius_mm=30.0,
                                             excitation=e, seed=seed)).encoder
        out += [enc["input"].to_numpy(), enc["output"].to_numpy()]
    return tuple(out)
