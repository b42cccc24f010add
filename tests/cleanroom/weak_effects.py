"""Clean-room generator of WEAK hidden effects on three hysteresis shapes (``tsm-rig-log/1``).

Written from
  * the raw-run format specification ``../shared/rig-log-format.md``,
  * the clean-room writer ``tests/cleanroom/riglog.py`` (imported by file path; its
    ``make_excitation``, ``run_id_for`` and ``write_run_folder``) and that folder's README,
  * the seeds' README and papers in ``../shared/seeds/`` (Bouc-Wen eq. 2-3 of seed 002,
    Coleman-Hodgdon eq. 10 of seed 000, the Preisach relay plane and Gauss-Gauss density,
    eq. 4.3 and 4.5 of seed 001),
  * textbook physics (Bouc-Wen, Preisach relays, Duhem / Coleman-Hodgdon, capstan friction).
The author did NOT read the project's implementation (``hysteresis/``, ``pipelines/``,
``rig_io/``), its docs, benches, configuration or tests (other than ``tests/cleanroom/riglog.py``
and ``tests/cleanroom/README.md``).

Purpose
-------
Check whether an analysis tool names a hidden physical effect when the effect is WEAK (its RMS
contribution on the held-out runs only ~1.5-2.5x, or ~3-5x, the output noise), on plants of
three different loop shapes, and whether it calls clean plants clean.

Plants (rate independent, input u and output y in mm, all loops turn the same way: the output
lags, the loading branch lies below the unloading branch; loop 1.00 +- 0.01 mm wide at u = 0
on the +-6 mm major loop, 0.91-1.08 mm wide horizontally at mid output; output gain
(y(+6) - y(-6)) / 12 = 0.86-0.88; the loop closes after the first period)
  * ``bouc_wen``: dz/du = A - |z|^n (beta sign(du z) + gamma), n = 1.5, integrated in the input
    (RK4, substeps per encoder sample); y = k_lin u - b z.  The minus sign makes the loop a
    backlash-like one (output slows right after a reversal) turning the same way as the others.
  * ``preisach``: a plane of non-ideal relays (+-1) with thresholds alpha = c + r, beta = c - r;
    density Gaussian in the half-width r and a two-piece (slightly asymmetric) Gaussian in the
    centre c, truncated to alpha <= 5.8, beta >= -5.8 mm; deterministic quantile grid of relays
    (equal weights, steps far below the noise); y = k_lin u + sum w R - (the same at rest).
  * ``duhem``: Coleman-Hodgdon dy/dt = alpha |du/dt| (f(u) - y) + g(u) du/dt with f(u) = c u and
    g(u) = b (b < c; alpha 0.6 /mm, c 0.95, b 0.63); solved exactly on each piecewise-linear
    input step.

Rest = input 0 with the internal state relaxed (z = 0; demagnetised relays, staircase alpha =
-beta; y = f(0)).  Loaded = the state after a pull from rest to +6 mm and back to 0 (the run's
starting input), so the first half-cycle starts on the other branch.

Hidden effects (one per source, on the measured output only; the load cells see the plant
without the effect), each "weak" or "moderate":
  * ``pull_push_gain``: excursion above the resting output (0) scaled by (1 + g), below by (1 - g).
  * ``cubic_softening``: y -> y - c y^3 (monotone: 3 c y_max^2 << 1).
  * ``loading_gain``: the hysteretic part's slope along each branch scaled by (1 + g) while the
    input increases and (1 - g) while it decreases.  Bounded because each plant's hysteretic
    state has the same attracting branch: BW dz/du and Duhem d(y - c u)/du are multiplied by
    (1 +- g); for the relay plane the relays see, along each monotone branch, the input advanced
    (1 +- g) times as fast from the branch's reversal point (the exact analogue: a BW / Duhem
    branch with its slope scaled is the unscaled branch with its input coordinate compressed
    about the reversal point).
  * ``linear_creep``: y -> y + r t, restarting at 0 at each run.
  * ``viscous``: y -> y - c du/dt.

Runs per source (encoders 100 Hz, load cells 1 kHz, output noise N(0, 0.01 mm) on the output
only, counts quantised by the writer at 10000 counts/mm):
  1. ``sine_decay`` 6, 4.75, 3.5, 2.25, 1 mm, 2 periods each at 0.125 Hz, 80 s (identification);
  2. ``triangle_decay`` 6 mm at 6 mm/s, 20 periods, 80 s (held out);
  3. ``trapezoid_decay`` 6 mm at 5 mm/s with 0.5 s dwells, 14 periods, 81.2 s (held out).

Load cells: T_out = F0 + k_s y_plant (return spring on the output), T_in = T_out exp(mu theta
tanh(du/dt / v0)) (capstan / Euler-Eytelwein with a smooth sign), mu theta = 0.47.

Oracle per source: the RMS over runs 2 and 3 (encoder samples) of y_with_effect - y_without,
both simulated noise-free from the same plant and start, divided by the noise sd (parameters
tuned so that it is ~2 for "weak" and ~4 for "moderate").  Also given: the same with each
signal taken relative to its first sample (as the encoders record it) and with each run's mean
difference removed (pull/push gain and linear creep carry half their RMS in the mean; a
viscous term at t = 0 offsets the recorded first sample).

Caveat on ``loading_gain``: with the slope scaled, a BW or Duhem branch is the clean branch
with its input compressed about the reversal point, i.e. the plant with direction-dependent
rate constants; on the held-out runs (all branches major) the relay plane's version is close
to a relay plane with shifted thresholds.  A flexible hysteresis model may absorb part of it.

Usage:  CLEANROOM_RIGLOG=<riglog.py or its folder> python weak_effects.py <root>
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import importlib.util
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

NOISE_SD_MM = 0.01
ENC_DT = 0.01
LC_DT = 0.001
CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
MU_THETA = 0.3 * math.pi / 2.0  # mu = 0.3 over a 90 deg wrap
F0_N = 5.0  # return spring preload
K_SPRING_N_PER_MM = 0.4
V0_SIGN_MM_S = 0.3  # smooth sign scale for the capstan law
LOADCELL_NOISE_N = 0.01


# ---------------------------------------------------------------------------------------------
# riglog
# ---------------------------------------------------------------------------------------------


def _load_riglog():
    env = os.environ.get("CLEANROOM_RIGLOG")
    if env:
        p = Path(env)
        if p.is_dir():
            p = p / "riglog.py"
    else:
        p = Path(__file__).resolve().parent / "riglog.py"
    if not p.is_file():
        raise FileNotFoundError(
            f"riglog.py not found at {p}; set CLEANROOM_RIGLOG to the file or its folder"
        )
    spec = importlib.util.spec_from_file_location("cleanroom_riglog_we", p)
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


_RIGLOG = None


def riglog():
    global _RIGLOG
    if _RIGLOG is None:
        _RIGLOG = _load_riglog()
    return _RIGLOG


# ---------------------------------------------------------------------------------------------
# Excitations (riglog's make_excitation, the spec's kinds)
# ---------------------------------------------------------------------------------------------

RUN_SPECS = (
    ("sine_decay", dict(amplitudes_mm=(6.0, 4.75, 3.5, 2.25, 1.0), periods_per_amplitude=2, frequency_hz=0.125)),
    ("triangle_decay", dict(amplitudes_mm=(6.0,), periods_per_amplitude=20, slope_mm_s=6.0)),
    ("trapezoid_decay", dict(amplitudes_mm=(6.0,), periods_per_amplitude=14, slope_mm_s=5.0, dwell_s=0.5)),
)
HELD_OUT = (1, 2)  # indices of the runs the tool is meant to hold out


def excitations(dt: float = ENC_DT):
    rl = riglog()
    return [rl.make_excitation(kind, dt, **kw) for kind, kw in RUN_SPECS]


# ---------------------------------------------------------------------------------------------
# Plants.  Each ``simulate(u, g_load=0.0, n_sub=None)`` maps a sampled input (from rest) to y.
# ---------------------------------------------------------------------------------------------


class BoucWen:
    name = "bouc_wen"

    def __init__(self, A=1.0, beta=0.6, gamma=0.4, n=1.5, k_lin=0.95, b=0.5, n_sub=4):
        self.A, self.beta, self.gamma, self.n = A, beta, gamma, n
        self.k_lin, self.b, self.n_sub = k_lin, b, n_sub

    def params(self) -> dict:
        return {
            "form": "dz/du = A - |z|^n (beta sign(du z) + gamma); y = k_lin u - b z",
            "A": self.A, "beta": self.beta, "gamma": self.gamma, "n": self.n,
            "k_lin": self.k_lin, "b": self.b, "rk4_substeps_per_sample": self.n_sub,
        }

    def simulate(self, u: np.ndarray, g_load: float = 0.0, n_sub: int | None = None) -> np.ndarray:
        A, beta, gamma, n = self.A, self.beta, self.gamma, self.n
        ns = int(n_sub or self.n_sub)
        uu = np.asarray(u, dtype=float).tolist()
        z = 0.0
        zs = [0.0] * len(uu)
        for k in range(1, len(uu)):
            du = uu[k] - uu[k - 1]
            if du != 0.0:
                s = 1.0 if du > 0 else -1.0
                m = 1.0 + s * g_load
                h = du / ns

                def f(zz: float, s: float = s, m: float = m) -> float:
                    sz = s * zz
                    sg = 1.0 if sz > 0 else (-1.0 if sz < 0 else 0.0)
                    return m * (A - abs(zz) ** n * (beta * sg + gamma))

                for _ in range(ns):
                    k1 = f(z)
                    k2 = f(z + 0.5 * h * k1)
                    k3 = f(z + 0.5 * h * k2)
                    k4 = f(z + h * k3)
                    z += h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
            zs[k] = z
        return self.k_lin * np.asarray(uu) - self.b * np.asarray(zs)


class Duhem:
    name = "duhem"

    def __init__(self, alpha=0.6, c=0.95, b=0.63):
        self.alpha, self.c, self.b = alpha, c, b

    def params(self) -> dict:
        return {
            "form": "Coleman-Hodgdon dy/dt = alpha |du/dt| (c u - y) + b du/dt (exact per linear input step)",
            "alpha_per_mm": self.alpha, "c": self.c, "b": self.b,
        }

    def simulate(self, u: np.ndarray, g_load: float = 0.0, n_sub: int | None = None) -> np.ndarray:
        # e = y - c u obeys de/du = -s alpha e + (b - c) on a step of sign s: exact exponential.
        al, c, b = self.alpha, self.c, self.b
        uu = np.asarray(u, dtype=float).tolist()
        e = 0.0
        es = [0.0] * len(uu)
        for k in range(1, len(uu)):
            du = uu[k] - uu[k - 1]
            if du != 0.0:
                s = 1.0 if du > 0 else -1.0
                e_inf = s * (b - c) / al
                e = e_inf + (e - e_inf) * math.exp(-(1.0 + s * g_load) * al * abs(du))
            es[k] = e
        return c * np.asarray(uu) + np.asarray(es)


def _two_piece_normal_ppf(p: np.ndarray, mode: float, s_lo: float, s_hi: float) -> np.ndarray:
    from scipy.stats import norm

    w_lo = s_lo / (s_lo + s_hi)
    out = np.empty_like(p)
    lo = p < w_lo
    out[lo] = mode + s_lo * norm.ppf(p[lo] / w_lo * 0.5)
    out[~lo] = mode + s_hi * norm.ppf(0.5 + (p[~lo] - w_lo) / (1.0 - w_lo) * 0.5)
    return out


class Preisach:
    name = "preisach"

    def __init__(self, c_mode=0.1, c_sd_lo=1.5, c_sd_hi=1.7, r_mean=1.2, r_sd=0.35,
                 n_c=240, n_r=24, width_target=1.0, k_lin=0.72, limit=5.8):
        from scipy.stats import norm

        self.cfg = dict(c_mode=c_mode, c_sd_lo=c_sd_lo, c_sd_hi=c_sd_hi, r_mean=r_mean, r_sd=r_sd,
                        n_c=n_c, n_r=n_r, width_target=width_target, k_lin=k_lin, limit=limit)
        pc = (np.arange(n_c) + 0.5) / n_c
        cc = _two_piece_normal_ppf(pc, c_mode, c_sd_lo, c_sd_hi)
        pr = (np.arange(n_r) + 0.5) / n_r
        # half-width from a normal truncated at r > 0.02
        lo = norm.cdf((0.02 - r_mean) / r_sd)
        rr = r_mean + r_sd * norm.ppf(lo + pr * (1.0 - lo))
        C, R = np.meshgrid(cc, rr, indexing="ij")
        C, R = C.ravel(), R.ravel()
        keep = (C + R <= limit) & (C - R >= -limit)
        self.c, self.r = C[keep], R[keep]
        self.alpha_t, self.beta_t = self.c + self.r, self.c - self.r
        # width of the major loop at u = 0 is 2 * (weight of relays with beta < 0 < alpha)
        straddle = np.count_nonzero((self.beta_t < 0) & (self.alpha_t > 0))
        self.w = width_target / (2.0 * straddle)
        self.k_lin = k_lin
        self.rest_state = np.where(self.c > 0, -1, 1).astype(np.int8)
        self.h_rest = float(self.w * self.rest_state.sum())

    def params(self) -> dict:
        d = dict(self.cfg)
        d.update({
            "form": "y = k_lin u + w sum(R) - (same at rest); relays alpha = c + r, beta = c - r",
            "density": "two-piece Gaussian in c (mode, sd below, sd above) x Gaussian in r, truncated",
            "n_relays": int(self.c.size), "weight_per_relay_mm": self.w,
        })
        return d

    def simulate(self, u: np.ndarray, g_load: float = 0.0, n_sub: int | None = None,
                 chunk: int = 800) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        nk = u.size
        du = np.diff(u)
        s = np.sign(du)
        # forward-fill direction over still steps; first moving direction backfills the start
        s_ff = s.copy()
        last = 0.0
        for i in range(s_ff.size):
            if s_ff[i] == 0:
                s_ff[i] = last
            else:
                last = s_ff[i]
        # effective input seen by the relays: along each monotone branch, advanced (1 + s g)
        # times as fast from the branch's reversal point
        if g_load != 0.0:
            v = u.copy()
            u_r = u[0]
            prev = 0.0
            for i in range(s_ff.size):
                si = s_ff[i]
                if si != prev and si != 0:
                    u_r = u[i]  # reversal at the sample before this step
                    prev = si
                v[i + 1] = u_r + (1.0 + si * g_load) * (u[i + 1] - u_r)
        else:
            v = u
        up_trig = np.full(nk, -np.inf)
        dn_trig = np.full(nk, np.inf)
        up_trig[1:][s_ff > 0] = v[1:][s_ff > 0]
        dn_trig[1:][s_ff < 0] = v[1:][s_ff < 0]
        idx = np.arange(nk, dtype=np.int32)[:, None]
        total = np.zeros(nk)
        for j0 in range(0, self.c.size, chunk):
            a = self.alpha_t[j0:j0 + chunk][None, :]
            b = self.beta_t[j0:j0 + chunk][None, :]
            last_up = np.maximum.accumulate(np.where(up_trig[:, None] >= a, idx, -1), axis=0)
            last_dn = np.maximum.accumulate(np.where(dn_trig[:, None] <= b, idx, -1), axis=0)
            r0 = self.rest_state[j0:j0 + chunk][None, :]
            state = np.where(last_up > last_dn, 1, np.where(last_dn > last_up, -1, r0))
            total += state.sum(axis=1)
        return self.k_lin * u + self.w * total - self.h_rest


def make_plants() -> dict[str, Any]:
    return {"bouc_wen": BoucWen(), "preisach": Preisach(), "duhem": Duhem()}


def simulate_run(plant, u: np.ndarray, start: str, g_load: float = 0.0, n_sub: int | None = None) -> np.ndarray:
    """Plant output for input ``u`` (u[0] = 0) started at rest or loaded (pulled to +6 mm and
    back to u[0] beforehand)."""
    if start == "rest":
        return plant.simulate(u, g_load=g_load, n_sub=n_sub)
    if start == "loaded":
        u0 = float(u[0])
        back = np.linspace(6.0, u0, max(2, int(round(abs(6.0 - u0) / 0.01)) + 1))
        pre = np.concatenate([np.linspace(0.0, 6.0, 601), back[1:]])  # ends exactly at u[0]
        y = plant.simulate(np.concatenate([pre, np.asarray(u, dtype=float)[1:]]), g_load=g_load, n_sub=n_sub)
        return y[pre.size - 1:]
    raise ValueError(start)


# ---------------------------------------------------------------------------------------------
# Hidden effects (on the measured output)
# ---------------------------------------------------------------------------------------------

EFFECTS = ("pull_push_gain", "cubic_softening", "loading_gain", "linear_creep", "viscous")

# parameters chosen so that the oracle (held-out RMS / noise sd) is ~2 (weak) and ~4 (moderate)
EFFECT_PARAMS: dict[str, dict[str, dict[str, dict[str, float]]]] = {
    "bouc_wen": {
        "pull_push_gain": {"weak": {"g": 0.0059}, "moderate": {"g": 0.0118}},
        "cubic_softening": {"weak": {"c": 2.8e-4}, "moderate": {"c": 5.6e-4}},
        "loading_gain": {"weak": {"g": 0.116}, "moderate": {"g": 0.224}},
        "linear_creep": {"weak": {"r_mm_s": 4.3e-4}, "moderate": {"r_mm_s": 8.6e-4}},
        "viscous": {"weak": {"c_s": 0.0038}, "moderate": {"c_s": 0.0076}},
    },
    "preisach": {
        "pull_push_gain": {"weak": {"g": 0.0059}, "moderate": {"g": 0.0118}},
        "cubic_softening": {"weak": {"c": 2.8e-4}, "moderate": {"c": 5.6e-4}},
        # the relay plane is far more sensitive: the compressed branch input moves every
        # relay's switching point, not just the knee after a reversal
        "loading_gain": {"weak": {"g": 0.013}, "moderate": {"g": 0.026}},
        "linear_creep": {"weak": {"r_mm_s": 4.3e-4}, "moderate": {"r_mm_s": 8.6e-4}},
        "viscous": {"weak": {"c_s": 0.0038}, "moderate": {"c_s": 0.0076}},
    },
    "duhem": {
        "pull_push_gain": {"weak": {"g": 0.0059}, "moderate": {"g": 0.0118}},
        "cubic_softening": {"weak": {"c": 2.8e-4}, "moderate": {"c": 5.6e-4}},
        "loading_gain": {"weak": {"g": 0.103}, "moderate": {"g": 0.2}},
        "linear_creep": {"weak": {"r_mm_s": 4.3e-4}, "moderate": {"r_mm_s": 8.6e-4}},
        "viscous": {"weak": {"c_s": 0.0038}, "moderate": {"c_s": 0.0076}},
    },
}

EFFECT_FORMS = {
    "clean": "none",
    "pull_push_gain": "y -> y (1 + g) above the resting output 0, y (1 - g) below",
    "cubic_softening": "y -> y - c y^3",
    "loading_gain": "hysteretic part's slope along each branch x (1 + g) while du > 0, x (1 - g) while du < 0",
    "linear_creep": "y -> y + r t (t from the run's start)",
    "viscous": "y -> y - c du/dt",
}


def apply_output_effect(effect: str, p: dict, t: np.ndarray, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    if effect in ("clean", "loading_gain"):
        return y.copy()
    if effect == "pull_push_gain":
        g = p["g"]
        return np.where(y > 0, (1.0 + g) * y, (1.0 - g) * y)
    if effect == "cubic_softening":
        return y - p["c"] * y ** 3
    if effect == "linear_creep":
        return y + p["r_mm_s"] * (t - t[0])
    if effect == "viscous":
        return y - p["c_s"] * np.gradient(u, t)
    raise ValueError(effect)


# ---------------------------------------------------------------------------------------------
# Loop metrics and convergence
# ---------------------------------------------------------------------------------------------


def loop_metrics(plant, n_sub: int | None = None) -> dict:
    """Major loop of the 6 mm/s triangle (run 2) from rest: width at u = 0 (unloading minus
    loading branch), the widest vertical gap, the horizontal width at the loop's mid output,
    the output gain (y(+6) - y(-6)) / 12 and closure (largest change between the last two
    periods)."""
    u = excitations()[1].u
    y = simulate_run(plant, u, "rest", n_sub=n_sub)
    per = 4.0  # s per period at 6 mm/s, +-6 mm
    n_per = int(round(per / ENC_DT))
    last = slice(u.size - 1 - n_per, u.size - 1)
    prev = slice(u.size - 1 - 2 * n_per, u.size - 1 - n_per)
    closure = float(np.max(np.abs(y[last] - y[prev])))
    ul, yl = u[last], y[last]
    d = np.diff(ul)
    up = np.concatenate([[False], d > 0])
    dn = np.concatenate([[False], d < 0])
    grid = np.linspace(-5.9, 5.9, 1181)
    iu = np.argsort(ul[up])
    idn = np.argsort(ul[dn])
    y_up = np.interp(grid, ul[up][iu], yl[up][iu])
    y_dn = np.interp(grid, ul[dn][idn], yl[dn][idn])
    gap = y_dn - y_up
    y_top, y_bot = float(np.max(yl)), float(np.min(yl))
    y_mid = 0.5 * (y_top + y_bot)
    u_up = np.interp(y_mid, y_up, grid)
    u_dn = np.interp(y_mid, y_dn, grid)
    slope_up = np.gradient(y_up, grid)
    return {
        "width_at_u0_mm": float(np.interp(0.0, grid, gap)),
        "max_vertical_width_mm": float(np.max(gap)),
        "horizontal_width_at_mid_output_mm": float(u_up - u_dn),
        "output_gain": float((y[np.argmax(ul) + last.start] - y[np.argmin(ul) + last.start]) / 12.0),
        "output_range_mm": [y_bot, y_top],
        "min_branch_slope": float(min(slope_up.min(), np.gradient(y_dn, grid).min())),
        "closure_mm": closure,
    }


def convergence_check(plants: dict | None = None) -> dict:
    """Largest output change on run 2 (from rest) when the internal step is halved
    (BW: twice the RK4 substeps; Duhem is exact per linear input step, so the input is
    sampled twice as finely; Preisach: the relay grid halved in c and r, four times the relays)."""
    plants = plants or make_plants()
    ex = excitations()[1]
    out = {}
    for name, pl in plants.items():
        y1 = simulate_run(pl, ex.u, "rest")
        if name == "bouc_wen":
            y2 = simulate_run(pl, ex.u, "rest", n_sub=2 * pl.n_sub)
            what = f"RK4 substeps {pl.n_sub} -> {2 * pl.n_sub}"
        elif name == "preisach":
            cfg = dict(pl.cfg)
            cfg["n_c"] *= 2
            cfg["n_r"] *= 2
            y2 = simulate_run(Preisach(**cfg), ex.u, "rest")
            what = "relays x4 (grid halved in c and r)"
        else:
            # exact per piecewise-linear step: compare against a 2x finer input sampling
            ex2 = riglog().make_excitation(RUN_SPECS[1][0], ENC_DT / 2, **RUN_SPECS[1][1])
            y2 = simulate_run(pl, ex2.u, "rest")[::2]
            what = "input sampled at 200 Hz instead of 100 Hz"
        d = y1 - y2
        out[name] = {"max_abs_change_mm": float(np.max(np.abs(d))),
                     "max_abs_change_offset_removed_mm": float(np.max(np.abs(d - d.mean()))),
                     "check": what}
    return out


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _opaque(seed: int, plant: str, effect: str, strength: str, start: str) -> str:
    h = hashlib.sha256(f"weak-effects|{seed}|{plant}|{effect}|{strength}|{start}".encode()).hexdigest()
    return "we-" + h[:8]


def _source_list() -> list[tuple[str, str, str, str]]:
    out = []
    for plant in ("bouc_wen", "preisach", "duhem"):
        out.append((plant, "clean", "none", "rest"))
        out.append((plant, "clean", "none", "loaded"))
        for eff in EFFECTS:
            for strength in ("weak", "moderate"):
                out.append((plant, eff, strength, "rest"))
    return out


def _loadcells(ex_fine, y_enc_t: np.ndarray, y_plant: np.ndarray):
    t_lc = ex_fine.t_s
    u_lc = ex_fine.u
    v = np.gradient(u_lc, t_lc)
    y_lc = np.interp(t_lc, y_enc_t, y_plant)
    t_out = F0_N + K_SPRING_N_PER_MM * y_lc
    t_in = t_out * np.exp(MU_THETA * np.tanh(v / V0_SIGN_MM_S))
    return t_lc, t_in, t_out


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else 0.0


def write_all(root: str, seed: int = 0, check_convergence: bool = True) -> dict:
    t0 = time.time()
    rl = riglog()
    rootp = Path(root)
    rootp.mkdir(parents=True, exist_ok=True)
    plants = make_plants()
    exs = excitations(ENC_DT)
    exs_fine = excitations(LC_DT)
    for e, ef in zip(exs, exs_fine):
        assert abs(e.t_s[-1] - ef.t_s[-1]) < 1e-9 and np.allclose(np.interp(e.t_s, ef.t_s, ef.u), e.u, atol=1e-9)
    base_cache: dict[tuple[str, str, int], np.ndarray] = {}

    def base(plant: str, start: str, i: int) -> np.ndarray:
        key = (plant, start, i)
        if key not in base_cache:
            base_cache[key] = simulate_run(plants[plant], exs[i].u, start)
        return base_cache[key]

    truth_sources: dict[str, Any] = {}
    names_seen = set()
    for plant, eff, strength, start in _source_list():
        name = _opaque(seed, plant, eff, strength, start)
        if name in names_seen:
            raise RuntimeError("opaque name collision")
        names_seen.add(name)
        params = {} if eff == "clean" else dict(EFFECT_PARAMS[plant][eff][strength])
        src_dir = rootp / name
        per_run = []
        diffs, diffs_rel, diffs_dm = [], [], []
        src_seed = int.from_bytes(hashlib.sha256(f"{seed}|{name}".encode()).digest()[:4], "little")
        # session time from the opaque hash, so the clock does not reveal the source's order
        start_day = _dt.datetime(2026, 3, 2, 8, 0, tzinfo=_dt.timezone.utc) + _dt.timedelta(
            days=src_seed % 10, minutes=10 * ((src_seed >> 8) % 54))
        for i, (ex, exf) in enumerate(zip(exs, exs_fine)):
            y0 = base(plant, start, i)
            if eff == "loading_gain":
                y_core = simulate_run(plants[plant], ex.u, start, g_load=params["g"])
            else:
                y_core = y0
            y_eff = apply_output_effect(eff, params, ex.t_s, ex.u, y_core)
            d = y_eff - y0
            d_rel = (y_eff - y_eff[0]) - (y0 - y0[0])
            d_dm = d - d.mean()
            per_run.append({
                "kind": ex.manifest["kind"],
                "held_out": i in HELD_OUT,
                "duration_s": float(ex.t_s[-1]),
                "rms_over_noise": _rms(d) / NOISE_SD_MM,
                "rms_over_noise_as_recorded": _rms(d_rel) / NOISE_SD_MM,
                "rms_over_noise_demeaned": _rms(d_dm) / NOISE_SD_MM,
                "peak_abs_mm": float(np.max(np.abs(d))),
            })
            if i in HELD_OUT:
                diffs.append(d)
                diffs_rel.append(d_rel)
                diffs_dm.append(d_dm)
            rng = np.random.default_rng([seed, src_seed, i])
            y_meas = y_eff + rng.normal(0.0, NOISE_SD_MM, y_eff.shape)
            lc = _loadcells(exf, ex.t_s, y0)
            run_id = rl.run_id_for(CONFIGURATION, ex.manifest["kind"], i + 1)
            rl.write_run_folder(
                src_dir, run_id, ex.t_s, ex.u, y_meas,
                configuration=CONFIGURATION, excitation=ex.manifest,
                loadcell=lc, loadcell_noise_n=LOADCELL_NOISE_N, events=True,
                started_at=start_day + _dt.timedelta(minutes=3 * i),
                seed=(src_seed + i) % (2**31),
            )
        oracle = _rms(np.concatenate(diffs)) / NOISE_SD_MM
        truth_sources[name] = {
            "plant": plant,
            "effect": eff,
            "strength": strength,
            "parameters": params,
            "effect_form": EFFECT_FORMS[eff],
            "start": start,
            "oracle_rms_over_noise": oracle,
            "oracle_rms_over_noise_as_recorded": _rms(np.concatenate(diffs_rel)) / NOISE_SD_MM,
            "oracle_rms_over_noise_demeaned": _rms(np.concatenate(diffs_dm)) / NOISE_SD_MM,
            "runs": per_run,
        }
    meta = {
        "generator": "weak_effects.py (clean room; spec + riglog.py + seeds + textbook physics)",
        "seed": seed,
        "noise_sd_mm": NOISE_SD_MM,
        "held_out_runs": [RUN_SPECS[i][0] for i in HELD_OUT],
        "oracle_definition": "RMS over the held-out runs (encoder samples) of output with effect minus "
                             "output without (same plant, same start, noise-free) / noise sd",
        "intended_oracle_range": {"weak": [1.5, 2.5], "moderate": [3.0, 5.0], "none": [0.0, 0.0]},
        "plants": {k: {"parameters": p.params(), "loop": loop_metrics(p)} for k, p in plants.items()},
        "loadcell": {"F0_n": F0_N, "k_spring_n_per_mm": K_SPRING_N_PER_MM, "mu_theta": MU_THETA,
                     "smooth_sign_v0_mm_s": V0_SIGN_MM_S, "noise_n": LOADCELL_NOISE_N,
                     "note": "tensions from the plant output without the hidden effect"},
        "configuration": CONFIGURATION,
        "convergence": convergence_check(plants) if check_convergence else None,
        "generation_seconds": None,
    }
    meta["generation_seconds"] = round(time.time() - t0, 1)
    truth = {"meta": meta, "sources": truth_sources}
    (rootp / "weak_effects_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def main() -> None:
    if len(sys.argv) < 2:
        print("usage: python weak_effects.py <root folder> [seed]", file=sys.stderr)
        raise SystemExit(2)
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    truth = write_all(sys.argv[1], seed=seed)
    for name, s in sorted(truth["sources"].items(), key=lambda kv: (kv[1]["plant"], kv[1]["effect"], kv[1]["strength"])):
        print(f"{name}  {s['plant']:9s} {s['effect']:16s} {s['strength']:9s} {s['start']:7s} "
              f"oracle {s['oracle_rms_over_noise']:.2f}")
    print(f"{len(truth['sources'])} sources in {truth['meta']['generation_seconds']} s")


if __name__ == "__main__":
    main()
