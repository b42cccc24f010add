"""Step 1 of the workflow: where do model and measurement disagree?

Residual analysis as system identification does it, plus a breakdown by the physical
situation: the noise floor estimated from the data, the residual by motion phase (loading,
unloading, just after a reversal, dwell), by velocity, tension, amplitude, time since start and
configuration, residual whiteness (autocorrelation, Ljung-Box) and the cross-correlation of the
residual with the input and its velocity, and the contiguous segments where the residual
exceeds the noise floor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import chdtrc  # the chi-square survival function (scipy.stats: +0.6 s import)

from hysteresis.discrepancy._ops import FloatArray, smooth
from hysteresis.discrepancy.runs import RunData

PHASES = ("loading", "unloading", "after_reversal", "dwell")


def noise_floor(residual: FloatArray) -> float:
    """Measurement-noise standard deviation from the high-frequency part of the residual.

    Model error is smooth in time; white measurement noise is not. Second differences remove
    the smooth part (up to a linear trend per three samples) and multiply the noise variance by
    6; the median absolute deviation keeps the estimate robust to the kinks at reversals.
    """
    e = np.asarray(residual, dtype=np.float64)
    if e.size < 3:
        return 0.0
    d = e[2:] - 2.0 * e[1:-1] + e[:-2]
    mad = float(np.median(np.abs(d - np.median(d))))
    return float(1.4826 * mad / np.sqrt(6.0))


def phases(run: RunData, *, reversal_fraction: float = 0.25) -> FloatArray:
    """Phase label per sample (index into :data:`PHASES`).

    ``after_reversal``: moving, and the input has travelled less than ``reversal_fraction`` of
    the current half-cycle's stroke since the last reversal. Dwell: input still.
    """
    s = run.s
    moving = np.abs(run.v) > run.v_eps
    label = np.where(s >= 0, 0, 1).astype(np.float64)
    amp = half_cycle_amplitude(run)
    last = _last_reversal_value(run)
    near = np.abs(run.u - last) < reversal_fraction * amp
    has_rev = np.isfinite(last)
    label[moving & near & has_rev] = 2
    label[~moving] = 3
    return label


def _reversal_indices(run: RunData) -> np.ndarray:
    s = run.s
    return np.flatnonzero((s[1:] != s[:-1]) & (s[:-1] != 0)) + 1


def _last_reversal_value(run: RunData) -> FloatArray:
    idx = _reversal_indices(run)
    out = np.full(run.n, np.nan)
    for i, k in enumerate(idx):
        # The extreme is where the motion stopped before the direction changed.
        start = idx[i - 1] if i > 0 else 0
        seg = run.u[start:k + 1]
        ext = float(seg.max() if run.s[k - 1] > 0 else seg.min())
        end = idx[i + 1] if i + 1 < idx.size else run.n
        out[k:end] = ext
    return out


def half_cycle_amplitude(run: RunData) -> FloatArray:
    """Stroke (max - min input) of the half-cycle each sample belongs to."""
    idx = np.r_[0, _reversal_indices(run), run.n]
    out = np.empty(run.n)
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        seg = run.u[max(a - 1, 0):b]
        out[a:b] = float(np.ptp(seg)) if seg.size else 0.0
    return out


def autocorrelation(x: FloatArray, max_lag: int) -> FloatArray:
    x = np.asarray(x, dtype=np.float64) - float(np.mean(x))
    den = float(np.dot(x, x))
    if den == 0:
        return np.zeros(max_lag + 1)
    return np.array([float(np.dot(x[: x.size - k], x[k:])) / den for k in range(max_lag + 1)])


def cross_correlation(e: FloatArray, x: FloatArray, max_lag: int) -> tuple[FloatArray, FloatArray]:
    """Normalised cross-correlation r(k) = corr(e[t], x[t - k]) for k = -max_lag..max_lag."""
    e = np.asarray(e, dtype=np.float64) - float(np.mean(e))
    x = np.asarray(x, dtype=np.float64) - float(np.mean(x))
    den = float(np.sqrt(np.dot(e, e) * np.dot(x, x)))
    lags = np.arange(-max_lag, max_lag + 1)
    if den == 0:
        return lags.astype(np.float64), np.zeros(lags.size)
    n = e.size
    vals = []
    for k in lags:
        if k >= 0:
            vals.append(float(np.dot(e[k:], x[: n - k])))
        else:
            vals.append(float(np.dot(e[: n + k], x[-k:])))
    return lags.astype(np.float64), np.asarray(vals) / den


def whiteness(residual: FloatArray, *, max_lag: int = 20) -> dict[str, float]:
    """Ljung-Box test of the residual; fraction of autocorrelations outside +-1.96/sqrt(N)."""
    n = residual.size
    r = autocorrelation(residual, max_lag)[1:]
    lags = np.arange(1, max_lag + 1)
    q = float(n * (n + 2) * np.sum(r**2 / (n - lags)))
    band = 1.96 / np.sqrt(n)
    p = float(chdtrc(max_lag, q))
    return {
        "ljung_box_q": q,
        "ljung_box_p": p,
        "acf_lag1": float(r[0]),
        "fraction_outside_band": float(np.mean(np.abs(r) > band)),
        "white": bool(p > 0.01),
    }


def _bins(values: FloatArray, labels: Sequence[str], edges: FloatArray) -> np.ndarray:
    return np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(labels) - 1)


def _stats(e: FloatArray, floor: float) -> dict[str, float]:
    if e.size == 0:
        return {"n": 0, "rmse": float("nan"), "mean": float("nan"), "above_floor": float("nan")}
    return {
        "n": int(e.size),
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mean": float(np.mean(e)),
        "above_floor": float(np.mean(np.abs(e) > 3.0 * floor)),
    }


@dataclass
class RunResidual:
    run: RunData
    residual: FloatArray
    phase: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        self.phase = phases(self.run)


def breakdown(items: Sequence[RunResidual], floor: float) -> dict[str, Any]:
    """Residual statistics per phase, velocity, tension, amplitude, time and configuration."""
    e = np.concatenate([it.residual for it in items])
    ph = np.concatenate([it.phase for it in items])
    speed = np.concatenate([np.abs(it.run.v) for it in items])
    amp = np.concatenate([half_cycle_amplitude(it.run) for it in items])
    tfrac = np.concatenate([it.run.ts / max(float(it.run.ts[-1]), 1e-12) for it in items])
    out: dict[str, Any] = {
        "phase": {p: _stats(e[ph == i], floor) for i, p in enumerate(PHASES)},
    }
    qs = np.quantile(speed, [0.0, 1 / 3, 2 / 3, 1.0])
    lab = ["slow", "medium", "fast"]
    idx = _bins(speed, lab, qs)
    out["velocity"] = {lab[i]: {**_stats(e[idx == i], floor), "speed_max": float(qs[i + 1])}
                       for i in range(3)}
    qa = np.quantile(amp, [0.0, 1 / 3, 2 / 3, 1.0])
    idx = _bins(amp, lab, qa)
    out["amplitude"] = {k: {**_stats(e[idx == i], floor), "stroke_max": float(qa[i + 1])}
                        for i, k in enumerate(("small", "medium", "large"))}
    tq = ["q1", "q2", "q3", "q4"]
    idx = _bins(tfrac, tq, np.array([0.0, 0.25, 0.5, 0.75, 1.0]))
    out["time"] = {k: _stats(e[idx == i], floor) for i, k in enumerate(tq)}
    if all(it.run.tension is not None for it in items):
        ten = np.concatenate([it.run.tension for it in items if it.run.tension is not None])
        qt = np.quantile(ten, [0.0, 1 / 3, 2 / 3, 1.0])
        idx = _bins(ten, lab, qt)
        out["tension"] = {k: {**_stats(e[idx == i], floor), "tension_max": float(qt[i + 1])}
                          for i, k in enumerate(("low", "medium", "high"))}
    configs: dict[str, list[FloatArray]] = {}
    for it in items:
        configs.setdefault(it.run.config_key, []).append(it.residual)
    out["configuration"] = {k: _stats(np.concatenate(v), floor) for k, v in configs.items()}
    return out


def segments(item: RunResidual, floor: float, *, k: float = 3.0, top: int = 5,
             min_duration_s: float = 0.1) -> list[dict[str, Any]]:
    """Contiguous spans where the smoothed |residual| exceeds ``k`` x the noise floor."""
    run = item.run
    w = max(1, int(round(0.1 / run.dt)))
    mag = smooth(np.abs(item.residual), w)
    above = mag > k * max(floor, 1e-12)
    edges = np.flatnonzero(np.diff(np.r_[0, above.astype(np.int8), 0]))
    spans: list[dict[str, Any]] = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if run.t[b - 1] - run.t[a] < min_duration_s:
            continue
        seg = item.residual[a:b]
        ph = item.phase[a:b].astype(int)
        spans.append({
            "run_id": run.run_id,
            "t_start_s": float(run.ts[a]),
            "t_end_s": float(run.ts[b - 1]),
            "phase": PHASES[int(np.bincount(ph, minlength=4).argmax())],
            "mean_residual": float(np.mean(seg)),
            "peak_residual": float(seg[np.argmax(np.abs(seg))]),
            "integral": float(np.sum(np.abs(seg)) * run.dt),
        })
    spans.sort(key=lambda s: -float(s["integral"]))
    return spans[:top]


def correlations(items: Sequence[RunResidual], *, max_lag_s: float = 0.5) -> dict[str, Any]:
    """Per-run residual whiteness and cross-correlation with input and input velocity."""
    out: dict[str, Any] = {}
    for it in items:
        lag = max(1, int(round(max_lag_s / it.run.dt)))
        band = 1.96 / np.sqrt(it.run.n)
        entry: dict[str, Any] = {"whiteness": whiteness(it.residual, max_lag=min(lag, 50))}
        for name, x in (("input", it.run.u), ("velocity", it.run.v)):
            lags, r = cross_correlation(it.residual, x, lag)
            j = int(np.argmax(np.abs(r)))
            entry[f"xcorr_{name}"] = {"max_abs": float(abs(r[j])), "value": float(r[j]),
                                      "lag_s": float(lags[j] * it.run.dt),
                                      "significant": bool(abs(r[j]) > band)}
        out[it.run.run_id] = entry
    return out


def locate(runs: Sequence[RunData], predictions: Sequence[FloatArray], *,
           k: float = 3.0) -> dict[str, Any]:
    """The whole of step 1 for a set of runs and the base model's predictions on them."""
    items = [RunResidual(r, np.asarray(r.y - p, dtype=np.float64))
             for r, p in zip(runs, predictions, strict=True)]
    floors = [noise_floor(it.residual) for it in items]
    floor = float(np.median(floors))
    e = np.concatenate([it.residual for it in items])
    rmse = float(np.sqrt(np.mean(e**2)))
    segs = [s for it in items for s in segments(it, floor, k=k)]
    segs.sort(key=lambda s: -s["integral"])
    return {
        "noise_floor": floor,
        "noise_floor_per_run": {it.run.run_id: f for it, f in zip(items, floors, strict=True)},
        "rmse": rmse,
        "rmse_over_noise": rmse / floor if floor > 0 else float("inf"),
        "fraction_above_floor": float(np.mean(np.abs(e) > k * floor)),
        "breakdown": breakdown(items, floor),
        "correlations": correlations(items),
        "segments": segs[:20],
    }
