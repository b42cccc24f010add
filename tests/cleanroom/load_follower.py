"""Clean-room generator: a tendon-sheath mechanism whose distal load depends on the follower's
position, so the tension along the sheath, the friction and the width of the input-output
hysteresis loop change along the stroke in a different way for each follower.

Written from the rig-log specification (``../shared/rig-log-format.md``), the seeds' README and
papers (``../shared/seeds/``: the thesis' rig, section 3.1, and its three excitations), ``riglog.py``
(imported by file path: ``CLEANROOM_RIGLOG`` names it, a file or the folder holding it; else the
copy beside this module) and textbook physics (capstan / Euler-Eytelwein Coulomb friction,
springs); by a session that had not read the project's implementation, tests or docs.

What it makes
-------------
``python tests/cleanroom/load_follower.py OUT_DIR [--seed S] [--check]`` writes eleven
``tsm-rig-log/1`` sources ``OUT_DIR/lf-<hex>/`` (opaque names) and the ground truth
``OUT_DIR/load_follower_truth.json``.  Every source holds three runs of 80 s of one configuration
(``phiAAA_r045_<kind>_000k``, rig ``tsm-bench``): a decaying sine (identification: 6, 4.5, 3,
1.5 mm, 5 periods each at 0.25 Hz) and, held out, a decaying triangle (same amplitudes, 8 periods
each at 6 mm/s) and a decaying trapezoid (5 periods each at 5 mm/s, 0.5 s dwell at each
extreme).  Encoders at 100 Hz (10000 counts/mm, output sign -1 as in the spec's example), load
cells at 1 kHz (spec calibration, 20 N range).  ``--check`` re-reads the written logs and prints
the loop widths measured on them.

* 6 clean sources: followers {linear return spring, constant force, stiffening spring} x sheath
  wrap {90, 270 deg}; each follower has one source started at rest and one started loaded.
* 5 sources with one hidden effect each, all on the linear-return-spring follower (the follower
  whose loop widens along the stroke): a 0.15 s latency of the output reading, an exponential
  creep of the output (0.3 mm, tau 10 s), a backlash (0.4 mm total dead zone) in the input
  coupling, a hard stop on the follower at 90 % of the stroke, a viscous term on the output
  reading (0.2 mm at the sine's peak speed).

The plant (quasi-static, rate independent, integrated at 1 kHz)
----------------------------------------------------------------
The tendon runs through a sheath of total wrap angle Theta, cut into N = 30 elements of wrap
dtheta = Theta / N.  Each element is represented by a contact node i = 1..N with rigid-stick
Coulomb (stick/slip) friction; between the nodes the tendon is a chain of N + 1 series springs:

    node 0 = the tendon's proximal end,   s_0 = u_c + c          (u_c: input after the coupling)
    node N+1 = the follower,              s_{N+1} = x            (output, mm)
    segment k = 0..N between nodes k and k+1:  T_k = (s_k - s_{k+1}) / C_k   (tension, N)
    C_0 = C_p + C_e / 2,  C_1..C_{N-1} = C_e,  C_N = C_e / 2 + C_d,   C_e = C_s / N

with C_p = 0.10 mm/N (proximal free tendon, coupling, load cell), C_s = 0.40 mm/N (the tendon
inside the sheath, total) and C_d = 0.05 mm/N (distal free tendon).  The constant offset
c = L(0) (C_p + C_s + C_d) puts the frictionless equilibrium at u = 0 at x = 0.

Friction on node i (force f_i = T_{i-1} - T_i resisting the tendon's pull) is bounded by the local
tension times the local wrap angle times mu (the discrete capstan law, mu = 0.15):

    |T_{i-1} - T_i| <= mu dtheta (T_{i-1} + T_i) / 2

A node sticks while the bound holds and slides when it is reached; while a stretch of tendon
slides in the pull direction the tension falls geometrically, T_i = r T_{i-1},
r = (1 - mu dtheta / 2) / (1 + mu dtheta / 2) (r^N ~ e^{-mu Theta}: Euler-Eytelwein), and while
it slides back it rises, T_i = T_{i-1} / r.  The follower is massless and frictionless: the last
segment's tension is the follower's load, T_N = L(x).

Step (exact for any monotone increment of the input, so path independent within a step): when
s_0 moves in direction dir, a front of sliding nodes 1..m enters from the proximal end and the
rest stays stuck with its old tensions.  For m < N, node m+1 stays stuck with
T_0 = (s_0 - s_{m+1}) / A_m,  A_m = sum_{k<=m} C_k rho^k  (rho = r pulling, 1/r releasing) and the
new T_m = T_0 rho^m must satisfy the stick bound against the old T_{m+1}:
dir (T_m - T_{m+1} / rho) <= 0.  The smallest such m is taken; when there is none (m = N) the whole
tendon slides and the follower moves to the root of

    s_0 - x = L(x) A_N / rho^N       (Newton, from the old x; monotone convergence, L convex)

The sliding nodes take s_k = s_0 - T_0 A_{k-1}.  While the input reverses, the tension profile
turns over from the proximal end and the follower stands still until the front reaches it: the
loop's width (input travel to reverse the output) is

    w(x) ~ L(x) [ C_p 2 sinh(mu Theta) + C_s 2 (cosh(mu Theta) - 1) / (mu Theta) ]

i.e. about 0.142 L mm/N at 90 deg and 0.447 L mm/N at 270 deg (the distal spring C_d adds nothing:
its tension does not change while the follower stands).  It is proportional to the follower's
load at the point of reversal: it grows along the stroke for the springs and is the same at both
ends for the constant-force follower.  The output's slope on a sliding branch is
1 / (1 + L'(x) C_eff), C_eff = C_p e^{+-mu Theta} + C_s (e^{+-mu Theta} - 1) / (+-mu Theta) + C_d.

Followers (x in mm, d = x - x_lo, x_lo = -7 mm, the spring's free end):

    linear return spring   L = 1.0 + 0.40 d                       (1.8 N at x = -5, 5.8 N at x = +5)
    constant force         L = 4.0                                (constant-force spring, as on the thesis'
                                                                   follower module; or a hanging weight)
    stiffening spring      L = 1.5 + 0.15 d + 0.0015 d^3          (1.8 N at x = -5, 5.9 N at x = +5)
    hard stop (effect)     L += 200 N/mm * max(0, x - x_stop)

Load cells: input tension = T_0 (proximal, behind the coupling), output tension = T_N = L(x)
(distal, the follower's load, including the stop's reaction); all stay below the 20 N range.

Starts: ``rest`` - the tendon was tensioned by the follower without motion: uniform tension
L(x0) along the sheath, no friction stress, x0 = 0 (the first pull first takes up half the loop);
``loaded`` - the rig cycled two periods of a 6 mm, 0.25 Hz sine before the log began (the log
starts on the pull branch, tension profile of a sliding pull).  Each run of a source starts from
its own state of the source's kind (the start is a property of the source).

Measurement: output = x + effect + N(0, 0.01 mm) on the 100 Hz encoder clock (the encoder
then quantises to 0.1 um); load cells + N(0, 0.02 N) at 1 kHz.

Hidden effects (linear return spring only; size chosen plainly visible):

    latency     y_read(t) = x(t - 0.15 s)                                    (pure transport delay)
    creep       y_read(t) = x(t) - 0.3 mm (1 - exp(-t / 10 s)), t from the run's start
                (the tendon creeping under the follower's load: the follower reads low)
    backlash    u_c = play(u, 0.2 mm): the tendon's clamp slides in a 0.4 mm slot of the input
                coupling (inside the plant: the tensions see it; the input encoder reads u)
    hard stop   the follower meets a stop (200 N/mm) at x_stop = x_min + 0.9 (x_max - x_min)
                of the clean plant's identification run (inside the plant; clips the top 10 %
                of the output stroke, the load cells see the stop's reaction)
    viscous     y_read(t) = x(t) - b du/dt, b = 0.2 mm / (2 pi 0.25 Hz 6 mm) = 0.02122 s
                (a reading effect, load cells untouched)

Ground truth ``load_follower_truth.json``: ``{"generator", "noise", "plant", "sources": {name:
{follower, follower_load, sheath_wrap_deg, configuration, start, effect, form, size, size_unit,
effect_params, oracle, oracle_per_run, loop_width_mm, runs}}}``.  ``effect``/``form``/``size`` are
null for clean sources; ``oracle`` is the RMS of the effect's contribution to the output on the
two held-out runs together (for backlash and hard stop: the output minus the same plant without
the effect, same start) divided by the output noise sd (0.01 mm); 0 for clean sources.
``loop_width_mm`` is measured on the noise-free held-out triangle run at the 6 mm reversals
(mean over the block's reversals after the first period).

Numbers measured on this module's output (seed 0): loop width in mm, input travel from a 6 mm
reversal until the output moves back, mean over the 6 mm block of the held-out triangle run after
its first period; noise-free 1 kHz plant (threshold 1e-6 mm) / fitted on the written logs (hinge
fit y = y0 + g max(0, travel - w) on the noisy 100 Hz encoder data; ``--check``):

    source (follower, wrap, start)      released end (u = -6)   pulled end (u = +6)
    linear spring,   90, rest              0.264 / 0.261           0.798 / 0.800
    linear spring,  270, loaded            0.864 / 0.871           2.364 / 2.367
    constant force,  90, loaded            0.564 / 0.568           0.564 / 0.569
    constant force, 270, rest              1.788 / 1.791           1.788 / 1.790
    stiffening,      90, rest              0.252 / 0.239           0.762 / 0.783
    stiffening,     270, loaded            0.810 / 0.799           2.184 / 2.194

(the formula above gives 0.266 / 0.800, 0.868 / 2.364, 0.569, 1.793, 0.253 / 0.764,
0.811 / 2.189).  Oracles (RMS of the effect on the held-out runs / 0.01 mm): latency 60.4, creep
27.0, backlash 16.1, hard stop 20.3 (stop 0.83 mm below the clean peak), viscous 11.1.  Largest
input tension 10.7 N on the clean sources, 12.7 N with the hard stop.  Run time about 45 s on
two slow cores (the 33 runs' plants simulated in one numpy batch, ~30 s; writing ~15 s).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import importlib.util
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

# ---------------------------------------------------------------------------------------------
# riglog, by file path
# ---------------------------------------------------------------------------------------------


def _load_riglog() -> Any:
    env = os.environ.get("CLEANROOM_RIGLOG")
    path = Path(env) if env else Path(__file__).resolve().with_name("riglog.py")
    if path.is_dir():
        path = path / "riglog.py"
    name = "_load_follower_riglog"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load riglog from {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()

# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------

MU = 0.15
N_ELEM = 30
C_PROX = 0.10  # mm/N
C_SHEATH = 0.40  # mm/N, the tendon inside the sheath
C_DIST = 0.05  # mm/N
C_TOTAL = C_PROX + C_SHEATH + C_DIST
X_LO = -7.0  # mm, where the follower spring's travel d is zero
RADIUS_MM = 45
WRAPS_DEG = (90, 270)

FOLLOWERS: dict[str, dict[str, float]] = {
    "linear_spring": {"f0": 1.0, "k1": 0.40, "k3": 0.0},
    "constant_force": {"f0": 4.0, "k1": 0.0, "k3": 0.0},
    "stiffening_spring": {"f0": 1.5, "k1": 0.15, "k3": 0.0015},
}
FOLLOWER_TEXT = {
    "linear_spring": "L = 1.0 N + 0.40 N/mm * (x + 7 mm)",
    "constant_force": "L = 4.0 N",
    "stiffening_spring": "L = 1.5 N + 0.15 N/mm * d + 0.0015 N/mm^3 * d^3, d = x + 7 mm",
}

SIM_RATE_HZ = 1000.0
ENC_DT = 0.01
SUB = 10  # simulation steps per encoder period
RUN_S = 80.0
PRELUDE_S = 8.0  # loaded start: two periods of a 6 mm, 0.25 Hz sine before the log
OUTPUT_NOISE_MM = 0.01
LOADCELL_NOISE_N = 0.02

LATENCY_S = 0.15
CREEP_MM = 0.3
CREEP_TAU_S = 10.0
BACKLASH_TOTAL_MM = 0.4
STOP_FRACTION = 0.10
STOP_STIFFNESS = 200.0  # N/mm
VISCOUS_PEAK_MM = 0.2
VISCOUS_B_S = VISCOUS_PEAK_MM / (2 * math.pi * 0.25 * 6.0)

RUN_KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay")
HELD_OUT = ("triangle_decay", "trapezoid_decay")
EXC_KW: dict[str, dict[str, Any]] = {
    "sine_decay": {"periods_per_amplitude": 5, "frequency_hz": 0.25},
    "triangle_decay": {"periods_per_amplitude": 8, "slope_mm_s": 6.0},
    "trapezoid_decay": {"periods_per_amplitude": 5, "slope_mm_s": 5.0, "dwell_s": 0.5},
}

# (key, follower, wrap, start, effect)
SOURCES: tuple[tuple[str, str, int, str, str | None], ...] = (
    ("clean-lin-090-rest", "linear_spring", 90, "rest", None),
    ("clean-lin-270-loaded", "linear_spring", 270, "loaded", None),
    ("clean-cf-090-loaded", "constant_force", 90, "loaded", None),
    ("clean-cf-270-rest", "constant_force", 270, "rest", None),
    ("clean-stiff-090-rest", "stiffening_spring", 90, "rest", None),
    ("clean-stiff-270-loaded", "stiffening_spring", 270, "loaded", None),
    ("fx-latency", "linear_spring", 90, "rest", "latency"),
    ("fx-creep", "linear_spring", 270, "rest", "creep"),
    ("fx-backlash", "linear_spring", 90, "loaded", "backlash"),
    ("fx-hardstop", "linear_spring", 270, "loaded", "hard_stop"),
    ("fx-viscous", "linear_spring", 90, "loaded", "viscous"),
)

EFFECT_INFO: dict[str, dict[str, Any]] = {
    "latency": {"effect": "latency", "form": "pure_delay", "size": LATENCY_S, "size_unit": "s",
                "params": {"delay_s": LATENCY_S}},
    "creep": {"effect": "creep", "form": "exponential", "size": CREEP_MM, "size_unit": "mm",
              "params": {"amplitude_mm": -CREEP_MM, "tau_s": CREEP_TAU_S,
                         "law": "y_read = x - 0.3 (1 - exp(-t / 10)), t from the run's start"}},
    "backlash": {"effect": "dead_zone", "form": "input_backlash", "size": BACKLASH_TOTAL_MM,
                 "size_unit": "mm",
                 "params": {"total_width_mm": BACKLASH_TOTAL_MM, "half_width_mm": BACKLASH_TOTAL_MM / 2,
                            "where": "input coupling, inside the plant (play operator on u)"}},
    "hard_stop": {"effect": "saturation", "form": "hard_stop", "size": STOP_FRACTION,
                  "size_unit": "fraction of the output stroke clipped",
                  "params": {"stiffness_n_per_mm": STOP_STIFFNESS, "where": "follower, inside the plant"}},
    "viscous": {"effect": "rate", "form": "viscous", "size": VISCOUS_PEAK_MM, "size_unit": "mm at 9.42 mm/s",
                "params": {"b_s": VISCOUS_B_S, "law": "y_read = x - b du/dt"}},
}

# ---------------------------------------------------------------------------------------------
# Plant
# ---------------------------------------------------------------------------------------------


def load(x: np.ndarray, f0: np.ndarray, k1: np.ndarray, k3: np.ndarray, xs: np.ndarray) -> np.ndarray:
    d = x - X_LO
    return f0 + k1 * d + k3 * d**3 + STOP_STIFFNESS * np.maximum(0.0, x - xs)


def _dload(x: np.ndarray, k1: np.ndarray, k3: np.ndarray, xs: np.ndarray) -> np.ndarray:
    d = x - X_LO
    return k1 + 3.0 * k3 * d**2 + STOP_STIFFNESS * (x > xs)


def compliances(n: int = N_ELEM) -> np.ndarray:
    ce = C_SHEATH / n
    c = np.full(n + 1, ce)
    c[0] = C_PROX + ce / 2
    c[-1] = ce / 2 + C_DIST
    return c


@dataclass
class SimSpec:
    follower: str
    wrap_deg: float
    start: str  # rest | loaded
    u: np.ndarray  # the run's input at SIM_RATE_HZ (mm), from t = 0
    backlash_half: float = 0.0
    x_stop: float = math.inf


def _prelude(start: str, rate_hz: float = SIM_RATE_HZ) -> np.ndarray:
    n = int(round(PRELUDE_S * rate_hz))
    t = np.arange(n) / rate_hz
    if start == "loaded":
        return 6.0 * np.sin(2 * np.pi * 0.25 * t)
    if start == "rest":
        return np.zeros(n)
    raise ValueError(start)


def simulate(specs: list[SimSpec], check_every: int = 0, rate_hz: float = SIM_RATE_HZ) -> list[dict[str, np.ndarray]]:
    """Simulate all specs together (batched over the specs; ``u`` sampled at ``rate_hz``).
    Returns per spec the arrays over prelude + run: ``x`` (follower position), ``t_in``,
    ``t_out`` (N), ``u`` and ``n_pre`` (the number of prelude samples)."""
    b = len(specs)
    n = N_ELEM
    c = compliances(n)
    pre = [_prelude(s.start, rate_hz) for s in specs]
    us = [np.concatenate([p, s.u]) for p, s in zip(pre, specs)]
    n_steps = us[0].size
    if any(v.size != n_steps for v in us):
        raise ValueError("batched specs must have the same length")
    uu = np.stack(us)  # (B, T)
    f0 = np.array([FOLLOWERS[s.follower]["f0"] for s in specs])
    k1 = np.array([FOLLOWERS[s.follower]["k1"] for s in specs])
    k3 = np.array([FOLLOWERS[s.follower]["k3"] for s in specs])
    xs = np.array([s.x_stop for s in specs])
    h = np.array([s.backlash_half for s in specs])
    a = MU * np.radians([s.wrap_deg for s in specs]) / n / 2.0
    r = (1 - a) / (1 + a)
    kk = np.arange(n + 1)
    pw_pull = r[:, None] ** kk
    pw_rel = (1.0 / r)[:, None] ** kk
    a_pull = np.cumsum(c * pw_pull, axis=1)
    a_rel = np.cumsum(c * pw_rel, axis=1)
    cvec = c[None, :]
    offset = load(np.zeros(b), f0, k1, k3, xs) * C_TOTAL  # frictionless equilibrium x = 0 at u = 0
    # rest state at the first sample: uniform tension, no friction stress
    ue = uu[:, 0].copy()
    s0 = ue + offset
    x = np.zeros(b)
    for _ in range(60):  # s0 - x = L(x) C_TOTAL
        g = x + C_TOTAL * load(x, f0, k1, k3, xs) - s0
        x = x - g / (1 + C_TOTAL * _dload(x, k1, k3, xs))
    t0 = load(x, f0, k1, k3, xs)
    cum = np.cumsum(c)
    pos = np.empty((b, n + 2))
    pos[:, 0] = s0
    pos[:, 1:] = s0[:, None] - t0[:, None] * cum[None, :]
    pos[:, -1] = x
    out_x = np.empty((b, n_steps))
    out_tin = np.empty((b, n_steps))
    out_tout = np.empty((b, n_steps))
    rows = np.arange(b)
    node_k = np.arange(1, n + 1)[None, :]
    for i in range(n_steps):
        ue = np.clip(ue, uu[:, i] - h, uu[:, i] + h)
        s0 = ue + offset
        ds = s0 - pos[:, 0]
        dirn = np.sign(ds)
        dirn[np.abs(ds) < 1e-13] = 0.0
        if np.any(dirn != 0):
            pull = (dirn > 0)[:, None]
            amat = np.where(pull, a_pull, a_rel)
            pmat = np.where(pull, pw_pull, pw_rel)
            rho = pmat[:, 1]
            t_old = (pos[:, 1:-1] - pos[:, 2:]) / cvec[:, 1:]  # segments 1..N (old)
            t0c = (s0[:, None] - pos[:, 1:-1]) / amat[:, :n]  # T_0 if node m+1 sticks, m = 0..N-1
            tm = t0c * pmat[:, :n]
            ok = dirn[:, None] * (tm - t_old / rho[:, None]) <= 0.0
            m = np.where(ok.any(axis=1), np.argmax(ok, axis=1), n)
            m = np.where(dirn == 0, 0, m)
            full = m == n
            xn = x.copy()
            if np.any(full):
                bc = amat[:, n] / pmat[:, n]
                for _ in range(40):
                    g = xn + bc * load(xn, f0, k1, k3, xs) - s0
                    step = g / (1 + bc * _dload(xn, k1, k3, xs))
                    xn = xn - step
                    if np.max(np.abs(np.where(full, step, 0.0))) < 1e-12:
                        break
            t0n = np.where(full, load(xn, f0, k1, k3, xs) / pmat[:, n], t0c[rows, np.minimum(m, n - 1)])
            cand = s0[:, None] - t0n[:, None] * amat[:, :n]  # s_k = s_0 - T_0 A_{k-1}, k = 1..N
            mask = node_k <= m[:, None]
            pos[:, 1:-1] = np.where(mask, cand, pos[:, 1:-1])
            x = np.where(full, xn, x)
            pos[:, -1] = x
            pos[:, 0] = s0
        out_x[:, i] = x
        out_tin[:, i] = (pos[:, 0] - pos[:, 1]) / c[0]
        out_tout[:, i] = load(x, f0, k1, k3, xs)
        if check_every and i % check_every == 0:
            _check_state(pos, c, a, x, f0, k1, k3, xs)
    return [
        {"x": out_x[j], "t_in": out_tin[j], "t_out": out_tout[j], "u": uu[j], "n_pre": pre[j].size}
        for j in range(b)
    ]


def _check_state(pos, c, a, x, f0, k1, k3, xs) -> None:
    """Debug: every friction bound holds and the follower is in equilibrium."""
    t = (pos[:, :-1] - pos[:, 1:]) / c[None, :]
    f = t[:, :-1] - t[:, 1:]
    lim = a[:, None] * (t[:, :-1] + t[:, 1:])
    if np.any(np.abs(f) > lim * (1 + 1e-7) + 1e-9):
        raise AssertionError(f"friction bound violated by {np.max(np.abs(f) - lim):.3g} N")
    if np.any(t < 0):
        raise AssertionError("slack tendon")
    lx = load(x, f0, k1, k3, xs)
    if np.any(np.abs(t[:, -1] - lx) > 1e-6 * (1 + lx)):
        raise AssertionError(f"follower not in equilibrium: {np.max(np.abs(t[:, -1] - lx)):.3g} N")


# ---------------------------------------------------------------------------------------------
# Excitations
# ---------------------------------------------------------------------------------------------


def excitation_pair(kind: str) -> tuple[Any, np.ndarray]:
    """The run's excitation on the encoder clock (riglog ``Excitation``) and its input at 1 kHz."""
    ex = riglog.make_excitation(kind, ENC_DT, **EXC_KW[kind])
    fine = riglog.make_excitation(kind, 1.0 / SIM_RATE_HZ, **EXC_KW[kind])
    if abs(ex.t_s[-1] - RUN_S) > 1e-9 or fine.u.size != (ex.u.size - 1) * SUB + 1:
        raise AssertionError(f"{kind}: run is not {RUN_S} s")
    if np.max(np.abs(fine.u[::SUB] - ex.u)) > 1e-9:
        raise AssertionError(f"{kind}: 1 kHz and 100 Hz excitations differ")
    return ex, fine.u


# ---------------------------------------------------------------------------------------------
# Loop widths
# ---------------------------------------------------------------------------------------------


def _reversals(u: np.ndarray) -> list[int]:
    du = np.diff(u)
    idx = np.flatnonzero(np.abs(du) > 1e-12)
    sg = np.sign(du[idx])
    return [int(idx[j + 1]) for j in range(len(idx) - 1) if sg[j + 1] != sg[j]]


def loop_widths_exact(u: np.ndarray, y: np.ndarray, level: float = 6.0, eps: float = 1e-6,
                      skip_first: int = 1) -> dict[str, float]:
    """Input travel from each reversal at |u| = ``level`` until the output has moved ``eps``
    the other way (noise-free data); mean over the reversals after the first ``skip_first``
    of each end."""
    top, bot = [], []
    for k in _reversals(u):
        if abs(abs(u[k]) - level) > 1e-6:
            continue
        s = 1.0 if u[k] > 0 else -1.0  # s = +1: reversal at the pulled end
        yr = y[k]
        moved = np.flatnonzero(s * (yr - y[k:]) > eps)
        if moved.size == 0:
            continue
        j = k + int(moved[0])
        (top if s > 0 else bot).append(abs(u[k] - u[j - 1]))
    return {"released_end": float(np.mean(bot[skip_first:])), "pulled_end": float(np.mean(top[skip_first:])),
            "released_end_all": [round(v, 4) for v in bot], "pulled_end_all": [round(v, 4) for v in top]}


def loop_widths_hinge(u: np.ndarray, y: np.ndarray, level: float = 6.0, window: float = 3.8,
                      skip_first: int = 1) -> dict[str, float]:
    """Noisy data: after each reversal at |u| = level fit y = y0 + g max(0, tau - w) over the
    input travel tau <= window (grid over w, least squares in y0, g)."""
    top, bot = [], []
    grid = np.arange(0.0, 3.2, 0.005)
    for k in _reversals(u):
        if abs(abs(u[k]) - level) > 1e-3:
            continue
        tau = np.abs(u[k:] - u[k])
        # stop at the next reversal
        nxt = np.flatnonzero(np.diff(tau) < -1e-9)
        end = int(nxt[0]) + 1 if nxt.size else tau.size
        tau, yy = tau[:end], y[k:k + end]
        sel = tau <= window
        tau, yy = tau[sel], yy[sel]
        best = (np.inf, 0.0)
        for w in grid:
            hcol = np.maximum(0.0, tau - w)
            if np.count_nonzero(hcol) < 5:
                continue
            a = np.column_stack([np.ones_like(tau), hcol])
            coef, *_ = np.linalg.lstsq(a, yy, rcond=None)
            sse = float(np.sum((a @ coef - yy) ** 2))
            if sse < best[0]:
                best = (sse, float(w))
        (top if u[k] > 0 else bot).append(best[1])
    return {"released_end": float(np.mean(bot[skip_first:])), "pulled_end": float(np.mean(top[skip_first:]))}


def width_theory(load_n: float, wrap_deg: float) -> float:
    mt = MU * math.radians(wrap_deg)
    return load_n * (C_PROX * 2 * math.sinh(mt) + C_SHEATH * 2 * (math.cosh(mt) - 1) / mt)


# ---------------------------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------------------------


def _folder_name(key: str, seed: int) -> str:
    return "lf-" + hashlib.sha256(f"load_follower/{seed}/{key}".encode()).hexdigest()[:10]


def _delay(t: np.ndarray, x: np.ndarray, d: float) -> np.ndarray:
    return np.interp(t - d, t, x, left=float(x[0]), right=float(x[-1]))


def generate(out_dir: str | Path, seed: int = 0, verbose: bool = True) -> dict[str, Any]:
    t_start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    exc = {k: excitation_pair(k) for k in RUN_KINDS}
    n_pre = int(round(PRELUDE_S * SIM_RATE_HZ))
    t_fine_full = (np.arange(n_pre + exc["sine_decay"][1].size) - n_pre) / SIM_RATE_HZ

    # ---- plants: every distinct (follower, wrap, start, backlash) x run kind -----------------
    def plant_key(follower: str, wrap: int, start: str, effect: str | None) -> tuple:
        return (follower, wrap, start, effect if effect in ("backlash", "hard_stop") else None)

    # hard stop: at 90 % of the clean plant's output stroke on its identification run (found on
    # a 100 Hz simulation of that run: the plant is rate independent and the extremes of the
    # output fall on the input's extremes, which are samples of both clocks)
    stops: dict[tuple, float] = {}
    for _, fol, wrap, start, eff in SOURCES:
        if eff == "hard_stop":
            pre = simulate([SimSpec(fol, wrap, start, exc["sine_decay"][0].u)], rate_hz=1.0 / ENC_DT)[0]
            xr = pre["x"][pre["n_pre"]:]
            stops[(fol, wrap, start, "hard_stop")] = float(xr.min() + (1 - STOP_FRACTION) * (xr.max() - xr.min()))

    keys: list[tuple] = []
    for _, fol, wrap, start, eff in SOURCES:
        pk = plant_key(fol, wrap, start, eff)
        for k in ([pk, pk[:3] + (None,)] if pk[3] else [pk]):
            if k not in keys:
                keys.append(k)
    specs, tags = [], []
    for pk in keys:
        for kind in RUN_KINDS:
            specs.append(SimSpec(pk[0], pk[1], pk[2], exc[kind][1],
                                 backlash_half=BACKLASH_TOTAL_MM / 2 if pk[3] == "backlash" else 0.0,
                                 x_stop=stops.get(pk, math.inf)))
            tags.append((pk, kind))
    res = dict(zip(tags, simulate(specs)))
    for pk, xst in stops.items():  # the 1 kHz clean run has the same stroke
        clean = res[(pk[:3] + (None,), "sine_decay")]
        xr = clean["x"][clean["n_pre"]:]
        if abs(xr.min() + (1 - STOP_FRACTION) * (xr.max() - xr.min()) - xst) > 1e-6:
            raise AssertionError("hard stop: 100 Hz and 1 kHz strokes differ")
    t_sim = time.perf_counter() - t_start

    # ---- write ----------------------------------------------------------------------------
    truth: dict[str, Any] = {
        "generator": "tests/cleanroom/load_follower.py",
        "seed": seed,
        "noise": {"output_sd_mm": OUTPUT_NOISE_MM, "loadcell_sd_n": LOADCELL_NOISE_N},
        "plant": {
            "mu": MU, "n_elements": N_ELEM, "c_prox_mm_per_n": C_PROX, "c_sheath_mm_per_n": C_SHEATH,
            "c_dist_mm_per_n": C_DIST, "x_lo_mm": X_LO, "followers": FOLLOWER_TEXT,
            "friction": "rigid-stick Coulomb (stick/slip) on each of N contact nodes, bound mu dtheta (T_prev + T_next)/2",
            "held_out_runs": list(HELD_OUT),
        },
        "sources": {},
    }
    rng_master = np.random.default_rng(seed)
    summary = []
    for si, (key, fol, wrap, start, eff) in enumerate(SOURCES):
        name = _folder_name(key, seed)
        cfg = {"curve_angle_deg": wrap, "radius_mm": RADIUS_MM}
        pk = plant_key(fol, wrap, start, eff)
        contrib: dict[str, np.ndarray] = {}
        runs_truth = []
        for ri, kind in enumerate(RUN_KINDS):
            ex, u_fine = exc[kind]
            r = res[(pk, kind)]
            npre = r["n_pre"]
            x_full = r["x"]
            x_run = x_full[npre:]
            x_enc = x_run[::SUB]
            t_enc = ex.t_s
            if eff == "latency":
                y_enc = _delay(t_fine_full, x_full, LATENCY_S)[npre::SUB]
            elif eff == "creep":
                y_enc = x_enc - CREEP_MM * (1 - np.exp(-t_enc / CREEP_TAU_S))
            elif eff == "viscous":
                v = np.gradient(u_fine, 1.0 / SIM_RATE_HZ)[::SUB]
                y_enc = x_enc - VISCOUS_B_S * v
            else:
                y_enc = x_enc
            if eff in ("backlash", "hard_stop"):
                clean = res[(pk[:3] + (None,), kind)]
                contrib[kind] = y_enc - clean["x"][clean["n_pre"]:][::SUB]
            else:
                contrib[kind] = y_enc - x_enc
            noise = rng_master.normal(0.0, OUTPUT_NOISE_MM, y_enc.shape)
            t_lc = np.arange(u_fine.size) / SIM_RATE_HZ
            rid = riglog.run_id_for(cfg, kind, ri + 1)
            started = _dt.datetime(2026, 4, 6, 9, 0, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=40 * si + 3 * ri)
            riglog.write_run_folder(
                out / name, rid, t_enc, ex.u, y_enc + noise, configuration=cfg, excitation=ex.manifest,
                loadcell=(t_lc, r["t_in"][npre:], r["t_out"][npre:]), loadcell_noise_n=LOADCELL_NOISE_N,
                events=True, started_at=started, seed=int(rng_master.integers(0, 2**31 - 1)),
            )
            runs_truth.append({"run_id": rid, "kind": kind, "held_out": kind in HELD_OUT,
                               "effect_rms_mm": float(np.sqrt(np.mean(contrib[kind] ** 2))),
                               "max_input_tension_n": float(r["t_in"][npre:].max()),
                               "output_stroke_mm": float(x_enc.max() - x_enc.min())})
        held = np.concatenate([contrib[k] for k in HELD_OUT])
        oracle = float(np.sqrt(np.mean(held**2)) / OUTPUT_NOISE_MM)
        tri = res[(pk, "triangle_decay")]
        lw = loop_widths_exact(tri["u"][tri["n_pre"]:], tri["x"][tri["n_pre"]:])
        info = EFFECT_INFO.get(eff) if eff else None
        params = dict(info["params"]) if info else None
        if eff == "hard_stop":
            params["x_stop_mm_plant"] = stops[pk]
            clean = res[(pk[:3] + (None,), "sine_decay")]
            xr = clean["x"][clean["n_pre"]:]
            params["clipped_depth_mm"] = float(xr.max() - stops[pk])
            params["x_stop_rel_first_sample_mm"] = {
                kind: float(stops[pk] - res[(pk, kind)]["x"][res[(pk, kind)]["n_pre"]]) for kind in RUN_KINDS}
        truth["sources"][name] = {
            "key": key,
            "follower": fol,
            "follower_load": FOLLOWER_TEXT[fol],
            "sheath_wrap_deg": wrap,
            "configuration": cfg,
            "start": start,
            "effect": info["effect"] if info else None,
            "form": info["form"] if info else None,
            "size": info["size"] if info else None,
            "size_unit": info["size_unit"] if info else None,
            "effect_params": params,
            "oracle": round(oracle, 3),
            "oracle_per_run": {k: round(float(np.sqrt(np.mean(contrib[k] ** 2)) / OUTPUT_NOISE_MM), 3) for k in HELD_OUT},
            "loop_width_mm": {"released_end": round(lw["released_end"], 4), "pulled_end": round(lw["pulled_end"], 4)},
            "runs": runs_truth,
        }
        summary.append((name, key, lw, oracle, max(rt["max_input_tension_n"] for rt in runs_truth)))
    (out / "load_follower_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    elapsed = time.perf_counter() - t_start
    if verbose:
        print(f"simulated in {t_sim:.1f} s, total {elapsed:.1f} s")
        print(f"{'folder':16s} {'source':24s} {'w released':>10s} {'w pulled':>9s} {'oracle':>7s} {'max T_in':>8s}")
        for name, key, lw, oracle, tmax in summary:
            print(f"{name:16s} {key:24s} {lw['released_end']:10.3f} {lw['pulled_end']:9.3f} {oracle:7.1f} {tmax:8.2f}")
    truth["elapsed_s"] = elapsed
    return truth


# ---------------------------------------------------------------------------------------------
# Read back (check)
# ---------------------------------------------------------------------------------------------


def read_run(folder: Path) -> dict[str, np.ndarray]:
    man = json.loads((folder / "manifest.json").read_text())
    enc = np.genfromtxt(folder / "encoder.csv", delimiter=",", names=True, dtype=np.int64)
    e = man["channels"]["encoder"]
    bits = e["counter_bits"]

    def pos(raw: np.ndarray, sign: int) -> np.ndarray:
        un = riglog.unwrap_counts(raw, bits)
        return sign * (un - un[0]) / e["counts_per_unit"]

    return {"t": enc["t_ns"] * 1e-9, "u": pos(enc["input_counts"], e["input_sign"]),
            "y": pos(enc["output_counts"], e["output_sign"]), "manifest": man}


def check(out_dir: str | Path) -> None:
    out = Path(out_dir)
    truth = json.loads((out / "load_follower_truth.json").read_text())
    print(f"{'folder':16s} {'follower':18s} {'wrap':>4s} {'start':6s} {'effect':10s} "
          f"{'w_rel log':>9s} {'w_pull log':>10s} {'w_rel true':>10s} {'w_pull true':>11s} {'oracle':>7s}")
    for name, s in truth["sources"].items():
        runs = sorted((out / name).iterdir())
        tri = [r for r in runs if "triangle_decay" in r.name][0]
        d = read_run(tri)
        lw = loop_widths_hinge(d["u"], d["y"])
        print(f"{name:16s} {s['follower']:18s} {s['sheath_wrap_deg']:4d} {s['start']:6s} {str(s['effect']):10s} "
              f"{lw['released_end']:9.3f} {lw['pulled_end']:10.3f} {s['loop_width_mm']['released_end']:10.3f} "
              f"{s['loop_width_mm']['pulled_end']:11.3f} {s['oracle']:7.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--check", action="store_true", help="only re-read OUT_DIR's logs and print loop widths")
    args = ap.parse_args(argv)
    if args.check:
        check(args.out_dir)
        return 0
    generate(args.out_dir, seed=args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
