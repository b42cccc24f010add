"""Clean-room generator: output END STOPS (saturation) hidden behind smooth hysteresis plants.

Provenance
----------
Read, and nothing else of the project: ``../shared/rig-log-format.md`` (the raw-run format
``tsm-rig-log/1``), ``../shared/seeds/README.md``, the papers ``000_*.txt`` (Coleman-Hodgdon
model, eq. 10-11), ``001_*.txt`` (the rig, the three excitations, Preisach relays and densities,
eq. 4.1-4.5) and ``002_*.txt`` (Bouc-Wen model, eq. 2-3), plus the clean-room writer
``tests/cleanroom/riglog.py`` (imported for the excitations and the run-folder writer).
NO implementation, test, configuration, document or benchmark of the project was read; the rest
is textbook physics.  ``riglog.py`` is imported by file path from the environment variable
``CLEANROOM_RIGLOG`` (the file or its folder), else from the ``riglog.py`` beside this module.

What it makes
-------------
``python stops_smooth.py OUTDIR [--seed 0] [--workers 1]`` writes 30 *sources* (folders) to
OUTDIR, 10 per plant (Bouc-Wen ``bw``, Coleman-Hodgdon ``ch``, Preisach ``preisach``):
4 stop forms (soft, hard, cubic, tanh) x 2 strengths (weak, strong), starting at rest, and 2
clean sources (one starting at rest, one starting loaded).  Each source holds three 80 s
``tsm-bench`` run folders of the same plant, configuration curve angle 90 deg / radius 30 mm:

* ``phi090_r030_sine_decay_0001``     identification: u = A_i sin(2 pi 0.25 t), A_i = 6, 4.5, 3,
  1.5 mm, 5 periods (20 s) each;
* ``phi090_r030_triangle_decay_0002`` held out: triangle 0 -> A -> -A -> 0 at 6 mm/s, same
  amplitudes, 8 periods each (32 + 24 + 16 + 8 s = 80 s);
* ``phi090_r030_trapezoid_decay_0003`` held out: as the triangle with a 0.75 s dwell at each
  extreme, 5 periods each (5 x (4A/6 + 1.5) s summed = 80 s).

Source names are ``st-`` + the first 10 hex digits of sha256("stops_smooth|seed|plant|tag");
nothing in a source tells its truth.  The truth goes to ``OUTDIR/stops_smooth_truth.json``
(name -> entry).  ``generate(outdir, seed=0, workers=1)`` does all of it; ``_write_source(job)``
writes one source (job: outdir, seed, plant, tag; tag is ``<form>-<strength>``,
``clean-rest`` or ``clean-loaded``) and returns its truth entry with its ``name``.

Plants (input u, plant output x, both mm; simulated on the 1 kHz grid, input linear between
samples; each plant scaled so that the steady +-6 mm loop (third 6 mm period of the
identification run) is 1.00 mm wide at u = 0 and its least-squares slope of x on u is 1.00; the
loop is counter-clockwise in (u, x): output lags the input, ascending branch below)

1. ``bw`` Bouc-Wen (seed 002 eq. 2-3), x = alpha u + beta h,
   dh/dt = A du/dt - B |du/dt| |h|^(n-1) h - C du/dt |h|^n, rate-independent so integrated in u:
   dh/du = A - (B sgn(du) sgn(h) + C) |h|^n;  A = 1, n = 1.5, B + C = h_max^-n with
   h_max = 0.4795 mm (B + C = 3.0117), C - B = 0.25 (B + C) (slope 0.25 alpha just after a
   reversal), i.e. B = 1.1294, C = 1.8823; alpha = 1.0429, beta = -1.0429 (x = 1.0429 (u - h)).
   Integration: classical RK4 with sub-steps of at most 0.002 mm of input travel (error < 1e-8 mm
   against 0.0005 mm sub-steps).  Rest: h = 0.
2. ``ch`` Coleman-Hodgdon / Duhem (seed 000 eq. 10-11 with O = (0, 0)):
   dx/dt = A |du/dt| (C u - x) + B du/dt, A = 0.8329 /mm, B = 0.6333, C = 1.0554.
   On each input segment of constant direction sg the equation is linear in u and is solved
   exactly: x1 = p(u1) + (x0 - p(u0)) exp(-A |u1 - u0|), p(u) = C u + (B - C) / (sg A).
   (Seed 000 states B < 0; with B < 0 the output would run backwards after every reversal
   (slope 2B - C < 0), so the textbook backlash-like condition C/2 < B < C is used: slope 2B - C
   = 0.21 after a reversal, C far from it.)  Rest: x = 0.
3. ``preisach``: x = a u + b sum_i w_i r_i(u), r_i the non-ideal relay of seed 001 eq. 4.1-4.2
   (+1 once u >= alpha_i, -1 once u <= beta_i, else unchanged), weights from the Gauss-Gauss
   density (eq. 4.5) written in half-width r = (alpha - beta)/2 and centre m = (alpha + beta)/2:
   mu = exp(-(r - H0)^2 / (2 s_r^2)) exp(-m^2 / (2 s_m^2)), H0 = 0.538 mm, s_r = 0.5 H0 = 0.269 mm,
   s_m = 30 mm (eq. 4.5 has s_r = s_m = sigma H0; the centre factor is widened so that the relay
   slope is nearly uniform over the +-6 mm stroke and the clean plant has no stop-like
   curvature of its own).  6000 relays: 200 centres on [-m_max, m_max], m_max = 6 + (H0 + 3 s_r)
   + 0.5 mm, x 30 half-widths on (0, H0 + 3 s_r], each jittered uniformly within its cell
   (numpy default_rng(20260302), fixed, independent of --seed), w_i = mu * 2 dm dr.
   Reversible part a = 0.15, relay scale b = 0.3406 (largest single relay step 2 b w_i
   = 0.0048 mm).  Rest = the demagnetised staircase: all
   relays at -1, then input extremes +12, -12 q, +12 q^2, ... (q = 0.9) until below 1e-4 mm,
   then back to 0.

Loaded start (clean-loaded only): before the run the plant (and the friction state below) is
driven from rest 0 -> +6 -> 0 mm, so the run starts on the upper (descending) branch.

Stop forms, y = S(x), applied to the plant output in its own coordinates (x = 0 at rest at u = 0)
* ``soft``:  y = x for x <= k, y = k + s tanh((x - k)/s) above the knee k; s = 0.3 mm.
* ``hard``:  y = min(x, k).
* ``cubic``: y = c0 + (x - c0) - a3 (x - c0)^3, c0 = centre (max + min)/2 of x on the
  identification run; a3 checked < 1 / (3 max|x - c0|^2) (monotone).
* ``tanh``:  y = c0 + Y tanh((x - c0)/Y), same c0.
The free parameter (k, k, a3, Y) is found by bisection so that the effect
RMS{(y - y[0]) - (x - x[0])} over the identification run (rest start, noise-free, encoder clock)
is 3.5 x 0.007 = 0.0245 mm (``weak``) or 12 x 0.007 = 0.084 mm (``strong``).  Soft and hard knees
therefore sit near the top (pull side) of the identification output range.

Channels (tsm-rig-log/1, written by riglog.write_run_folder, rig ``tsm-bench``)
* encoder.csv, 100 Hz (8001 rows, t = 0..80 s): counts_per_unit 1000 (1 um counts), 32-bit
  counters, input_sign +1, output_sign -1, counters zeroed at the first sample.  The recorded
  output is y + n, n ~ N(0, 0.007 mm) on every sample after the first (the first sample is the
  zero reference), then quantised to 1 um.
* loadcell.csv, 1 kHz (80001 rows), the spec's example calibration (9.81 N per mV/V, zeros
  0.012 / -0.004 mV/V, range 20 N), Gaussian noise 0.01 N added by riglog:
  output tension (return spring on the follower)  T_out = F0 + k_s y, F0 = 5 N, k_s = 0.05 N/mm;
  input tension (capstan across the bend)          T_in = T_out exp(mu_f Theta s_f), mu_f = 0.2,
  Theta = radians(90) (wrap = curve angle); s_f in [-1, 1] is a Dahl-like friction-direction
  state driven by input travel: s_f <- d + (s_f - d) exp(-|du| / delta), d = sgn(du),
  delta = 0.25 mm, s_f = 0 at rest (unchanged during dwells).  The stop reaches the load cells
  only through y (the clipped follower position in T_out).
* events.csv: start / stop.  Manifest notes empty; started_at derived from the source name.

Oracle (truth ``oracle``, mm, on the encoder samples of the two held-out runs pooled; the
recorded output is decoded from the written counts, relative to the first sample):
``heldout_rmse_true_mm`` = RMSE of the true plant+stop output (y - y[0]) against it (about the
noise, 0.007); ``heldout_rmse_plain_mm`` = RMSE of the plain plant (x - x[0]) against it (the
size of the stop on held-out runs).  Also the same two on the identification run, the noise-free
effect RMS on both, and the effect RMS left after the best affine refit y ~ p x + q (how much a
gain/offset change of the plant could absorb).

Deterministic for a seed (the seed changes the noise and the names, not plants or stops).
Uses numpy, pandas (through riglog) and the standard library.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import functools
import hashlib
import importlib.util
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

# ------------------------------------------------------------------------------------------
# riglog import (by file path)
# ------------------------------------------------------------------------------------------


def _load_riglog():
    env = os.environ.get("CLEANROOM_RIGLOG")
    if env:
        p = Path(env)
        if p.is_dir():
            p = p / "riglog.py"
    else:
        p = Path(__file__).resolve().parent / "riglog.py"
    if not p.is_file():
        raise ImportError(f"riglog.py not found at {p} (set CLEANROOM_RIGLOG)")
    if "cr_riglog" in sys.modules:
        return sys.modules["cr_riglog"]
    spec = importlib.util.spec_from_file_location("cr_riglog", p)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["cr_riglog"] = mod
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


rl = _load_riglog()

# ------------------------------------------------------------------------------------------
# Constants
# ------------------------------------------------------------------------------------------

CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
AMPLITUDES = (6.0, 4.5, 3.0, 1.5)
RUNS = (
    ("sine_decay", {"periods_per_amplitude": 5, "frequency_hz": 0.25}),
    ("triangle_decay", {"periods_per_amplitude": 8, "slope_mm_s": 6.0}),
    ("trapezoid_decay", {"periods_per_amplitude": 5, "slope_mm_s": 6.0, "dwell_s": 0.75}),
)
IDENT_KIND = "sine_decay"
HELDOUT_KINDS = ("triangle_decay", "trapezoid_decay")
DT_FINE = 0.001  # 1 kHz simulation / load-cell grid
DECIM = 10  # encoder = every 10th fine sample (100 Hz)
COUNTS_PER_MM = 1000  # 1 um counts
OUTPUT_SIGN = -1
NOISE_Y_MM = 0.007
LC_NOISE_N = 0.01
F0_N = 5.0
K_SPRING_N_PER_MM = 0.05
MU_F = 0.2
THETA_RAD = math.radians(90.0)
DAHL_DELTA_MM = 0.25
TARGET_RMS = {"weak": 3.5 * NOISE_Y_MM, "strong": 12.0 * NOISE_Y_MM}
SOFT_S_MM = 0.3
LOADED_TOP_MM = 6.0

PLANTS = ("bw", "ch", "preisach")
FORMS = ("soft", "hard", "cubic", "tanh")
STRENGTHS = ("weak", "strong")
TAGS = tuple(f"{f}-{s}" for f in FORMS for s in STRENGTHS) + ("clean-rest", "clean-loaded")

# Bouc-Wen (seed 002 eq. 2-3)
BW_N = 1.5
BW_A = 1.0
BW_HMAX = 0.4795
BW_GL = BW_HMAX ** (-BW_N)  # B + C
BW_GU = 0.25 * BW_GL  # C - B
BW_B = 0.5 * (BW_GL - BW_GU)
BW_C = 0.5 * (BW_GL + BW_GU)
BW_ALPHA = 1.0429
BW_BETA = -1.0429
BW_DH = 0.002  # max sub-step of input travel (mm)

# Coleman-Hodgdon (seed 000 eq. 10-11)
CH_A = 0.8329
CH_B = 0.6333
CH_C = 1.0554

# Preisach (seed 001 eq. 4.1-4.5)
PR_H0 = 0.538
PR_SR = 0.5 * PR_H0
PR_SM = 30.0
PR_NM, PR_NR = 200, 30
PR_A = 0.15
PR_B = 0.3406
PR_RNG = 20260302
PR_DEMAG_AMP, PR_DEMAG_Q = 12.0, 0.9

PLANT_PARAMS = {
    "bw": {"model": "Bouc-Wen seed 002 eq. 2-3", "A": BW_A, "B": round(BW_B, 5), "C": round(BW_C, 5), "n": BW_N,
           "alpha": BW_ALPHA, "beta": BW_BETA, "h_max_mm": BW_HMAX, "rk4_max_substep_mm": BW_DH},
    "ch": {"model": "Coleman-Hodgdon seed 000 eq. 10-11", "A_per_mm": CH_A, "B": CH_B, "C": CH_C,
           "origin": [0.0, 0.0]},
    "preisach": {"model": "Preisach relays seed 001 eq. 4.1-4.5, Gauss-Gauss in (half-width, centre)",
                 "H0_mm": PR_H0, "sigma_halfwidth_mm": PR_SR, "sigma_centre_mm": PR_SM,
                 "n_relays": PR_NM * PR_NR, "reversible_slope_a": PR_A, "relay_scale_b": PR_B,
                 "relay_rng": PR_RNG, "start": "demagnetised staircase (q=0.9 from 12 mm)"},
}


# ------------------------------------------------------------------------------------------
# Plants
# ------------------------------------------------------------------------------------------


def _bw_run(u: np.ndarray, h: float) -> tuple[np.ndarray, float]:
    """Bouc-Wen in the input: dh/du = A - (B sgn(du h) + C)|h|^n, RK4 sub-steps <= BW_DH."""
    n, A, gl, gu = BW_N, BW_A, BW_GL, BW_GU
    up = u.tolist()
    hs = [h]
    for k in range(1, len(up)):
        du = up[k] - up[k - 1]
        if du != 0.0:
            m = int(abs(du) / BW_DH) + 1
            st = du / m
            for _ in range(m):
                k1 = A - (gl if h * st > 0 else gu) * abs(h) ** n
                h2 = h + 0.5 * st * k1
                k2 = A - (gl if h2 * st > 0 else gu) * abs(h2) ** n
                h3 = h + 0.5 * st * k2
                k3 = A - (gl if h3 * st > 0 else gu) * abs(h3) ** n
                h4 = h + st * k3
                k4 = A - (gl if h4 * st > 0 else gu) * abs(h4) ** n
                h += st * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        hs.append(h)
    harr = np.asarray(hs)
    return BW_ALPHA * u + BW_BETA * harr, h


def _ch_run(u: np.ndarray, x: float) -> tuple[np.ndarray, float]:
    """Coleman-Hodgdon, exact on each linear input segment."""
    A, B, C = CH_A, CH_B, CH_C
    up = u.tolist()
    xs = [x]
    off = (B - C) / A
    for k in range(1, len(up)):
        du = up[k] - up[k - 1]
        if du != 0.0:
            o = off if du > 0 else -off
            x = C * up[k] + o + (x - C * up[k - 1] - o) * math.exp(-A * abs(du))
        xs.append(x)
    return np.asarray(xs), x


@functools.lru_cache(maxsize=1)
def _relays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rmax = PR_H0 + 3.0 * PR_SR
    mmax = 6.0 + rmax + 0.5
    rng = np.random.default_rng(PR_RNG)
    dm, dr = 2.0 * mmax / PR_NM, rmax / PR_NR
    M, R = np.meshgrid(-mmax + dm * (np.arange(PR_NM) + 0.5), dr * (np.arange(PR_NR) + 0.5), indexing="ij")
    M = M.ravel() + rng.uniform(-0.5, 0.5, M.size) * dm
    R = R.ravel() + rng.uniform(-0.5, 0.5, R.size) * dr
    w = np.exp(-((R - PR_H0) ** 2) / (2 * PR_SR**2)) * np.exp(-(M**2) / (2 * PR_SM**2)) * 2.0 * dm * dr
    return M + R, M - R, w


def _pr_demag() -> np.ndarray:
    al, be, _ = _relays()
    s = -np.ones(al.size)
    a, sign = PR_DEMAG_AMP, 1
    while a > 1e-4:
        if sign > 0:
            s[al <= a] = 1.0
        else:
            s[be >= -a] = -1.0
        sign, a = -sign, a * PR_DEMAG_Q
    if sign > 0:
        s[al <= 0.0] = 1.0
    else:
        s[be >= 0.0] = -1.0
    return s


def _pr_run(u: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    al, be, w = _relays()
    s = s.copy()
    up = u.tolist()
    out = np.empty(len(up))
    out[0] = w @ s
    for k in range(1, len(up)):
        du = up[k] - up[k - 1]
        if du > 0:
            s[al <= up[k]] = 1.0
        elif du < 0:
            s[be >= up[k]] = -1.0
        out[k] = w @ s
    return PR_A * u + PR_B * out, s


def _plant_run(plant: str, u: np.ndarray, state: Any) -> tuple[np.ndarray, Any]:
    if plant == "bw":
        return _bw_run(u, state)
    if plant == "ch":
        return _ch_run(u, state)
    if plant == "preisach":
        return _pr_run(u, state)
    raise ValueError(plant)


def _plant_rest(plant: str) -> Any:
    return _pr_demag() if plant == "preisach" else 0.0


def _dahl(u: np.ndarray, s: float) -> tuple[np.ndarray, float]:
    up = u.tolist()
    ss = [s]
    for k in range(1, len(up)):
        du = up[k] - up[k - 1]
        if du != 0.0:
            d = 1.0 if du > 0 else -1.0
            s = d + (s - d) * math.exp(-abs(du) / DAHL_DELTA_MM)
        ss.append(s)
    return np.asarray(ss), s


# ------------------------------------------------------------------------------------------
# Excitations and simulation (cached per process)
# ------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _excitation(kind: str) -> tuple[Any, Any]:
    kw = dict(RUNS)[kind]
    fine = rl.make_excitation(kind, DT_FINE, amplitudes_mm=AMPLITUDES, **kw)
    enc = rl.make_excitation(kind, rl.ENCODER_DT_S, amplitudes_mm=AMPLITUDES, **kw)
    if fine.u.size != (enc.u.size - 1) * DECIM + 1 or not np.allclose(fine.u[::DECIM], enc.u, atol=1e-9):
        raise RuntimeError(f"{kind}: 1 kHz and 100 Hz excitations disagree")
    if abs(enc.t_s[-1] - 80.0) > 1e-6 or abs(enc.u[0]) > 1e-12:
        raise RuntimeError(f"{kind}: expected an 80 s run starting at 0 mm")
    return fine, enc


@functools.lru_cache(maxsize=None)
def _start_state(plant: str, start: str) -> tuple[Any, float]:
    st = _plant_rest(plant)
    sf = 0.0
    if start == "loaded":
        pre = np.concatenate([np.linspace(0.0, LOADED_TOP_MM, 601), np.linspace(LOADED_TOP_MM, 0.0, 601)[1:]])
        _, st = _plant_run(plant, pre, st)
        _, sf = _dahl(pre, sf)
    return st, sf


@functools.lru_cache(maxsize=None)
def _simulate(plant: str, kind: str, start: str) -> dict[str, np.ndarray]:
    """Noise-free plant output x and friction state on the 1 kHz grid."""
    fine, _ = _excitation(kind)
    st, sf = _start_state(plant, start)
    x, _ = _plant_run(plant, fine.u, st)
    s_f, _ = _dahl(fine.u, sf)
    return {"x": x, "s_f": s_f}


# ------------------------------------------------------------------------------------------
# Stops
# ------------------------------------------------------------------------------------------


def apply_stop(x: np.ndarray, form: str | None, p: dict[str, float]) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if form is None:
        return x.copy()
    if form == "soft":
        k, s = p["knee_mm"], p["s_mm"]
        return np.where(x > k, k + s * np.tanh((x - k) / s), x)
    if form == "hard":
        return np.minimum(x, p["knee_mm"])
    if form == "cubic":
        d = x - p["c0_mm"]
        return p["c0_mm"] + d - p["a_per_mm2"] * d**3
    if form == "tanh":
        Y = p["Y_mm"]
        return p["c0_mm"] + Y * np.tanh((x - p["c0_mm"]) / Y)
    raise ValueError(form)


def _effect_rms(x: np.ndarray, y: np.ndarray) -> float:
    e = (y - y[0]) - (x - x[0])
    return float(np.sqrt(np.mean(e**2)))


def _affine_residual_rms(x: np.ndarray, y: np.ndarray) -> float:
    X = np.column_stack([x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    return float(np.sqrt(np.mean((y - X @ coef) ** 2)))


def _bisect(f, lo: float, hi: float, it: int = 80) -> float:
    flo = f(lo)
    for _ in range(it):
        mid = 0.5 * (lo + hi)
        fm = f(mid)
        if (fm > 0) == (flo > 0):
            lo, flo = mid, fm
        else:
            hi = mid
    return 0.5 * (lo + hi)


@functools.lru_cache(maxsize=None)
def _stop_params(plant: str, form: str, strength: str) -> dict[str, float]:
    """Solve the stop's free parameter for the target effect RMS on the identification run."""
    x = _simulate(plant, IDENT_KIND, "rest")["x"][::DECIM]
    target = TARGET_RMS[strength]
    lo_x, hi_x = float(x.min()), float(x.max())
    c0 = 0.5 * (lo_x + hi_x)
    if form in ("soft", "hard"):
        base = {"s_mm": SOFT_S_MM} if form == "soft" else {}
        f = lambda k: _effect_rms(x, apply_stop(x, form, {**base, "knee_mm": k})) - target  # noqa: E731
        k = _bisect(f, lo_x, hi_x)
        p = {"knee_mm": k, **base, "depth_below_ident_max_mm": hi_x - k}
    elif form == "cubic":
        amax = 1.0 / (3.0 * max(hi_x - c0, c0 - lo_x) ** 2)
        f = lambda a: _effect_rms(x, apply_stop(x, form, {"c0_mm": c0, "a_per_mm2": a})) - target  # noqa: E731
        a = _bisect(f, 0.0, amax)
        p = {"c0_mm": c0, "a_per_mm2": a, "monotone_limit_a_per_mm2": amax}
        if a >= amax:
            raise RuntimeError("cubic stop would not be monotone")
    elif form == "tanh":
        f = lambda Y: _effect_rms(x, apply_stop(x, form, {"c0_mm": c0, "Y_mm": Y})) - target  # noqa: E731
        p = {"c0_mm": c0, "Y_mm": _bisect(f, 0.5, 1e4)}
    else:
        raise ValueError(form)
    p["ident_x_range_mm"] = [lo_x, hi_x]
    return {k: (round(v, 6) if isinstance(v, float) else [round(q, 6) for q in v]) for k, v in p.items()}


# ------------------------------------------------------------------------------------------
# Sources
# ------------------------------------------------------------------------------------------


def _h(*parts: Any) -> str:
    return hashlib.sha256("|".join(str(p) for p in parts).encode()).hexdigest()


def source_name(seed: int, plant: str, tag: str) -> str:
    return "st-" + _h("stops_smooth", seed, plant, tag)[:10]


def _parse_tag(tag: str) -> tuple[str | None, str | None, str]:
    if tag == "clean-rest":
        return None, None, "rest"
    if tag == "clean-loaded":
        return None, None, "loaded"
    form, _, strength = tag.partition("-")
    if form not in FORMS or strength not in STRENGTHS:
        raise ValueError(f"bad tag {tag!r}")
    return form, strength, "rest"


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def _write_source(job: dict) -> dict:
    """Write one source folder; return its truth entry (with ``name``)."""
    outdir = Path(job["outdir"])
    seed = int(job.get("seed", 0))
    plant, tag = job["plant"], job["tag"]
    if plant not in PLANTS:
        raise ValueError(plant)
    form, strength, start = _parse_tag(tag)
    name = source_name(seed, plant, tag)
    params = _stop_params(plant, form, strength) if form else {}
    src = outdir / name
    src.mkdir(parents=True, exist_ok=True)
    base_min = int(_h("start", name)[:8], 16) % (60 * 24 * 60)
    t_start = _dt.datetime(2026, 3, 2, 8, 0, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=base_min)

    rec: dict[str, dict[str, np.ndarray]] = {}
    runs = {}
    for i, (kind, _) in enumerate(RUNS):
        fine, enc = _excitation(kind)
        sim = _simulate(plant, kind, start)
        x_f = sim["x"]
        y_f = apply_stop(x_f, form, params)
        t_out = F0_N + K_SPRING_N_PER_MM * y_f
        t_in = t_out * np.exp(MU_F * THETA_RAD * sim["s_f"])
        x_e, y_e = x_f[::DECIM], y_f[::DECIM]
        rng = np.random.default_rng(int(_h("noise", seed, plant, tag, kind)[:15], 16))
        noise = rng.normal(0.0, NOISE_Y_MM, y_e.size)
        noise[0] = 0.0
        run_id = rl.run_id_for(CONFIGURATION, kind, i + 1)
        rl.write_run_folder(
            src, run_id, enc.t_s, enc.u, y_e + noise, rig="tsm-bench", unit="mm",
            configuration=CONFIGURATION, excitation=enc.manifest, counts_per_unit=COUNTS_PER_MM,
            counter_bits=32, input_sign=1, output_sign=OUTPUT_SIGN,
            loadcell=(t_in, t_out), loadcell_rate_hz=1000.0, loadcell_noise_n=LC_NOISE_N,
            events=True, started_at=t_start + _dt.timedelta(minutes=4 * i),
            seed=int(_h("lc", seed, plant, tag, kind)[:15], 16), truth_dir=None,
        )
        counts = rl.counts_from_position(y_e + noise, counts_per_unit=COUNTS_PER_MM, sign=OUTPUT_SIGN, counter_bits=32)
        recorded = OUTPUT_SIGN * rl.unwrap_counts(counts, 32).astype(float) / COUNTS_PER_MM
        rec[kind] = {"rec": recorded - recorded[0], "y": y_e - y_e[0], "x": x_e - x_e[0], "xa": x_e, "ya": y_e}
        runs[run_id] = kind

    ho = {k: np.concatenate([rec[kk][k] for kk in HELDOUT_KINDS]) for k in ("rec", "y", "x")}
    idr = rec[IDENT_KIND]
    ident_x, ident_y = idr["xa"], idr["ya"]
    oracle = {
        "noise_sd_mm": NOISE_Y_MM,
        "heldout_rmse_true_mm": round(_rmse(ho["y"], ho["rec"]), 6),
        "heldout_rmse_plain_mm": round(_rmse(ho["x"], ho["rec"]), 6),
        "ident_rmse_true_mm": round(_rmse(idr["y"], idr["rec"]), 6),
        "ident_rmse_plain_mm": round(_rmse(idr["x"], idr["rec"]), 6),
        "effect_rms_ident_mm": round(_effect_rms(ident_x, ident_y), 6),
        "effect_rms_heldout_mm": round(_rmse(ho["y"], ho["x"]), 6),
        "effect_rms_ident_after_affine_refit_mm": round(_affine_residual_rms(ident_x, ident_y), 6),
    }
    entry = {
        "name": name,
        "plant": plant,
        "plant_params": PLANT_PARAMS[plant],
        "effect": "saturation" if form else None,
        "form": form,
        "strength": strength,
        "parameters": params or None,
        "start": start,
        "x_at_run_start_mm": round(float(_simulate(plant, IDENT_KIND, start)["x"][0]), 6),
        "configuration": dict(CONFIGURATION),
        "runs": runs,
        "identification_run": rl.run_id_for(CONFIGURATION, IDENT_KIND, 1),
        "held_out_runs": [rl.run_id_for(CONFIGURATION, k, i + 1) for i, (k, _) in enumerate(RUNS) if k in HELDOUT_KINDS],
        "oracle": oracle,
    }
    return entry


def loop_stats(plant: str) -> dict[str, float]:
    """Width at u = 0, LS slope, tip-to-tip slope and signed area of the steady +-6 mm loop."""
    fine, _ = _excitation(IDENT_KIND)
    x = _simulate(plant, IDENT_KIND, "rest")["x"]
    sel = (fine.t_s >= 8.0) & (fine.t_s < 12.0)
    uu, xx = fine.u[sel], x[sel]
    asc, dsc = [], []
    for i in range(uu.size - 1):
        if uu[i] <= 0.0 < uu[i + 1] or uu[i] > 0.0 >= uu[i + 1]:
            v = xx[i] + (xx[i + 1] - xx[i]) * (0.0 - uu[i]) / (uu[i + 1] - uu[i])
            (asc if uu[i + 1] > uu[i] else dsc).append(v)
    du = np.diff(uu)
    return {
        "width_at_u0_mm": float(np.mean(dsc) - np.mean(asc)),
        "ls_slope": float(np.polyfit(uu, xx, 1)[0]),
        "tip_slope": float((xx[np.argmax(uu)] - xx[np.argmin(uu)]) / (uu.max() - uu.min())),
        "signed_area_int_x_du": float(np.sum(0.5 * (xx[1:] + xx[:-1]) * du)),  # < 0: counter-clockwise
        "slope_after_reversal": _slope_after_top(uu, xx),
    }


def _slope_after_top(uu: np.ndarray, xx: np.ndarray, travel: float = 0.05) -> float:
    i = int(np.argmax(uu))
    j = i + int(np.argmax(uu[i:] <= uu[i] - travel))
    return float((xx[j] - xx[i]) / (uu[j] - uu[i]))


def _jobs(outdir: str | Path, seed: int) -> list[dict]:
    return [{"outdir": str(outdir), "seed": int(seed), "plant": p, "tag": t} for p in PLANTS for t in TAGS]


def generate(outdir: str | Path, seed: int = 0, workers: int = 1) -> dict:
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    jobs = _jobs(out, seed)
    names = [source_name(seed, j["plant"], j["tag"]) for j in jobs]
    if len(set(names)) != len(names):
        raise RuntimeError("source name collision")
    if workers > 1:
        by_plant = [[j for j in jobs if j["plant"] == p] for p in PLANTS]
        with ProcessPoolExecutor(max_workers=workers) as ex:
            entries = [e for chunk in ex.map(_write_chunk, by_plant) for e in chunk]
    else:
        entries = [_write_source(j) for j in jobs]
    truth = {e["name"]: e for e in sorted(entries, key=lambda e: e["name"])}
    (out / "stops_smooth_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def _write_chunk(jobs: list[dict]) -> list[dict]:
    return [_write_source(j) for j in jobs]


def _table(truth: dict) -> str:
    hdr = f"{'name':15s} {'plant':9s} {'form':6s} {'str':6s} {'start':6s} {'ho_true':>8s} {'ho_plain':>8s} {'eff_id':>7s}"
    lines = [hdr]
    order = {p: i for i, p in enumerate(PLANTS)}
    for e in sorted(truth.values(), key=lambda e: (order[e["plant"]], str(e["form"]), str(e["strength"]), e["start"])):
        o = e["oracle"]
        lines.append(
            f"{e['name']:15s} {e['plant']:9s} {str(e['form']):6s} {str(e['strength']):6s} {e['start']:6s} "
            f"{o['heldout_rmse_true_mm']:8.4f} {o['heldout_rmse_plain_mm']:8.4f} {o['effect_rms_ident_mm']:7.4f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    a = ap.parse_args(argv)
    t0 = time.time()
    truth = generate(a.outdir, seed=a.seed, workers=max(1, a.workers))
    for p in PLANTS:
        s = loop_stats(p)
        print(f"loop {p:9s} " + " ".join(f"{k}={v:.4f}" for k, v in s.items()))
    print(_table(truth))
    print(f"{len(truth)} sources in {time.time() - t0:.1f} s -> {Path(a.outdir) / 'stops_smooth_truth.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
