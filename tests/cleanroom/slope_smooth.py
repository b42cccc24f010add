"""Clean-room test data: smooth rate-independent TSM plants with a hidden *held-slope backlash*
(backlash with different loading / unloading slopes) on the output.

Written only from:

* ``../shared/rig-log-format.md`` - the ``tsm-rig-log/1`` raw-run format (run folders, encoder
  counts, load cells, manifest);
* ``../shared/seeds/README.md`` and the seed papers ``../shared/seeds/000_*.txt`` (Coleman-Hodgdon
  backlash-like model, eq. 10-11), ``../shared/seeds/001_*.txt`` (the bench: input and follower
  modules, linear encoders, load cells, constant-force spring, 10 ms loop; the three decaying
  excitations; the Preisach relay plane and its Gauss-Gauss density, eq. 4.1-4.5) and
  ``../shared/seeds/002_*.txt`` (Bouc-Wen model, eq. 2-3);
* ``tests/cleanroom/riglog.py`` - the clean-room writer of the raw-run format, whose
  ``make_excitation`` and ``write_run_folder`` are used here (imported by file path: the
  environment variable ``CLEANROOM_RIGLOG`` (a file or its folder) if set, else the
  ``riglog.py`` beside this module);
* textbook physics (Euler-Eytelwein capstan law, Dahl friction, Tao & Kokotovic's backlash with
  different slopes).

No implementation or test of the project under analysis was read.

What it makes
-------------
``generate(outdir, seed=0, workers=2)`` writes 15 *sources* (a source = a folder of run folders)
into ``outdir``, 5 per plant, each named ``ss-<10 hex>`` (sha256 of seed, plant and tag, so the
name tells nothing), plus ``outdir/slope_smooth_truth.json`` (ground truth, outside the sources).

Every source holds three 80 s ``tsm-bench`` runs of ONE plant (configuration phi 90 deg /
r 30 mm), each starting at input 0 mm:

* ``sine_decay`` (identification): 6, 4.5, 3, 1.5 mm, 5 periods each at 0.25 Hz (80 s);
* ``triangle_decay`` (held out): same amplitudes at 6 mm/s; 8 periods per amplitude so that the
  run lasts 80 s like the other two (5 periods would last only 50 s);
* ``trapezoid_decay`` (held out): same amplitudes, 6 mm/s, 0.75 s dwells, 5 periods (80 s).

Channels: encoders at 100 Hz with 1 um counts (``counts_per_unit`` 1000, 32-bit, output sign -1),
output position noise Gaussian sd 0.007 mm (input encoder noise-free); load cells at 1 kHz with
0.01 N Gaussian noise:

* output tension from the follower's return spring, T_out = F0 + k_s * y (F0 = 5 N,
  k_s = 0.05 N/mm, y the follower displacement from its rest position);
* input tension by the capstan (Euler-Eytelwein) law across the 90 deg sheath,
  T_in = T_out * exp(mu * theta * s) (mu = 0.2), with a smooth Dahl-type friction-direction state
  s in [-1, 1] integrated in the input travel, ds/du = (1 - s sgn(du)) / delta (delta = 0.15 mm),
  updated exactly per 1 kHz sample: s <- sgn + (s - sgn) exp(-|du| / delta).

Plants (smooth, rate-independent, no play operators; output lags the input like a tendon-sheath:
loading branch below the unloading branch, counter-clockwise loop in (u, y); each loop scaled to
1.0 mm vertical width at u = 0 on the +-6 mm cycles):

1. ``preisach``: a Preisach plane of ~4500 non-ideal relays (seed 001 eq. 4.1-4.3) on a jittered
   grid in centre c = (alpha+beta)/2 and half-width h = (alpha-beta)/2, Gauss-Gauss density
   (eq. 4.5 with separate widths per axis) mu ~ exp(-(h-H0)^2/2 s_h^2) exp(-c^2/2 s_c^2),
   H0 = 0.7 mm, s_h = 0.2 mm, s_c = 6 mm; x = a u + sum_i w_i r_i(u), a = 0.3, weights scaled
   to the loop width. Relay states are tracked with numpy per time step. Rest state: the
   demagnetised staircase (relays with c > 0 at -1, c < 0 at +1).
2. ``duhem``: Coleman-Hodgdon (seed 000 eq. 10-11) integrated in the input,
   dx/du = A sgn(du) (C u - x) + B with A = 0.8 /mm, C = 1 and B in (C/2, C) (so that the output
   never moves against the input right after a reversal; the paper's B < 0 would), B set by the
   loop width. Per sample the linear ODE is solved exactly for the linearly interpolated input.
3. ``bouc_wen``: Bouc-Wen with n = 1.5 (seed 002 eq. 2-3) integrated in the input with RK4
   sub-steps (<= 0.01 mm), dh/du = A - B sgn(du) |h|^(n-1) h - C |h|^n (A = 1.6, B = 0.6,
   C = 0.2), turned to lag by taking x = a u - beta h (a = 1, beta set by the loop width).

Hidden effect (output only): Tao & Kokotovic's backlash with different slopes, held between its
branches. With L(x) = m_l (x - c_l) (loading) and U(x) = m_u (x - c_u) (unloading):
y_k = L(x_k) if x rises and L(x_k) >= y_{k-1}; U(x_k) if x falls and U(x_k) <= y_{k-1}; else
y_{k-1} (held) - i.e. y_k = min(U(x_k), max(L(x_k), y_{k-1})). The branches cross at a pivot
(x_p, x_p) so y - x = +-g (x - x_p) on them; y starts at y_0 = x_0 (middle of the band).

* pivot ``top``: x_p = max(x over the source's three runs) + 0.25 mm (the pulled end);
  m_l = 1 + g, m_u = 1 - g; the band opens toward the released end.
* pivot ``bottom``: x_p = min(x) - 0.25 mm (the released end). With m_l = 1 + g > m_u the
  loading line would lie ABOVE the unloading line everywhere above a bottom pivot (an inverted,
  leading band: no hold is possible), so for this pivot the slopes are exchanged:
  m_l = 1 - g, m_u = 1 + g (``g_signed`` = -g in the truth, m_l = 1 + g_signed); the band then
  opens toward the pulled end.

Per plant: effect sources at (g, pivot) = (0.08, top), (0.16, top), (0.16, bottom), starting from
rest; one clean source from rest; one clean source started loaded (before every run a hidden
0 -> 6 -> 0 mm pull and release leaves the plant on the released (descending) edge of its loop and
the friction state at -1; the recorded run then starts at input 0 mm).

Oracle (per source, in units of the output noise sd 0.007 mm, on the two held-out runs pooled,
noise-free signals at 100 Hz): ``effect_rms_noise_sd`` = RMS(y_with_effect - x);
``gain_offset_residual_noise_sd`` = RMS residual of the best single gain k and offset b fitted
y_with_effect ~ k x + b (k, b also recorded). The same two figures are also given for the
identification run. Clean sources have both figures exactly 0.

CLI: ``python slope_smooth.py OUTDIR [--seed N] [--workers N]``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import functools
import hashlib
import importlib.util
import json
import math
import multiprocessing as mp
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

# ---------------------------------------------------------------------------------------------
# riglog (clean-room writer) by file path
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
        raise FileNotFoundError(f"riglog.py not found at {p} (set CLEANROOM_RIGLOG)")
    name = "_cleanroom_riglog"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, p)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()

# ---------------------------------------------------------------------------------------------
# Constants
# ---------------------------------------------------------------------------------------------

PLANTS = ("preisach", "duhem", "bouc_wen")
AMPLITUDES_MM = (6.0, 4.5, 3.0, 1.5)
ENC_DT = 0.01
LC_DT = 0.001
OUTPUT_NOISE_SD_MM = 0.007
LOADCELL_NOISE_N = 0.01
COUNTS_PER_MM = 1000  # 1 um counts
LOOP_WIDTH_MM = 1.0
PIVOT_MARGIN_MM = 0.25
F0_N = 5.0
SPRING_N_PER_MM = 0.05
MU = 0.2
WRAP_DEG = 90.0
DAHL_DELTA_MM = 0.15
CONFIG = {"curve_angle_deg": 90, "radius_mm": 30}
PREHISTORY_PULL_MM = 6.0

RUNS = (
    # (role, kind, make_excitation keywords)
    ("identification", "sine_decay", dict(frequency_hz=0.25, periods_per_amplitude=5)),
    ("held_out", "triangle_decay", dict(slope_mm_s=6.0, periods_per_amplitude=8)),
    ("held_out", "trapezoid_decay", dict(slope_mm_s=6.0, dwell_s=0.75, periods_per_amplitude=5)),
)

EFFECT_SPECS = (  # (tag, g, pivot)
    ("g0.08-top", 0.08, "top"),
    ("g0.16-top", 0.16, "top"),
    ("g0.16-bottom", 0.16, "bottom"),
)
CLEAN_SPECS = (("clean-rest", "rest"), ("clean-loaded", "loaded"))


def _excitation(i: int, dt: float):
    _, kind, kw = RUNS[i]
    return riglog.make_excitation(kind, dt, amplitudes_mm=AMPLITUDES_MM, **kw)


def _h(*parts: Any) -> str:
    return hashlib.sha256("|".join(str(p) for p in parts).encode()).hexdigest()


def folder_name(seed: int, plant: str, tag: str) -> str:
    return "ss-" + _h("slope_smooth", seed, plant, tag)[:10]


def _int_seed(*parts: Any) -> int:
    return int(_h(*parts)[:8], 16)


# ---------------------------------------------------------------------------------------------
# Plants.  Each has  init(start) -> state,  run(u, state) -> (x, state); output at rest = 0.
# ---------------------------------------------------------------------------------------------


class PreisachPlant:
    name = "preisach"

    def __init__(self, seed: int, a: float = 0.3, h0: float = 0.7, s_h: float = 0.2, s_c: float = 6.0):
        rng = np.random.default_rng(_int_seed(seed, "preisach-plane"))
        dc, dh = 0.06, 0.1
        cg = np.arange(-9.0, 9.0 + 1e-9, dc)
        hg = np.arange(0.05, 1.55 + 1e-9, dh)
        C, H = np.meshgrid(cg, hg, indexing="ij")
        C = C.ravel() + rng.uniform(-dc / 2, dc / 2, C.size)
        H = np.maximum(H.ravel() + rng.uniform(-dh / 2, dh / 2, H.size), 0.01)
        w = np.exp(-((H - h0) ** 2) / (2 * s_h**2)) * np.exp(-(C**2) / (2 * s_c**2)) * dc * dh
        self.alpha = C + H  # switch-up threshold
        self.beta = C - H  # switch-down threshold
        self.c = C
        self.a = a
        self.w = w
        self.params = {
            "n_relays": int(w.size), "a": a, "H0_mm": h0, "sigma_h_mm": s_h, "sigma_c_mm": s_c,
            "grid_dc_mm": dc, "grid_dh_mm": dh, "density": "gauss-gauss (seed 001 eq. 4.5, separate widths)",
        }
        self.scale = 1.0
        self.scale = LOOP_WIDTH_MM / loop_width(self)[0]
        self.w = self.w * self.scale
        self.params["weight_sum"] = float(self.w.sum())
        self._x_rest = float(self.w @ self._virgin())

    def _virgin(self) -> np.ndarray:
        return np.where(self.c > 0, -1.0, 1.0)

    def init(self):
        return {"r": self._virgin()}

    def run(self, u: np.ndarray, state):
        r = state["r"].copy()
        al, be, w = self.alpha, self.beta, self.w
        out = np.empty(u.size)
        x_rest = getattr(self, "_x_rest", 0.0)
        for k, uk in enumerate(u):
            r[uk >= al] = 1.0
            r[uk <= be] = -1.0
            out[k] = w @ r
        return self.a * u + out - x_rest, {"r": r}


class DuhemPlant:
    """Coleman-Hodgdon: dx/du = A sgn(du) (C u - x) + B, solved exactly per linear input step."""

    name = "duhem"

    def __init__(self, seed: int, A: float = 0.8, C: float = 1.0):
        self.A, self.C = A, C
        self.d = 0.4  # C - B, rescaled below (x - C u scales linearly with C - B)
        w = loop_width(self)[0]
        self.d = self.d * LOOP_WIDTH_MM / w
        self.B = C - self.d
        self.params = {"A_per_mm": A, "B": self.B, "C": C, "law": "dx/du = A sgn(du) (C u - x) + B (seed 000 eq. 10)"}
        if not (C / 2 <= self.B < C):
            raise ValueError("Coleman-Hodgdon B outside (C/2, C): reversal would not be monotone")

    def init(self):
        return {"x": 0.0, "u": 0.0}

    def run(self, u: np.ndarray, state):
        A, C, d = self.A, self.C, self.d
        x = float(state["x"])
        up = float(state["u"])
        out = np.empty(u.size)
        for k in range(u.size):
            uk = float(u[k])
            du = uk - up
            if du != 0.0:
                sg = 1.0 if du > 0 else -1.0
                # particular solution x* = C u - sg (C - B)/A ; deviation decays as exp(-A |du|)
                xs0 = C * up - sg * d / A
                xs1 = C * uk - sg * d / A
                x = xs1 + (x - xs0) * math.exp(-A * abs(du))
            out[k] = x
            up = uk
        return out, {"x": x, "u": up}


class BoucWenPlant:
    """dh/du = A - B sgn(du)|h|^(n-1) h - C |h|^n ; x = a u - beta h (lagging)."""

    name = "bouc_wen"

    def __init__(self, seed: int, A: float = 1.6, B: float = 0.6, C: float = 0.2, n: float = 1.5, a: float = 1.0):
        self.A, self.B, self.C, self.n, self.a = A, B, C, n, a
        self.beta = 1.0
        self.beta = LOOP_WIDTH_MM / loop_width(self)[0]
        max_dhdu = 2 * A * B / (B + C)
        self.params = {
            "A": A, "B": B, "C": C, "n": n, "a": a, "beta": self.beta,
            "law": "dh/du = A - B sgn(du)|h|^(n-1)h - C|h|^n (seed 002 eq. 3); x = a u - beta h",
            "min_branch_slope": a - self.beta * max_dhdu,
        }
        if a - self.beta * max_dhdu < 0:
            raise ValueError("Bouc-Wen output would move against the input")

    def init(self):
        return {"h": 0.0, "u": 0.0}

    def run(self, u: np.ndarray, state):
        A, B, C, n = self.A, self.B, self.C, self.n
        h = float(state["h"])
        up = float(state["u"])
        out = np.empty(u.size)
        max_sub = 0.01

        def f(hh: float, sg: float) -> float:
            ah = abs(hh)
            p = ah ** (n - 1.0)
            return A - B * sg * p * hh - C * p * ah

        for k in range(u.size):
            uk = float(u[k])
            du = uk - up
            if du != 0.0:
                sg = 1.0 if du > 0 else -1.0
                m = max(1, int(math.ceil(abs(du) / max_sub)))
                s = du / m
                for _ in range(m):
                    k1 = f(h, sg)
                    k2 = f(h + 0.5 * s * k1, sg)
                    k3 = f(h + 0.5 * s * k2, sg)
                    k4 = f(h + s * k3, sg)
                    h += s * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
            out[k] = h
            up = uk
        return self.a * u - self.beta * out, {"h": h, "u": up}


def loop_width(plant) -> tuple[float, float]:
    """(vertical width at u = 0, horizontal width at the loop's mid level) on the 6 mm cycles
    2-5 of the identification run from rest."""
    ex = _excitation(0, ENC_DT)
    x, _ = plant.run(ex.u, plant.init())
    return _widths(ex.t_s, ex.u, x)


def _widths(t: np.ndarray, u: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    idx = lambda tt: int(round(tt / ENC_DT))  # noqa: E731
    asc = [x[idx(4.0 * k)] for k in (1, 2, 3, 4)]  # u = 0 rising
    desc = [x[idx(4.0 * k + 2.0)] for k in (1, 2, 3, 4)]  # u = 0 falling
    vert = float(np.mean(desc) - np.mean(asc))
    # horizontal: on a rising (t in [7, 9]) and a falling (t in [9, 11]) sweep, u at x = mid
    ir = slice(idx(7.0), idx(9.0) + 1)
    ifl = slice(idx(9.0), idx(11.0) + 1)
    mid = 0.5 * (np.mean(desc) + np.mean(asc))
    u_r = float(np.interp(mid, x[ir], u[ir]))
    u_f = float(np.interp(mid, x[ifl][::-1], u[ifl][::-1]))
    return vert, float(u_r - u_f)


_PLANT_CLASSES = {"preisach": PreisachPlant, "duhem": DuhemPlant, "bouc_wen": BoucWenPlant}


@functools.lru_cache(maxsize=None)
def _plant(seed: int, name: str):
    return _PLANT_CLASSES[name](seed)


def _prehistory_u() -> np.ndarray:
    up = np.arange(0.0, PREHISTORY_PULL_MM + 1e-9, 0.02)
    return np.concatenate([up, up[::-1][1:]])


@functools.lru_cache(maxsize=None)
def plant_runs(seed: int, name: str, start: str) -> tuple:
    """Noise-free plant output x (100 Hz) for the three runs, each started at `start`."""
    plant = _plant(seed, name)
    xs = []
    for i in range(len(RUNS)):
        st = plant.init()
        if start == "loaded":
            _, st = plant.run(_prehistory_u(), st)
        ex = _excitation(i, ENC_DT)
        x, _ = plant.run(ex.u, st)
        xs.append(x)
    return tuple(xs)


# ---------------------------------------------------------------------------------------------
# Hidden effect: backlash with different slopes (held between branches)
# ---------------------------------------------------------------------------------------------


def held_slope_backlash(x: np.ndarray, m_l: float, c_l: float, m_u: float, c_u: float, y0: float) -> np.ndarray:
    L = m_l * (x - c_l)
    U = m_u * (x - c_u)
    y = np.empty_like(x)
    yp = float(y0)
    for k in range(x.size):
        lk, uk = L[k], U[k]
        if lk > uk:
            raise ValueError("inverted backlash band (loading line above unloading line)")
        if yp < lk:
            yp = lk
        elif yp > uk:
            yp = uk
        y[k] = yp
    return y


def effect_params(xs: tuple, g: float, pivot: str) -> dict[str, float]:
    lo = min(float(np.min(x)) for x in xs)
    hi = max(float(np.max(x)) for x in xs)
    if pivot == "top":
        xp, gs = hi + PIVOT_MARGIN_MM, g
    elif pivot == "bottom":
        xp, gs = lo - PIVOT_MARGIN_MM, -g
    else:
        raise ValueError(pivot)
    m_l, m_u = 1.0 + gs, 1.0 - gs
    yp = xp
    return {
        "g": g, "g_signed": gs, "m_l": m_l, "m_u": m_u,
        "c_l": xp - yp / m_l, "c_u": xp - yp / m_u,
        "pivot_x_mm": xp, "pivot_y_mm": yp, "output_range_mm": [lo, hi],
        "pivot_margin_mm": PIVOT_MARGIN_MM,
    }


def _oracle(xs: list[np.ndarray], ys: list[np.ndarray]) -> dict[str, float]:
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    e = y - x
    rms = float(np.sqrt(np.mean(e**2)))
    M = np.column_stack([x, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(M, y, rcond=None)
    res = y - M @ coef
    rr = float(np.sqrt(np.mean(res**2)))
    if rms == 0.0:
        rr, coef = 0.0, np.array([1.0, 0.0])
    return {
        "effect_rms_mm": rms,
        "effect_rms_noise_sd": rms / OUTPUT_NOISE_SD_MM,
        "gain_offset_gain": float(coef[0]),
        "gain_offset_offset_mm": float(coef[1]),
        "gain_offset_residual_mm": rr,
        "gain_offset_residual_noise_sd": rr / OUTPUT_NOISE_SD_MM,
    }


# ---------------------------------------------------------------------------------------------
# Channels and writing
# ---------------------------------------------------------------------------------------------


def dahl_state(u: np.ndarray, s0: float, delta: float = DAHL_DELTA_MM) -> np.ndarray:
    s = np.empty(u.size)
    sp = float(s0)
    up = float(u[0])
    for k in range(u.size):
        uk = float(u[k])
        du = uk - up
        if du != 0.0:
            sg = 1.0 if du > 0 else -1.0
            sp = sg + (sp - sg) * math.exp(-abs(du) / delta)
        s[k] = sp
        up = uk
    return s


def _write_source(job: dict) -> dict:
    seed, plant_name, tag = job["seed"], job["plant"], job["tag"]
    start, g, pivot = job["start"], job.get("g"), job.get("pivot")
    outdir = Path(job["outdir"])
    name = folder_name(seed, plant_name, tag)
    src = outdir / name
    src.mkdir(parents=True, exist_ok=True)
    plant = _plant(seed, plant_name)
    xs = plant_runs(seed, plant_name, start)
    if g is not None:
        ep = effect_params(xs, g, pivot)
        ys = [held_slope_backlash(x, ep["m_l"], ep["c_l"], ep["m_u"], ep["c_u"], y0=float(x[0])) for x in xs]
    else:
        ep = None
        ys = [x.copy() for x in xs]
    theta = math.radians(WRAP_DEG)
    run_ids, widths = [], []
    for i, (role, kind, _) in enumerate(RUNS):
        ex = _excitation(i, ENC_DT)
        ex_lc = _excitation(i, LC_DT)
        y_true = ys[i]
        rng = np.random.default_rng(_int_seed(seed, plant_name, tag, "out-noise", i))
        y_meas = y_true + rng.normal(0.0, OUTPUT_NOISE_SD_MM, y_true.shape)
        # load cells at 1 kHz
        y_lc = np.interp(ex_lc.t_s, ex.t_s, y_true)
        t_out = F0_N + SPRING_N_PER_MM * y_lc
        s = dahl_state(ex_lc.u, -1.0 if start == "loaded" else 0.0)
        t_in = t_out * np.exp(MU * theta * s)
        rid = riglog.run_id_for(CONFIG, kind, i + 1)
        started = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.timezone.utc) + _dt.timedelta(
            minutes=int(_int_seed(seed, plant_name, tag) % 600) + 3 * i)
        riglog.write_run_folder(
            src, rid, ex.t_s, ex.u, y_meas, rig="tsm-bench", configuration=CONFIG,
            excitation=ex.manifest, counts_per_unit=COUNTS_PER_MM, loadcell=(t_in, t_out),
            loadcell_noise_n=LOADCELL_NOISE_N, events=True, started_at=started,
            seed=_int_seed(seed, plant_name, tag, "lc-noise", i),
        )
        run_ids.append({"run_id": rid, "role": role, "kind": kind, "duration_s": float(ex.t_s[-1])})
        if i == 0:
            widths = list(_widths(ex.t_s, ex.u, xs[0]))
    held = [j for j, r in enumerate(RUNS) if r[0] == "held_out"]
    oracle = _oracle([xs[j] for j in held], [ys[j] for j in held])
    ident = _oracle([xs[0]], [ys[0]])
    oracle["identification_effect_rms_noise_sd"] = ident["effect_rms_noise_sd"]
    oracle["identification_gain_offset_residual_noise_sd"] = ident["gain_offset_residual_noise_sd"]
    oracle["noise_sd_mm"] = OUTPUT_NOISE_SD_MM
    params = {
        "plant": dict(plant.params),
        "effect": ep,
        "channels": {
            "output_noise_sd_mm": OUTPUT_NOISE_SD_MM, "counts_per_mm": COUNTS_PER_MM,
            "loadcell_noise_n": LOADCELL_NOISE_N, "spring_F0_n": F0_N, "spring_rate_n_per_mm": SPRING_N_PER_MM,
            "mu": MU, "wrap_angle_deg": WRAP_DEG, "dahl_delta_mm": DAHL_DELTA_MM,
            "friction_state_start": -1.0 if start == "loaded" else 0.0,
        },
        "loop_width_vertical_mm": widths[0],
        "loop_width_horizontal_mm": widths[1],
    }
    if start == "loaded":
        params["prehistory"] = f"hidden 0 -> {PREHISTORY_PULL_MM} -> 0 mm pull and release before every run"
    entry = {
        "plant": plant_name,
        "tag": tag,
        "effect": "backlash_different_slopes" if g is not None else None,
        "form": "held_slope_backlash" if g is not None else None,
        "g": g,
        "pivot": pivot,
        "parameters": params,
        "start": start,
        "identifiable": g is not None,
        "oracle": oracle,
        "runs": run_ids,
    }
    return {"name": name, "entry": entry}


def _jobs(outdir: Path, seed: int) -> list[dict]:
    jobs = []
    for p in PLANTS:
        for tag, g, pivot in EFFECT_SPECS:
            jobs.append({"outdir": str(outdir), "seed": seed, "plant": p, "tag": tag, "start": "rest", "g": g, "pivot": pivot})
        for tag, start in CLEAN_SPECS:
            jobs.append({"outdir": str(outdir), "seed": seed, "plant": p, "tag": tag, "start": start, "g": None, "pivot": None})
    return jobs


def generate(outdir: str | Path, seed: int = 0, workers: int = 2) -> dict:
    """Write the 15 sources and ``slope_smooth_truth.json`` into ``outdir``; return the truth."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    jobs = _jobs(out, int(seed))
    # order jobs so each worker mostly reuses one plant's cached simulations
    if workers and workers > 1:
        try:
            ctx = mp.get_context("fork")
        except ValueError:
            ctx = mp.get_context()
        with ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx) as pool:
            results = list(pool.map(_write_source, jobs))
    else:
        results = [_write_source(j) for j in jobs]
    truth = {r["name"]: r["entry"] for r in results}
    doc = {
        "generator": "slope_smooth (clean room)",
        "format": riglog.FORMAT,
        "seed": int(seed),
        "noise_sd_mm": OUTPUT_NOISE_SD_MM,
        "sources": truth,
    }
    (out / "slope_smooth_truth.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return doc


def _table(doc: dict) -> str:
    rows = [f"{'source':<14} {'plant':<9} {'start':<7} {'g':>5} {'pivot':<7} {'width_v':>7} {'width_h':>7} "
            f"{'rms/sd':>8} {'gain+off/sd':>11} {'gain':>6}"]
    for name, e in sorted(doc["sources"].items(), key=lambda kv: (kv[1]["plant"], kv[1]["tag"])):
        o = e["oracle"]
        g = "-" if e["g"] is None else f"{e['g']:.2f}"
        rows.append(
            f"{name:<14} {e['plant']:<9} {e['start']:<7} {g:>5} {str(e['pivot'] or '-'):<7} "
            f"{e['parameters']['loop_width_vertical_mm']:7.3f} {e['parameters']['loop_width_horizontal_mm']:7.3f} "
            f"{o['effect_rms_noise_sd']:8.1f} {o['gain_offset_residual_noise_sd']:11.1f} {o['gain_offset_gain']:6.3f}"
        )
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    doc = generate(a.outdir, seed=a.seed, workers=a.workers)
    print(_table(doc))
    print(f"{len(doc['sources'])} sources written to {a.outdir} in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
