"""Clean-room generator of raw ``tsm-rig-log/1`` sources whose hidden discrepancy is a
RATE-DEPENDENT effect (test data for an independent hysteresis analysis).

Written only from:

* ``../shared/rig-log-format.md`` - the rig-log specification (run folders, manifest, encoder
  and load-cell channels, excitation kinds);
* ``../shared/seeds/001_9db1eb7439089598.txt`` - the TSM bench (input and follower modules,
  linear encoders, load cells on both sides, constant-force spring for pretension, 10 ms loop),
  the decaying-sine identification run, the 6 mm/s triangle validation run, the play operator
  and the weighted sum of plays (eq. 4.7-4.9) with P = (0, 0.2, ..., 2.0) mm;
* ``../shared/seeds/002_2b9594ed99c85a30.txt`` - the Bouc-Wen model (eq. 2-3);
* ``../shared/seeds/000_fb211136be205d13.txt`` (background: backlash-like TSM hysteresis);
* ``riglog.py`` beside this file (a clean-room writer of the raw format, imported by path);
* textbook physics (capstan / Euler-Eytelwein friction, Stribeck friction, first-order lag).

Nothing in a source folder announces the hidden effect; the ground truth is returned by
:func:`write_source` and written by :func:`write_all` to ``<root>/../rate_truth.json``.

Base plants (input u = proximal tendon displacement, output y = follower displacement, mm)
------------------------------------------------------------------------------------------
``bouc_wen`` (seed 002 eq. 2-3, written in the input displacement, so rate independent)::

    y  = alpha*u + beta*h,            beta = -alpha   (output = alpha * (u - h): lost motion h)
    dh = A du - B |du| |h|^(n-1) h - C du |h|^n
    A = 1, n = 1.5, alpha = 0.95, B = 0.45 K, C = 0.55 K, K = A / h_s^n, h_s = 0.8 mm

  h saturates at +-h_s, so the output loop is about 2*alpha*h_s = 1.52 mm wide; right after a
  reversal dy/du = alpha*(1 - (A + (B - C) h_s^n)) = 0.1*alpha (backlash-like).  h is integrated
  in u (the input is linear between samples) with RK4 sub-steps of at most 0.05 mm.

``play_sum`` (Prandtl-Ishlinskii; seed 001 eq. 4.7-4.9)::

    y = sum_i q_i w_i,   w_i[k] = max(u[k] - r_i, min(u[k] + r_i, w_i[k-1])),   r_i = p_i / 2
    P = (0, 0.2, ..., 2.0) mm (seed 001),  Q = (0.10, 0.02, 0.03, 0.04, 0.06, 0.08, 0.10,
    0.12, 0.14, 0.15, 0.16) (sum 1, the thesis' constraint; my choice of weights)

  i.e. the symmetric play of half-width p_i/2; it equals the thesis' play f_p (output in
  [v, v + p]) up to the constant offset p_i/2.  Output loop half-width sum q_i r_i = 0.635 mm.

Initial state: every run starts at u(0) = 0 moving upwards (pull) and ends at u = 0 after a
pull, and the three runs are taken in their order on the rig (sine_decay, rate probe,
triangle_decay, 5 min apart).  Before the first run the plant had been PULLED to u(0) and
left at rest: every play sits at the trailing edge of its (Coulomb, rate-independent) band,
w_i(0) = u(0) - r_i (the thesis' W(1) = 0 with v(1) = 0, in its own offset), and the Bouc-Wen
state is saturated on the pull branch, h(0) = +h_s.  Each later run starts from the
hysteresis state (w_i or h) the previous run left - nothing moves at rest between runs (the
Stribeck bands only widen).  Rate states start at rest in every run: zero speed at the first
sample, and the relaxation filter at y(0) = y_static(0).

Rate effects (each hidden alone in one source; v = du/dt is the central difference of the
commanded input on the 10 ms clock, one-sided at the last sample and 0 at the first sample,
where the plant is still at rest - so the first sample, which the reader takes as the zero of
both encoders, carries no rate contribution)
------------------------------------------------------------------------------------------
``clean``:              y = y_static                                   (no effect)
``viscous``:            y = y_static - c v,                c = 0.16 s
``nonlinear_damping``:  y = y_static - c |v|^a sign(v),    c = 0.5 mm^(1-a) s^a, a = 0.5
``stribeck``:           the friction coefficient of the sheath follows a Stribeck curve of the
                        current sliding speed (the input speed |v|)::

                            mu(v) = mu_c + (mu_s - mu_c) exp(-(v/v_s)^2) + mu_v |v|

                        and the friction sets the loop's half-width through the capstan law
                        (dead band ~ T_out sinh(mu theta)), so every play half-width r_i
                        (``play_sum``) or the Bouc-Wen saturation h_s (``bouc_wen``, with
                        K = A / h_s(v)^n) is scaled at every sample by
                        S(v) = sinh(mu(v) theta) / sinh(mu_c theta) >= 1.  This is the
                        "play whose width follows the Stribeck law of the current speed"
                        option (not a massless node: a massless node with a falling friction
                        curve is ill-posed).  The clean plant is the Coulomb limit S = 1.
                        mu_c = 0.1, mu_s = 0.35, v_s = 3 mm/s, mu_v = 0.015 s/mm.
``relaxation``:         tau dy/dt = y_static - y,  tau = 0.25 s (exact first-order-hold
                        discretisation, i.e. y_static linear between samples).

The "contribution" of an effect is y_case - y_clean (both noise free); for ``stribeck`` the
clean reference is the Coulomb-only plant.

Tensions (load cells on both sides; simple tendon-sheath physics)
-----------------------------------------------------------------
Distal (follower) tension: constant-force spring F0 = 6 N plus a small residual rate,
T_out = F0 + k_f (y - y(0)), k_f = 0.05 N/mm.  Proximal tension: capstan friction over the
wrap angle theta = the configuration's curve angle (90 deg), with the friction mobilised by the
plant's friction state s in [-1, 1] (+1 sliding in pull, -1 in release; s = h/h_s for Bouc-Wen,
s = sum q_i (u - w_i) / sum q_i r_i for the plays), plus the force that stretches the tendon by
the rate effect's displacement::

    T_in = T_out exp(mu theta s) + (y_rate_independent - y) / lambda
    lambda = (output loop half-width) / (F0 sinh(mu_c theta))   (effective compliance, mm/N)

so the same compliance turns the friction dead band and the rate effect's lag into tension
(mu = mu(v) and no extra term for ``stribeck``, whose effect is inside the capstan friction).

Runs per source (one configuration, phi = 90 deg, r = 30 mm; 80 s each on the 10 ms clock)
-------------------------------------------------------------------------------------------
1. ``sine_decay``: 6, 4.5, 3, 1.5 mm, 5 periods each, 0.25 Hz (seed 001 identification).
2. A fixed-amplitude stepped-frequency sine (the rate probe): u = 3 sin(2 pi f_j t') mm with
   f_j = 0.1, 0.2, 0.4, 0.8 Hz for 20 s each (2, 4, 8, 16 whole periods, so the input is
   continuous and each segment starts at 0 going up), peak speeds 1.9 - 15 mm/s.  No kind in
   the spec's table describes a frequency sequence (``sine`` has one ``frequency_hz``;
   ``mixed_sine`` is a sum, not a sequence), so it is recorded as ``kind: free`` (no
   parameters, as the spec says) and the schedule is written in the manifest's free-text
   ``notes``.  At one amplitude the rate-independent loop is the same in every step, so any
   change of the loop with frequency is the rate effect.
3. ``triangle_decay``: 6, 4.5, 3, 1.5 mm at the spec's 6 mm/s slope; 8 periods per amplitude
   so that it lasts 80 s like the other two (5 periods would last 50 s).

Measurement: Gaussian noise of 0.01 mm (std) on the output, then encoder quantisation at
10000 counts/mm (32-bit counters, input_sign 1, output_sign -1 as in the spec's example; the
counters start at a random value, no wrap); load cells at 1 kHz (interpolated from the 10 ms
clock) with 0.01 N Gaussian noise, the spec's example calibration (range 20 N; the tensions
written stay within about 1.5-11 N); ``events.csv`` with start/stop.

Only numpy, scipy, pandas (through riglog.py) and the standard library are used.  Paths above
are relative to the repository root.
"""

from __future__ import annotations

import datetime as _dt
import importlib.util
import json
import math
import pathlib
import sys
from functools import cache
from typing import Any

import numpy as np
from scipy.signal import lfilter

__all__ = ["CASES", "PLANTS", "write_source", "write_all"]

CASES: tuple[str, ...] = ("clean", "viscous", "nonlinear_damping", "stribeck", "relaxation")
PLANTS: tuple[str, ...] = ("bouc_wen", "play_sum")


def _load_riglog() -> Any:
    name = "_cleanroom_riglog_for_rate_forms"
    if name in sys.modules:
        return sys.modules[name]
    path = pathlib.Path(__file__).resolve().with_name("riglog.py")
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:  # pragma: no cover
        raise ImportError(f"cannot load {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses look their module up while the class is built
    spec.loader.exec_module(mod)
    return mod


_rl = _load_riglog()

# ---------------------------------------------------------------------------------------------
# Parameters (all documented in the module docstring)
# ---------------------------------------------------------------------------------------------

DT_S = 0.01
DURATION_S = 80.0
CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
NOISE_STD_MM = 0.01
LOADCELL_NOISE_N = 0.01
COUNTS_PER_UNIT = 10000
COUNTER_BITS = 32

BOUC_WEN = {"A": 1.0, "n": 1.5, "alpha": 0.95, "h_s_mm": 0.8, "b_frac": 0.45, "c_frac": 0.55}
PLAY_P_MM = tuple(round(0.2 * i, 1) for i in range(11))
PLAY_Q = (0.10, 0.02, 0.03, 0.04, 0.06, 0.08, 0.10, 0.12, 0.14, 0.15, 0.16)

TENSION = {"pretension_n": 6.0, "follower_rate_n_per_mm": 0.05, "mu_coulomb": 0.1}

EFFECTS: dict[str, dict[str, float]] = {
    "viscous": {"c_s": 0.16},
    "nonlinear_damping": {"c": 0.5, "a": 0.5},
    "stribeck": {
        "mu_coulomb": 0.1,
        "mu_static": 0.35,
        "v_stribeck_mm_s": 3.0,
        "mu_viscous_s_per_mm": 0.015,
    },
    "relaxation": {"tau_s": 0.25},
}

PROBE_AMPLITUDE_MM = 3.0
PROBE_FREQUENCIES_HZ = (0.1, 0.2, 0.4, 0.8)
PROBE_SEGMENT_S = 20.0


def _theta() -> float:
    return math.radians(float(CONFIGURATION["curve_angle_deg"]))


# ---------------------------------------------------------------------------------------------
# Excitations
# ---------------------------------------------------------------------------------------------


def _rate_probe() -> tuple[np.ndarray, np.ndarray, dict[str, Any], str]:
    n = int(round(DURATION_S / DT_S)) + 1
    t = np.arange(n, dtype=float) * DT_S
    freqs = np.asarray(PROBE_FREQUENCIES_HZ, dtype=float)
    seg = PROBE_SEGMENT_S
    idx = np.minimum((t / seg + 1e-9).astype(int), freqs.size - 1)
    u = PROBE_AMPLITUDE_MM * np.sin(2.0 * np.pi * freqs[idx] * (t - idx * seg))
    notes = (
        "stepped-frequency sine: amplitude {:g} mm, {} Hz, {:g} s each, whole periods, "
        "each step starting at 0 going up".format(
            PROBE_AMPLITUDE_MM, "/".join(f"{f:g}" for f in freqs), seg
        )
    )
    return t, u, {"kind": "free"}, notes


# run key -> (t, u, manifest excitation block, notes, role_hint)
@cache
def _runs() -> tuple[tuple[str, np.ndarray, np.ndarray, dict[str, Any], str, str], ...]:
    ident = _rl.make_excitation(
        "sine_decay",
        DT_S,
        amplitudes_mm=(6.0, 4.5, 3.0, 1.5),
        periods_per_amplitude=5,
        frequency_hz=0.25,
    )
    valid = _rl.make_excitation(
        "triangle_decay",
        DT_S,
        amplitudes_mm=(6.0, 4.5, 3.0, 1.5),
        periods_per_amplitude=8,
        slope_mm_s=6.0,
    )
    t2, u2, ex2, notes2 = _rate_probe()
    runs = (
        ("sine_decay", ident.t_s, ident.u, dict(ident.manifest), "", "identification"),
        ("free", t2, u2, ex2, notes2, "rate_probe"),
        ("triangle_decay", valid.t_s, valid.u, dict(valid.manifest), "", "validation"),
    )
    for kind, t, u, *_ in runs:
        if abs(t[-1] - DURATION_S) > 1e-9 or abs(u[0]) > 1e-12:
            raise AssertionError(f"{kind}: run must last {DURATION_S} s and start at u = 0")
        t.setflags(write=False)
        u.setflags(write=False)
    return runs


def _speed(t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Input speed du/dt: central difference, one-sided at the last sample, and 0 at the first
    sample (the plant is at rest there: the motion starts at t = 0)."""
    v = np.asarray(np.gradient(u, t), dtype=float)
    v[0] = 0.0
    return v


# ---------------------------------------------------------------------------------------------
# Plants
# ---------------------------------------------------------------------------------------------


def _stribeck_mu(v: np.ndarray) -> np.ndarray:
    """Stribeck friction coefficient mu(v) = mu_c + (mu_s - mu_c) exp(-(v/v_s)^2) + mu_v |v|."""
    p = EFFECTS["stribeck"]
    av = np.abs(np.asarray(v, dtype=float))
    excess = (p["mu_static"] - p["mu_coulomb"]) * np.exp(-((av / p["v_stribeck_mm_s"]) ** 2))
    return np.asarray(p["mu_coulomb"] + excess + p["mu_viscous_s_per_mm"] * av, dtype=float)


def _stribeck_scale(v: np.ndarray) -> np.ndarray:
    """Width scale S(v) = sinh(mu(v) theta) / sinh(mu_c theta) (capstan dead band ratio)."""
    th = _theta()
    return np.asarray(
        np.sinh(_stribeck_mu(v) * th) / math.sinh(EFFECTS["stribeck"]["mu_coulomb"] * th),
        dtype=float,
    )


def _bw_slope(x: float, A: float, n: float, kb_signed: float, kc: float) -> float:
    """dh/du = A - B sign(du) |h|^(n-1) h - C |h|^n (kb_signed = B sign(du))."""
    ax = abs(x)
    return float(A - kb_signed * ax ** (n - 1.0) * x - kc * ax**n)


def _bouc_wen(
    u: np.ndarray, scale: np.ndarray | None, h0: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Output, friction state s = h / h_s(current) and final h of the Bouc-Wen plant from h(0) = h0."""
    A, n, alpha = BOUC_WEN["A"], BOUC_WEN["n"], BOUC_WEN["alpha"]
    hs0 = BOUC_WEN["h_s_mm"]
    bf, cf = BOUC_WEN["b_frac"], BOUC_WEN["c_frac"]
    N = u.size
    hs = np.full(N, hs0) if scale is None else hs0 * np.asarray(scale, dtype=float)
    h = np.empty(N)
    hk = float(h0)
    h[0] = hk
    max_sub = 0.05
    ul = u.tolist()
    hsl = hs.tolist()
    for k in range(1, N):
        du = ul[k] - ul[k - 1]
        if du == 0.0:
            h[k] = hk
            continue
        K = A / hsl[k] ** n
        kb, kc = bf * K, cf * K
        sgn = 1.0 if du > 0 else -1.0
        m = int(abs(du) / max_sub) + 1
        d = du / m

        for _ in range(m):
            k1 = _bw_slope(hk, A, n, sgn * kb, kc)
            k2 = _bw_slope(hk + 0.5 * d * k1, A, n, sgn * kb, kc)
            k3 = _bw_slope(hk + 0.5 * d * k2, A, n, sgn * kb, kc)
            k4 = _bw_slope(hk + d * k3, A, n, sgn * kb, kc)
            hk = hk + d * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        h[k] = hk
    y = alpha * (u - h)
    s = np.clip(h / hs, -1.0, 1.0)
    return y, s, hk


def _play_sum(
    u: np.ndarray, scale: np.ndarray | None, lag0: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Output, friction state and final lags u - w_i of the weighted sum of symmetric plays,
    starting from w_i(0) = u(0) - lag0_i."""
    r0 = np.asarray(PLAY_P_MM, dtype=float) / 2.0
    q = np.asarray(PLAY_Q, dtype=float)
    N = u.size
    sc = np.ones(N) if scale is None else np.asarray(scale, dtype=float)
    w = np.empty((N, r0.size))
    wk = u[0] - np.asarray(lag0, dtype=float)
    w[0] = wk
    for k in range(1, N):
        r = r0 * sc[k]
        wk = np.maximum(u[k] - r, np.minimum(u[k] + r, wk))
        w[k] = wk
    y = w @ q
    lag = (u[:, None] - w) @ q
    s = np.clip(lag / (sc * float(q @ r0)), -1.0, 1.0)
    return y, s, u[-1] - wk


def _half_width_mm(plant: str) -> float:
    if plant == "bouc_wen":
        return BOUC_WEN["alpha"] * BOUC_WEN["h_s_mm"]
    return float(np.dot(PLAY_Q, np.asarray(PLAY_P_MM) / 2.0))


def _compliance_mm_per_n(plant: str) -> float:
    return _half_width_mm(plant) / (
        TENSION["pretension_n"] * math.sinh(TENSION["mu_coulomb"] * _theta())
    )


@cache
def _chain(plant: str, stribeck: bool) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """(y, s) of the rate-independent plant (Coulomb, or with the Stribeck widths) over the
    three runs in their order on the rig: the first starts from the pulled state, each later
    one from the hysteresis state the previous run left (all runs start and end at u = 0; at
    rest between runs the bands may widen but nothing moves)."""
    if plant == "bouc_wen":
        state: Any = BOUC_WEN["h_s_mm"]  # pulled: saturated on the pull branch
    elif plant == "play_sum":
        state = np.asarray(PLAY_P_MM, dtype=float) / 2.0  # pulled: w_i = u - r_i
    else:
        raise ValueError(f"unknown plant {plant!r}; known: {PLANTS}")
    out = []
    for _, t, u, *_ in _runs():
        scale = _stribeck_scale(_speed(t, u)) if stribeck else None
        if plant == "bouc_wen":
            y, s, state = _bouc_wen(np.asarray(u), scale, state)
        else:
            y, s, state = _play_sum(np.asarray(u), scale, state)
        y.setflags(write=False)
        s.setflags(write=False)
        out.append((y, s))
    return tuple(out)


def _base(plant: str, run_index: int, stribeck: bool) -> tuple[np.ndarray, np.ndarray]:
    return _chain(plant, stribeck)[run_index]


def _simulate(plant: str, case: str, run_index: int) -> dict[str, np.ndarray]:
    """Noise-free output, clean reference and the two tensions of one run."""
    _, t, u, *_ = _runs()[run_index]
    t = np.asarray(t)
    u = np.asarray(u)
    v = _speed(t, u)
    y_clean, s_clean = _base(plant, run_index, False)
    mu = np.full(u.size, TENSION["mu_coulomb"])
    y_ri, s = y_clean, s_clean  # rate-independent part
    if case == "clean":
        y = y_clean.copy()
    elif case == "viscous":
        y = y_clean - EFFECTS["viscous"]["c_s"] * v
    elif case == "nonlinear_damping":
        p = EFFECTS["nonlinear_damping"]
        y = y_clean - p["c"] * np.abs(v) ** p["a"] * np.sign(v)
    elif case == "relaxation":
        tau = EFFECTS["relaxation"]["tau_s"]
        a = math.exp(-DT_S / tau)
        g = tau * (1.0 - a) / DT_S
        b0, b1 = 1.0 - g, g - a  # exact for y_static linear between samples; unit DC gain
        y = lfilter([b0, b1], [1.0, -a], y_clean - y_clean[0]) + y_clean[0]
    elif case == "stribeck":
        y_ri, s = _base(plant, run_index, True)
        y = y_ri.copy()
        mu = _stribeck_mu(v)
    else:
        raise ValueError(f"unknown case {case!r}; known: {CASES}")
    lam = _compliance_mm_per_n(plant)
    t_out = TENSION["pretension_n"] + TENSION["follower_rate_n_per_mm"] * (y - y[0])
    t_in = t_out * np.exp(mu * _theta() * s) + (y_ri - y) / lam
    return {"t": t, "u": u, "y": y, "y_clean": np.asarray(y_clean), "t_in": t_in, "t_out": t_out}


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _parameters(plant: str, case: str) -> dict[str, Any]:
    if plant == "bouc_wen":
        A, n, hs = BOUC_WEN["A"], BOUC_WEN["n"], BOUC_WEN["h_s_mm"]
        K = A / hs**n
        plant_p: dict[str, Any] = {
            "model": "y = alpha*u + beta*h; dh = A du - B|du||h|^(n-1)h - C du|h|^n",
            "A": A,
            "B": BOUC_WEN["b_frac"] * K,
            "C": BOUC_WEN["c_frac"] * K,
            "n": n,
            "alpha": BOUC_WEN["alpha"],
            "beta": -BOUC_WEN["alpha"],
            "h_saturation_mm": hs,
            "initial_state": "run 1: h(0) = +h_s (pulled to u(0)); later runs: the state the previous run left",
        }
    else:
        plant_p = {
            "model": "y = sum q_i w_i, w_i = max(u - p_i/2, min(u + p_i/2, w_i_prev))",
            "plays_p_mm": list(PLAY_P_MM),
            "weights_q": list(PLAY_Q),
            "initial_state": "run 1: w_i(0) = u(0) - p_i/2 (pulled to u(0)); later runs: the state the previous run left",
        }
    plant_p["output_loop_half_width_mm"] = _half_width_mm(plant)
    out: dict[str, Any] = {
        "plant": plant_p,
        "tension": dict(TENSION)
        | {
            "wrap_angle_deg": float(CONFIGURATION["curve_angle_deg"]),
            "compliance_mm_per_n": _compliance_mm_per_n(plant),
            "model": "T_out = F0 + k_f (y - y0); T_in = T_out exp(mu theta s) + (y_rate_independent - y)/lambda",
        },
        "configuration": dict(CONFIGURATION),
        "velocity": "central difference of the commanded input on the 10 ms clock; 0 at the first sample (at rest)",
        "rate_probe": {
            "form": "stepped-frequency sine",
            "amplitude_mm": PROBE_AMPLITUDE_MM,
            "frequencies_hz": list(PROBE_FREQUENCIES_HZ),
            "segment_s": PROBE_SEGMENT_S,
        },
        "measurement": {
            "output_noise_std_mm": NOISE_STD_MM,
            "counts_per_mm": COUNTS_PER_UNIT,
            "loadcell_noise_std_n": LOADCELL_NOISE_N,
            "loadcell_rate_hz": 1000.0,
            "encoder_dt_s": DT_S,
        },
    }
    if case != "clean":
        eff: dict[str, Any] = dict(EFFECTS[case])
        eff["equation"] = {
            "viscous": "y = y_static - c_s * du/dt",
            "nonlinear_damping": "y = y_static - c * |du/dt|^a * sign(du/dt)",
            "stribeck": "loop half-width x sinh(mu(v) theta)/sinh(mu_c theta), "
            "mu(v) = mu_c + (mu_s - mu_c) exp(-(v/v_s)^2) + mu_v |v|, v = |du/dt|",
            "relaxation": "tau dy/dt = y_static - y",
        }[case]
        out["effect"] = eff
    return out


def _started_at(i: int) -> str:
    t0 = _dt.datetime(2026, 3, 2, 10, 15, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=5 * i)
    return t0.strftime("%Y-%m-%dT%H:%M:%SZ")


def write_source(dest: pathlib.Path, plant: str, case: str, *, seed: int = 0) -> dict[str, Any]:
    """Write one source folder ``dest`` (three run folders inside, no ground truth) and return
    the ground truth: ``plant``, ``case``, ``effect`` ("rate_dependence" or None), ``form`` (the
    case or None), ``parameters``, ``noise_std_mm``, ``runs`` (run_id, excitation_kind,
    role_hint), ``effect_peak_mm`` (max |y_case - y_clean| on the identification run, noise
    free), ``output_p2p_mm`` (peak-to-peak of the noise-free output on that run), plus
    ``effect_peak_by_run_mm`` and ``source`` (the folder name)."""
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; known: {PLANTS}")
    if case not in CASES:
        raise ValueError(f"unknown case {case!r}; known: {CASES}")
    dest = pathlib.Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    tag = PLANTS.index(plant) * len(CASES) + CASES.index(case)
    rng = np.random.default_rng([int(seed), 7919, tag])
    runs_truth = []
    effect_peak = output_p2p = 0.0
    peaks_by_run = {}
    for i, (kind, _t, _u, ex_block, notes, role) in enumerate(_runs()):
        sim = _simulate(plant, case, i)
        run_id = _rl.run_id_for(CONFIGURATION, kind, i + 1)
        y_meas = sim["y"] + rng.normal(0.0, NOISE_STD_MM, sim["y"].shape)
        _rl.write_run_folder(
            dest,
            run_id,
            sim["t"],
            sim["u"],
            y_meas,
            rig="tsm-bench",
            unit="mm",
            configuration=CONFIGURATION,
            excitation=ex_block,
            counts_per_unit=COUNTS_PER_UNIT,
            counter_bits=COUNTER_BITS,
            input_sign=1,
            output_sign=-1,
            counter_start_input=int(rng.integers(-(1 << 20), 1 << 20)),
            counter_start_output=int(rng.integers(-(1 << 20), 1 << 20)),
            loadcell=(sim["t_in"], sim["t_out"]),
            loadcell_noise_n=LOADCELL_NOISE_N,
            events=True,
            started_at=_started_at(tag * 3 + i),
            notes=notes,
            seed=int(rng.integers(0, 2**31 - 1)),
        )
        contrib = sim["y"] - sim["y_clean"]
        peak = float(np.max(np.abs(contrib)))
        peaks_by_run[run_id] = peak
        if role == "identification":
            effect_peak = peak
            output_p2p = float(np.ptp(sim["y"]))
        runs_truth.append({"run_id": run_id, "excitation_kind": kind, "role_hint": role})
    return {
        "plant": plant,
        "case": case,
        "effect": None if case == "clean" else "rate_dependence",
        "form": None if case == "clean" else case,
        "parameters": _parameters(plant, case),
        "noise_std_mm": NOISE_STD_MM,
        "runs": runs_truth,
        "effect_peak_mm": 0.0 if case == "clean" else effect_peak,
        "output_p2p_mm": output_p2p,
        "effect_peak_by_run_mm": peaks_by_run,
        "source": dest.name,
    }


def write_all(root: pathlib.Path, *, seed: int = 0) -> list[dict[str, Any]]:
    """Every plant x case under ``root/<plant>__<case>/``; the truth list goes to
    ``root/../rate_truth.json`` (outside the sources)."""
    root = pathlib.Path(root)
    root.mkdir(parents=True, exist_ok=True)
    truths = [write_source(root / f"{p}__{c}", p, c, seed=seed) for p in PLANTS for c in CASES]
    (root.parent / "rate_truth.json").write_text(
        json.dumps(truths, indent=2) + "\n", encoding="utf-8"
    )
    return truths
