"""Small signal kernels shared by the discrepancy analysis (numba where it is a hot loop)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def _play(u: Any, r: float, z0: float) -> Any:  # pragma: no cover - compiled
    out = np.empty_like(u)
    z = z0
    for k in range(u.size):
        x = u[k]
        if x - r > z:
            z = x - r
        elif x + r < z:
            z = x + r
        out[k] = z
    return out


def play(u: FloatArray, r: float, *, z0: float | None = None) -> FloatArray:
    """Play (backlash) operator of half-width ``r`` >= 0; state starts at ``z0`` (default u[0])."""
    uu = np.ascontiguousarray(u, dtype=np.float64)
    if r < 0:
        raise ValueError(f"play half-width must be >= 0, got {r}")
    start = float(uu[0]) if z0 is None else float(z0)
    return np.asarray(_play(uu, float(r), start), dtype=np.float64)


@njit(cache=True)
def _scaled_play(u: Any, h: Any, z0: float) -> Any:  # pragma: no cover - compiled
    out = np.empty_like(u)
    z = z0
    for k in range(u.size):
        if u[k] - h[k] > z:
            z = u[k] - h[k]
        elif u[k] + h[k] < z:
            z = u[k] + h[k]
        out[k] = z
    return out


def scaled_play(u: FloatArray, half_width: FloatArray, *, z0: float) -> FloatArray:
    """Play operator whose half-width varies in time (>= 0): it widens without moving the
    output (the operator holds) and pulls the output along when it narrows."""
    uu = np.ascontiguousarray(u, dtype=np.float64)
    hh = np.ascontiguousarray(half_width, dtype=np.float64)
    if hh.shape != uu.shape or np.any(hh < 0):
        raise ValueError("half_width must be >= 0 and as long as u")
    return np.asarray(_scaled_play(uu, hh, float(z0)), dtype=np.float64)


@njit(cache=True)
def _scaled_play_bank(u: Any, f: Any, p: Any, w0: Any) -> Any:  # pragma: no cover - compiled
    out = np.empty((u.size, p.size))
    for i in range(p.size):
        half = 0.5 * p[i]
        out[:, i] = _scaled_play(u, half * f, w0[i] + half) - half
    return out


def scaled_play_bank(u: FloatArray, factor: FloatArray, thresholds: FloatArray,
                     start: FloatArray) -> FloatArray:
    """Gamma play operators with time-scaled thresholds, one column per threshold ``p_i``:
    ``scaled_play(u, p_i f / 2, z0=w_i + p_i / 2) - p_i / 2`` from the start outputs ``w_i``
    (with ``f = 1`` exactly ``min(u, max(u - p_i, w))``), in one compiled pass."""
    uu = np.ascontiguousarray(u, dtype=np.float64)
    ff = np.ascontiguousarray(factor, dtype=np.float64)
    pp = np.ascontiguousarray(thresholds, dtype=np.float64)
    ww = np.ascontiguousarray(start, dtype=np.float64)
    if ff.shape != uu.shape or np.any(ff < 0) or np.any(pp < 0) or ww.shape != pp.shape:
        raise ValueError("factor must be >= 0 and as long as u; thresholds >= 0, one start each")
    return np.asarray(_scaled_play_bank(uu, ff, pp, ww), dtype=np.float64)


def smooth(x: FloatArray, window: int) -> FloatArray:
    """Centred moving average with edge replication (window forced odd, >= 1)."""
    w = max(1, int(window)) | 1
    if w == 1 or x.size < 2:
        return np.asarray(x, dtype=np.float64).copy()
    pad = w // 2
    xp = np.pad(np.asarray(x, dtype=np.float64), pad, mode="edge")
    c = np.cumsum(np.concatenate([[0.0], xp]))
    return np.asarray((c[w:] - c[:-w]) / w, dtype=np.float64)


def velocity(t: FloatArray, u: FloatArray, *, window_s: float = 0.1) -> FloatArray:
    """Smoothed time derivative of ``u`` (the moving average kills encoder quantisation)."""
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    w = max(1, int(round(window_s / dt)))
    return np.asarray(np.gradient(smooth(u, w), t), dtype=np.float64)


@njit(cache=True)
def _direction(v: Any, eps: float) -> Any:  # pragma: no cover - compiled
    out = np.zeros_like(v)
    s = 0.0
    for k in range(v.size):
        if v[k] > eps:
            s = 1.0
        elif v[k] < -eps:
            s = -1.0
        out[k] = s
    return out


def direction(v: FloatArray, *, eps: float) -> FloatArray:
    """Sign of the last motion faster than ``eps`` (held through dwells; 0 before any motion)."""
    return np.asarray(_direction(np.ascontiguousarray(v, dtype=np.float64), float(eps)))


def shift(t: FloatArray, y: FloatArray, delay_s: float) -> FloatArray:
    """``y`` delayed by ``delay_s`` seconds (linear interpolation; the first value held)."""
    if delay_s == 0.0:
        return np.asarray(y, dtype=np.float64).copy()
    return np.asarray(np.interp(t - delay_s, t, y), dtype=np.float64)
