"""Commanded trajectories of the format's excitation kinds, at the 10 ms control rate."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from rig_io.manifest import EXCITATION_KINDS as FORMAT_KINDS

FloatArray = npt.NDArray[np.float64]

EXCITATION_KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay", "ramp", "sine",
                    "sine_decay_offset", "mixed_sine", "band_random", "free")

_REQUIRED: dict[str, tuple[str, ...]] = {
    "sine_decay": ("amplitudes_mm", "periods_per_amplitude", "frequency_hz"),
    "sine_decay_offset": ("amplitudes_mm", "periods_per_amplitude", "frequency_hz", "offset"),
    "triangle_decay": ("amplitudes_mm", "periods_per_amplitude", "slope_mm_s"),
    "trapezoid_decay": ("amplitudes_mm", "periods_per_amplitude", "slope_mm_s", "dwell_s"),
    "ramp": ("velocity_mm_s", "stroke_mm"),
    "sine": ("amplitude", "offset", "frequency_hz"),
    "mixed_sine": ("terms",),
    "band_random": ("amplitude_mm", "band_hz", "duration_s", "seed"),
    "free": ("t_s", "command"),
}
#: The campaign's evaluation-only excitations (``conf/campaign/*.yaml`` lists the same):
#: seed 001 eq. 4.11 at 0.45 x its amplitudes (-5.6..4.4 mm, inside the +-6 mm identification
#: range) and band-limited random motion (seed 002's non-periodic test). No model is
#: identified on them, so they show whether a model generalises beyond its record.
EVALUATION_EXCITATIONS: tuple[dict[str, Any], ...] = (
    {"kind": "mixed_sine", "duration_s": 30.0, "terms": [
        {"amplitude": 3.15, "frequency_hz": 0.125, "phase_rad": 0.0},
        {"amplitude": 0.9, "frequency_hz": 0.1375, "phase_rad": 0.0},
        {"amplitude": -1.8, "frequency_hz": 0.025, "phase_rad": 0.0},
        {"amplitude": 0.45, "frequency_hz": 0.05625, "phase_rad": 0.0}]},
    {"kind": "band_random", "amplitude_mm": 5.0, "band_hz": [0.03, 0.35], "duration_s": 30.0,
     "seed": 11},
)
#: Extra (non-format) parameters some kinds accept.
_OPTIONAL: dict[str, tuple[str, ...]] = {
    "sine": ("duration_s",), "mixed_sine": ("duration_s",), "ramp": ("dwell_s",),
    "band_random": ("envelope_hz", "rate_range", "taper_s"),
}


def _positive(name: str, value: Any) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0.0:
        raise ValueError(f"excitation parameter {name!r} must be positive, got {value!r}")
    return v


def _amplitudes(value: Any) -> list[float]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) == 0:
        raise ValueError(f"'amplitudes_mm' must be a non-empty list of numbers, got {value!r}")
    return [_positive("amplitudes_mm", a) for a in value]


def check_excitation(kind: str, params: dict[str, Any]) -> None:
    """Raise ``ValueError`` naming what is wrong with an excitation spec."""
    if kind not in _REQUIRED:
        raise ValueError(f"unknown excitation kind {kind!r}; expected one of {EXCITATION_KINDS}")
    missing = [k for k in _REQUIRED[kind] if k not in params]
    if missing:
        raise ValueError(f"excitation {kind!r} is missing parameter(s) {missing}")
    extra = sorted(set(params) - set(_REQUIRED[kind]) - set(_OPTIONAL.get(kind, ())))
    if extra:
        raise ValueError(f"excitation {kind!r} does not take parameter(s) {extra}")


def _sample(t_end: float, dt: float) -> FloatArray:
    n = int(round(t_end / dt)) + 1
    return np.arange(n, dtype=float) * dt


def _decay_periods(amps: list[float], n_per: int, period_of: Any, shape: Any, dt: float
                   ) -> tuple[FloatArray, FloatArray]:
    """Concatenate ``n_per`` periods of ``shape(phase_time, amplitude, period)`` per amplitude."""
    starts: list[float] = []
    durations: list[float] = []
    t0 = 0.0
    for a in amps:
        per = period_of(a)
        for _ in range(n_per):
            starts.append(t0)
            durations.append(per)
            t0 += per
    t = _sample(t0, dt)
    y = np.zeros_like(t)
    idx = 0
    for a in amps:
        for _ in range(n_per):
            s, d = starts[idx], durations[idx]
            mask = (t >= s - 1e-12) & (t < s + d - 1e-12)
            y[mask] = shape(t[mask] - s, a, d)
            idx += 1
    return t, y


def _triangle(tau: FloatArray, a: float, per: float) -> FloatArray:
    # 0 -> +a -> -a -> 0 over one period (starts upwards from rest, like the sine).
    x = tau / per
    return a * np.where(x < 0.25, 4 * x, np.where(x < 0.75, 2 - 4 * x, 4 * x - 4))


def _band_noise(rng: np.random.Generator, n: int, dt: float, lo: float, hi: float
                ) -> FloatArray:
    """Gaussian noise with every frequency outside ``[lo, hi]`` Hz removed, peak 1."""
    freqs = np.fft.rfftfreq(n, dt)
    inside = (freqs >= lo) & (freqs <= hi) & (freqs > 0)
    if not inside.any():
        raise ValueError(f"band [{lo:g}, {hi:g}] Hz holds no frequency of a {n * dt:g} s "
                         "record; widen it or lengthen the record")
    spec = np.zeros(freqs.size, dtype=np.complex128)
    k = int(inside.sum())
    spec[inside] = rng.standard_normal(k) + 1j * rng.standard_normal(k)
    x = np.fft.irfft(spec, n)
    return np.asarray(x / np.max(np.abs(x)), dtype=np.float64)


def band_random(t: FloatArray, *, amplitude_mm: float, band_hz: Sequence[float], seed: int,
                envelope_hz: float = 0.05, rate_range: Sequence[float] = (0.5, 1.5),
                taper_s: float = 2.0) -> FloatArray:
    """Band-limited random motion: non-periodic, with drifting amplitude and rate.

    Band-limited Gaussian noise (``band_hz``) is played on a warped clock whose speed
    wanders slowly inside ``rate_range`` (so the rate varies beyond what the band alone
    gives) and is multiplied by a slow envelope between 0.25 and 1 (so large reversals
    alternate with small ones: minor loops nested in major ones). Cosine tapers of
    ``taper_s`` start and end it at rest. The peak is ``amplitude_mm``; the same parameters
    and ``seed`` give the same record.
    """
    if len(band_hz) != 2 or not 0 <= float(band_hz[0]) < float(band_hz[1]):
        raise ValueError(f"'band_hz' must be [low, high] with 0 <= low < high, got {band_hz!r}")
    if len(rate_range) != 2 or not 0 < float(rate_range[0]) <= float(rate_range[1]):
        raise ValueError(f"'rate_range' must be [low, high] with 0 < low <= high, got "
                         f"{rate_range!r}")
    amp = _positive("amplitude_mm", amplitude_mm)
    env_hz = _positive("envelope_hz", envelope_hz)
    taper = float(taper_s)
    if not np.isfinite(taper) or taper < 0:
        raise ValueError(f"'taper_s' must be >= 0, got {taper_s!r}")
    n = t.size
    dt = float(t[1] - t[0]) if n > 1 else 1.0
    rng = np.random.default_rng(int(seed))
    lo_rate, hi_rate = float(rate_range[0]), float(rate_range[1])
    # The slow processes keep at least the record's lowest frequency (a short record).
    slow_hz = max(env_hz, 1.0 / (n * dt))
    rate = lo_rate + (hi_rate - lo_rate) * 0.5 * (1.0 + _band_noise(rng, n, dt, 0.0, slow_hz))
    clock = np.concatenate([[0.0], np.cumsum(rate[:-1]) * dt])
    # The noise lives on the warped clock; a grid as fine as the fastest clock keeps the band.
    m = int(np.ceil(clock[-1] / dt)) + 2
    fast = _band_noise(rng, m, dt, float(band_hz[0]), float(band_hz[1]))
    y = np.interp(clock, np.arange(m) * dt, fast)
    env = _band_noise(rng, n, dt, 0.0, slow_hz)
    y = y * (0.25 + 0.75 * (env - env.min()) / max(float(np.ptp(env)), 1e-12))
    if taper > 0:
        ramp = np.clip(np.minimum(t - t[0], t[-1] - t) / taper, 0.0, 1.0)
        y = y * 0.5 * (1.0 - np.cos(np.pi * ramp))
    return np.asarray(amp * y / max(float(np.max(np.abs(y))), 1e-12), dtype=np.float64)


def make_excitation(kind: str, *, dt_s: float = 0.01, **params: Any
                    ) -> tuple[FloatArray, FloatArray]:
    """Commanded trajectory ``(t_s, command)`` of an excitation kind (format section 1).

    Decaying kinds start at rest, go up first, and run ``periods_per_amplitude`` periods at
    each amplitude. Units are the input channel's (mm of pull, or deg of motor angle).
    """
    check_excitation(kind, params)
    dt = _positive("dt_s", dt_s)
    build = _BUILDERS.get(kind, _free)
    return build(kind, params, dt)


def _sine_decay(kind: str, params: dict[str, Any], dt: float) -> tuple[FloatArray, FloatArray]:
    amps = _amplitudes(params["amplitudes_mm"])
    n_per = int(params["periods_per_amplitude"])
    f = _positive("frequency_hz", params["frequency_hz"])
    if n_per < 1:
        raise ValueError("'periods_per_amplitude' must be >= 1")
    t, y = _decay_periods(amps, n_per, lambda a: 1.0 / f,
                          lambda tau, a, per: a * np.sin(2 * np.pi * tau / per), dt)
    if kind == "sine_decay_offset":
        y = y + float(params["offset"])
    return t, y


def _triangle_or_trapezoid(kind: str, params: dict[str, Any], dt: float
                           ) -> tuple[FloatArray, FloatArray]:
    amps = _amplitudes(params["amplitudes_mm"])
    n_per = int(params["periods_per_amplitude"])
    v = _positive("slope_mm_s", params["slope_mm_s"])
    if n_per < 1:
        raise ValueError("'periods_per_amplitude' must be >= 1")
    if kind == "triangle_decay":
        return _decay_periods(amps, n_per, lambda a: 4 * a / v, _triangle, dt)
    dwell = float(params["dwell_s"])
    if dwell < 0:
        raise ValueError("'dwell_s' must be >= 0")

    def trapezoid(tau: FloatArray, a: float, per: float) -> FloatArray:
        ramp = a / v
        knots_t = np.cumsum([0, ramp, dwell, 2 * ramp, dwell, ramp])
        knots_y = [0, a, a, -a, -a, 0]
        return np.interp(tau, knots_t, knots_y)

    return _decay_periods(amps, n_per, lambda a: 4 * a / v + 2 * dwell, trapezoid, dt)


def _ramp(kind: str, params: dict[str, Any], dt: float) -> tuple[FloatArray, FloatArray]:
    v = float(params["velocity_mm_s"])
    stroke = float(params["stroke_mm"])
    if v == 0 or not np.isfinite(v):
        raise ValueError("'velocity_mm_s' must be non-zero")
    dwell = float(params.get("dwell_s", 1.0))
    t_ramp = abs(stroke / v)
    t = _sample(dwell + t_ramp + dwell, dt)
    y = np.clip((t - dwell) * abs(v), 0.0, abs(stroke)) * np.sign(stroke)
    return t, y


def _sine(kind: str, params: dict[str, Any], dt: float) -> tuple[FloatArray, FloatArray]:
    a = float(params["amplitude"])
    off = float(params["offset"])
    f = _positive("frequency_hz", params["frequency_hz"])
    dur = _positive("duration_s", params.get("duration_s", 5.0 / f))
    t = _sample(dur, dt)
    # Eases in from rest at the offset: the rig starts where the sine starts.
    return t, off + a * np.sin(2 * np.pi * f * t)


def _mixed_sine(kind: str, params: dict[str, Any], dt: float) -> tuple[FloatArray, FloatArray]:
    terms = params["terms"]
    if not isinstance(terms, Sequence) or len(terms) == 0:
        raise ValueError("'terms' must be a non-empty list of {amplitude, frequency_hz, "
                         "phase_rad}")
    fmin = min(_positive("frequency_hz", tm["frequency_hz"]) for tm in terms)
    dur = _positive("duration_s", params.get("duration_s", 2.0 / fmin))
    t = _sample(dur, dt)
    y = np.zeros_like(t)
    for tm in terms:
        y += float(tm["amplitude"]) * (np.sin(2 * np.pi * float(tm["frequency_hz"]) * t
                                              + float(tm.get("phase_rad", 0.0)))
                                       - np.sin(float(tm.get("phase_rad", 0.0))))
    return t, y


def _band_random(kind: str, params: dict[str, Any], dt: float
                 ) -> tuple[FloatArray, FloatArray]:
    t = _sample(_positive("duration_s", params["duration_s"]), dt)
    opts = {k: params[k] for k in _OPTIONAL["band_random"] if k in params}
    return t, band_random(t, amplitude_mm=params["amplitude_mm"], band_hz=params["band_hz"],
                          seed=params["seed"], **opts)


def _free(kind: str, params: dict[str, Any], dt: float) -> tuple[FloatArray, FloatArray]:
    """Given samples, resampled to the control rate."""
    t_in = np.asarray(params["t_s"], dtype=float)
    c_in = np.asarray(params["command"], dtype=float)
    if t_in.ndim != 1 or t_in.shape != c_in.shape or t_in.size < 2:
        raise ValueError("free excitation: 't_s' and 'command' must be 1-D arrays of equal "
                         "length >= 2")
    if np.any(np.diff(t_in) <= 0) or not np.all(np.isfinite(c_in)):
        raise ValueError("free excitation: 't_s' must increase and 'command' be finite")
    t = _sample(t_in[-1] - t_in[0], dt)
    return t, np.interp(t + t_in[0], t_in, c_in)


_BUILDERS: dict[str, Callable[[str, dict[str, Any], float], tuple[FloatArray, FloatArray]]] = {
    "sine_decay": _sine_decay, "sine_decay_offset": _sine_decay,
    "triangle_decay": _triangle_or_trapezoid, "trapezoid_decay": _triangle_or_trapezoid,
    "ramp": _ramp, "sine": _sine, "mixed_sine": _mixed_sine, "band_random": _band_random,
}


def manifest_excitation(kind: str, params: dict[str, Any]) -> dict[str, Any]:
    """The manifest's ``excitation`` block (``free`` samples are not written)."""
    if kind == "free":
        return {"kind": "free"}
    # The log format lists no kind for the rig's own extra excitations: they are written as
    # ``free`` runs with their name, which ingest uses as the dataset's excitation.
    out: dict[str, Any] = ({"kind": kind} if kind in FORMAT_KINDS
                           else {"kind": "free", "name": kind})
    for key, value in params.items():
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, tuple):
            value = list(value)
        out[key] = value
    return out
