"""Clean-room generator of synthetic hysteresis-plant data (numpy + scipy only).

Written from the physics alone (textbook hysteresis models and the three reference texts
under ../shared/seeds), independently of any existing implementation.  It is meant to
produce *test data* for a hysteresis-modelling product: excitations like the ones of the
reference rigs, plants with a known ground truth, and records in the rig / catheter layouts.

Contents
--------
Excitations (``dt`` in seconds, default 0.01 s = a 100 Hz rig loop; every function returns
``(t, u)`` with ``t = k*dt`` and *includes the end point*):

* :func:`sine_decay`        - thesis (seed 001, Fig. 3.1a / 4.8) decaying sinusoid.
* :func:`triangle_decay`    - thesis validation triangle (6 mm/s slopes).
* :func:`trapezoid_decay`   - thesis validation trapezoid (6 mm/s slopes + dwell).
* :func:`sine_decay_to_mid` - one-sided 7-cycle sinusoid that decays towards mid-stroke
  (catheter ``data_1`` family).
* :func:`sine_decay_to_zero`- one-sided 7-cycle sinusoid that decays back to 0
  (catheter ``data_2`` family).

Plants (pure functions ``plant(u, **params) -> y``; every plant is *rate independent*, so the
sampling grid of ``u`` only matters through the reversal points it contains; every plant
takes an initial state and can return its final state with ``return_state=True``):

* :func:`bouc_wen`               - textbook Bouc-Wen (softening loop).
* :func:`bouc_wen_seed002`       - the same ODE in seed 002's output form (eq. 2-3).
* :func:`play_sum`               - weighted sum of play (backlash) operators (seed 001 eq. 4.7-4.9).
* :func:`seed001_play_sum`       - the thesis' Gamma_11 with a Table 4.1 weight vector.
* :func:`preisach_plane`         - discretised classical Preisach model (seed 001 eq. 4.1-4.6).
* :func:`tendon_sheath_backlash` - lumped tendon-sheath model: clearance + capstan friction
  dead band, smooth slack take-up (hardening loop).

Records:

* :func:`record`            - one noisy record ``{t, u, y, meta}`` of one plant/excitation.
* :func:`multi_record_runs` - identification (to-mid) + held-out (to-zero) runs, one per
  frequency, each starting from its own state (so joined records have seams).
* :func:`write_catheter_csv`- write a record in the catheter data's CSV column layout.

Sign/units conventions: the input ``u`` is a tendon displacement in mm (positive = pull);
the plant output ``y`` is in mm unless a record converts it.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "sine_decay",
    "triangle_decay",
    "trapezoid_decay",
    "sine_decay_to_mid",
    "sine_decay_to_zero",
    "bouc_wen",
    "bouc_wen_seed002",
    "play_sum",
    "seed001_play_sum",
    "SEED001_PLAYS_MM",
    "SEED001_TABLE_4_1",
    "preisach_plane",
    "gauss_gauss_density",
    "lorentzian_density",
    "tendon_sheath_backlash",
    "PLANT_DEFAULTS",
    "EXCITATIONS",
    "record",
    "multi_record_runs",
    "write_catheter_csv",
]


# =====================================================================================
# Excitations
# =====================================================================================


def _time(duration: float, dt: float) -> FloatArray:
    """Uniform grid 0, dt, ..., duration (end point included, rounded to whole steps)."""
    if dt <= 0:
        raise ValueError("dt must be > 0")
    n = int(round(duration / dt))
    return np.arange(n + 1, dtype=np.float64) * dt


def sine_decay(
    dt: float = 0.01,
    amplitudes: Sequence[float] = (6.0, 4.5, 3.0, 1.5),
    periods_per_amplitude: int = 5,
    frequency_hz: float = 0.25,
    offset: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Decaying-amplitude sinusoid of the thesis (seed 001, Fig. 3.1a and 4.8).

    ``u(t) = offset + a_j * sin(2*pi*f*t)`` where ``a_j`` is held for ``periods_per_amplitude``
    whole periods, then steps down to the next amplitude.  Amplitude changes happen at the
    zero crossings of the sine, so ``u`` is continuous (its slope steps from ``2 pi f a_j`` to
    ``2 pi f a_{j+1}``).  Defaults: 6, 4.5, 3, 1.5 mm, 5 periods each at 0.25 Hz = 80 s
    (8001 samples at 100 Hz).

    Start: ``u(0) = offset`` exactly, rising with slope ``2*pi*f*a_1`` (continuous start
    from ``offset``, *not* a zero-slope start).  The record also ends at ``offset``.
    """
    period = 1.0 / frequency_hz
    block = periods_per_amplitude * period
    t = _time(block * len(amplitudes), dt)
    idx = np.minimum((t / block + 1e-9).astype(int), len(amplitudes) - 1)
    a = np.asarray(amplitudes, dtype=np.float64)[idx]
    u = offset + a * np.sin(2.0 * np.pi * frequency_hz * t)
    return t, u


def _tri_unit(phase: FloatArray) -> FloatArray:
    """Unit triangle wave, period 1, value 0 at phase 0 rising to +1 at 1/4, -1 at 3/4."""
    p = np.mod(phase, 1.0)
    return np.where(p < 0.25, 4 * p, np.where(p < 0.75, 2 - 4 * p, 4 * p - 4))


def triangle_decay(
    dt: float = 0.01,
    amplitudes: Sequence[float] = (6.0, 4.5, 3.0, 1.5),
    periods_per_amplitude: int = 5,
    slope: float = 6.0,
    offset: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Decaying-amplitude triangle wave (thesis validation input, Fig. 3.1b / 4.9a).

    Every ramp has speed ``slope`` (mm/s, 6 mm/s in the thesis), so a period of amplitude
    ``a`` lasts ``4 a / slope`` s (4, 3, 2, 1 s at the defaults; 50 s total).  Each period
    starts at ``offset``, rises to ``offset + a``, falls to ``offset - a`` and returns.
    Starts at ``u = offset`` and rises immediately (continuous start from offset).
    """
    t0 = 0.0
    durations = [periods_per_amplitude * 4.0 * a / slope for a in amplitudes]
    total = float(sum(durations))
    t = _time(total, dt)
    u = np.full_like(t, offset)
    for a, d in zip(amplitudes, durations):
        m = (t >= t0 - 1e-12) & (t < t0 + d - 1e-12)
        period = 4.0 * a / slope
        u[m] = offset + a * _tri_unit((t[m] - t0) / period)
        t0 += d
    return t, u


def trapezoid_decay(
    dt: float = 0.01,
    amplitudes: Sequence[float] = (6.0, 4.5, 3.0, 1.5),
    periods_per_amplitude: int = 5,
    slope: float = 6.0,
    dwell_s: float = 1.0,
    offset: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Decaying-amplitude trapezoid (thesis validation input, Fig. 3.1c / 4.9b).

    One period of amplitude ``a``: ramp ``offset -> offset+a`` at ``slope`` mm/s, dwell
    ``dwell_s`` at the top, ramp down through ``offset`` to ``offset-a``, dwell ``dwell_s``
    at the bottom, ramp back to ``offset``.  Period = ``4 a / slope + 2 dwell_s``.
    Starts at ``u = offset`` and rises immediately (continuous start from offset).
    """
    periods = [4.0 * a / slope + 2.0 * dwell_s for a in amplitudes]
    durations = [periods_per_amplitude * p for p in periods]
    t = _time(float(sum(durations)), dt)
    u = np.full_like(t, offset)
    t0 = 0.0
    for a, p, d in zip(amplitudes, periods, durations):
        m = (t >= t0 - 1e-12) & (t < t0 + d - 1e-12)
        tr = a / slope  # time of one quarter ramp
        x = np.mod(t[m] - t0, p)
        # breakpoints: rise [0,tr], dwell [tr,tr+w], fall [tr+w, 3tr+w], dwell, rise back
        b1, b2, b3, b4 = tr, tr + dwell_s, 3 * tr + dwell_s, 3 * tr + 2 * dwell_s
        v = np.where(
            x < b1,
            slope * x,
            np.where(
                x < b2,
                a,
                np.where(x < b3, a - slope * (x - b2), np.where(x < b4, -a, -a + slope * (x - b4))),
            ),
        )
        u[m] = offset + v
        t0 += d
    return t, u


def _one_sided_decay(
    dt: float, amplitude: float, cycles: int, frequency_hz: float, mid: float
) -> tuple[FloatArray, FloatArray]:
    """Shared construction of the one-sided (tendon can only pull) decaying sinusoids.

    ``u(t) = mid + env(t) * ((amplitude/2 - mid) - (amplitude/2) * cos(2 pi f t))``
    with a linear envelope ``env(t) = 1 - t/T``, ``T = cycles / f``.  Hence ``u(0) = 0`` with
    (almost) zero slope, the first peak is close to ``amplitude``, every trough is >= 0
    (for 0 <= mid <= amplitude), and ``u(T) = mid``.  The oscillation amplitude decays
    linearly from ``amplitude/2`` to 0 while its centre moves from ``amplitude/2`` to ``mid``.
    """
    if not (0.0 <= mid <= amplitude):
        raise ValueError("need 0 <= mid <= amplitude")
    T = cycles / frequency_hz
    t = _time(T, dt)
    env = 1.0 - t / T
    half = 0.5 * amplitude
    u = mid + env * ((half - mid) - half * np.cos(2.0 * np.pi * frequency_hz * t))
    return t, np.maximum(u, 0.0)


def sine_decay_to_mid(
    dt: float = 0.002,
    amplitude: float = 6.0,
    cycles: int = 7,
    frequency_hz: float = 0.1,
    mid: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """7-cycle one-sided sinusoid from 0 whose oscillation decays towards ``mid``.

    Like the catheter ``data_1_*`` runs (identification family).  ``mid`` defaults to
    ``amplitude/2`` (mid-stroke).  Range 0..amplitude (a tendon can only be pulled).
    Starts at ``u = 0`` with zero slope up to the small envelope term, then rises.
    See :func:`_one_sided_decay` for the formula.  Duration ``cycles / frequency_hz``
    (70 s at 0.1 Hz, 14 s at 0.5 Hz).
    """
    m = 0.5 * amplitude if mid is None else float(mid)
    return _one_sided_decay(dt, amplitude, cycles, frequency_hz, m)


def sine_decay_to_zero(
    dt: float = 0.002,
    amplitude: float = 6.0,
    cycles: int = 7,
    frequency_hz: float = 0.1,
) -> tuple[FloatArray, FloatArray]:
    """7-cycle one-sided sinusoid from 0 that decays back to 0 (catheter ``data_2_*``).

    ``u = env(t) * amplitude/2 * (1 - cos(2 pi f t))``, linear envelope 1 -> 0 (this is
    :func:`_one_sided_decay` with ``mid = 0``).  Starts and ends at 0 with zero slope.
    """
    return _one_sided_decay(dt, amplitude, cycles, frequency_hz, 0.0)


EXCITATIONS: dict[str, Callable[..., tuple[FloatArray, FloatArray]]] = {
    "sine_decay": sine_decay,
    "triangle_decay": triangle_decay,
    "trapezoid_decay": trapezoid_decay,
    "sine_decay_to_mid": sine_decay_to_mid,
    "sine_decay_to_zero": sine_decay_to_zero,
}


# =====================================================================================
# Plant 1: Bouc-Wen
# =====================================================================================


def _bw_exact_n1(u: Sequence[float], A: float, beta: float, gamma: float, h0: float) -> tuple[list[float], float]:
    """Exact piecewise solution of the n = 1 Bouc-Wen equation, sample to sample.

    For n = 1 and a fixed direction s = sign(du) and sign sg = sign(h), the equation
    dh/du = A - beta*s*h - gamma*|h| = A - c*h with c = beta*s + gamma*sg is linear, so
    h(u0 + s*x) = A/c + (h0 - A/c) * exp(-s*c*x) (or h0 + s*A*x if c = 0).  A change of
    sign of h inside a step is located exactly and the step is split there.
    """
    out = [0.0] * len(u)
    h = float(h0)
    prev = float(u[0])
    for k in range(len(u)):
        uk = float(u[k])
        du = uk - prev
        prev = uk
        if du != 0.0:
            s = 1.0 if du > 0.0 else -1.0
            x = abs(du)  # remaining travel
            for _ in range(4):  # at most one sign change of h per monotone step in practice
                if h > 0.0:
                    sg = 1.0
                elif h < 0.0:
                    sg = -1.0
                else:
                    sg = s if A > 0 else -s  # h leaves 0 in the direction of A*du
                c = beta * s + gamma * sg
                if abs(c) < 1e-14:
                    hn = h + s * A * x
                    if hn * sg < 0.0:  # crossed zero
                        x0 = -h / (s * A)
                        h = 0.0
                        x -= x0
                        continue
                    h = hn
                    break
                heq = A / c
                hn = heq + (h - heq) * math.exp(-s * c * x)
                if h != 0.0 and hn * sg < 0.0:
                    # time (travel) to zero: 0 = heq + (h-heq) e^{-s c x0}
                    ratio = heq / (heq - h)
                    x0 = -math.log(ratio) / (s * c)
                    h = 0.0
                    x -= x0
                    if x <= 0.0:
                        break
                    continue
                h = hn
                break
        out[k] = h
    return out, h


def _bw_rk4(
    u: Sequence[float], A: float, beta: float, gamma: float, n: float, h0: float, max_du: float
) -> tuple[list[float], float]:
    """RK4 in the input variable u with sub-steps of at most ``max_du`` (general n >= 1)."""

    def f(h: float, s: float) -> float:
        ah = abs(h)
        return A - beta * s * (ah ** (n - 1.0)) * h - gamma * (ah**n)

    out = [0.0] * len(u)
    h = float(h0)
    prev = float(u[0])
    for k in range(len(u)):
        uk = float(u[k])
        du = uk - prev
        prev = uk
        if du != 0.0:
            s = 1.0 if du > 0.0 else -1.0
            m = max(1, int(math.ceil(abs(du) / max_du)))
            d = du / m
            for _ in range(m):
                k1 = f(h, s)
                k2 = f(h + 0.5 * d * k1, s)
                k3 = f(h + 0.5 * d * k2, s)
                k4 = f(h + d * k3, s)
                h += d * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
        out[k] = h
    return out, h


def bouc_wen(
    u: ArrayLike,
    A: float = 1.0,
    beta: float = 0.45,
    gamma: float = 0.25,
    n: float = 1.0,
    alpha: float = 0.0,
    k: float = 1.0,
    h0: float = 0.0,
    *,
    method: str = "auto",
    max_du: float = 0.005,
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, float]:
    """Textbook Bouc-Wen hysteresis (Bouc 1967, Wen 1976; Ikhouane & Rodellar normalised form).

    Equation (rate independent, written per unit of input travel)::

        dh/dt = A du/dt - beta |du/dt| |h|^(n-1) h - gamma du/dt |h|^n     (seed 002 eq. 3,
                                                                           with B = beta, C = gamma)
        y     = k * (alpha * u + (1 - alpha) * h)

    i.e. the Ikhouane-Rodellar output form; seed 002's eq. 2 ``y = a*u + b*h`` is the same
    with ``a = k*alpha`` and ``b = k*(1-alpha)`` (see :func:`bouc_wen_seed002`).

    Integration: dividing by du/dt gives an ODE in ``u`` whose right-hand side only depends on
    ``sign(du)``, so the model is integrated in the input variable sample by sample.  For
    ``n == 1`` (``method='auto'`` or ``'exact'``) the piecewise-linear ODE is solved in closed
    form (exponential segments, exact zero crossings of h); otherwise RK4 with sub-steps of at
    most ``max_du`` in u.  Requires n >= 1.

    Shape: with A=1, beta=0.45, gamma=0.25, n=1 (beta > gamma > 0) the loop is *softening*:
    just after a reversal dh/du = A + (beta-gamma)|h| (= 1.29 at saturation), it then falls
    towards 0 as h approaches h_max = (A/(beta+gamma))^(1/n) = 1.4286.

    Initial state: ``h0`` (0 = rest / virgin; +-0.8*h_max = a loaded start).
    ``return_state=True`` returns ``(y, h_final)``.
    """
    uu = np.asarray(u, dtype=np.float64).ravel()
    if n < 1.0:
        raise ValueError("n must be >= 1")
    ul = uu.tolist()
    if method == "exact" or (method == "auto" and n == 1.0):
        if n != 1.0:
            raise ValueError("exact method only for n == 1")
        hl, hf = _bw_exact_n1(ul, A, beta, gamma, h0)
    else:
        hl, hf = _bw_rk4(ul, A, beta, gamma, n, h0, max_du)
    h = np.asarray(hl)
    y = k * (alpha * uu + (1.0 - alpha) * h)
    return (y, hf) if return_state else y


def bouc_wen_seed002(
    u: ArrayLike,
    A: float = 1.0,
    B: float = 0.45,
    C: float = 0.25,
    n: float = 1.0,
    a: float = 0.0,
    b: float = 2.8,
    h0: float = 0.0,
    *,
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, float]:
    """Bouc-Wen exactly in seed 002's notation (ViO-Com, eq. 2-3).

    ``y = a*u + b*h``, ``dh/dt = A du/dt - B|du/dt||h|^(n-1)h - C du/dt|h|^n``
    (seed 002 calls a, b "alpha" and "beta").  Implemented through :func:`bouc_wen` with
    ``k = 1`` and the output recombined.
    """
    h, hf = bouc_wen(u, A=A, beta=B, gamma=C, n=n, alpha=0.0, k=1.0, h0=h0, return_state=True)  # type: ignore[misc]
    y = a * np.asarray(u, dtype=np.float64).ravel() + b * h
    return (y, hf) if return_state else y


# =====================================================================================
# Plant 2: sums of play operators (seed 001 eq. 4.7-4.9)
# =====================================================================================

#: Play amounts P of the thesis' Gamma_11 (seed 001, section 4.4, eq. 4.11 first list), mm.
SEED001_PLAYS_MM: tuple[float, ...] = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0)

#: Weight vectors Q of seed 001 Table 4.1, keyed by (curve angle deg, radius mm).
SEED001_TABLE_4_1: dict[tuple[int, int], tuple[float, ...]] = {
    (15, 30): (-0.647, 0.871, -0.253, 0.006, 0.068, -0.060, 0.063, -0.002, -0.099, 1.144, -0.119),
    (15, 45): (-0.265, 0.372, -0.099, -0.015, 0.068, -0.052, 0.023, 0.058, -0.208, 1.339, -0.239),
    (15, 60): (-0.547, 0.730, -0.205, 0.043, -0.007, 0.014, -0.015, 0.046, -0.134, 1.156, -0.106),
    (15, 75): (-0.636, 0.836, -0.209, -0.001, 0.027, 0.018, -0.024, 0.080, -0.216, 1.148, -0.049),
    (30, 30): (-0.642, 0.828, -0.208, 0.022, -0.011, 0.054, 0.012, -0.071, 0.319, 0.917, -0.249),
    (30, 45): (-0.473, 0.612, -0.118, -0.024, 0.033, -0.009, 0.023, -0.054, 0.301, 0.973, -0.287),
    (30, 60): (-0.630, 0.820, -0.198, 0.038, -0.043, 0.042, -0.003, 0.000, 0.075, 1.127, -0.255),
    (30, 75): (-0.701, 0.899, -0.194, -0.034, 0.061, -0.007, 0.008, 0.015, -0.053, 1.152, -0.176),
    (45, 30): (-0.504, 0.651, -0.128, -0.020, 0.017, 0.065, -0.121, 0.332, 0.634, 0.318, -0.268),
    (45, 45): (-0.742, 0.964, -0.241, 0.036, -0.025, 0.036, 0.028, -0.088, 0.703, 0.527, -0.229),
    (45, 60): (-0.527, 0.666, -0.133, 0.002, 0.022, -0.010, 0.027, -0.061, 0.513, 0.782, -0.306),
    (45, 75): (-0.721, 0.932, -0.218, 0.018, -0.008, 0.039, -0.020, -0.032, 0.177, 1.042, -0.238),
    (60, 30): (-0.764, 1.007, -0.256, 0.016, 0.079, -0.108, 0.183, 0.853, -0.103, 0.221, -0.155),
    (60, 45): (-0.805, 1.041, -0.259, 0.030, -0.002, 0.004, -0.025, 0.207, 0.757, 0.130, -0.109),
    (60, 60): (-0.810, 1.051, -0.276, 0.050, 0.008, -0.006, -0.032, 0.136, 0.778, 0.224, -0.156),
    (60, 75): (-0.397, 0.519, -0.098, -0.019, 0.036, -0.028, 0.040, -0.066, 0.551, 0.789, -0.348),
    (75, 30): (-0.516, 0.687, -0.201, 0.164, -0.236, 0.528, 0.615, -0.051, -0.130, 0.433, -0.318),
    (75, 45): (-0.354, 0.507, -0.126, 0.097, -0.202, 0.864, 0.220, 0.008, -0.180, 0.544, -0.398),
    (75, 60): (-0.562, 0.755, -0.203, 0.014, 0.036, -0.063, 0.212, 0.815, -0.109, 0.292, -0.210),
    (75, 75): (-0.575, 0.735, -0.126, -0.059, 0.059, 0.001, -0.078, 0.305, 0.660, 0.291, -0.237),
    (90, 30): (-0.333, 0.422, 0.056, 0.798, 0.031, 0.006, -0.019, 0.066, -0.226, 0.649, -0.473),
    (90, 45): (-0.306, 0.478, -0.202, 0.640, 0.174, 0.189, -0.017, 0.080, -0.260, 0.738, -0.537),
    (90, 60): (-0.450, 0.676, -0.208, 0.070, 0.875, 0.022, -0.029, 0.072, -0.223, 0.636, -0.464),
    (90, 75): (-0.413, 0.528, -0.043, -0.026, -0.010, 0.776, 0.180, 0.017, -0.159, 0.473, -0.345),
}


def _play_bands(thresholds: FloatArray, convention: str) -> tuple[FloatArray, FloatArray]:
    """(lo, hi): a play's output w must satisfy v - lo <= w <= v + hi."""
    r = np.asarray(thresholds, dtype=np.float64)
    if np.any(r < 0):
        raise ValueError("thresholds must be >= 0")
    if convention == "symmetric":
        return r.copy(), r.copy()
    if convention == "thesis":
        return r.copy(), np.zeros_like(r)
    raise ValueError("convention must be 'symmetric' or 'thesis'")


def play_sum(
    u: ArrayLike,
    thresholds: Sequence[float] | FloatArray,
    weights: Sequence[float] | FloatArray,
    offset: float = 0.0,
    init: str | float | Sequence[float] | FloatArray | None = None,
    *,
    convention: str = "symmetric",
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, FloatArray]:
    """Weighted sum of play (backlash) operators, Prandtl-Ishlinskii / thesis Gamma_n form.

    Each play operator is a piston in a cylinder (seed 001 Fig. 4.3): its output ``w_i``
    stays put while the input moves inside a band, and is dragged by the input at the band's
    edges.  Discrete update (seed 001 eq. 4.8 / 4.9)::

        w_i(k) = min( v(k) + hi_i , max( v(k) - lo_i , w_i(k-1) ) )
        y(k)   = offset + sum_i q_i * w_i(k)

    ``convention='symmetric'`` (textbook Prandtl-Ishlinskii, Brokate-Sprekels): lo = hi = r_i,
    the band half-width is the threshold r_i.  ``convention='thesis'`` (seed 001 eq. 4.8):
    lo = p_i, hi = 0, i.e. ``v - p <= w <= v``: the output follows the input when it falls and
    lags it by p when it rises.  (Seed 001 eq. 4.7 writes the mirror image
    ``max{v, min{v+p, w}}``, i.e. ``v <= w <= v+p``; eq. 4.8 - the one used for Gamma_n and the
    Table 4.1 identification - is implemented.)  Weights may have mixed signs.

    Initial state ``init``: None -> every play starts at ``u[0]`` (clipped into its band; with
    the thesis convention that is the thesis' w(1) = v(1) initial condition); ``'upper'`` ->
    ``u[0] + hi_i`` (as after a long *decrease* of the input: the "unloaded" edge);
    ``'lower'`` -> ``u[0] - lo_i`` (as after a long *increase*: the loaded edge); a float
    ``f`` in [0, 1] -> ``u[0] + hi_i - f*(lo_i+hi_i)``; or an explicit array of play outputs.
    ``return_state=True`` returns ``(y, w_final)``.
    """
    uu = np.asarray(u, dtype=np.float64).ravel()
    q = np.asarray(weights, dtype=np.float64).ravel()
    lo, hi = _play_bands(np.asarray(thresholds, dtype=np.float64).ravel(), convention)
    if q.shape != lo.shape:
        raise ValueError("thresholds and weights must have the same length")
    u0 = uu[0]
    if init is None:
        w = np.full_like(lo, u0)
    elif isinstance(init, str):
        if init == "upper":
            w = u0 + hi
        elif init == "lower":
            w = u0 - lo
        else:
            raise ValueError("init must be None, 'upper', 'lower', a fraction or an array")
    elif np.isscalar(init):
        f = float(init)  # type: ignore[arg-type]
        w = u0 + hi - f * (lo + hi)
    else:
        w = np.asarray(init, dtype=np.float64).ravel().copy()
        if w.shape != lo.shape:
            raise ValueError("init array must have one entry per play")
    # Per-operator scalar loops (fast in pure Python for ~10 operators x 35k samples).
    ul = uu.tolist()
    y = np.full(uu.shape, float(offset))
    wf = np.empty_like(lo)
    for i in range(lo.size):
        wi = float(w[i])
        l_i = float(lo[i])
        h_i = float(hi[i])
        col = [0.0] * len(ul)
        for kk, v in enumerate(ul):
            a = v - l_i
            if wi < a:
                wi = a
            else:
                b = v + h_i
                if wi > b:
                    wi = b
            col[kk] = wi
        wf[i] = wi
        y += q[i] * np.asarray(col)
    return (y, wf) if return_state else y


def seed001_play_sum(
    u: ArrayLike,
    configuration: tuple[int, int] = (90, 30),
    init: str | float | Sequence[float] | FloatArray | None = None,
    *,
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, FloatArray]:
    """The thesis' complex operator Gamma_11 (seed 001 eq. 4.9) with Table 4.1 weights.

    ``y(k) = sum_i q_i gamma_i[v(k), w_i(k-1), p_i]`` with play amounts
    P = (0, 0.2, ..., 2.0) mm (section 4.4) and Q the Table 4.1 row of ``configuration``
    (curve angle deg, radius mm); default (90 deg, 30 mm), the thesis' highlighted example:
    Q = (-0.333, 0.422, 0.056, 0.798, 0.031, 0.006, -0.019, 0.066, -0.226, 0.649, -0.473)
    (mixed signs, sum = 0.977).  Plays follow eq. 4.8 (``v - p <= w <= v``, see
    :func:`play_sum`, ``convention='thesis'``), initial condition w_i(1) = v(1) by default.
    """
    q = SEED001_TABLE_4_1[tuple(configuration)]  # type: ignore[index]
    return play_sum(u, SEED001_PLAYS_MM, q, 0.0, init, convention="thesis", return_state=return_state)


# =====================================================================================
# Plant 3: discretised classical Preisach model (seed 001 eq. 4.1-4.6)
# =====================================================================================


def gauss_gauss_density(H0: float, sigma: float, centre: float = 0.0) -> Callable[[FloatArray, FloatArray], FloatArray]:
    """Gauss-Gauss Preisach density, seed 001 eq. 4.5 (N dropped, normalised later).

    ``mu(a, b) = exp(-((a-b)/2 - H0)^2 / (2 sigma^2 H0^2)) * exp(-((a+b)/2 - centre)^2 / (2 sigma^2 H0^2))``
    i.e. Gaussian in the relay half-width (a-b)/2 centred at H0 (off the diagonal) and in the
    relay centre (a+b)/2 centred at ``centre``.
    """

    def mu(a: FloatArray, b: FloatArray) -> FloatArray:
        s2 = 2.0 * (sigma * H0) ** 2
        return np.exp(-(((a - b) / 2 - H0) ** 2) / s2) * np.exp(-(((a + b) / 2 - centre) ** 2) / s2)

    return mu


def lorentzian_density(H0: float, sigma: float, centre: float = 0.0) -> Callable[[FloatArray, FloatArray], FloatArray]:
    """Factorised-Lorentzian Preisach density, seed 001 eq. 4.4 (shifted by ``centre``)."""

    def mu(a: FloatArray, b: FloatArray) -> FloatArray:
        w = sigma * H0
        return 1.0 / (1 + ((a - centre - H0) / w) ** 2) / (1 + ((b - centre + H0) / w) ** 2)

    return mu


def preisach_plane(
    u: ArrayLike,
    n: int = 20,
    density: str | Callable[[FloatArray, FloatArray], FloatArray] = "gaussian",
    umin: float | None = None,
    umax: float | None = None,
    init: str | FloatArray = "negative_saturation",
    *,
    H0: float | None = None,
    sigma: float = 0.8,
    scale: float | None = None,
    offset: float | None = None,
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, FloatArray]:
    """Discretised classical Preisach model (Preisach 1935; Mayergoyz; seed 001 eq. 4.1-4.3).

    Relays r_ab (seed 001 eq. 4.1-4.2, non-ideal relay with switching-up threshold a and
    switching-down threshold b, a >= b) switch to +1 when ``u >= a`` and to -1 when ``u < b``,
    and keep their state in between.  The relay thresholds are the ``n`` cell centres
    ``g_j = umin + (j + 1/2) (umax - umin)/n`` of a uniform grid; every pair a = g_i >= b = g_j
    is a relay (n(n+1)/2 relays, the diagonal a = b included with half a cell of weight).
    Output (eq. 4.3 discretised)::

        y = offset + scale * sum_ab mu(a, b) dA r_ab[u] / sum_ab mu(a, b) dA

    so ``y`` ranges over ``offset +- scale``; defaults ``offset = (umin+umax)/2``,
    ``scale = (umax-umin)/2`` (output range = input range at saturation).

    ``density``: ``'gaussian'`` (Gauss-Gauss, eq. 4.5, centred off the diagonal at half-width
    ``H0`` and at the middle of the range; ``H0`` defaults to 0.3*(umax-umin)/2, spread
    ``sigma*H0``), ``'lorentzian'`` (eq. 4.4), or any ``callable mu(a, b)`` in input units.
    ``umin/umax`` default to the data range with a 5 % margin (pass them explicitly so that
    several records share the same plant).

    Initial state ``init``: ``'negative_saturation'`` (all relays -1, as after u -> -inf),
    ``'positive'`` (all +1), ``'demagnetised'`` (the limit of an AC-demagnetisation about the
    centre c of the range: +1 where a + b < 2c, -1 where a + b > 2c, 0 on the line), or an
    explicit array of relay states.  Note the discretisation: the output is a staircase with
    steps each time u crosses a grid value.  ``return_state=True`` returns ``(y, states)``.
    """
    uu = np.asarray(u, dtype=np.float64).ravel()
    if umin is None or umax is None:
        span = float(uu.max() - uu.min()) or 1.0
        umin = float(uu.min()) - 0.05 * span if umin is None else umin
        umax = float(uu.max()) + 0.05 * span if umax is None else umax
    if umax <= umin:
        raise ValueError("umax must exceed umin")
    h = (umax - umin) / n
    g = umin + (np.arange(n) + 0.5) * h
    ia, ib = np.tril_indices(n)  # ia >= ib  -> a = g[ia] >= b = g[ib]
    a: FloatArray = g[ia].astype(np.float64)
    b: FloatArray = g[ib].astype(np.float64)
    centre = 0.5 * (umin + umax)
    if H0 is None:
        H0 = 0.3 * 0.5 * (umax - umin)
    if isinstance(density, str):
        if density == "gaussian":
            mu_f = gauss_gauss_density(H0, sigma, centre)
        elif density == "lorentzian":
            mu_f = lorentzian_density(H0, sigma, centre)
        else:
            raise ValueError("density must be 'gaussian', 'lorentzian' or a callable")
    else:
        mu_f = density
    area = np.where(ia == ib, 0.5, 1.0) * h * h
    wts = np.asarray(mu_f(a, b), dtype=np.float64) * area
    if np.any(wts < 0) or wts.sum() <= 0:
        raise ValueError("density must be non-negative and not identically zero")
    wts = wts / wts.sum()
    sc = 0.5 * (umax - umin) if scale is None else scale
    off = centre if offset is None else offset
    if isinstance(init, str):
        if init == "negative_saturation":
            s = -np.ones_like(a)
        elif init == "positive":
            s = np.ones_like(a)
        elif init == "demagnetised":
            d = a + b - 2 * centre
            s = np.where(d < -1e-12, 1.0, np.where(d > 1e-12, -1.0, 0.0))
        else:
            raise ValueError("unknown init")
    else:
        s = np.asarray(init, dtype=np.float64).ravel().copy()
        if s.shape != a.shape:
            raise ValueError("init array must have n(n+1)/2 entries")
    # Event-driven update: relay states only change when u crosses a grid value, so the
    # weighted sum is recomputed only then.
    y = np.empty_like(uu)
    cell_prev = None
    cur = 0.0
    for k, v in enumerate(uu):
        up_cell = int(np.searchsorted(g, v, side="right"))  # number of grid values <= v
        dn_cell = int(np.searchsorted(g, v, side="left"))  # number of grid values < v
        key = (up_cell, dn_cell)
        if key != cell_prev or k == 0:
            s = np.where(a <= v, 1.0, np.where(b > v, -1.0, s))
            cur = float(wts @ s)
            cell_prev = key
        y[k] = off + sc * cur
    return (y, s) if return_state else y


# =====================================================================================
# Plant 4: lumped tendon-sheath backlash (hardening loop)
# =====================================================================================


def tendon_sheath_backlash(
    u: ArrayLike,
    clearance: float = 0.6,
    stiffness_ratio: float = 0.25,
    friction: float = 0.6,
    stretch_mm: float = 1.0,
    sharpness: int = 2,
    q0: float | str = "rest",
    *,
    return_state: bool = False,
) -> FloatArray | tuple[FloatArray, float]:
    """Lumped, quasi-static tendon-sheath mechanism (TSM) with a smooth slack take-up.

    Physics (own lumped model built from the capstan / tendon-sheath picture of Kaneko et al.
    and seed 001 ch. 1-3: tendon elongation, sheath friction, loss of motion):

    * Sheath friction (capstan, total wrap angle Theta, friction coefficient mu,
      ``friction = mu*Theta``).  Pulling, the tension decays along the sheath as
      T(s) = T_d exp(mu Theta (1 - s/L)); releasing it grows as T_d exp(-mu Theta (1 - s/L)).
      With ``stretch_mm = T_d L / (EA)`` (tendon stretch at the nominal distal tension T_d) the
      input travel needed to turn one profile into the other, during which the distal end does
      not move, is  ``d_f = stretch_mm * 2 (cosh(mu Theta) - 1) / (mu Theta)``.
    * Clearance: ``clearance`` mm of tendon slack in the sheath lumen / distal attachment that
      must be taken up after each reversal.
    * Total dead band ``D = clearance + d_f``; engagement state ``q`` in [0, 1]
      (0 = fully released configuration, 1 = fully engaged in pull).
    * Transmission: the distal load (bending section / follower spring, stiffness k_L) in
      series with the elastic tendon gives a far-from-reversal slope
      ``K = 1 / (1 + stiffness_ratio * sinh(mu Theta)/(mu Theta))``, where
      ``stiffness_ratio = k_L L / (EA)`` and sinh(x)/x is the mean of the pull and release
      stretch factors (e^x - 1)/x and (1 - e^-x)/x.

    Equations (input travel x >= 0 in direction s = sign(du); g = engagement in that direction,
    g = q when pulling, g = 1 - q when releasing; m = ``sharpness``)::

        dg/dx = (1 - g^m) / D                 (slack taken up, fast at first then saturating)
        p     = u - D q                       (position of the taut tendon after the slack)
        y     = K p = K (u - D q)             (distal displacement; y = 0 at u = 0, q = 0)

    so the output slope is  dy/du = K g^m : zero just after a full reversal (dead band), then
    GROWING to K as the tendon takes up its slack (a hardening, backlash-like loop).  The
    output lags the input and falls short of it (loading branch y ~ K (u - D)).
    Closed-form steps: m = 1 -> 1 - g = (1 - g0) exp(-x/D); m = 2 -> atanh(g) = atanh(g0) + x/D.

    Approximations: quasi-static (no inertia, no rate dependence), nominal tension in d_f
    (the real friction band grows with tension), lumped single-state slack.

    Initial state ``q0``: ``'rest'`` (= 0, released, slack on the release side), ``'loaded'``
    (= 1, taut after a pull), or a float in [0, 1].  ``return_state=True`` -> ``(y, q_final)``.
    """
    uu = np.asarray(u, dtype=np.float64).ravel()
    if sharpness not in (1, 2):
        raise ValueError("sharpness must be 1 or 2 (closed-form steps)")
    mt = float(friction)
    if mt > 0:
        d_f = stretch_mm * 2.0 * (math.cosh(mt) - 1.0) / mt
        favg = math.sinh(mt) / mt
    else:
        d_f, favg = 0.0, 1.0
    D = float(clearance) + d_f
    K = 1.0 / (1.0 + stiffness_ratio * favg)
    if isinstance(q0, str):
        q = {"rest": 0.0, "released": 0.0, "loaded": 1.0}[q0]
    else:
        q = float(q0)
    if not (0.0 <= q <= 1.0):
        raise ValueError("q0 must be in [0, 1]")
    if D <= 0:
        y = K * uu
        return (y, q) if return_state else y
    ul = uu.tolist()
    qs = [0.0] * len(ul)
    prev = ul[0]
    gmax = 1.0 - 1e-15
    for k, v in enumerate(ul):
        du = v - prev
        prev = v
        if du != 0.0:
            x = abs(du) / D
            g = q if du > 0 else 1.0 - q
            if sharpness == 2:
                g = math.tanh(math.atanh(min(g, gmax)) + x)
            else:
                g = 1.0 - (1.0 - g) * math.exp(-x)
            q = g if du > 0 else 1.0 - g
        qs[k] = q
    qa = np.asarray(qs)
    y = K * (uu - D * qa)
    return (y, q) if return_state else y


# =====================================================================================
# Records
# =====================================================================================

#: Bouc-Wen output gain used by :func:`record`: with A=1, beta=0.45, gamma=0.25, n=1,
#: alpha=0 the state saturates at h_max = 1/0.7 = 1.4286; k = 2.8 gives y ~ +-4 mm on the
#: 6 mm stage of the default sine_decay (h reaches ~ +-1.40 there).
BW_RECORD_K = 2.8

PLANT_DEFAULTS: dict[str, dict[str, Any]] = {
    "bouc_wen": dict(A=1.0, beta=0.45, gamma=0.25, n=1.0, alpha=0.0, k=BW_RECORD_K),
    "play_sum": dict(configuration=(90, 30)),  # seed001_play_sum, thesis convention
    "preisach": dict(n=40, density="gaussian", umin=-6.6, umax=6.6, H0=2.0, sigma=0.8),
    "tendon_sheath": dict(clearance=0.6, stiffness_ratio=0.25, friction=0.6, stretch_mm=1.0, sharpness=2),
}

_PLANT_ALIASES = {
    "bouc_wen": "bouc_wen",
    "play_sum": "play_sum",
    "seed001_play_sum": "play_sum",
    "preisach": "preisach",
    "preisach_plane": "preisach",
    "tendon_sheath": "tendon_sheath",
    "tendon_sheath_backlash": "tendon_sheath",
}


def _bw_hmax(p: dict[str, Any]) -> float:
    return float((p["A"] / (p["beta"] + p["gamma"])) ** (1.0 / p["n"]))


def _start_state(plant: str, start: str | dict[str, Any], params: dict[str, Any]) -> dict[str, Any]:
    """Initial-state keyword for a plant: 'rest', 'loaded' (after a pull), 'unloaded'."""
    if isinstance(start, dict):
        return dict(start)
    if plant == "bouc_wen":
        hm = _bw_hmax(params)
        return {"h0": {"rest": 0.0, "loaded": 0.8 * hm, "unloaded": -0.8 * hm}[start]}
    if plant == "play_sum":
        return {"init": {"rest": None, "loaded": "lower", "unloaded": "upper"}[start]}
    if plant == "preisach":
        return {"init": {"rest": "demagnetised", "loaded": "positive", "unloaded": "negative_saturation"}[start]}
    if plant == "tendon_sheath":
        return {"q0": {"rest": 0.0, "loaded": 1.0, "unloaded": 0.0}[start]}
    raise ValueError(plant)


def _run_plant(plant: str, u: FloatArray, params: dict[str, Any], state: dict[str, Any]) -> tuple[FloatArray, Any]:
    """Run a named plant with parameters and an initial-state dict; return (y, final state)."""
    if plant == "bouc_wen":
        y, hf = bouc_wen(u, **params, **state, return_state=True)  # type: ignore[misc]
        return y, {"h0": float(hf)}
    if plant == "play_sum":
        y, wf = seed001_play_sum(u, **params, **state, return_state=True)  # type: ignore[misc]
        return y, {"init": wf}
    if plant == "preisach":
        y, sf = preisach_plane(u, **params, **state, return_state=True)  # type: ignore[misc]
        return y, {"init": sf}
    if plant == "tendon_sheath":
        y, qf = tendon_sheath_backlash(u, **params, **state, return_state=True)  # type: ignore[misc]
        return y, {"q0": float(qf)}
    raise ValueError(f"unknown plant {plant!r}")


_UNIT_SCALE = {"mm": 1.0, "deg": 15.0, "x1000": 1000.0}


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


def record(
    plant_name: str,
    excitation_name: str,
    *,
    units: str = "mm",
    amplitude_scale: float = 1.0,
    noise: float = 0.004,
    seed: int = 0,
    start: str | dict[str, Any] = "rest",
    dt: float = 0.01,
    plant_params: dict[str, Any] | None = None,
    excitation_params: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Generate one record ``{'t', 'u', 'y', 'y_clean', 'meta'}``.

    ``plant_name``: 'bouc_wen', 'play_sum' (= seed001_play_sum, Table 4.1 90 deg / 30 mm),
    'preisach' or 'tendon_sheath' (defaults in :data:`PLANT_DEFAULTS`, overridable through
    ``plant_params``).  ``excitation_name``: a key of :data:`EXCITATIONS`; its amplitudes
    (``amplitudes`` or ``amplitude``/``mid``/``offset``) are multiplied by
    ``amplitude_scale`` (use 1.0 and 0.5).  ``start``: 'rest', 'loaded' (state after a long
    pull: Bouc-Wen h0 = +0.8 h_max, plays at their lower band edge, Preisach positive
    saturation, TSM q0 = 1), 'unloaded' (the mirror state), or an explicit state dict.

    Units: 'mm' - u and y in mm; 'deg' - u in mm, output treated as an angle y_deg = 15*y_mm
    (+-4 mm -> +-60 deg); 'x1000' - u and y in micrometres.  ``noise`` is the standard
    deviation of additive white Gaussian output noise expressed at the mm scale; it is
    multiplied by the same unit factor (15 or 1000).  ``y_clean`` is the noise-free output.

    Bouc-Wen scaling: k = 2.8 (``BW_RECORD_K``) so that the default sine_decay (6 mm) gives
    about +-4 mm.
    """
    plant = _PLANT_ALIASES.get(plant_name)
    if plant is None:
        raise ValueError(f"unknown plant {plant_name!r}")
    if excitation_name not in EXCITATIONS:
        raise ValueError(f"unknown excitation {excitation_name!r}")
    if units not in _UNIT_SCALE:
        raise ValueError("units must be 'mm', 'deg' or 'x1000'")
    params = dict(PLANT_DEFAULTS[plant])
    params.update(plant_params or {})
    ex = dict(excitation_params or {})
    if excitation_name in ("sine_decay", "triangle_decay", "trapezoid_decay"):
        amps = ex.pop("amplitudes", (6.0, 4.5, 3.0, 1.5))
        ex["amplitudes"] = tuple(float(a) * amplitude_scale for a in amps)
        if "offset" in ex:
            ex["offset"] = float(ex["offset"]) * amplitude_scale
    else:
        ex["amplitude"] = float(ex.get("amplitude", 6.0)) * amplitude_scale
        if ex.get("mid") is not None:
            ex["mid"] = float(ex["mid"]) * amplitude_scale
    t, u = EXCITATIONS[excitation_name](dt=dt, **ex)
    state0 = _start_state(plant, start, params)
    y_mm, state_f = _run_plant(plant, u, params, state0)
    sc = _UNIT_SCALE[units]
    rng = np.random.default_rng(seed)
    y_clean = y_mm * sc
    y = y_clean + rng.normal(0.0, noise * sc, size=y_clean.shape) if noise > 0 else y_clean.copy()
    u_out = u * (1000.0 if units == "x1000" else 1.0)
    meta = {
        "plant": plant,
        "plant_params": _jsonable(params),
        "excitation": excitation_name,
        "excitation_params": _jsonable(ex),
        "amplitude_scale": amplitude_scale,
        "units": units,
        "input_unit": "um" if units == "x1000" else "mm",
        "output_unit": {"mm": "mm", "deg": "deg", "x1000": "um"}[units],
        "output_scale_per_mm": sc,
        "noise_std": noise * sc,
        "seed": seed,
        "start": start if isinstance(start, str) else "custom",
        "initial_state": _jsonable(state0),
        "final_state": _jsonable(state_f),
        "dt": dt,
    }
    return {"t": t, "u": u_out, "y": y, "y_clean": y_clean, "meta": meta}


def _prehistory(amplitude: float, rng: np.random.Generator, n_turns: int = 3, step: float = 0.01) -> FloatArray:
    """A random input history that ends at u = 0 (used to reach varied, physically reachable states).

    Turning points are drawn in [-0.5, 1] x amplitude (the tendon may have been pulled or
    released beyond the run's zero before the encoder was re-zeroed), then the history
    approaches 0 from below (loaded: the last motion was a pull, probability 1/2) or from
    above, over a random final stroke of 0.1..1.9 mm (shorter than the widest play of the
    seed-001 operator and about the TSM dead band), so the plant keeps a memory of its history.
    """
    pts = [0.0]
    for j in range(n_turns):
        pts.append(float(rng.uniform(0.2, 1.0) * amplitude if j % 2 == 0 else rng.uniform(-0.5, 0.3) * amplitude))
    last = float(rng.uniform(0.1, 1.9))
    if rng.random() < 0.5:
        pts.append(-last)  # last motion a pull from -last up to 0 (the previous point is high)
    else:
        pts.append(-float(rng.uniform(0.1, 1.9)))  # a low point first, so that the final
        pts.append(last)  # descent from +last does not wipe the memory of the rise before it
    pts.append(0.0)
    segs = [np.linspace(a, b, max(2, int(abs(b - a) / step) + 1))[1:] for a, b in zip(pts[:-1], pts[1:])]
    return np.concatenate([np.array([0.0])] + segs)


def multi_record_runs(
    plant_name: str = "bouc_wen",
    frequencies: Sequence[float] = (0.1, 0.2, 0.3, 0.4, 0.5),
    *,
    amplitude: float = 5.8,
    cycles: int = 7,
    mid: float | None = None,
    dt: float = 0.002,
    jitter: float = 0.05,
    noise: float = 0.004,
    seed: int = 0,
    start_mode: str = "varied",
    units: str = "deg",
    plant_params: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Identification and held-out runs of ONE plant, one run per frequency and family.

    Returns ``2*len(frequencies)`` records, first the identification family
    (:func:`sine_decay_to_mid`, names ``data_1_<k>``) then the held-out family
    (:func:`sine_decay_to_zero`, ``data_2_<k>``), k = 1..len(frequencies), all with the SAME
    plant parameters, input 0..``amplitude`` mm.

    Initial states (``start_mode``): ``'varied'`` (default) - the first run starts from rest,
    every other run from its own loaded state, reached by running the plant through a random
    prehistory (random turning points, then a last stroke of random length and direction ending
    at u = 0, see :func:`_prehistory`), so states are physically reachable and all different; ``'chained'`` - each run starts in the state the previous run
    ended in, after the actuator has returned from the previous run's last input to 0;
    ``'rest'`` - all from rest.  With ``'varied'`` joining the records end to end therefore
    puts a seam (a jump of the output, and for data_1 also of the input) at every boundary;
    with ``'chained'`` the data_1 boundaries jump (input mid -> 0) but the data_2 -> data_2
    boundaries are continuous (both ends at u = 0, state carried over).

    Sampling: nominally ``dt`` (500 Hz); with ``jitter > 0`` the time stamps are irregular
    (each interval ``dt*(1 + jitter*N(0,1))``, clipped to [0.5 dt, 1.5 dt]) and the input is the
    excitation evaluated at those times (the plants are rate independent).

    Units: ``'deg'`` (default, catheter-like): the output is mapped to a bending angle
    ``y_deg = 30 + g*(y_mm - y_ref)`` with one (g, y_ref) for the whole batch, chosen so that
    the rest-started identification run at the first frequency spans 30..90 deg; noise std is
    ``noise*g`` deg.  ``'mm'`` / ``'x1000'`` as in :func:`record`.
    """
    plant = _PLANT_ALIASES[plant_name]
    params = dict(PLANT_DEFAULTS[plant])
    params.update(plant_params or {})
    rng = np.random.default_rng(seed)
    m = 0.5 * amplitude if mid is None else mid

    def excitation(family: int, f: float) -> tuple[FloatArray, FloatArray]:
        T = cycles / f
        tu = _time(T, dt)
        if jitter > 0:
            d = dt * np.clip(1.0 + jitter * rng.standard_normal(tu.size - 1), 0.5, 1.5)
            tj = np.concatenate([[0.0], np.cumsum(d)])
            tj = tj[tj <= T]
        else:
            tj = tu
        if family == 1:
            _, uu = sine_decay_to_mid(dt=dt, amplitude=amplitude, cycles=cycles, frequency_hz=f, mid=m)
        else:
            _, uu = sine_decay_to_zero(dt=dt, amplitude=amplitude, cycles=cycles, frequency_hz=f)
        return tj, np.interp(tj, tu, uu)

    # Reference mapping mm -> deg from the rest-started first identification run.
    _, uref = sine_decay_to_mid(dt=dt, amplitude=amplitude, cycles=cycles, frequency_hz=frequencies[0], mid=m)
    yref, _ = _run_plant(plant, uref, params, _start_state(plant, "rest", params))
    y_lo, y_hi = float(yref.min()), float(yref.max())
    g = 60.0 / max(y_hi - y_lo, 1e-9)

    runs: list[dict[str, Any]] = []
    prev_state: dict[str, Any] | None = None
    prev_u_end = 0.0
    idx = 0
    for family in (1, 2):
        for kf, f in enumerate(frequencies, start=1):
            t, u = excitation(family, f)
            if idx == 0 or start_mode == "rest":
                state0 = _start_state(plant, "rest", params)
                how = "rest"
            elif start_mode == "chained":
                ret = np.linspace(prev_u_end, 0.0, max(2, int(abs(prev_u_end) / 0.01) + 1))
                _, state0 = _run_plant(plant, ret, params, prev_state)  # type: ignore[arg-type]
                how = "chained"
            elif start_mode == "varied":
                pre = _prehistory(amplitude, rng)
                _, state0 = _run_plant(plant, pre, params, _start_state(plant, "rest", params))
                how = "varied"
            else:
                raise ValueError("start_mode must be 'varied', 'chained' or 'rest'")
            y_mm, state_f = _run_plant(plant, u, params, state0)
            prev_state, prev_u_end = state_f, float(u[-1])
            if units == "deg":
                y_clean = 30.0 + g * (y_mm - y_lo)
                nstd = noise * g
                u_out = u
            else:
                sc = _UNIT_SCALE[units]
                y_clean = y_mm * sc
                nstd = noise * sc
                u_out = u * (1000.0 if units == "x1000" else 1.0)
            y = y_clean + rng.normal(0.0, nstd, size=y_clean.shape) if nstd > 0 else y_clean.copy()
            runs.append(
                {
                    "t": t,
                    "u": u_out,
                    "y": y,
                    "y_clean": y_clean,
                    "meta": {
                        "name": f"data_{family}_{kf}",
                        "family": "identification" if family == 1 else "held_out",
                        "excitation": "sine_decay_to_mid" if family == 1 else "sine_decay_to_zero",
                        "frequency_hz": f,
                        "amplitude_mm": amplitude,
                        "mid_mm": m if family == 1 else 0.0,
                        "cycles": cycles,
                        "plant": plant,
                        "plant_params": _jsonable(params),
                        "units": units,
                        "deg_map": {"offset_deg": 30.0, "deg_per_mm": g, "y_ref_mm": y_lo} if units == "deg" else None,
                        "noise_std": nstd,
                        "start": how,
                        "initial_state": _jsonable(state0),
                        "final_state": _jsonable(state_f),
                        "dt_nominal": dt,
                        "jitter": jitter,
                        "seed": seed,
                    },
                }
            )
            idx += 1
    return runs


def write_catheter_csv(path: str, rec: dict[str, Any], *, seed: int = 0, bend_length_mm: float = 50.0) -> None:
    """Write a record in the catheter data's CSV layout.

    Header ``Time,Tendon Disp.,Motor Curr.,Pos x,Pos y,Pos z,Angle x,Angle y,Angle z``:

    * Time (s) = ``rec['t']``; Tendon Disp. (mm) = ``rec['u']`` (divided by 1000 for x1000).
    * Angle x (deg) = the output: used as is when the record's units are 'deg' and it carries
      a ``deg_map`` (records of :func:`multi_record_runs`, 30..90 deg); otherwise mapped
      as ``30 + 15*y_mm`` (records of :func:`record`, 'deg' records divided back by 15).
    * Pos x/z: tip of a constant-curvature bending section of length ``bend_length_mm`` bent
      by Angle x (x = L(1-cos th)/th, z = L sin th/th) plus 0.05 mm tracker noise; Pos y,
      Angle y, Angle z: small noise about constants (0 mm, 0.5 deg, -1 deg).
    * Motor Curr.: integer proxy of the tendon tension (NOT a physical model):
      round(60 + 35*u + 12*tanh(du/dt / 0.5) + N(0, 2)).
    """
    meta = rec.get("meta", {})
    units = meta.get("units", "mm")
    t = np.asarray(rec["t"], dtype=np.float64)
    u = np.asarray(rec["u"], dtype=np.float64)
    y = np.asarray(rec["y"], dtype=np.float64)
    if units == "x1000":
        u = u / 1000.0
        y_mm = y / 1000.0
        ang = 30.0 + 15.0 * y_mm
    elif units == "deg":
        ang = y if meta.get("deg_map") else 30.0 + y  # record(): y is 15*y_mm already
    else:
        ang = 30.0 + 15.0 * y
    rng = np.random.default_rng(seed)
    n = t.size
    th = np.radians(np.maximum(ang, 1e-6))
    L = bend_length_mm
    px = L * (1 - np.cos(th)) / th + rng.normal(0, 0.05, n)
    pz = L * np.sin(th) / th + rng.normal(0, 0.05, n)
    py = rng.normal(0, 0.05, n)
    ay = 0.5 + rng.normal(0, 0.05, n)
    az = -1.0 + rng.normal(0, 0.05, n)
    vel = np.gradient(u, t) if n > 1 else np.zeros(n)
    cur = np.rint(60 + 35 * u + 12 * np.tanh(vel / 0.5) + rng.normal(0, 2, n)).astype(int)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("Time,Tendon Disp.,Motor Curr.,Pos x,Pos y,Pos z,Angle x,Angle y,Angle z\n")
        for i in range(n):
            fh.write(
                f"{t[i]:.4f},{u[i]:.5f},{cur[i]:d},{px[i]:.4f},{py[i]:.4f},{pz[i]:.4f},"
                f"{ang[i]:.4f},{ay[i]:.4f},{az[i]:.4f}\n"
            )
