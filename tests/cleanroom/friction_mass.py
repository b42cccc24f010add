"""Clean-room test-data generator: tendon-sheath drive with DYNAMIC (LuGre) friction at the follower.

Written from textbook mechanics and the LuGre friction model (C. Canudas de Wit, H. Olsson,
K. J. Astrom, P. Lischinsky, "A new model for control of systems with friction", IEEE TAC 40(3),
1995), for the raw run format ``tsm-rig-log/1`` (``../shared/rig-log-format.md``).  Runs are written
with the clean-room writer ``riglog.py``, imported by file path (``$CLEANROOM_RIGLOG``, else the
``riglog=`` argument / ``--riglog`` option, else ``riglog.py`` beside this file).
Only numpy and scipy are used here (riglog itself also needs pandas).

Plant (units: mm, N, s; a mass in N s^2/mm = 1000 kg)
---------------------------------------------------------
State x = (y, v, z): follower position y (mm, from its rest position), velocity v = dy/dt,
LuGre bristle deflection z (mm).  Input u(t) (proximal tendon displacement, mm, measured from its
value at t = 0) is imposed by the excitation.  The tendon is a Kelvin-Voigt spring between u and
y (stiffness k_t, small structural damping c_t), pre-tensioned to F0 by the distal constant-force
spring, which has a small residual rate k_l::

    tendon force (input load cell)   T_in  = F0 + k_t (u - y) + c_t (du/dt - v)
    load spring (output load cell)   T_out = F0 + k_l y
    LuGre friction                   g(v)  = F_C + (F_S - F_C) exp(-(v / v_S)^2)
                                     dz/dt = v - sigma0 |v| z / g(v)
                                     F_f   = sigma0 z + sigma1 dz/dt + sigma2 v
    follower                         m dv/dt = T_in - T_out - F_f

Every run starts at rest: y = v = z = 0 with u - u(0) = 0, so T_in = T_out = F0 and F_f = 0.
Quasi-statically the follower slides with k_t (u - y) = k_l y + F_ss(v) sign(v), F_ss(v) = g(v) +
sigma2 |v|, so the y-u loop has a lost motion (horizontal width) 2 F_ss / k_t = 1.0 mm in the
Coulomb limit; its corners are rounded over the bristle (pre-sliding) deflection F_C / sigma0 =
0.1 mm.  The ODE is integrated with scipy's implicit Radau method (analytic Jacobian, rtol 1e-8),
piece by piece between the excitation's kinks, and sampled at 1 ms (load cells, 1 kHz) and every
10 ms (encoders).

Shared plant parameters (``PLANT``)
    m = 1e-4 N s^2/mm (100 g follower carriage), k_t = 4 N/mm (about 1 m of 0.3 mm steel cable),
    c_t = 0.02 N s/mm (tendon-follower mode: 32 Hz, damping ratio 0.5 sliding, 0.2 sticking;
    time constant c_t/k_t = 5 ms), F0 = 5 N, k_l = 0.05 N/mm, F_C = 2 N, sigma0 = 20 N/mm (a soft,
    lumped "bristle": the sheath's distributed pre-sliding), sigma1 = 0.01 N s/mm.

    sigma0 is deliberately soft.  With the LuGre paper's stiff bristles (sigma0 ~ 100 N/mm) and a
    velocity-weakening Stribeck curve whose v_S is comparable to the run speeds, the compliant
    tendon drive is unstable in steady sliding and the follower stick-slips at the low speeds of
    these runs (velocity spikes of 10-15 mm/s against 1-5 mm/s commanded).  The soft bristle
    gives the friction state a memory length F_C / sigma0 = 0.1 mm long enough that steady
    sliding stays stable for every case below (checked: the follower never outruns the input;
    with F_S = 2.5 N stick-slip starts near sigma0 = 30 N/mm, so the margin is about 1.5x), and
    rounds the loop corners like the gradual slip of a real sheath.  The price: during a
    reversal the follower already creeps back at up to k_t / (k_t + sigma0) = 1/6 of the input
    speed (pre-sliding), so the loop's transitions slope instead of being flat.

    The clean plant is rate-independent to well below the noise: one 3 mm sine period at 0.25 Hz
    and at 0.025 Hz differ by 3.5 um peak, 1.0 um RMS (inertia, c_t and sigma1 together);
    integration error (rtol 1e-8 vs 1e-10) is below 1e-4 um.

Cases (``CASES``; each case is one SOURCE of 3 runs)
    clean            F_S = F_C = 2 N, sigma2 = 0            (Coulomb limit: the reference plant)
    stribeck_weak    F_S = 2.12 N (6 % static excess), v_S = 1.5 mm/s, sigma2 = 0.002 N s/mm
    stribeck_strong  F_S = 2.50 N (25 %),              v_S = 1.5 mm/s, sigma2 = 0.004 N s/mm
    viscous_strong   F_S = F_C = 2 N, sigma2 = 0.08 N s/mm (0.38 N extra at 4.7 mm/s)

Runs (80 s, 10 ms encoder loop, 1 kHz load cells; riglog's ``make_excitation``)
    1. ``sine_decay``      amplitudes 3, 2.25, 1.5, 0.75 mm, 0.25 Hz, 5 periods each (<= 4.7 mm/s)
    2. ``triangle_decay``  amplitudes 5, 4, 3, 2 mm, 3.5 mm/s, 5 periods each (80 s exactly)
    3. ``mixed_sine``      0.0125, 0.0375, 0.0875, 0.1875, 0.41 Hz; 1.92, 1.2, 0.96, 0.6, 0.36 mm,
                           phases +-pi/2 chosen so that u(0) = 0 and du/dt(0) = 0 (+-3.3 mm,
                           <= 2.1 mm/s)

Measurement (as on the rig): output encoder = y + N(0, 2 um), quantised to 1 um
(``counts_per_unit`` = 1000, ``output_sign`` = -1); input encoder = u quantised to 1 um; load
cells T_in, T_out + N(0, 0.02 N) (riglog's noise) at 1 kHz, riglog's default calibration
(range 20 N; the tensions stay within about 2.3-8 N).  The manifest has the standard
configuration phi 90 deg / r 30 mm for every case and says nothing about the case.

Ground truth (``write_all``: ``<root>/ground_truth.json``, outside the source folders)
    per case: the plant and friction parameters, the noise model, and per run the loop width and
    the EFFECT = noise-free y(case) - noise-free y(clean) on the same input, as RMS and peak (mm)
    and as multiples of the output noise standard deviation sqrt(2^2 + 1/12) um = 2.02 um.

Effect sizes (noise-free, all 3 runs; output noise std 2.02 um)
    case             RMS      peak     RMS/noise  peak/noise  loop width (3 mm sine / 5 mm triangle)
    clean            0        0        0          0           1.00 / 1.00 mm
    stribeck_weak    14 um    28 um    7          14          1.00 / 1.00 mm (triangle: only 2 um RMS,
                                                              its 3.5 mm/s is far above v_S)
    stribeck_strong  56 um    114 um   28         56          1.01 / 1.01 mm (effect largest at low speed)
    viscous_strong   43 um    92 um    21         45          1.18 / 1.14 mm

Use::

    python friction_mass.py OUT_DIR [--seed N] [--riglog PATH] [--no-check]
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.integrate import solve_ivp

DEFAULT_RIGLOG = str(Path(__file__).resolve().parent / "riglog.py")

# ------------------------------------------------------------------------------------------------
# parameters
# ------------------------------------------------------------------------------------------------

PLANT: dict[str, float] = {
    "m_n_s2_per_mm": 1e-4,  # 0.1 kg
    "k_t_n_per_mm": 4.0,
    "c_t_n_s_per_mm": 0.02,
    "F0_n": 5.0,
    "k_l_n_per_mm": 0.05,
    "F_C_n": 2.0,
    "sigma0_n_per_mm": 20.0,
    "sigma1_n_s_per_mm": 0.01,
}

CASES: dict[str, dict[str, Any]] = {
    "clean": {"F_S_n": 2.0, "v_S_mm_s": None, "sigma2_n_s_per_mm": 0.0,
              "description": "Coulomb limit F_S = F_C, sigma2 = 0: rate-independent friction (reference plant)"},
    "stribeck_weak": {"F_S_n": 2.12, "v_S_mm_s": 1.5, "sigma2_n_s_per_mm": 0.002,
                      "description": "weak Stribeck: 6 % static excess, v_S comparable to run speeds, small sigma2"},
    "stribeck_strong": {"F_S_n": 2.5, "v_S_mm_s": 1.5, "sigma2_n_s_per_mm": 0.004,
                        "description": "strong Stribeck: 25 % static excess, v_S comparable to run speeds, small sigma2"},
    "viscous_strong": {"F_S_n": 2.0, "v_S_mm_s": None, "sigma2_n_s_per_mm": 0.08,
                       "description": "Coulomb F_S = F_C plus a clear viscous term sigma2"},
}

NOISE: dict[str, float] = {
    "output_encoder_gauss_mm": 0.002,
    "encoder_quantum_mm": 0.001,  # both encoders, counts_per_unit = 1000
    "loadcell_gauss_n": 0.02,
}
OUTPUT_NOISE_STD_MM = math.sqrt(NOISE["output_encoder_gauss_mm"] ** 2 + NOISE["encoder_quantum_mm"] ** 2 / 12.0)

CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
DURATION_S = 80.0
DT_ENC = 0.01
DT_LC = 0.001

MULTISINE_TERMS = [
    {"amplitude": 1.92, "frequency_hz": 0.0125, "phase_rad": math.pi / 2},
    {"amplitude": 1.20, "frequency_hz": 0.0375, "phase_rad": -math.pi / 2},
    {"amplitude": 0.96, "frequency_hz": 0.0875, "phase_rad": -math.pi / 2},
    {"amplitude": 0.60, "frequency_hz": 0.1875, "phase_rad": math.pi / 2},
    {"amplitude": 0.36, "frequency_hz": 0.41, "phase_rad": -math.pi / 2},
]

EXCITATIONS: list[dict[str, Any]] = [
    {"kind": "sine_decay", "amplitudes_mm": [3.0, 2.25, 1.5, 0.75], "periods_per_amplitude": 5, "frequency_hz": 0.25},
    {"kind": "triangle_decay", "amplitudes_mm": [5.0, 4.0, 3.0, 2.0], "periods_per_amplitude": 5, "slope_mm_s": 3.5},
    {"kind": "mixed_sine", "terms": MULTISINE_TERMS, "duration_s": DURATION_S},
]


# ------------------------------------------------------------------------------------------------
# riglog
# ------------------------------------------------------------------------------------------------

_RIGLOG_CACHE: dict[str, Any] = {}


def load_riglog(path: str | os.PathLike[str] | None = None) -> Any:
    """Import riglog.py by file path: ``$CLEANROOM_RIGLOG``, else ``path``, else the default."""
    p = os.environ.get("CLEANROOM_RIGLOG") or (str(path) if path else None) or DEFAULT_RIGLOG
    p = str(Path(p).resolve())
    if p in _RIGLOG_CACHE:
        return _RIGLOG_CACHE[p]
    name = "cleanroom_riglog_cr58"
    spec = importlib.util.spec_from_file_location(name, p)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import riglog from {p}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses need the module registered while it executes
    saved = sys.dont_write_bytecode
    sys.dont_write_bytecode = True  # leave no __pycache__ beside riglog.py
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.dont_write_bytecode = saved
    _RIGLOG_CACHE[p] = mod
    return mod


# ------------------------------------------------------------------------------------------------
# excitations as continuous functions (same definitions as riglog.make_excitation)
# ------------------------------------------------------------------------------------------------

Piece = tuple[float, float, Callable[[float], tuple[float, float]]]


def excitation_pieces(man: dict[str, Any]) -> list[Piece]:
    """The excitation described by a manifest block as smooth pieces ``(t0, t1, f)`` with
    ``f(t) -> (u, du/dt)``; the kinks (amplitude switches, triangle corners) are piece ends."""
    kind = man["kind"]
    if kind == "sine_decay":
        f = float(man["frequency_hz"])
        w = 2.0 * math.pi * f
        seg = int(man["periods_per_amplitude"]) / f
        out: list[Piece] = []
        for i, a in enumerate(man["amplitudes_mm"]):
            a = float(a)
            out.append((i * seg, (i + 1) * seg, lambda t, a=a: (a * math.sin(w * t), a * w * math.cos(w * t))))
        return out
    if kind == "triangle_decay":
        slope = float(man["slope_mm_s"])
        bt, bu = [0.0], [0.0]
        for a in man["amplitudes_mm"]:
            a = float(a)
            for _ in range(int(man["periods_per_amplitude"])):
                for du in (a, -2.0 * a, a):
                    bt.append(bt[-1] + abs(du) / slope)
                    bu.append(bu[-1] + du)
        out = []
        for k in range(len(bt) - 1):
            t0, t1, u0 = bt[k], bt[k + 1], bu[k]
            s = (bu[k + 1] - bu[k]) / (t1 - t0)
            out.append((t0, t1, lambda t, t0=t0, u0=u0, s=s: (u0 + s * (t - t0), s)))
        return out
    if kind == "mixed_sine":
        a = np.array([float(x["amplitude"]) for x in man["terms"]])
        w = 2.0 * np.pi * np.array([float(x["frequency_hz"]) for x in man["terms"]])
        ph = np.array([float(x.get("phase_rad", 0.0)) for x in man["terms"]])

        def fm(t: float) -> tuple[float, float]:
            arg = w * t + ph
            return float(a @ np.sin(arg)), float((a * w) @ np.cos(arg))

        return [(0.0, DURATION_S, fm)]
    raise ValueError(f"unsupported excitation kind {kind!r}")


def make_run_excitation(rl: Any, spec: dict[str, Any]) -> Any:
    """riglog excitation (sampled t, u and the manifest block) for one entry of EXCITATIONS."""
    kw = {k: v for k, v in spec.items() if k != "kind"}
    return rl.make_excitation(spec["kind"], DT_ENC, **kw)


# ------------------------------------------------------------------------------------------------
# simulation
# ------------------------------------------------------------------------------------------------


def friction_params(case: str) -> dict[str, Any]:
    c = CASES[case]
    return {"F_C_n": PLANT["F_C_n"], "F_S_n": c["F_S_n"], "v_S_mm_s": c["v_S_mm_s"],
            "sigma0_n_per_mm": PLANT["sigma0_n_per_mm"], "sigma1_n_s_per_mm": PLANT["sigma1_n_s_per_mm"],
            "sigma2_n_s_per_mm": c["sigma2_n_s_per_mm"]}


def simulate(case: str, pieces: list[Piece], t_eval: np.ndarray, *, rtol: float = 1e-8) -> dict[str, np.ndarray]:
    """Integrate the plant of ``case`` from rest along the excitation ``pieces``; return
    ``t, u, du, y, v, z, T_in, T_out, F_f`` at ``t_eval`` (u measured from u(0))."""
    m = PLANT["m_n_s2_per_mm"]
    kt, ct, F0, kl = PLANT["k_t_n_per_mm"], PLANT["c_t_n_s_per_mm"], PLANT["F0_n"], PLANT["k_l_n_per_mm"]
    s0, s1 = PLANT["sigma0_n_per_mm"], PLANT["sigma1_n_s_per_mm"]
    FC = PLANT["F_C_n"]
    c = CASES[case]
    dF = float(c["F_S_n"]) - FC
    vs = float(c["v_S_mm_s"]) if c["v_S_mm_s"] else 1.0
    s2 = float(c["sigma2_n_s_per_mm"])
    u_start = pieces[0][2](pieces[0][0])[0]

    def g_and_slope(v: float) -> tuple[float, float]:
        if dF == 0.0:
            return FC, 0.0
        e = math.exp(-(v / vs) ** 2)
        return FC + dF * e, dF * e * (-2.0 * v / vs**2)

    def rhs(t: float, x: np.ndarray, fu: Callable[[float], tuple[float, float]]) -> list[float]:
        y, v, z = x
        u, du = fu(t)
        g, _ = g_and_slope(v)
        zd = v - s0 * abs(v) * z / g
        ff = s0 * z + s1 * zd + s2 * v
        t_in = kt * (u - u_start - y) + ct * (du - v)  # minus F0
        return [v, (t_in - kl * y - ff) / m, zd]

    def jac(t: float, x: np.ndarray, fu: Callable[[float], tuple[float, float]]) -> np.ndarray:
        y, v, z = x
        g, gp = g_and_slope(v)
        dzdv = 1.0 - s0 * z * (math.copysign(1.0, v) * g - abs(v) * gp) / g**2 if v != 0.0 else 1.0
        dzdz = -s0 * abs(v) / g
        return np.array([
            [0.0, 1.0, 0.0],
            [-(kt + kl) / m, -(ct + s1 * dzdv + s2) / m, -(s0 + s1 * dzdz) / m],
            [0.0, dzdv, dzdz],
        ])

    x = np.zeros(3)
    ys: list[np.ndarray] = []
    ts: list[np.ndarray] = []
    us: list[np.ndarray] = []
    tol = 1e-9
    for i, (t0, t1, fu) in enumerate(pieces):
        last = i == len(pieces) - 1
        sel = t_eval > t0 + tol
        if not last:
            sel &= t_eval <= t1 + tol
        if i == 0:
            sel |= np.abs(t_eval - t0) <= tol
        te = np.clip(t_eval[sel], t0, t1)
        tq = te if (te.size and te[-1] == t1) else np.append(te, t1)  # always end the piece at t1
        sol = solve_ivp(rhs, (t0, t1), x, method="Radau", t_eval=tq, args=(fu,), jac=jac,
                        rtol=rtol, atol=[1e-8, 1e-6, 1e-9], max_step=0.05)
        if not sol.success:
            raise RuntimeError(f"{case}: integration failed on [{t0}, {t1}]: {sol.message}")
        x = sol.y[:, -1].copy()
        ys.append(sol.y[:, : te.size])
        ts.append(te)
        us.append(np.array([fu(tk) for tk in te]).reshape(-1, 2))
    t = np.concatenate(ts)
    yy = np.concatenate(ys, axis=1)
    uu, du = np.concatenate(us).T
    uu = uu.copy()
    uu -= u_start
    y, v, z = yy
    g = FC + (dF * np.exp(-(v / vs) ** 2) if dF else 0.0)
    zd = v - s0 * np.abs(v) * z / g
    ff = s0 * z + s1 * zd + s2 * v
    t_in = F0 + kt * (uu - y) + ct * (du - v)
    t_out = F0 + kl * y
    return {"t": t, "u": uu, "du": du, "y": y, "v": v, "z": z, "T_in": t_in, "T_out": t_out, "F_f": ff}


def loop_width(t: np.ndarray, u: np.ndarray, y: np.ndarray, t0: float, t1: float) -> float:
    """Lost motion: horizontal width u_up - u_down of the y-u loop at mid-height of y over the
    window [t0, t1] (one or more whole periods), averaged over the crossings."""
    w = (t >= t0) & (t <= t1)
    tt, uu, yy = t[w], u[w], y[w]
    mid = 0.5 * (yy.max() + yy.min())
    s = yy - mid
    up, down = [], []
    for k in np.nonzero(np.sign(s[:-1]) != np.sign(s[1:]))[0]:
        if s[k] == s[k + 1]:
            continue
        a = s[k] / (s[k] - s[k + 1])
        uc = uu[k] + a * (uu[k + 1] - uu[k])
        (up if s[k + 1] > s[k] else down).append(uc)
    if not up or not down:
        return float("nan")
    return float(np.mean(up) - np.mean(down))


def sliding_width(u: np.ndarray, y: np.ndarray, v: np.ndarray, v_min: float = 0.3) -> float:
    """Lost motion from the sliding parts of any run: median tendon stretch u - y while the
    follower slides up (v > v_min mm/s) minus the median while it slides down."""
    up, down = v > v_min, v < -v_min
    if not up.any() or not down.any():
        return float("nan")
    return float(np.median((u - y)[up]) - np.median((u - y)[down]))


def _width_window(man: dict[str, Any]) -> tuple[float, float] | None:
    """Last whole period of the first (largest) amplitude of a decaying excitation."""
    if man["kind"] == "sine_decay":
        p = 1.0 / float(man["frequency_hz"])
        return (int(man["periods_per_amplitude"]) - 1) * p, int(man["periods_per_amplitude"]) * p
    if man["kind"] == "triangle_decay":
        p = 4.0 * float(man["amplitudes_mm"][0]) / float(man["slope_mm_s"])
        return (int(man["periods_per_amplitude"]) - 1) * p, int(man["periods_per_amplitude"]) * p
    return None  # no single loop (multisine)


# ------------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------------

_CLEAN_CACHE: dict[tuple[str, str], dict[str, np.ndarray]] = {}


def _sim_run(case: str, man: dict[str, Any], n_lc: int) -> dict[str, np.ndarray]:
    key = (case, json.dumps(man, sort_keys=True))
    if key in _CLEAN_CACHE:
        return _CLEAN_CACHE[key]
    t_lc = np.arange(n_lc) * DT_LC
    res = simulate(case, excitation_pieces(man), t_lc)
    if case == "clean":
        _CLEAN_CACHE[key] = res
    return res


def write_source(root: str | os.PathLike[str], case: str, seed: int = 0, *, riglog: str | None = None) -> dict[str, Any]:
    """Write the source ``<root>/<case>/`` (3 run folders) and return its ground-truth entry."""
    if case not in CASES:
        raise ValueError(f"unknown case {case!r}; known: {list(CASES)}")
    rl = load_riglog(riglog)
    src = Path(root) / case
    src.mkdir(parents=True, exist_ok=True)
    case_idx = list(CASES).index(case)
    runs = []
    for j, spec in enumerate(EXCITATIONS):
        ex = make_run_excitation(rl, spec)
        man = dict(ex.manifest)
        n_lc = int(round((ex.t_s[-1] - ex.t_s[0]) / DT_LC)) + 1
        res = _sim_run(case, man, n_lc)
        ref = _sim_run("clean", man, n_lc)
        step = int(round(DT_ENC / DT_LC))
        enc = slice(0, None, step)
        t_enc = res["t"][enc]
        if t_enc.shape != ex.t_s.shape or np.max(np.abs(t_enc - ex.t_s)) > 1e-9:
            raise RuntimeError("simulation clock does not match the excitation clock")
        u_dev = float(np.max(np.abs(res["u"][enc] - (ex.u - ex.u[0]))))
        if u_dev > 1e-9:
            raise RuntimeError(f"continuous excitation differs from riglog's by {u_dev} mm")
        rng = np.random.default_rng([int(seed), case_idx, j])
        y_free = res["y"][enc]
        y_meas = y_free + rng.normal(0.0, NOISE["output_encoder_gauss_mm"], y_free.shape)
        rid = rl.run_id_for(CONFIGURATION, man["kind"], j + 1)
        rl.write_run_folder(
            src, rid, ex.t_s, ex.u, y_meas,
            rig="tsm-bench", unit="mm", configuration=CONFIGURATION, excitation=man,
            counts_per_unit=round(1.0 / NOISE["encoder_quantum_mm"]), counter_bits=32, input_sign=1, output_sign=-1,
            loadcell=(res["T_in"], res["T_out"]), loadcell_noise_n=NOISE["loadcell_gauss_n"],
            events=True, started_at=f"2026-03-02T{10 + case_idx:02d}:{15 + 5 * j:02d}:00Z",
            seed=int(seed) * 1000 + case_idx * 10 + j,
        )
        eff = res["y"][enc] - ref["y"][enc]
        rms = float(np.sqrt(np.mean(eff**2)))
        peak = float(np.max(np.abs(eff)))
        win = _width_window(man)
        runs.append({
            "run_id": rid,
            "excitation": man,
            "max_input_speed_mm_s": float(np.max(np.abs(res["du"]))),
            "loop_width_mm": loop_width(res["t"], res["u"], res["y"], *win) if win else None,
            "loop_width_window_s": list(win) if win else None,
            "clean_loop_width_mm": loop_width(ref["t"], ref["u"], ref["y"], *win) if win else None,
            "sliding_width_mm": sliding_width(res["u"], res["y"], res["v"]),
            "clean_sliding_width_mm": sliding_width(ref["u"], ref["y"], ref["v"]),
            "output_range_mm": [float(res["y"].min()), float(res["y"].max())],
            "tension_in_range_n": [float(res["T_in"].min()), float(res["T_in"].max())],
            "tension_out_range_n": [float(res["T_out"].min()), float(res["T_out"].max())],
            "max_follower_speed_over_max_input_speed": float(np.max(np.abs(res["v"])) / np.max(np.abs(res["du"]))),
            "output_offset_mm": float(y_meas[0] - y_free[0]),
            "effect_rms_mm": rms,
            "effect_peak_mm": peak,
            "effect_rms_over_noise": rms / OUTPUT_NOISE_STD_MM,
            "effect_peak_over_noise": peak / OUTPUT_NOISE_STD_MM,
        })
    all_rms = float(np.sqrt(np.mean([r["effect_rms_mm"] ** 2 for r in runs])))
    all_peak = float(max(r["effect_peak_mm"] for r in runs))
    return {
        "case": case,
        "source_dir": case,
        "description": CASES[case]["description"],
        "model": "LuGre friction at the follower, Kelvin-Voigt tendon, mass, constant-force load spring",
        "plant": dict(PLANT),
        "friction": friction_params(case),
        "quasi_static_lost_motion_mm": 2.0 * PLANT["F_C_n"] / PLANT["k_t_n_per_mm"],
        "noise": dict(NOISE) | {"output_noise_std_mm": OUTPUT_NOISE_STD_MM},
        "notes": ("clean plant residual rate dependence (3 mm sine, 0.25 vs 0.025 Hz): 3.5 um peak, 1.0 um RMS; "
                  "loop_width_mm: horizontal width at mid-height over loop_width_window_s; sliding_width_mm: "
                  "median (u - y) sliding up minus sliding down (|v| > 0.3 mm/s); output_offset_mm: the output noise "
                  "at the first sample, so decoded y (relative to the first sample) = y_true - output_offset_mm + noise"),
        "effect_definition": "noise-free y(case) - noise-free y(clean) on the same input, 10 ms samples",
        "effect_rms_mm": all_rms,
        "effect_peak_mm": all_peak,
        "effect_rms_over_noise": all_rms / OUTPUT_NOISE_STD_MM,
        "effect_peak_over_noise": all_peak / OUTPUT_NOISE_STD_MM,
        "seed": int(seed),
        "runs": runs,
    }


def write_all(root: str | os.PathLike[str], seed: int = 0, *, riglog: str | None = None) -> dict[str, Any]:
    """Write every case to ``<root>/<case>/`` and ``<root>/ground_truth.json``; return the truth."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    truth = {
        "generator": "friction_mass.py (clean-room, LuGre dynamic friction)",
        "format": "tsm-rig-log/1",
        "seed": int(seed),
        "cases": {case: write_source(root, case, seed, riglog=riglog) for case in CASES},
    }
    (root / "ground_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


# ------------------------------------------------------------------------------------------------
# independent check of written run folders against the spec (riglog offers no validator)
# ------------------------------------------------------------------------------------------------


def _read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    text = path.read_text(encoding="utf-8")
    if not text.endswith("\n"):
        raise ValueError(f"{path}: truncated last line")
    lines = text.splitlines()
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    if any(len(r) != len(header) for r in rows):
        raise ValueError(f"{path}: ragged row")
    return header, np.array([[float(c) for c in r] for r in rows])


def check_run_folder(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """Spec checks of one run folder; returns the decoded positions and tensions."""
    folder = Path(folder)
    man = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    for k in ("format", "run_id", "rig", "started_at", "configuration", "excitation", "channels", "notes"):
        if k not in man:
            raise ValueError(f"{folder}: manifest lacks {k}")
    if man["format"] != "tsm-rig-log/1" or man["run_id"] != folder.name or man["rig"] != "tsm-bench":
        raise ValueError(f"{folder}: bad format/run_id/rig")
    enc_cfg = man["channels"]["encoder"]
    h, a = _read_csv(folder / "encoder.csv")
    if h != ["t_ns", "input_counts", "output_counts"]:
        raise ValueError(f"{folder}: encoder header {h}")
    t_ns = a[:, 0].astype(np.int64)
    dt = np.diff(t_ns)
    if np.any(dt <= 0) or np.any(dt > 10 * np.median(dt)):
        raise ValueError(f"{folder}: encoder timestamps not increasing or gapped")
    if not np.all(a[:, 1:] == np.round(a[:, 1:])):
        raise ValueError(f"{folder}: non-integer counts")
    bits = int(enc_cfg["counter_bits"])
    half, full = 1 << (bits - 1), 1 << bits

    def unwrap(c: np.ndarray) -> np.ndarray:
        d = (np.diff(c.astype(np.int64)) + half) % full - half
        return np.concatenate([[0], np.cumsum(d)])

    cpu = float(enc_cfg["counts_per_unit"])
    u = enc_cfg["input_sign"] * unwrap(a[:, 1]) / cpu
    y = enc_cfg["output_sign"] * unwrap(a[:, 2]) / cpu
    out: dict[str, Any] = {"t_s": t_ns / 1e9, "u": u, "y": y, "manifest": man}
    if (folder / "loadcell.csv").exists():
        h, b = _read_csv(folder / "loadcell.csv")
        if h != ["t_ns", "input_mv_per_v", "output_mv_per_v"]:
            raise ValueError(f"{folder}: loadcell header {h}")
        if np.any(np.diff(b[:, 0]) <= 0):
            raise ValueError(f"{folder}: loadcell timestamps not increasing")
        cal = man["channels"]["loadcell"]
        f_in = (b[:, 1] - cal["input"]["zero_mv_per_v"]) * cal["input"]["newton_per_mv_per_v"]
        f_out = (b[:, 2] - cal["output"]["zero_mv_per_v"]) * cal["output"]["newton_per_mv_per_v"]
        if np.any(np.abs(f_in) >= cal["input"]["range_n"]) or np.any(np.abs(f_out) >= cal["output"]["range_n"]):
            raise ValueError(f"{folder}: load cell saturated")
        out.update(t_lc_s=b[:, 0] / 1e9, T_in=f_in, T_out=f_out)
    if (folder / "events.csv").exists():
        ev = (folder / "events.csv").read_text(encoding="utf-8").splitlines()
        if ev[0] != "t_ns,event,detail" or any(",estop," in e for e in ev):
            raise ValueError(f"{folder}: bad events")
    return out


def check_all(root: str | os.PathLike[str]) -> dict[str, Any]:
    """Check every run folder under ``root`` against the spec and the ground truth."""
    root = Path(root)
    truth = json.loads((root / "ground_truth.json").read_text(encoding="utf-8"))
    report = {}
    for case, entry in truth["cases"].items():
        rows = []
        for run in entry["runs"]:
            d = check_run_folder(root / entry["source_dir"] / run["run_id"])
            n = d["t_s"].size
            if abs(d["t_s"][-1] - DURATION_S) > 1e-9 or n != int(DURATION_S / DT_ENC) + 1:
                raise ValueError(f"{run['run_id']}: wrong length")
            win = run["loop_width_window_s"]
            rows.append({"run_id": run["run_id"], "rows": n, "loadcell_rows": int(d["T_in"].size),
                         "measured_loop_width_mm": loop_width(d["t_s"], d["u"], d["y"], *win) if win else float("nan"),
                         "T_in_range": [float(d["T_in"].min()), float(d["T_in"].max())]})
        report[case] = rows
    return report


# ------------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--riglog", default=None, help="path of riglog.py (CLEANROOM_RIGLOG wins)")
    ap.add_argument("--no-check", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    truth = write_all(args.out_dir, args.seed, riglog=args.riglog)
    t_write = time.perf_counter() - t0
    print(f"wrote {len(truth['cases'])} sources to {args.out_dir} in {t_write:.1f} s "
          f"(output noise std {OUTPUT_NOISE_STD_MM * 1e3:.2f} um)")
    print(f"{'case':16s} {'run':34s} {'width':>7s} {'clean w':>7s} {'slide w':>7s} {'eff rms':>8s} {'eff pk':>8s} "
          f"{'rms/n':>6s} {'pk/n':>6s} {'v/u max':>7s}")

    def f3(x: float | None) -> str:
        return f"{x:7.3f}" if x is not None else f"{'-':>7s}"

    for case, e in truth["cases"].items():
        for r in e["runs"]:
            print(f"{case:16s} {r['run_id']:34s} {f3(r['loop_width_mm'])} {f3(r['clean_loop_width_mm'])} "
                  f"{f3(r['sliding_width_mm'])} "
                  f"{r['effect_rms_mm'] * 1e3:6.1f}um {r['effect_peak_mm'] * 1e3:6.1f}um "
                  f"{r['effect_rms_over_noise']:6.1f} {r['effect_peak_over_noise']:6.1f} "
                  f"{r['max_follower_speed_over_max_input_speed']:7.2f}")
        print(f"{case:16s} {'(all runs)':34s} {'':7s} {'':7s} {'':7s} {e['effect_rms_mm'] * 1e3:6.1f}um "
              f"{e['effect_peak_mm'] * 1e3:6.1f}um {e['effect_rms_over_noise']:6.1f} {e['effect_peak_over_noise']:6.1f}")
    if not args.no_check:
        rep = check_all(args.out_dir)
        for case, rows in rep.items():
            for r in rows:
                print(f"check ok {case:16s} {r['run_id']:34s} rows {r['rows']}/{r['loadcell_rows']} measured width "
                      f"{r['measured_loop_width_mm']:.3f} mm  T_in {r['T_in_range'][0]:.2f}..{r['T_in_range'][1]:.2f} N")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
