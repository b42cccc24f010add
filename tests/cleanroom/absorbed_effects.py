"""Clean-room sources for the discrepancy analysis: three plants outside the standard families.

Written from physics only (the seed papers' rig description, the ``tsm-rig-log/1`` specification
in ``../shared/rig-log-format.md`` and textbook friction/hysteresis models); it has not read the
project's implementation or tests.  Runs are written with the clean-room ``riglog.py`` writer,
imported by file path: the environment variable ``CLEANROOM_RIGLOG`` names the file or the folder
holding it, else the ``riglog.py`` beside this module is used.

Plants (millimetres of tendon travel in, millimetres of follower travel out; each loop is tuned to
1.00 mm wide at mid-stroke on a steady +-6 mm, 0.2 Hz sine, and to the stated output gain, the
least-squares slope of that loop)
-----------------------------------------------------------------------------------------------
``lugre``  Tendon-sheath with LuGre friction at a massless sliding node (curve 90 deg, r 30 mm).
    The input tendon is a spring ``k_t`` from the input ``u`` to the node ``x``.  The bristle state
    ``s = sigma0 z / F_c`` obeys the LuGre law ``ds/dx = (1 - sign(dx) s / s_ss(v)) / z_c`` with
    the Stribeck ratio ``s_ss(v) = 1 + rho exp(-(v / v_s)^2)`` (rho 0.05, v_s 0.3 mm/s, so the
    rate dependence is very weak) and no bristle damping.  The friction is of capstan form: the
    node balance is ``F0 + k_t (u - x) = T_out exp(mu theta s) + c_v dx/dt`` (Euler-Eytelwein with
    the bristle state in place of ``sign(v)``, and a small viscous term ``c_v``), and the node
    drives the follower through a series spring ``k_s`` against a preloaded return spring ``k_r``:
    ``y = g x`` with ``g = k_s / (k_s + k_r)`` and ``T_out = F0 + k_r y``.  The loop is a
    smoothed parallelogram whose width grows with the stroke (the friction scales with tension).
    Integrated exactly in the node travel per 10 ms step (bracketed Newton on the balance).
``kp``  A Krasnosel'skii-Pokrovskii operator sum (curve 60 deg, r 45 mm): kernels on a grid of
    centres ``c`` (-10..10 mm, 0.5 mm) and half-widths ``r`` (0.1..1.6 mm) with linear ridges of
    different widths for switching up (1.0 mm) and down (0.5 mm; both multiples of the grid, so the
    ridges tile without ripple); each kernel is
    ``k = clip(k_prev, R_up(u), R_dn(u))``; density Gaussian in the centre (sd 5.5 mm) and
    gamma-like in the half-width; ``y = k_lin u + sum w k`` less its resting value.  The rest
    state is the demagnetised one (decaying alternating input ending at 0).
``gpi``  An asymmetric generalised Prandtl-Ishlinskii sum (curve 75 deg, r 60 mm): ten
    generalised plays ``z = max(g_up(u) - r, min(g_dn(u) + r, z_prev))`` with mildly nonlinear,
    different envelopes ``g_up(u) = u + 0.010 u^2`` and ``g_dn(u) = u + 0.018 u^2 + 0.0008 u^3``
    (the loop widens toward the pulled end), half-widths 0.05..1.85 mm, weights ``exp(-r/1.0)``;
    ``y = k0 u + sum p z``.

Tensions (load cells).  The follower is held by a return spring with preload:
``T_out = F0 + k_r y`` (F0 5 N, k_r 0.3 N/mm).  The input tension follows the capstan law
``T_in = T_out exp(mu theta s)`` (mu 0.2, theta the configuration's curve angle), where ``s`` is
the plant's friction state: the LuGre bristle state, or for the KP/GPI sums the weighted position
of each operator in its band (+1 at the pulled edge, -1 at the released edge).  ``s`` equals
``sign(v)`` once the tendon slides and holds its value during a dwell.

Hidden effects (one per source, on a plant started at rest; its resting output is ``y0 = 0``)
--------------------------------------------------------------------------------------------
``pull_push_gain``    ``y' = y + a |y - y0|``  (gain ``1 + a`` above the rest value, ``1 - a`` below)
``cubic_softening``   ``y' = y - c (y - y0)^3``
``input_stretch``     the plant sees ``u - k T_in`` with ``T_in`` its own input tension, solved
                      consistently every step (the constant stretch under the resting tension
                      is in the encoder zero); for the LuGre plant this is exactly an input
                      tendon of compliance ``1/k_t + k``.  The load cells carry the new tensions.
``one_way_backlash``  on the output: when unloading the follower is held until the output has
                      fallen by ``b`` (a dead band), then follows ``b`` above it; when loading
                      there is no dead band: it moves at once at half the speed
                      (``takeup_slope`` 0.5) until the slack is taken up.
``relaxation``        first-order relaxation of the output, ``y' = y - a (y - L)`` with
                      ``tau dL/dt = y - L`` (tau 0.7 s): a small part of the follower's travel
                      relaxes, lagging during motion and catching up during dwells.
Each at two strengths (``2x`` and ``5x``) tuned by an oracle so that the effect's RMS contribution
(effect output minus clean output, noise-free) pooled over the two held-out runs is 2 and 5 times
the output noise sd.  Output effects act on the follower reading only (the load cells keep the
plant's tensions).  Clean sources: per plant one started at rest and one started loaded (before
the first sample the input was pulled from -6 mm to its starting position 0, so every friction
element sits at the pulled edge of its band, the first motion continues the pull without a
virgin transient, the output starts offset from its resting value by about half the loop width and
the input load cell starts at ``T_out exp(mu theta)``).

Runs (three per source, one configuration per source, 80 s each, encoders 100 Hz, load cells
1 kHz interpolated from the 100 Hz plant and with 0.01 N noise; white N(0, 0.01 mm) noise on the
output encoder reading): ``sine_decay`` 6/4.5/3/1.5 mm at 0.2 Hz, 4 periods each
(identification); ``triangle_decay`` same amplitudes at 6 mm/s, 8 periods each, and
``trapezoid_decay`` at 5 mm/s with 0.5 s dwells, 5 periods each (held out).

What it writes::

    OUTDIR/ae-<hex>/<run_id>/{manifest.json,encoder.csv,loadcell.csv,events.csv}
    OUTDIR/absorbed_effects_truth.json     (outside the source folders)

The truth lists per source: plant, configuration, start (rest/loaded, with the output offset and
starting tensions), effect (name, form, strength label, parameters) and the oracle figures: the
effect's RMS on the held-out runs in noise sd (pooled, per run, after removing each run's mean,
after removing the best affine map of the clean output, and on the identification run).  Per
plant it lists the parameters and loop metrics (mid-stroke and largest width, gain; for LuGre the
width at 0.05 and 0.5 Hz).

Command line::

    python absorbed_effects.py OUTDIR [--plants lugre kp gpi] [--seed N] [--jobs 2]

Dependencies: numpy, scipy (brentq), pandas through riglog; about 30 s on two cores (``--jobs 2``,
one process per plant, forked), about a minute in one process.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import importlib.util
import json
import math
import multiprocessing
import os
import pickle
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.optimize import brentq

# ---------------------------------------------------------------------------------------------
# riglog by file path
# ---------------------------------------------------------------------------------------------


def _load_riglog() -> Any:
    """Import the clean-room ``riglog.py`` from ``CLEANROOM_RIGLOG`` (file or folder) or beside us."""
    if "_ae_riglog" in sys.modules:
        return sys.modules["_ae_riglog"]
    env = os.environ.get("CLEANROOM_RIGLOG")
    path = Path(env) if env else Path(__file__).resolve().parent / "riglog.py"
    if path.is_dir():
        path = path / "riglog.py"
    if not path.is_file():
        raise ImportError(f"riglog.py not found at {path} (set CLEANROOM_RIGLOG to the file or its folder)")
    spec = importlib.util.spec_from_file_location("_ae_riglog", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["_ae_riglog"] = mod
    spec.loader.exec_module(mod)
    return mod


# ---------------------------------------------------------------------------------------------
# Constants
# ---------------------------------------------------------------------------------------------

DT_S = 0.01  # encoder clock, 100 Hz
NOISE_SD_MM = 0.01  # output encoder noise
LOADCELL_NOISE_N = 0.01
AMPLITUDES_MM = (6.0, 4.5, 3.0, 1.5)
F0_N = 5.0  # return-spring preload at rest
K_RETURN_N_PER_MM = 0.3  # return-spring rate
MU = 0.2  # tendon-sheath friction coefficient
TARGET_WIDTH_MM = 1.0
RELAX_TAU_S = 0.7
BACKLASH_TAKEUP = 0.5
STRENGTHS = (("2x", 2.0), ("5x", 5.0))

RUNS = (
    ("sine_decay", {"frequency_hz": 0.2, "periods_per_amplitude": 4}, "identification"),
    ("triangle_decay", {"slope_mm_s": 6.0, "periods_per_amplitude": 8}, "held_out"),
    ("trapezoid_decay", {"slope_mm_s": 5.0, "dwell_s": 0.5, "periods_per_amplitude": 5}, "held_out"),
)
HELD_OUT = tuple(i for i, r in enumerate(RUNS) if r[2] == "held_out")

PLANT_CONFIG = {
    "lugre": {"curve_angle_deg": 90, "radius_mm": 30},
    "kp": {"curve_angle_deg": 60, "radius_mm": 45},
    "gpi": {"curve_angle_deg": 75, "radius_mm": 60},
}
PLANT_GAIN = {"lugre": 0.83, "kp": 0.85, "gpi": 0.91}
EFFECTS = ("pull_push_gain", "cubic_softening", "input_stretch", "one_way_backlash", "relaxation")


def _wrap(plant: str) -> float:
    return MU * math.radians(PLANT_CONFIG[plant]["curve_angle_deg"])


# ---------------------------------------------------------------------------------------------
# Plants
# ---------------------------------------------------------------------------------------------


class LuGrePlant:
    """Tendon-sheath: input spring k_t, LuGre/capstan friction node, series spring to a return spring."""

    name = "lugre"

    def __init__(self) -> None:
        self.a = _wrap("lugre")  # mu * theta
        self.kt = 2.6  # N/mm, calibrated
        self.g = 0.97  # k_s / (k_s + k_r), calibrated
        self.zc = 0.15  # mm, presliding (bristle) length
        self.rho = 0.05  # Stribeck excess of the breakaway friction
        self.vs = 0.3  # mm/s, Stribeck speed
        self.cv = 0.003  # N s/mm, viscous
        self.k_stretch = 0.0  # mm/N, input-side stretch (effect)

    @property
    def ke(self) -> float:
        return K_RETURN_N_PER_MM * self.g

    def params(self) -> dict[str, Any]:
        ks = self.g * K_RETURN_N_PER_MM / (1.0 - self.g)
        return {
            "model": "LuGre bristle state with capstan friction at a massless node, series spring to a preloaded return spring",
            "k_t_n_per_mm": self.kt, "k_s_n_per_mm": ks, "k_r_n_per_mm": K_RETURN_N_PER_MM, "g": self.g,
            "F0_n": F0_N, "mu_theta": self.a, "z_c_mm": self.zc, "stribeck_rho": self.rho,
            "stribeck_v_s_mm_s": self.vs, "viscous_n_s_per_mm": self.cv, "bristle_damping": 0.0,
        }

    def rest_state(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def _run(self, u: np.ndarray, state: tuple[float, float, float], h: float):
        kt = self.kt / (1.0 + self.k_stretch * self.kt)  # stretch: tendon compliance 1/k_t + k
        ke, a, zc, rho, vs, cv, F0 = self.ke, self.a, self.zc, self.rho, self.vs, self.cv, F0_N
        exp = math.exp
        n = u.size
        xs = np.empty(n)
        ss = np.empty(n)
        x, s, v = state
        ul = u.tolist()
        for i in range(n):
            if i > 0:
                target = ul[i]
                sss = 1.0 + rho * exp(-((v / vs) ** 2))
                r0 = F0 + kt * (target - x) - (F0 + ke * x) * exp(a * s)
                if r0 == 0.0:
                    dx = 0.0
                    s1 = s
                else:
                    sig = 1.0 if r0 > 0 else -1.0
                    lo, hi = 0.0, abs(r0) / kt
                    zs = zc * sss

                    def f(m: float) -> tuple[float, float, float]:
                        e = exp(-m / zs)
                        s1_ = sig * sss + (s - sig * sss) * e
                        dx_ = sig * m
                        t_ = F0 + ke * (x + dx_)
                        ea = exp(a * s1_)
                        r = F0 + kt * (target - x - dx_) - t_ * ea - cv * dx_ / h
                        ds = -(s - sig * sss) * e / zs  # d s1 / d m
                        dr = -kt * sig - ke * sig * ea - t_ * ea * a * ds - cv * sig / h
                        return sig * r, sig * dr, s1_

                    fh = f(hi)[0]
                    k = 0
                    while fh > 0 and k < 60:
                        lo, hi = hi, hi * 2.0
                        fh = f(hi)[0]
                        k += 1
                    m = 0.5 * (lo + hi)
                    s1 = s
                    for _ in range(60):
                        fv, dfv, s1 = f(m)
                        if fv > 0:
                            lo = m
                        else:
                            hi = m
                        if abs(fv) < 1e-12 or hi - lo < 1e-14:
                            break
                        mn = m - fv / dfv if dfv != 0 else 0.5 * (lo + hi)
                        if not (lo < mn < hi):
                            mn = 0.5 * (lo + hi)
                        m = mn
                    dx = sig * m
                x += dx
                s = s1
                v = dx / h
            xs[i] = x
            ss[i] = s
        y = self.g * xs
        t_out = F0 + ke * xs
        t_in = F0 + kt * (u - xs)
        return y, t_in, t_out, ss, (x, s, v)

    def loaded_state(self) -> tuple[float, float, float]:
        """Rest, then the input ramped 0 -> -6 -> 0 mm at 6 mm/s (a pull ending at 0)."""
        seg1 = np.linspace(0.0, -6.0, 101)
        seg2 = np.linspace(-6.0, 0.0, 101)[1:]
        u = np.concatenate([seg1, seg2])
        return self._run(u, self.rest_state(), DT_S)[4]

    def simulate(self, u: np.ndarray, start: str = "rest", h: float = DT_S) -> dict[str, np.ndarray]:
        st = self.rest_state() if start == "rest" else self.loaded_state()
        y, t_in, t_out, s, _ = self._run(np.asarray(u, float), st, h)
        return {"y": y, "t_in": t_in, "t_out": t_out, "s": s}


class _ClipSum:
    """Sum of clip operators ``state = clip(state, lo(u), hi(u))`` plus a linear term."""

    name = "clip"
    weights: np.ndarray
    lin: float
    y_rest: float = 0.0

    def __init__(self) -> None:
        self.a = _wrap(self.name)
        self.k_stretch = 0.0
        self.rest = self._rest()

    def bounds(self, u: float) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _rest(self) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _raw(self, u: float, st: np.ndarray) -> float:
        return self.lin * u + float(self.weights @ st)

    def _fstate(self, lo: np.ndarray, hi: np.ndarray, st: np.ndarray) -> float:
        w = self.weights
        den = float(w @ (hi - lo))
        return float(w @ (lo + hi - 2.0 * st)) / den if den > 1e-12 else 0.0

    def loaded_state(self) -> np.ndarray:
        st = self.rest.copy()
        for uu in (-6.0, 0.0):  # exact at reversal points: monotone segments
            lo, hi = self.bounds(uu)
            st = np.clip(st, lo, hi)
        return st

    def _eval(self, ue: float, st_prev: np.ndarray):
        lo, hi = self.bounds(ue)
        st = np.minimum(np.maximum(st_prev, lo), hi)
        y = self._raw(ue, st) - self.y_rest
        t_out = F0_N + K_RETURN_N_PER_MM * y
        s = self._fstate(lo, hi, st)
        return st, y, t_out, s, t_out * math.exp(self.a * s)

    def simulate(self, u: np.ndarray, start: str = "rest", h: float = DT_S) -> dict[str, np.ndarray]:
        del h  # rate independent
        u = np.asarray(u, float)
        st = (self.rest if start == "rest" else self.loaded_state()).copy()
        n = u.size
        out = {k: np.empty(n) for k in ("y", "t_in", "t_out", "s", "u_eff")}
        k = self.k_stretch
        t_in_prev = None
        for i, ui in enumerate(u.tolist()):
            if k == 0.0:
                ue = ui
                st_new, y, t_out, s, t_in = self._eval(ue, st)
            else:
                # solve ue + k (T_in(ue) - F0) = u: fixed point then secant
                if t_in_prev is None:
                    t_in_prev = self._eval(ui, st)[4]
                ue0 = ui - k * (t_in_prev - F0_N)
                r = self._eval(ue0, st)
                f0 = ue0 + k * (r[4] - F0_N) - ui
                ue1 = ue0 - f0
                for _ in range(30):
                    r = self._eval(ue1, st)
                    f1 = ue1 + k * (r[4] - F0_N) - ui
                    if abs(f1) < 1e-9:
                        break
                    d = f1 - f0
                    ue2 = ue1 - f1 * (ue1 - ue0) / d if d != 0 else ue1 - f1
                    if not np.isfinite(ue2) or abs(ue2 - ue1) > 1.0:
                        ue2 = ue1 - f1
                    ue0, f0, ue1 = ue1, f1, ue2
                ue = ue1
                st_new, y, t_out, s, t_in = r
            st = st_new
            t_in_prev = t_in
            out["y"][i], out["t_in"][i], out["t_out"][i], out["s"][i], out["u_eff"][i] = y, t_in, t_out, s, ue
        return out


class KPPlant(_ClipSum):
    """Krasnosel'skii-Pokrovskii kernels with linear ridges on a (centre, half-width) grid."""

    name = "kp"

    def __init__(self) -> None:
        c, r = np.meshgrid(np.arange(-10.0, 10.0001, 0.5), np.array([0.1, 0.25, 0.4, 0.6, 0.8, 1.0, 1.3, 1.6]))
        self.c, self.r = c.ravel(), r.ravel()
        self.a_up, self.a_dn = 1.0, 0.5  # ridge widths (smooth edges), multiples of the 0.5 mm grid, mm
        self.shape = np.exp(-0.5 * (self.c / 5.5) ** 2) * (self.r / 0.5) * np.exp(-self.r / 0.5)
        self.shape /= self.shape.sum()
        self.weights = self.shape.copy()
        self.lin = 0.0
        self.up0 = self.c + self.r - 0.5 * self.a_up
        self.dn0 = self.c - self.r - 0.5 * self.a_dn
        super().__init__()

    def bounds(self, u: float) -> tuple[np.ndarray, np.ndarray]:
        lo = 2.0 * np.clip((u - self.up0) / self.a_up, 0.0, 1.0) - 1.0
        hi = 2.0 * np.clip((u - self.dn0) / self.a_dn, 0.0, 1.0) - 1.0
        return lo, hi

    def _rest(self) -> np.ndarray:
        """Demagnetised: from saturation, alternating reversals decaying from 12 mm to 0."""
        st = -np.ones_like(self.c)
        amps = np.arange(12.0, 0.0, -0.02)
        for j, aa in enumerate(amps):
            lo, hi = self.bounds(aa if j % 2 == 0 else -aa)
            st = np.clip(st, lo, hi)
        lo, hi = self.bounds(0.0)
        return np.clip(st, lo, hi)

    def params(self) -> dict[str, Any]:
        return {
            "model": "Krasnosel'skii-Pokrovskii kernels, linear ridges, clip(k, R_up(u), R_dn(u))",
            "centres_mm": [-10.0, 10.0, 0.5], "half_widths_mm": sorted(set(self.r.tolist())),
            "ridge_up_mm": self.a_up, "ridge_down_mm": self.a_dn,
            "density": "exp(-c^2/(2*5.5^2)) * (r/0.5) exp(-r/0.5), scaled", "weight_sum": float(self.weights.sum()),
            "k_lin": self.lin, "mu_theta": self.a, "F0_n": F0_N, "k_r_n_per_mm": K_RETURN_N_PER_MM,
            "rest": "demagnetised (alternating reversals decaying 12 -> 0 mm)",
        }


class GPIPlant(_ClipSum):
    """Asymmetric generalised Prandtl-Ishlinskii: plays between different up/down envelopes."""

    name = "gpi"

    def __init__(self) -> None:
        self.r = 0.05 + 0.2 * np.arange(10)
        self.shape = np.exp(-self.r / 1.0)
        self.shape /= self.shape.sum()
        self.weights = self.shape.copy()
        self.lin = 0.0
        self.cu, self.cd, self.ed = 0.010, 0.018, 0.0008
        super().__init__()

    def g_up(self, u: float) -> float:
        return u + self.cu * u * u

    def g_dn(self, u: float) -> float:
        return u + self.cd * u * u + self.ed * u * u * u

    def bounds(self, u: float) -> tuple[np.ndarray, np.ndarray]:
        return self.g_up(u) - self.r, self.g_dn(u) + self.r

    def _rest(self) -> np.ndarray:
        return np.zeros_like(self.r)

    def params(self) -> dict[str, Any]:
        return {
            "model": "generalised plays z = max(g_up(u) - r, min(g_dn(u) + r, z))",
            "g_up": f"u + {self.cu} u^2", "g_dn": f"u + {self.cd} u^2 + {self.ed} u^3",
            "half_widths_mm": [round(v, 4) for v in self.r.tolist()], "weights": self.weights.tolist(), "k0": self.lin,
            "mu_theta": self.a, "F0_n": F0_N, "k_r_n_per_mm": K_RETURN_N_PER_MM, "rest": "z = 0",
        }


PLANTS: dict[str, Callable[[], Any]] = {"lugre": LuGrePlant, "kp": KPPlant, "gpi": GPIPlant}


# ---------------------------------------------------------------------------------------------
# Loop metrics and calibration
# ---------------------------------------------------------------------------------------------


def loop_metrics(plant: Any, freq_hz: float = 0.2, amp: float = 6.0) -> dict[str, float]:
    """Third cycle of ``amp sin(2 pi f t)`` from rest: width at u = 0, largest width, LS gain."""
    per = 1.0 / freq_hz
    t = np.arange(0.0, 3 * per + 1e-9, DT_S)
    u = amp * np.sin(2 * np.pi * freq_hz * t)
    y = plant.simulate(u, "rest")["y"]
    m = t >= 2 * per - 1e-9
    uu, yy = u[m], y[m]
    du = np.gradient(uu)
    grid = np.linspace(-0.92 * amp, 0.92 * amp, 185)
    up, dn = du > 0, du < 0
    iu = np.argsort(uu[up])
    idn = np.argsort(uu[dn])
    y_up = np.interp(grid, uu[up][iu], yy[up][iu])
    y_dn = np.interp(grid, uu[dn][idn], yy[dn][idn])
    w = y_dn - y_up
    gain = float(np.polyfit(uu, yy, 1)[0])
    return {"width_mid_mm": float(np.interp(0.0, grid, w)), "width_max_mm": float(w.max()),
            "width_at_-5mm": float(np.interp(-5.0, grid, w)), "width_at_+5mm": float(np.interp(5.0, grid, w)),
            "gain": gain}


def calibrate(plant: Any) -> Any:
    """Scale the plant to a 1.00 mm mid-stroke loop and its target gain."""
    gain_t = PLANT_GAIN[plant.name]
    if isinstance(plant, _ClipSum):
        # y is linear in (lin, W): calibrate from the unit-weight, zero-linear responses.
        plant.weights, plant.lin, plant.y_rest = plant.shape.copy(), 0.0, 0.0
        plant.y_rest = plant._raw(0.0, plant.rest)
        m_h = loop_metrics(plant)
        W = TARGET_WIDTH_MM / m_h["width_mid_mm"]
        plant.weights = plant.shape * W
        plant.lin = gain_t - W * m_h["gain"]
        plant.y_rest = plant._raw(0.0, plant.rest)
        return plant
    # LuGre: k_t sets the width/gain ratio, g the gain
    for _ in range(4):
        def ratio(kt: float) -> float:
            plant.kt = kt
            mm = loop_metrics(plant)
            return mm["width_mid_mm"] / mm["gain"] - TARGET_WIDTH_MM / gain_t
        plant.kt = brentq(ratio, 0.8, 20.0, xtol=1e-6)
        mm = loop_metrics(plant)
        plant.g = min(plant.g * gain_t / mm["gain"], 0.995)
    return plant


# ---------------------------------------------------------------------------------------------
# Effects on the output reading
# ---------------------------------------------------------------------------------------------


def eff_pull_push_gain(y: np.ndarray, a: float, y0: float = 0.0) -> np.ndarray:
    return y + a * np.abs(y - y0)


def eff_cubic(y: np.ndarray, c: float, y0: float = 0.0) -> np.ndarray:
    return y - c * (y - y0) ** 3


def eff_one_way_backlash(y: np.ndarray, b: float, takeup: float = BACKLASH_TAKEUP) -> np.ndarray:
    """Slack d in [0, b]: unloading opens it (output held), loading closes it at ``takeup`` per mm."""
    out = np.empty_like(y)
    d = 0.0
    yl = y.tolist()
    out[0] = yl[0]
    for i in range(1, len(yl)):
        dy = yl[i] - yl[i - 1]
        if dy < 0:
            d = min(b, d - dy)
        elif dy > 0:
            d = max(0.0, d - takeup * dy)
        out[i] = yl[i] + d
    return out


def eff_relaxation(y: np.ndarray, a: float, tau: float = RELAX_TAU_S, h: float = DT_S) -> np.ndarray:
    """``y - a (y - L)``, ``tau L' = y - L``, exact for y linear between samples."""
    e = math.exp(-h / tau)
    c1 = 1.0 - tau * (1.0 - e) / h
    lp = np.empty_like(y)
    L = float(y[0])
    yl = y.tolist()
    lp[0] = L
    for i in range(1, len(yl)):
        L = e * L + (1.0 - e) * yl[i - 1] + (yl[i] - yl[i - 1]) * c1
        lp[i] = L
    return y - a * (y - lp)


OUTPUT_EFFECTS = {
    "pull_push_gain": (eff_pull_push_gain, "a", "y' = y + a*|y - y0| (gain 1+a above the resting output y0, 1-a below)"),
    "cubic_softening": (eff_cubic, "c", "y' = y - c*(y - y0)^3 (per mm^2)"),
    "one_way_backlash": (eff_one_way_backlash, "b_mm",
                         "output slack d in [0, b]: unloading dy<0 opens it (d -= dy, output held), loading dy>0 "
                         "closes it (d -= takeup*dy, output moves at 1-takeup of the plant's speed); y' = y + d"),
    "relaxation": (eff_relaxation, "a",
                   "y' = y - a*(y - L), tau*dL/dt = y - L (first-order relaxation of a fraction a of the output)"),
}


# ---------------------------------------------------------------------------------------------
# Runs, oracle, sources
# ---------------------------------------------------------------------------------------------


def excitations() -> list[Any]:
    rl = _load_riglog()
    return [rl.make_excitation(kind, DT_S, amplitudes_mm=AMPLITUDES_MM, **kw) for kind, kw, _ in RUNS]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def oracle(clean: list[np.ndarray], eff: list[np.ndarray]) -> dict[str, Any]:
    """Effect contribution (noise-free) in units of the noise sd."""
    d = [e - c for c, e in zip(clean, eff)]
    ho = np.concatenate([d[i] for i in HELD_OUT])
    dm = np.concatenate([d[i] - d[i].mean() for i in HELD_OUT])
    aff = []
    for i in HELD_OUT:
        A = np.column_stack([np.ones_like(clean[i]), clean[i]])
        coef, *_ = np.linalg.lstsq(A, d[i], rcond=None)
        aff.append(d[i] - A @ coef)
    ident = [i for i, r in enumerate(RUNS) if r[2] == "identification"][0]
    return {
        "effect_rms_heldout_noise_sd": _rms(ho) / NOISE_SD_MM,
        "effect_rms_per_run_noise_sd": {RUNS[i][0]: _rms(d[i]) / NOISE_SD_MM for i in range(len(RUNS))},
        "effect_rms_heldout_demeaned_noise_sd": _rms(dm) / NOISE_SD_MM,
        "effect_rms_heldout_after_affine_noise_sd": _rms(np.concatenate(aff)) / NOISE_SD_MM,
        "effect_rms_identification_noise_sd": _rms(d[ident]) / NOISE_SD_MM,
        "effect_peak_heldout_mm": float(np.max(np.abs(ho))),
    }


def _held_rms(clean: list[np.ndarray], eff: list[np.ndarray]) -> float:
    return _rms(np.concatenate([eff[i] - clean[i] for i in HELD_OUT]))


def _simulate_all(plant: Any, exs: list[Any], start: str, only: tuple[int, ...] | None = None) -> list[dict | None]:
    return [plant.simulate(ex.u, start) if (only is None or i in only) else None for i, ex in enumerate(exs)]


def _tune_stretch(plant: Any, exs: list[Any], clean: list[dict], target_mm: float) -> tuple[float, list[dict], int]:
    """Secant on k (mm/N) for the held-out RMS; returns k, the three runs, and evaluations used."""
    def run(k: float) -> tuple[float, list[dict | None]]:
        plant.k_stretch = k
        sims = _simulate_all(plant, exs, "rest", HELD_OUT)
        plant.k_stretch = 0.0
        return _held_rms([c["y"] for c in clean], [s["y"] if s else clean[i]["y"] for i, s in enumerate(sims)]), sims

    k0 = 0.0
    r0 = 0.0
    k1 = 0.01 * target_mm / 0.02
    r1, sims = run(k1)
    n = 1
    for _ in range(8):
        if abs(r1 - target_mm) < 0.005 * target_mm:
            break
        k2 = k1 + (target_mm - r1) * (k1 - k0) / (r1 - r0) if r1 != r0 else k1 * target_mm / r1
        k0, r0 = k1, r1
        k1 = max(k2, 1e-6)
        r1, sims = run(k1)
        n += 1
    plant.k_stretch = k1
    for i in range(len(exs)):
        if sims[i] is None:
            sims[i] = plant.simulate(exs[i].u, "rest")
    plant.k_stretch = 0.0
    return k1, sims, n  # type: ignore[return-value]


def _source_name(seed: int, plant: str, tag: str) -> str:
    return "ae-" + hashlib.sha256(f"absorbed-effects/{seed}/{plant}/{tag}".encode()).hexdigest()[:10]


def build_plant_sources(plant_name: str, outdir: str, seed: int) -> dict[str, Any]:
    """Calibrate one plant, make its sources, write them; return its truth entries."""
    rl = _load_riglog()
    t_start = time.time()
    plant = calibrate(PLANTS[plant_name]())
    metrics = loop_metrics(plant)
    if plant_name == "lugre":
        metrics["width_mid_mm_at_0.05Hz"] = loop_metrics(plant, 0.05)["width_mid_mm"]
        metrics["width_mid_mm_at_0.5Hz"] = loop_metrics(plant, 0.5)["width_mid_mm"]
    exs = excitations()
    cfg = dict(PLANT_CONFIG[plant_name])
    clean = {st: _simulate_all(plant, exs, st) for st in ("rest", "loaded")}
    y_clean = [c["y"] for c in clean["rest"]]

    specs: list[dict[str, Any]] = []
    for st in ("rest", "loaded"):
        c0 = clean[st][0]
        specs.append({"tag": f"clean-{st}", "start": st, "effect": None, "sims": clean[st],
                      "start_info": {"output_offset_from_rest_mm": float(c0["y"][0]),
                                     "input_tension_n": float(c0["t_in"][0]), "output_tension_n": float(c0["t_out"][0]),
                                     "friction_state": float(c0["s"][0])}})
    for eff in EFFECTS:
        for label, mult in STRENGTHS:
            target = mult * NOISE_SD_MM
            if eff == "input_stretch":
                k, sims, nev = _tune_stretch(plant, exs, clean["rest"], target)
                params = {"k_mm_per_n": k, "stretch_at_max_tension_mm": k * float(max(np.max(s["t_in"]) - F0_N for s in sims)),
                          "tuning_evaluations": nev}
                form = "plant input u_eff = u - k*(T_in - F0), T_in the input tension solved with the plant each step"
            else:
                fn, pname, form = OUTPUT_EFFECTS[eff]
                extra: dict[str, Any] = {}
                if eff == "relaxation":
                    extra = {"tau": RELAX_TAU_S}
                if eff == "one_way_backlash":
                    extra = {"takeup": BACKLASH_TAKEUP}
                if eff == "one_way_backlash":
                    p = brentq(lambda b: _held_rms(y_clean, [fn(y, b, **extra) for y in y_clean]) - target, 1e-5, 2.0, xtol=1e-9)
                else:  # linear in the parameter
                    unit = _held_rms(y_clean, [fn(y, 1.0, **extra) for y in y_clean])
                    p = target / unit
                sims = []
                for c in clean["rest"]:
                    sims.append(dict(c, y=fn(c["y"], p, **extra)))
                params = {pname: float(p), "y0_mm": 0.0} if eff in ("pull_push_gain", "cubic_softening") else {pname: float(p)}
                if eff == "relaxation":
                    params["tau_s"] = RELAX_TAU_S
                if eff == "one_way_backlash":
                    params["takeup_slope"] = BACKLASH_TAKEUP
            specs.append({"tag": f"{eff}-{label}", "start": "rest", "sims": sims,
                          "effect": {"name": eff, "form": form, "strength": label, "target_noise_sd": mult,
                                     "parameters": params},
                          "start_info": {"output_offset_from_rest_mm": 0.0}})

    truth_sources: dict[str, Any] = {}
    out = Path(outdir)
    base = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.timezone.utc)
    pidx = list(PLANTS).index(plant_name)
    for si, sp in enumerate(specs):
        name = _source_name(seed, plant_name, sp["tag"])
        sims = sp["sims"]
        orc = oracle(y_clean if sp["start"] == "rest" else [c["y"] for c in clean["loaded"]], [s["y"] for s in sims])
        runs = []
        for ri, (ex, sim) in enumerate(zip(exs, sims)):
            rng = np.random.default_rng([seed, pidx, si, ri])
            y_meas = sim["y"] + rng.normal(0.0, NOISE_SD_MM, sim["y"].shape)
            rid = rl.run_id_for(cfg, RUNS[ri][0], ri + 1)
            started = base + _dt.timedelta(days=pidx, minutes=20 * si + 5 * ri)
            rl.write_run_folder(
                out / name, rid, ex.t_s, ex.u, y_meas, configuration=cfg, excitation=ex.manifest,
                loadcell=(sim["t_in"], sim["t_out"]), loadcell_noise_n=LOADCELL_NOISE_N, events=True,
                started_at=started, seed=int(seed * 100003 + pidx * 1009 + si * 31 + ri),
            )
            runs.append({"run_id": rid, "kind": RUNS[ri][0], "role": RUNS[ri][2]})
        truth_sources[name] = {
            "plant": plant_name, "configuration": cfg, "start": sp["start"], "start_detail": sp["start_info"],
            "effect": sp["effect"] or {"name": "none"}, "runs": runs, "oracle": orc,
        }
    print(f"{plant_name}: {len(specs)} sources in {time.time() - t_start:.1f} s", flush=True)
    return {"plant": {"name": plant_name, "parameters": plant.params(), "loop": metrics},
            "sources": truth_sources}


def generate(outdir: str | Path, plants: list[str] | None = None, seed: int = 0, jobs: int = 2) -> dict[str, Any]:
    """Write every source of ``plants`` into ``outdir`` and ``outdir/absorbed_effects_truth.json``."""
    plants = list(plants or PLANTS)
    for p in plants:
        if p not in PLANTS:
            raise ValueError(f"unknown plant {p!r}; known: {list(PLANTS)}")
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    _load_riglog()
    parts = None
    if jobs > 1 and len(plants) > 1 and "fork" in multiprocessing.get_all_start_methods():
        # fork: the workers inherit this module and riglog however they were imported
        try:
            with ProcessPoolExecutor(max_workers=min(jobs, len(plants)), mp_context=multiprocessing.get_context("fork")) as ex:
                parts = list(ex.map(build_plant_sources, plants, [str(out)] * len(plants), [seed] * len(plants)))
        except (OSError, RuntimeError, pickle.PicklingError):  # no worker processes here: do it in turn
            parts = None
    if parts is None:
        parts = [build_plant_sources(p, str(out), seed) for p in plants]
    truth: dict[str, Any] = {
        "generator": "absorbed_effects.py (clean room)",
        "seed": seed,
        "noise_sd_mm": NOISE_SD_MM,
        "loadcell_noise_n": LOADCELL_NOISE_N,
        "return_spring": {"F0_n": F0_N, "k_r_n_per_mm": K_RETURN_N_PER_MM, "mu": MU},
        "runs": [{"kind": k, "parameters": kw, "amplitudes_mm": list(AMPLITUDES_MM), "role": role} for k, kw, role in RUNS],
        "oracle_definition": "RMS of (output with effect - clean output), noise-free, on the 100 Hz encoder clock, "
                             "pooled over the held-out runs (triangle_decay, trapezoid_decay), divided by noise_sd_mm",
        "plants": {p["plant"]["name"]: p["plant"] for p in parts},
        "sources": {k: v for p in parts for k, v in sorted(p["sources"].items())},
    }
    (out / "absorbed_effects_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("outdir")
    ap.add_argument("--plants", nargs="+", default=list(PLANTS), choices=list(PLANTS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    t0 = time.time()
    truth = generate(a.outdir, a.plants, a.seed, a.jobs)
    print(f"wrote {len(truth['sources'])} sources to {a.outdir} in {time.time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
