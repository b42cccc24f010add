"""Clean-room generator of raw ``tsm-rig-log/1`` test sources: SMOOTH tendon-sheath plants, each
with ONE hidden physical effect (or none).

Provenance
==========
Written only from

* ``../shared/rig-log-format.md`` -- the raw format ``tsm-rig-log/1`` (run folder, manifest,
  encoder / load-cell channels, excitations);
* ``../shared/seeds/README.md`` and the papers it lists:
  ``../shared/seeds/000_fb211136be205d13.txt`` (Coleman-Hodgdon / Duhem backlash model, eq. 10-11),
  ``../shared/seeds/001_9db1eb7439089598.txt`` (the bench: input and follower modules, linear
  encoders, load cells, constant-force spring, 10 ms loop; decaying sine / triangle / trapezoid
  excitations; Preisach relays and the Gauss-Gauss density, eq. 4.1-4.5),
  ``../shared/seeds/002_2b9594ed99c85a30.txt`` (Bouc-Wen model, eq. 2-3);
* ``tests/cleanroom/riglog.py`` -- the clean-room raw-format writer (imported, not copied);
* textbook physics (capstan / Euler-Eytelwein friction, Dahl friction, Maxwell element, creep,
  Stribeck curve).

No code, configuration, documentation or test of the analysis tool itself was read.

Conventions
===========
``u`` is the proximal tendon displacement (mm, + = pull), ``y`` the distal follower displacement
(mm, same direction), ``t`` the run's clock (s, 100 Hz, 80 s per run).  All three plants are
rate-independent, smooth (no play / backlash operator) and lag the input: the releasing branch
lies ABOVE the pulling branch (counter-clockwise loop in the (u, y) plane).  Their loop is
~1.00 mm wide (vertical distance between the two branches at u = 0 on the steady +-6 mm sine
cycle) with a peak-to-peak gain of 0.89 (y spans 89 % of u).  Numbers are in
``PLANT_PARAMS`` and are written, with the measured width, to the truth file.

Plants
------
``bouc_wen_hard``
    Bouc-Wen in the input (paper 002 eq. 3 with d/dt -> d/du, hence rate independent), n = 2::

        dz/du = A - beta * sgn(du) * |z| z - gamma * z^2        (A = 1, gamma = beta / 2)
        y     = g * (u - kappa * z),   kappa = (beta + gamma) / (2 beta A)

    z is a dissipative (beta >= |gamma|) friction-like state: it saturates at
    z_u = (A / (beta + gamma))^(1/2).  The "a*u + (1-a)*z" mix is taken with a NEGATIVE weight on
    z because a displacement output LAGS (a positive weight gives a force-like, clockwise loop).
    kappa is the largest weight for which the output never runs backwards: right after a reversal
    from the saturated branch dy/du = 0 exactly (a hard, backlash-like take-up), then the slope
    rises smoothly to g (the n = 2 knee).  "hard" = this hard take-up with the sharp n = 2 knee.
    Integrated with RK4 in u, 2 sub-steps per sample.

``duhem``
    Coleman-Hodgdon / Duhem (paper 000 eq. 10 written for a displacement output)::

        dy/dt = alpha |du/dt| (c u - y) + b du/dt,    b = c / 2

    i.e. dy/du = alpha sgn(du) (c u - y) + b (rate independent).  The branches approach
    y = c u -+ (c - b)/alpha exponentially over 1/alpha mm, so the loop width is
    2 (c - b)/alpha = c / alpha; b = c/2 makes dy/du = 0 right after a reversal from a saturated
    branch (no backward motion).  Solved exactly per sample (linear ODE in u).

``preisach_gauss``
    Discrete Preisach plane (seed 001 eq. 4.1-4.3) of N_r x N_m = 30 x 300 non-ideal relays with
    thresholds alpha = m + r (switch up) and beta = m - r (switch down), half-widths
    r_i = (i + 1/2) R/N_r, centres m_j uniform on [-M, M] with a fixed +-half-cell jitter (so the
    9000 switching thresholds are all distinct), weights from the Gauss-Gauss density of
    eq. 4.5 (centred on the positive half-width H0, Gaussian spread sigma_r in r and sigma_m
    in m), plus a reversible part k u::

        y = k u + sum_ij w_ij R_ij[u],   w_ij ~ exp(-(r_i - H0)^2/2 sigma_r^2) exp(-m_j^2/2 sigma_m^2)

    Evaluated exactly through the identity R_{m,r}[u](t) = sgn(P_r[u](t) - m), P_r the play of
    half-width r started consistently (a relay plane with equal half-widths is a play followed by
    a step sum).  30 x 30 relays would give 0.03 mm steps (3 x the noise); 300 centres keep every
    step below ~0.005 mm, so the plant is smooth at the noise level.

Start state
-----------
``rest``: the demagnetised / zero state at u = 0 (z = 0; y = 0; every play at 0, i.e. relays with
m < 0 up and m > 0 down).  ``loaded``: the state after a quasi-static stroke 0 -> +6 mm -> 0
(the previous run ended pulled and the rig was driven back to zero): the plant sits on its
releasing (upper) branch, ~ +0.5 mm above the centre.  Encoder positions are written relative
to the first sample (spec), so the reader sees 0 at t = 0 in both cases; the plant-frame value
y(0) is in the truth file.

Tensions (load cells)
---------------------
Follower: the constant-force spring, ``T_out = F0 + k_s y`` (F0 = 5 N, small residual rate
k_s = 0.05 N/mm).  Input: capstan (Euler-Eytelwein) friction over the sheath's wrap angle theta
(= the configuration's curve angle, 90 deg) with coefficient mu = 0.2, following the direction
of motion through a Dahl friction state s in [-1, 1]::

    ds/du = (sgn(du) - s) / delta_s     (delta_s = 0.3 mm, rate independent, smooth)
    T_in  = T_out * exp(mu * theta * s)

(pulling: T_in -> 1.37 T_out; releasing: T_in -> 0.73 T_out).  s = 0 at rest, s = -1 loaded.

Hidden effects (one per source; ``effect`` / ``form``)
------------------------------------------------------
v = du/dt of the commanded input.  Each effect's coefficient is scaled per source so that its
largest contribution |y_effect - y_clean| over the source's three runs equals a target
``TARGET_MM[form]`` times a seeded factor in [0.85, 1.15] (targets 0.30-0.40 mm, so every
contribution is within ~0.24-0.46 mm; the tendon-stretch forms land ~3 % under target because the
plant's gain is 0.89); the achieved sizes are in the truth file.

rate_dependence
    ``viscous``           y - c v                                    (c ~ 0.03 s)
    ``nonlinear_damping`` y - c sgn(v) |v|^0.5                       (c ~ 0.1 mm^0.5 s^0.5)
    ``relaxation``        y - c w,  tau dw/dt = v - w, tau = 1.0 s   (Maxwell element: viscous
                          force c * speed through a first-order lag; c ~ 0.06 s)
    ``stribeck``          velocity-strengthening Stribeck curve for the sheath friction,
                          mu(v)/mu_0 = m(v) = 1 + (rho - 1)(1 - exp(-(v/v_s)^2)),
                          v_s = 4 mm/s, rho = mu_k/mu_0 ~ 1.6 (friction, hence the loop's
                          width, rises from its static level mu_0 to the kinetic mu_k with
                          sliding speed).  The friction state follows the motion with that
                          level, sigma: d sigma/du = (sgn(du) m(v) - sigma)/delta_s, and
                          y = y_plant - h (sigma - s),  h = 0.5 mm (the plant's half-width),
                          so the loop widens by 2 h (m(v) - 1) at speed v, the extra lag builds
                          up and reverses over delta_s = 0.3 mm of travel and holds while the
                          input is still; the capstan uses sigma too (T_in = T_out e^{mu theta
                          sigma}), the only effect that changes the load cells' law.
drift
    ``exponential_creep`` y - c (1 - exp(-t/tau)), tau in [20, 40] s (tendon creep elongation
                          under the spring's tension: the follower falls back), c ~ 0.4 mm
    ``linear_creep``      y - c t, c ~ 0.004 mm/s
saturation (in the plant frame, 0 = the rest centre)
    ``soft_tanh``         a soft stop near the top of the output's range:
                          y' = y (y <= y_k);  y_k + Y tanh((y - y_k)/Y) (y > y_k),  Y = 2 mm,
                          y_k solved so the top of the stroke is cut by the target (~0.35 mm);
                          continuous in value, slope and curvature.
    ``cubic_softening``   y' = y - k y^3, k ~ 0.0025 mm^-2 (symmetric)
tendon_stretch (the plant sees the input less the tendon's stretch under the input tension)
    ``linear_input``      u_p = u - (T_in - T_in(0)) / k_t                (1/k_t ~ 0.1 mm/N)
    ``quadratic_input``   u_p = u - q (T_in^2 - T_in(0)^2)                (q ~ 0.01 mm/N^2)  
                          (referenced to t = 0 because encoder zero is the first sample;
                          solved by two fixed-point passes, T_in <- y <- u_p)
clean
    ``none``              nothing added (rest and loaded sources).

Runs (each source = 3 ``tsm-bench`` run folders, configuration phi 90 deg / r 30 mm, 80 s each)
-----------------------------------------------------------------------------------------------
``sine_decay``       6 / 4.5 / 3 / 1.5 mm, 5 periods each at 0.25 Hz (peak speed 9.4 mm/s);
``triangle_decay``   same amplitudes, 8 periods each at 6 mm/s;
``trapezoid_decay``  same amplitudes, 5 periods each at 5 mm/s, 0.5 s dwell at each extreme.

Noise (white, Gaussian, independent per sample, seeded): output encoder 0.010 mm, input encoder
0.002 mm (then quantised to 0.1 um counts by the writer), load cells 0.02 N at 1 kHz.

Output layout
-------------
``<root>/sp-<8 hex>/<run_id>/{manifest.json, encoder.csv, loadcell.csv, events.csv}`` and the
ground truth ``<root>/smooth_plants_truth.json`` (outside the source folders): per source the
plant and its parameters, start, effect, form, effect parameters, target and achieved sizes,
noise, tension law, and per run the kind, the plant-frame y(0) and the measured loop width.

Default matrix (``default_matrix()``, written by ``write_all``): 3 plants x (10 effect forms +
clean rest x 2 + clean loaded x 2) = 42 sources, 126 runs; effect sources alternate rest / loaded,
shifted per plant so each form appears with both starts.  ~30 s on one core, ~310 MB
(``gzip_files=True``: ~100 MB, ~2 min).

API: ``write_all(root) -> dict`` (the truth document, also written to the truth file) and
``write_source(root, plant, effect, form, start, seed) -> str`` (the source folder; its truth is
merged into the truth file).  Clean sources: ``effect="clean", form="none"``.
The riglog writer is imported by file path from ``$CLEANROOM_RIGLOG`` or ``riglog.py`` beside
this file.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import importlib.util
import json
import math
import os
import sys
from functools import cache, lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

__all__ = [
    "EFFECT_FORMS",
    "NOISE",
    "PLANTS",
    "PLANT_PARAMS",
    "TARGET_MM",
    "TENSION",
    "default_matrix",
    "friction_state",
    "loop_width",
    "plant_loop_width",
    "plant_output",
    "preisach_relays",
    "simulate_source",
    "source_name",
    "write_all",
    "write_source",
]

TRUTH_FILE = "smooth_plants_truth.json"
DT_S = 0.01
PLANTS = ("bouc_wen_hard", "duhem", "preisach_gauss")
EFFECT_FORMS: dict[str, tuple[str, ...]] = {
    "rate_dependence": ("viscous", "nonlinear_damping", "relaxation", "stribeck"),
    "drift": ("exponential_creep", "linear_creep"),
    "saturation": ("soft_tanh", "cubic_softening"),
    "tendon_stretch": ("linear_input", "quadratic_input"),
    "clean": ("none",),
}
STARTS = ("rest", "loaded")
PRESTROKE_MM = 6.0

PLANT_PARAMS: dict[str, dict[str, float]] = {
    "bouc_wen_hard": {"A": 1.0, "beta": 1.421, "gamma_over_beta": 0.5, "n": 2.0, "g": 0.9733},
    "duhem": {"alpha_per_mm": 0.968, "c": 0.9738, "b_over_c": 0.5},
    "preisach_gauss": {
        "N_r": 30, "N_m": 300, "R_mm": 1.75, "M_mm": 8.0, "H0_mm": 0.7, "sigma_r_mm": 0.3,
        "sigma_m_mm": 3.5, "k": 0.4384, "W_mm": 3.052, "jitter_seed": 20260302,
    },
}

TARGET_MM = {
    "viscous": 0.30, "nonlinear_damping": 0.30, "relaxation": 0.30, "stribeck": 0.30,
    "exponential_creep": 0.35, "linear_creep": 0.30, "soft_tanh": 0.35, "cubic_softening": 0.40,
    "linear_input": 0.30, "quadratic_input": 0.30, "none": 0.0,
}
NOISE = {"output_mm": 0.010, "input_mm": 0.002, "loadcell_n": 0.02}
TENSION = {"F0_n": 5.0, "spring_rate_n_per_mm": 0.05, "mu": 0.2, "delta_s_mm": 0.3}
CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
RELAX_TAU_S = 1.0
STRIBECK_VS_MM_S = 4.0
TANH_Y_MM = 2.0

RUN_KINDS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("sine_decay", {}),
    ("triangle_decay", {"periods_per_amplitude": 8, "slope_mm_s": 6.0}),
    ("trapezoid_decay", {"periods_per_amplitude": 5, "slope_mm_s": 5.0, "dwell_s": 0.5}),
)


# ---------------------------------------------------------------------------------------------
# riglog (imported by file path)
# ---------------------------------------------------------------------------------------------

_RIGLOG: Any = None


def _riglog() -> Any:
    global _RIGLOG
    if _RIGLOG is None:
        path = os.environ.get("CLEANROOM_RIGLOG") or str(Path(__file__).resolve().with_name("riglog.py"))
        name = "_cleanroom_riglog_for_smooth_plants"
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot import riglog writer from {path!r} (set CLEANROOM_RIGLOG)")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
        _RIGLOG = mod
    return _RIGLOG


# ---------------------------------------------------------------------------------------------
# Plants (rate independent; arrays in, arrays out)
# ---------------------------------------------------------------------------------------------


def _prehistory() -> np.ndarray:
    """Quasi-static stroke 0 -> +PRESTROKE_MM -> 0 in 0.01 mm steps (ends at 0, not repeated)."""
    n = round(PRESTROKE_MM / 0.01)
    return np.concatenate([np.linspace(0.0, PRESTROKE_MM, n + 1), np.linspace(PRESTROKE_MM, 0.0, n + 1)[1:-1]])


def _with_start(u: np.ndarray, start: str) -> tuple[np.ndarray, int]:
    if start == "rest":
        return np.asarray(u, float), 0
    if start == "loaded":
        pre = _prehistory() + float(u[0])
        return np.concatenate([pre, u]), pre.size
    raise ValueError(f"start must be one of {STARTS}, not {start!r}")


def _bouc_wen(u: np.ndarray) -> np.ndarray:
    p = PLANT_PARAMS["bouc_wen_hard"]
    A, beta = p["A"], p["beta"]
    gamma = p["gamma_over_beta"] * beta
    kappa = (beta + gamma) / (2.0 * beta * A)
    z = np.empty_like(u)
    zz = 0.0
    uprev = float(u[0])
    for k in range(u.size):
        du = float(u[k]) - uprev
        if du != 0.0:
            s = 1.0 if du > 0 else -1.0
            h = du / 2.0
            for _ in range(2):
                k1 = A - s * beta * abs(zz) * zz - gamma * zz * zz
                z2 = zz + 0.5 * h * k1
                k2 = A - s * beta * abs(z2) * z2 - gamma * z2 * z2
                z3 = zz + 0.5 * h * k2
                k3 = A - s * beta * abs(z3) * z3 - gamma * z3 * z3
                z4 = zz + h * k3
                k4 = A - s * beta * abs(z4) * z4 - gamma * z4 * z4
                zz += h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        z[k] = zz
        uprev = float(u[k])
    return p["g"] * (u - kappa * z)


def _duhem(u: np.ndarray) -> np.ndarray:
    p = PLANT_PARAMS["duhem"]
    a, c = p["alpha_per_mm"], p["c"]
    b = p["b_over_c"] * c
    du = np.diff(u, prepend=u[0])
    y = np.empty_like(u)
    e = 0.0  # e = y - c u; de/du = -alpha sgn(du) e + (b - c)
    for k in range(u.size):
        d = float(du[k])
        if d != 0.0:
            s = 1.0 if d > 0 else -1.0
            e_inf = (b - c) / (a * s)
            e = e_inf + (e - e_inf) * math.exp(-a * abs(d))
        y[k] = c * float(u[k]) + e
    return y


@lru_cache(maxsize=1)
def _preisach_plane() -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], float]:
    """(half-widths r_i, per i the sorted centres m_ij, per i cumulative weights, W_total)."""
    p = PLANT_PARAMS["preisach_gauss"]
    nr, nm = int(p["N_r"]), int(p["N_m"])
    r = (np.arange(nr) + 0.5) * p["R_mm"] / nr
    cell = 2.0 * p["M_mm"] / nm
    m0 = -p["M_mm"] + (np.arange(nm) + 0.5) * cell
    rng = np.random.default_rng(int(p["jitter_seed"]))
    m = m0[None, :] + rng.uniform(-0.5, 0.5, (nr, nm)) * cell
    w = np.exp(-((r[:, None] - p["H0_mm"]) ** 2) / (2 * p["sigma_r_mm"] ** 2)) * np.exp(
        -(m**2) / (2 * p["sigma_m_mm"] ** 2)
    )
    w *= p["W_mm"] / w.sum()
    ms, cws = [], []
    for i in range(nr):
        order = np.argsort(m[i])
        ms.append(m[i][order])
        cws.append(np.concatenate([[0.0], np.cumsum(w[i][order])]))
    return r, ms, cws, float(w.sum())


def preisach_relays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The relay plane as flat arrays (alpha_up, beta_down, weight), for checks."""
    r, ms, cws, _ = _preisach_plane()
    al, be, ww = [], [], []
    for i in range(r.size):
        al.append(ms[i] + r[i])
        be.append(ms[i] - r[i])
        ww.append(np.diff(cws[i]))
    return np.concatenate(al), np.concatenate(be), np.concatenate(ww)


def _preisach(u: np.ndarray) -> np.ndarray:
    p = PLANT_PARAMS["preisach_gauss"]
    r, ms, cws, _ = _preisach_plane()
    # plays of every half-width, started at 0 (demagnetised plane)
    P = np.empty((u.size, r.size))
    pz = np.zeros(r.size)
    for k in range(u.size):
        uk = float(u[k])
        pz = np.minimum(uk + r, np.maximum(uk - r, pz))
        P[k] = pz
    y = p["k"] * u.copy()
    for i in range(r.size):
        below = cws[i][np.searchsorted(ms[i], P[:, i], side="left")]  # weight of relays up
        y += 2.0 * below - cws[i][-1]  # up minus down
    return y


_PLANT_FUN = {"bouc_wen_hard": _bouc_wen, "duhem": _duhem, "preisach_gauss": _preisach}


def plant_output(plant: str, u: np.ndarray, start: str = "rest") -> np.ndarray:
    """Noise-free follower displacement (plant frame: 0 = rest centre) for input ``u``."""
    if plant not in _PLANT_FUN:
        raise ValueError(f"plant must be one of {PLANTS}, not {plant!r}")
    uu, n0 = _with_start(np.asarray(u, float), start)
    return _PLANT_FUN[plant](uu)[n0:]


def friction_state(u: np.ndarray, start: str = "rest", scale: np.ndarray | None = None) -> np.ndarray:
    """Dahl friction state: ds/du = (sgn(du) * m - s) / delta_s, exact per sample, with target
    level m = 1 (or ``scale[k]``, the Stribeck factor, per sample; 1 during the prehistory).
    s stays where it is while the input is still (static friction holds)."""
    uu, n0 = _with_start(np.asarray(u, float), start)
    sc = np.ones_like(uu)
    if scale is not None:
        sc[n0:] = np.asarray(scale, float)
    d = TENSION["delta_s_mm"]
    du = np.diff(uu, prepend=uu[0])
    s = np.empty_like(uu)
    sv = 0.0
    for k in range(uu.size):
        dk = float(du[k])
        if dk != 0.0:
            target = (1.0 if dk > 0 else -1.0) * float(sc[k])
            sv = target + (sv - target) * math.exp(-abs(dk) / d)
        s[k] = sv
    return s[n0:]


def _branches(u: np.ndarray, y: np.ndarray, npts: int = 241) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v = np.gradient(u)
    lo, hi = float(u.min()), float(u.max())
    grid = np.linspace(lo, hi, npts)
    a, d = v > 0, v < 0
    ia, idd = np.argsort(u[a]), np.argsort(u[d])
    ya = np.interp(grid, u[a][ia], y[a][ia])
    yd = np.interp(grid, u[d][idd], y[d][idd])
    return ya, yd, grid


def loop_width(u: np.ndarray, y: np.ndarray, at: float = 0.0) -> float:
    """Vertical loop width (releasing branch minus pulling branch) at input ``at`` for ONE
    cycle of data (u, y); branches split by the sign of du."""
    ya, yd, grid = _branches(np.asarray(u, float), np.asarray(y, float))
    return float(np.interp(at, grid, yd - ya))


@cache
def plant_loop_width(plant: str) -> dict[str, float]:
    t = np.arange(0.0, 12.0 + 1e-9, 0.005)
    u = 6.0 * np.sin(2 * np.pi * 0.25 * t)
    y = plant_output(plant, u, "rest")
    m = t >= 8.0
    return {
        "width_at_u0_mm": loop_width(u[m], y[m]),
        "gain_peak_to_peak": float((y[m].max() - y[m].min()) / 12.0),
    }


# ---------------------------------------------------------------------------------------------
# Effects
# ---------------------------------------------------------------------------------------------


def _form_effect(form: str) -> str:
    for eff, forms in EFFECT_FORMS.items():
        if form in forms:
            return eff
    raise ValueError(f"unknown form {form!r}")


def _lowpass(v: np.ndarray, tau: float, dt: float) -> np.ndarray:
    a = math.exp(-dt / tau)
    return lfilter([1.0 - a], [1.0, -a], v)


def _stribeck_factor(v: np.ndarray, rho: float) -> np.ndarray:
    return 1.0 + (rho - 1.0) * (1.0 - np.exp(-((v / STRIBECK_VS_MM_S) ** 2)))


def _soft_tanh(y: np.ndarray, knee: float, Y: float) -> np.ndarray:
    out = y.copy()
    m = y > knee
    out[m] = knee + Y * np.tanh((y[m] - knee) / Y)
    return out


def _tensions(y: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constant-force spring at the follower; capstan at the input with friction state s."""
    theta = math.radians(float(CONFIGURATION["curve_angle_deg"]))
    t_out = TENSION["F0_n"] + TENSION["spring_rate_n_per_mm"] * y
    t_in = t_out * np.exp(TENSION["mu"] * theta * s)
    return t_in, t_out


def _run_signals(plant: str, form: str, start: str, t: np.ndarray, u: np.ndarray, par: dict[str, float]) -> dict[str, np.ndarray]:
    """Noise-free signals of one run with effect ``form`` at parameters ``par``."""
    v = np.gradient(u, t)
    s = friction_state(u, start)
    y_clean = plant_output(plant, u, start)
    u_p = u
    y = y_clean
    if form in ("linear_input", "quadratic_input"):
        t_in, _ = _tensions(y_clean, s)
        for _ in range(2):
            if form == "linear_input":
                stretch = (t_in - t_in[0]) * par["compliance_mm_per_n"]
            else:
                stretch = (t_in**2 - t_in[0] ** 2) * par["q_mm_per_n2"]
            u_p = u - stretch
            y = plant_output(plant, u_p, start)
            t_in, _ = _tensions(y, s)
    elif form == "stribeck":
        sig = friction_state(u, start, _stribeck_factor(v, par["rho"]))
        y = y_clean - par["h_mm"] * (sig - s)
        s = sig
    elif form == "soft_tanh":
        y = _soft_tanh(y_clean, par["knee_mm"], par["Y_mm"])
    elif form == "cubic_softening":
        y = y_clean - par["k_per_mm2"] * y_clean**3
    elif form == "viscous":
        y = y_clean - par["c_s"] * v
    elif form == "nonlinear_damping":
        y = y_clean - par["c_mm05_s05"] * np.sign(v) * np.sqrt(np.abs(v))
    elif form == "relaxation":
        y = y_clean - par["c_s"] * _lowpass(v, par["tau_s"], float(np.median(np.diff(t))))
    elif form == "exponential_creep":
        y = y_clean - par["c_mm"] * (1.0 - np.exp(-(t - t[0]) / par["tau_s"]))
    elif form == "linear_creep":
        y = y_clean - par["rate_mm_s"] * (t - t[0])
    elif form != "none":
        raise ValueError(f"unknown form {form!r}")
    t_in, t_out = _tensions(y, s)
    return {"t": t, "u": u, "u_plant": u_p, "v": v, "s": s, "y_clean": y_clean, "y": y, "t_in": t_in, "t_out": t_out}


def _solve_params(plant: str, form: str, start: str, runs: list[tuple[np.ndarray, np.ndarray]], target: float, rng: np.random.Generator) -> dict[str, float]:
    """Effect parameters such that max |y - y_clean| over the runs is ~ ``target`` mm."""
    if form == "none":
        return {}
    vs = [np.gradient(u, t) for t, u in runs]
    ycs = [plant_output(plant, u, start) for _, u in runs]
    if form == "viscous":
        return {"c_s": target / max(np.abs(v).max() for v in vs)}
    if form == "nonlinear_damping":
        return {"c_mm05_s05": target / max(np.sqrt(np.abs(v)).max() for v in vs), "exponent": 0.5}
    if form == "relaxation":
        lp = max(np.abs(_lowpass(v, RELAX_TAU_S, DT_S)).max() for v in vs)
        return {"c_s": target / lp, "tau_s": RELAX_TAU_S}
    if form == "stribeck":  # contribution is linear in (rho - 1): evaluate at rho = 2
        h = 0.5 * plant_loop_width(plant)["width_at_u0_mm"]
        unit = 0.0
        for (t, u), v in zip(runs, vs):
            d = friction_state(u, start, _stribeck_factor(v, 2.0)) - friction_state(u, start)
            unit = max(unit, float(np.abs(h * d).max()))
        return {"rho": 1.0 + target / unit, "v_s_mm_s": STRIBECK_VS_MM_S, "h_mm": h,
                "delta_s_mm": TENSION["delta_s_mm"]}
    if form == "exponential_creep":
        tau = float(rng.uniform(20.0, 40.0))
        dur = max(float(t[-1] - t[0]) for t, _ in runs)
        return {"c_mm": target / (1.0 - math.exp(-dur / tau)), "tau_s": tau}
    if form == "linear_creep":
        dur = max(float(t[-1] - t[0]) for t, _ in runs)
        return {"rate_mm_s": target / dur}
    if form == "soft_tanh":
        ymax = max(float(yc.max()) for yc in ycs)
        d = brentq(lambda x: x - TANH_Y_MM * math.tanh(x / TANH_Y_MM) - target, 1e-6, 50.0)
        return {"knee_mm": ymax - d, "Y_mm": TANH_Y_MM}
    if form == "cubic_softening":
        return {"k_per_mm2": target / max(float(np.abs(yc).max()) ** 3 for yc in ycs)}
    if form in ("linear_input", "quadratic_input"):
        top = 0.0
        for (t, u), yc in zip(runs, ycs):
            t_in, _ = _tensions(yc, friction_state(u, start))
            dev = t_in - t_in[0] if form == "linear_input" else t_in**2 - t_in[0] ** 2
            top = max(top, float(np.abs(dev).max()))
        key = "compliance_mm_per_n" if form == "linear_input" else "q_mm_per_n2"
        return {key: target / top}
    raise ValueError(f"unknown form {form!r}")


# ---------------------------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------------------------


def _excitations() -> list[Any]:
    rl = _riglog()
    return [rl.make_excitation(kind, DT_S, **kw) for kind, kw in RUN_KINDS]


def _normalise(effect: str | None, form: str | None) -> tuple[str, str]:
    if form in (None, "", "none", "clean") or effect in (None, "", "none", "clean"):
        if form not in (None, "", "none", "clean") or effect not in (None, "", "none", "clean"):
            raise ValueError(f"clean sources take effect 'clean' and form 'none' (got {effect!r}, {form!r})")
        return "clean", "none"
    if effect not in EFFECT_FORMS or form not in EFFECT_FORMS[effect]:
        raise ValueError(f"form {form!r} is not a form of effect {effect!r}; known: {EFFECT_FORMS}")
    return effect, form


def source_name(plant: str, effect: str, form: str, start: str, seed: int) -> str:
    h = hashlib.sha256(f"smooth-plants|{plant}|{effect}|{form}|{start}|{seed}".encode()).hexdigest()
    return "sp-" + h[:8]


def simulate_source(plant: str, effect: str, form: str, start: str, seed: int) -> dict[str, Any]:
    """Noise-free signals of the three runs plus the parameters, without writing anything."""
    effect, form = _normalise(effect, form)
    if plant not in PLANTS:
        raise ValueError(f"plant must be one of {PLANTS}")
    if start not in STARTS:
        raise ValueError(f"start must be one of {STARTS}")
    rng = np.random.default_rng([int(seed), 7])
    target = TARGET_MM[form] * float(rng.uniform(0.85, 1.15)) if form != "none" else 0.0
    exs = _excitations()
    runs = [(ex.t_s, ex.u) for ex in exs]
    par = _solve_params(plant, form, start, runs, target, rng)
    sigs = [_run_signals(plant, form, start, t, u, par) for t, u in runs]
    return {"effect": effect, "form": form, "target_mm": target, "params": par, "excitations": exs, "signals": sigs}


def _to_builtin(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _to_builtin(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_to_builtin(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def _read_truth(root: Path) -> dict[str, Any]:
    p = root / TRUTH_FILE
    if p.exists():
        return json.loads(p.read_text(encoding="utf-8"))
    return _empty_truth()


def _empty_truth() -> dict[str, Any]:
    return {
        "generator": "smooth_plants (clean-room)",
        "note": "y in mm in the plant frame (0 = rest centre); encoder files are relative to t = 0",
        "plants": {p: {"params": PLANT_PARAMS[p], **plant_loop_width(p)} for p in PLANTS},
        "noise": dict(NOISE),
        "tension": dict(TENSION) | {"wrap_angle_deg": CONFIGURATION["curve_angle_deg"]},
        "sources": {},
    }


def _write_source(root: Path, plant: str, effect: str, form: str, start: str, seed: int, index: int,
                  gzip_files: bool, loadcell_rate_hz: float | None) -> tuple[str, dict[str, Any]]:
    rl = _riglog()
    sim = simulate_source(plant, effect, form, start, seed)
    effect, form = sim["effect"], sim["form"]
    name = source_name(plant, effect, form, start, seed)
    src = root / name
    src.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([int(seed), 11])
    base = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.UTC) + _dt.timedelta(hours=2 * index)
    run_truth = []
    for j, (ex, sg) in enumerate(zip(sim["excitations"], sim["signals"])):
        kind = ex.manifest["kind"]
        rid = rl.run_id_for(CONFIGURATION, kind, j + 1)
        y_meas = sg["y"] + rng.normal(0.0, NOISE["output_mm"], sg["y"].shape)
        u_meas = sg["u"] + rng.normal(0.0, NOISE["input_mm"], sg["u"].shape)
        rl.write_run_folder(
            src, rid, sg["t"], u_meas, y_meas, rig="tsm-bench", configuration=dict(CONFIGURATION),
            excitation=ex.manifest, loadcell=(sg["t_in"], sg["t_out"]), loadcell_rate_hz=loadcell_rate_hz,
            loadcell_noise_n=NOISE["loadcell_n"], events=True,
            started_at=base + _dt.timedelta(minutes=5 * j), seed=int(rng.integers(2**31)), gzip_files=gzip_files,
        )
        d = sg["y"] - sg["y_clean"]
        entry = {
            "run_id": rid,
            "kind": kind,
            "excitation": ex.manifest,
            "duration_s": float(sg["t"][-1] - sg["t"][0]),
            "y0_plant_frame_mm": float(sg["y"][0]),
            "effect_max_mm": float(np.abs(d).max()),
            "effect_rms_mm": float(np.sqrt(np.mean(d**2))),
            "tension_in_range_n": [float(sg["t_in"].min()), float(sg["t_in"].max())],
            "tension_out_range_n": [float(sg["t_out"].min()), float(sg["t_out"].max())],
        }
        if kind == "sine_decay":  # last 6 mm period (16-20 s) of the sine: measured loop width
            m = (sg["t"] >= 16.0) & (sg["t"] < 20.0)
            entry["loop_width_6mm_true_mm"] = loop_width(sg["u"][m], sg["y"][m])
            entry["loop_width_6mm_clean_mm"] = loop_width(sg["u"][m], sg["y_clean"][m])
        run_truth.append(entry)
    truth = {
        "plant": plant,
        "start": start,
        "prestroke_mm": PRESTROKE_MM if start == "loaded" else 0.0,
        "effect": effect,
        "form": form,
        "params": sim["params"],
        "target_mm": sim["target_mm"],
        "effect_max_mm": max(r["effect_max_mm"] for r in run_truth),
        "noise": dict(NOISE),
        "plant_params": PLANT_PARAMS[plant],
        "configuration": dict(CONFIGURATION),
        "seed": int(seed),
        "runs": run_truth,
    }
    return name, _to_builtin(truth)


def write_source(root: str | os.PathLike[str], plant: str, effect: str, form: str, start: str, seed: int, *,
                 gzip_files: bool = False, loadcell_rate_hz: float | None = 1000.0) -> str:
    """Write one source ``<root>/sp-<hex>/`` (three runs), merge its truth into
    ``<root>/smooth_plants_truth.json`` and return the source folder's path."""
    rootp = Path(root)
    rootp.mkdir(parents=True, exist_ok=True)
    doc = _read_truth(rootp)
    name, truth = _write_source(rootp, plant, effect, form, start, int(seed), len(doc["sources"]), gzip_files, loadcell_rate_hz)
    doc["sources"][name] = truth
    (rootp / TRUTH_FILE).write_text(json.dumps(_to_builtin(doc), indent=2) + "\n", encoding="utf-8")
    return str(rootp / name)


def default_matrix() -> list[tuple[str, str, str, str, int]]:
    """(plant, effect, form, start, seed): 3 plants x (10 effect forms + 2 clean rest + 2 clean
    loaded) = 42 sources.  Effect sources alternate rest / loaded, shifted per plant so every
    form is seen with both starts across the plants."""
    out = []
    seed = 1000
    forms = [(e, f) for e, fs in EFFECT_FORMS.items() if e != "clean" for f in fs]
    for pi, plant in enumerate(PLANTS):
        for fi, (eff, form) in enumerate(forms):
            out.append((plant, eff, form, STARTS[(fi + pi) % 2], seed))
            seed += 1
        for start in ("rest", "rest", "loaded", "loaded"):
            out.append((plant, "clean", "none", start, seed))
            seed += 1
    return out


def write_all(root: str | os.PathLike[str], *, gzip_files: bool = False, loadcell_rate_hz: float | None = 1000.0) -> dict[str, Any]:
    """Write the default matrix under ``root`` and ``<root>/smooth_plants_truth.json`` (replaced);
    return the truth document (``doc["sources"][name]`` per source)."""
    rootp = Path(root)
    rootp.mkdir(parents=True, exist_ok=True)
    doc = _empty_truth()
    for i, (plant, eff, form, start, seed) in enumerate(default_matrix()):
        name, truth = _write_source(rootp, plant, eff, form, start, seed, i, gzip_files, loadcell_rate_hz)
        if name in doc["sources"]:
            raise RuntimeError(f"source name collision {name}")
        doc["sources"][name] = truth
    doc = _to_builtin(doc)
    (rootp / TRUTH_FILE).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return doc


if __name__ == "__main__":  # pragma: no cover
    import time

    dest = sys.argv[1] if len(sys.argv) > 1 else "smooth_plants_out"
    t0 = time.time()
    d = write_all(dest)
    print(f"{len(d['sources'])} sources in {time.time() - t0:.1f} s -> {dest}")
