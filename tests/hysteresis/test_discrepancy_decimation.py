"""The analysis decimation keeps the input's reversals: a hysteresis plant's memory is set by
the extremes of the input it saw, and a moving average shaves a sharp corner."""

from __future__ import annotations

import numpy as np

from hysteresis.discrepancy._ops import play
from hysteresis.discrepancy.runs import RunData, turning_samples


def _triangle(n: int = 8001, dt: float = 0.01, slope: float = 3.5, amp: float = 5.0
              ) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * dt
    period = 4.0 * amp / slope
    phase = (t / period) % 1.0
    u = amp * (1.0 - 4.0 * np.abs(phase - 0.5)) * np.minimum(t / 2.0, 1.0)
    return t, u


def test_every_reversal_lands_in_exactly_one_kept_sample() -> None:
    t, u = _triangle()
    turn = turning_samples(u, 4)
    du = np.diff(u)
    raw = np.flatnonzero(np.sign(du[1:]) * np.sign(du[:-1]) < 0) + 1
    assert set(turn[turn >= 0]) >= set(raw)
    # and a monotone ramp has none
    assert np.all(turning_samples(np.linspace(0.0, 1.0, 400), 4) < 0)


def test_a_play_plant_on_a_triangle_survives_the_decimation() -> None:
    t, u = _triangle()
    y = 0.5 * play(u, 0.0) + 0.3 * play(u, 0.6) + 0.2 * play(u, 1.5)
    run = RunData(run_id="tri", t=t, u=u, y=y)
    dec = run.decimated(4)
    model = 0.5 * play(dec.u, 0.0) + 0.3 * play(dec.u, 0.6) + 0.2 * play(dec.u, 1.5)
    # the plant seen through the decimation is the plant of the decimated input (averaged
    # corners leave 8.5 um RMS, up to 27 um held over a stroke)
    err = dec.y - model
    assert np.sqrt(np.mean(err**2)) < 2e-3
    assert dec.u.max() == u.max() and dec.u.min() == u.min()
