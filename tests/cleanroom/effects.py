"""Clean-room discrepancy test bench for tendon-sheath hysteresis models.

Written from: ``../shared/rig-log-format.md`` (run folder format), the seed papers in
``../shared/seeds/`` (seed 001: the thesis' play operator eq. 4.7/4.8, its sum Gamma_n
eq. 4.9 with P = (0, 0.2, ..., 2.0) mm eq. 4.11 and the weights of Table 4.1; seed 002: the
Bouc-Wen model eq. 2-3; seed 000: the Coleman-Hodgdon (Duhem) model eq. 10) and textbook
physics (Euler-Eytelwein capstan friction, Hooke's law for the tendon, Stribeck friction,
first-order relaxation).  The project's implementation was NOT read.

What it makes
-------------
A *source* is one folder of 3 raw runs (``tsm-rig-log/1`` run folders, 80 s each, three
different excitations) of one underlying *plant* with at most one hidden *effect*.  The
ground truth (plant, effect, form, parameters, identifiability class, effect size vs noise)
is written outside the source folders, in ``<root>/ground_truth.json``.

Plants (proximal input u in mm -> distal output y in mm, plus tensions T_in, T_out in N):

* ``play_sum``     : seed 001 Gamma_n, thesis play w_k = max(v_k, min(v_k + p, w_{k-1})),
                     P = (0, 0.2, ..., 2.0) mm, Q = Table 4.1 row (90 deg, 30 mm), mixed signs.
* ``bouc_wen``     : seed 002 eq. 2-3, y = alpha u + beta h (beta < 0: the output lags, the
                     loop runs anticlockwise like a backlash; alpha > |beta| max dh/du keeps
                     the output moving with the input right after a reversal),
                     dh = A du - B |du| |h|^{n-1} h - C du |h|^n  (rate independent).
* ``preisach``     : a Preisach plane of 4000 relays whose (alpha, beta) thresholds are drawn
                     from a density (log-normal half-width, normal centre) + a linear part.
* ``duhem``        : Coleman-Hodgdon (seed 000 eq. 10) dy = A |du| (C u - y) + B du.
* ``tendon_sheath``: quasi-static lumped tendon-sheath: elastic tendon (compliance c_T) in a
                     sheath with capstan friction (dT/ds = -/+ mu kappa T on slipping
                     stretches, stuck stretches keep their tension), distal load
                     T_L = F0 + K_L x_out.  Gives T_in = T(0) and T_out = T(L) physically.

For the first four plants (no tendon in the model) tensions come from a generic load model:
T_out = F0 + K_L y (follower spring), T_in = T_out exp(mu theta s) with s in [-1, 1] the
capstan sliding state (a centred play of half width r_s on the plant input, s = (v - z)/r_s).

Every plant can start ``loaded``: before the run the input makes a slow excursion to
+/- 7 mm and back to the run's first value (a prehistory that is simulated but not written),
so the run starts with the plant's memory at a band edge, not at the virgin/zero state.

Effects: see :data:`FORMS` (canonical ``(effect, form)`` names), each with ``weak`` and
``strong`` parameter sets (both clearly above the noise: the truth records the effect's RMS
and peak against the output noise).  Identifiability classes are given by
:func:`identifiability` (reasoning in its docstring).

Noise: output encoder Gaussian noise 2 um then quantised to 1 um (counts_per_unit 1000),
input quantised to 1 um; load cells Gaussian 0.02 N.  Optional ragged load-cell streams
(ending a few samples early, or with a short gap) through riglog's faults.

The writer uses ``riglog.py`` (clean-room ``tsm-rig-log/1`` writer) from
``tests/cleanroom/``, imported by file path (override with the environment
variable ``CLEANROOM_RIGLOG``).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

__all__ = [
    "PLANTS",
    "FORMS",
    "EFFECTS",
    "DT_S",
    "plant_defaults",
    "simulate_plant",
    "play_operator_thesis",
    "play_operator_centred",
    "play_sum_plant",
    "bouc_wen_plant",
    "preisach_plant",
    "duhem_plant",
    "tendon_sheath_plant",
    "generic_tensions",
    "prehistory",
    "source_excitations",
    "apply_chain",
    "identifiability",
    "form_params",
    "write_source",
    "write_matrix",
    "list_forms",
]

DT_S = 0.01  # seed 001: 10 ms real-time loop
RUN_S = 80.0
CONFIG = {"curve_angle_deg": 90, "radius_mm": 30}


# ---------------------------------------------------------------------------------------------
# riglog (clean-room format writer) import by path
# ---------------------------------------------------------------------------------------------


def _riglog():
    if "cleanroom_riglog" in sys.modules:
        return sys.modules["cleanroom_riglog"]
    path = os.environ.get("CLEANROOM_RIGLOG", str(Path(__file__).with_name("riglog.py")))
    spec = importlib.util.spec_from_file_location("cleanroom_riglog", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["cleanroom_riglog"] = mod
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


# ---------------------------------------------------------------------------------------------
# Play operators
# ---------------------------------------------------------------------------------------------


def play_operator_thesis(v: np.ndarray, p: np.ndarray, w0: np.ndarray | float = 0.0) -> np.ndarray:
    """Seed 001 eq. 4.7/4.8: w_k = max(v_k, min(v_k + p, w_{k-1})), vectorised over plays p.

    The output lies in [v, v + p]: it follows v while v rises, and lags above by p while v
    falls.  Returns an array (len(v), len(p)).  w0 = 0 with v_0 = 0 is the thesis' initial
    condition (which is the rising edge of every band)."""
    v = np.asarray(v, float)
    p = np.atleast_1d(np.asarray(p, float))
    w = np.broadcast_to(np.asarray(w0, float), p.shape).copy()
    out = np.empty((v.size, p.size))
    for k, vk in enumerate(v):
        w = np.maximum(vk, np.minimum(vk + p, w))
        out[k] = w
    return out


def play_operator_centred(v: np.ndarray, r: float, z0: float | None = None) -> np.ndarray:
    """Centred backlash of half width r: z_k = min(v_k + r, max(v_k - r, z_{k-1}))."""
    v = np.asarray(v, float)
    z = float(v[0]) if z0 is None else float(z0)
    out = np.empty_like(v)
    if r <= 0:
        return v.copy()
    for k, vk in enumerate(v):
        z = min(vk + r, max(vk - r, z))
        out[k] = z
    return out


# ---------------------------------------------------------------------------------------------
# Plants
# ---------------------------------------------------------------------------------------------

# seed 001 Table 4.1, phi = 90 deg, r = 30 mm; P from eq. 4.11
THESIS_P = tuple(round(0.2 * i, 1) for i in range(11))
THESIS_Q_90_30 = (-0.333, 0.422, 0.056, 0.798, 0.031, 0.006, -0.019, 0.066, -0.226, 0.649, -0.473)

_GENERIC_LOAD = {"F0_n": 5.0, "K_L_n_per_mm": 0.5, "mu": 0.2, "wrap_deg": 180.0, "r_s_mm": 0.3}

PLANTS: dict[str, dict[str, Any]] = {
    "play_sum": {"P": list(THESIS_P), "Q": list(THESIS_Q_90_30), **_GENERIC_LOAD},
    "bouc_wen": {"alpha": 1.0, "beta": -1.0, "A": 0.5, "B": 0.6, "C": 0.1, "n": 1.0, **_GENERIC_LOAD},
    "preisach": {
        "n_relays": 4000, "halfwidth_median_mm": 0.5, "halfwidth_gsd": 1.8, "centre_sd_mm": 3.0,
        "relay_gain_mm": 1.6, "linear_gain": 0.55, "density_seed": 1234, **_GENERIC_LOAD,
    },
    "duhem": {"A": 1.2, "B": 0.3, "C": 0.85, **_GENERIC_LOAD},
    "tendon_sheath": {
        "F0_n": 5.0, "K_L_n_per_mm": 0.5, "mu": 0.2, "wrap_deg": 180.0, "compliance_mm_per_n": 0.15,
        "n_nodes": 40,
    },
}
"""Default plant parameters.  ``wrap_deg`` = total angle the sheath turns through (the 90 deg
curve of the default configuration plus 90 deg of routing)."""


def plant_defaults(plant: str) -> dict[str, Any]:
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; known {sorted(PLANTS)}")
    return json.loads(json.dumps(PLANTS[plant]))


def play_sum_plant(v: np.ndarray, P: Sequence[float], Q: Sequence[float], w0: np.ndarray | float = 0.0) -> np.ndarray:
    """Seed 001 eq. 4.9: y_k = sum_i q_i gamma_i[v_k, w_i(k-1), p_i]."""
    W = play_operator_thesis(v, np.asarray(P, float), w0)
    return W @ np.asarray(Q, float)


def bouc_wen_plant(v: np.ndarray, alpha: float, beta: float, A: float, B: float, C: float, n: float = 1.0,
                   h0: float = 0.0) -> np.ndarray:
    """Seed 002 eq. 2-3 (rate independent: integrated in du with sub-steps of <= 0.005 mm)."""
    v = np.asarray(v, float)
    y = np.empty_like(v)
    h = float(h0)
    y[0] = alpha * v[0] + beta * h
    for k in range(1, v.size):
        du = v[k] - v[k - 1]
        m = max(1, int(math.ceil(abs(du) / 0.005)))
        d = du / m
        for _ in range(m):
            ah = abs(h)
            h += A * d - B * abs(d) * ah ** (n - 1.0) * h - C * d * ah ** n if ah > 0 else A * d
        y[k] = alpha * v[k] + beta * h
    return y


def _preisach_relays(n_relays: int, halfwidth_median_mm: float, halfwidth_gsd: float, centre_sd_mm: float,
                     density_seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(density_seed)
    r = halfwidth_median_mm * np.exp(np.log(halfwidth_gsd) * rng.standard_normal(n_relays))
    c = centre_sd_mm * rng.standard_normal(n_relays)
    return c + r, c - r  # alpha (switch up), beta (switch down)


def preisach_plant(v: np.ndarray, n_relays: int, halfwidth_median_mm: float, halfwidth_gsd: float,
                   centre_sd_mm: float, relay_gain_mm: float, linear_gain: float, density_seed: int,
                   **_: Any) -> np.ndarray:
    """Preisach plane: y = linear_gain v + relay_gain * mean(R), relays R in {-1, +1} switching
    up at alpha, down at beta; thresholds sampled from mu(alpha, beta) (log-normal half width,
    normal centre).  Virgin (demagnetised) start: R = +1 where alpha + beta < 0."""
    v = np.asarray(v, float)
    a, b = _preisach_relays(n_relays, halfwidth_median_mm, halfwidth_gsd, centre_sd_mm, density_seed)
    R = np.where(a + b < 0, 1.0, -1.0)
    R[v[0] >= a] = 1.0
    R[v[0] <= b] = -1.0
    y = np.empty_like(v)
    for k, vk in enumerate(v):
        R[vk >= a] = 1.0
        R[vk <= b] = -1.0
        y[k] = R.mean()
    return linear_gain * v + relay_gain_mm * y


def duhem_plant(v: np.ndarray, A: float, B: float, C: float, y0: float = 0.0, **_: Any) -> np.ndarray:
    """Coleman-Hodgdon (seed 000 eq. 10) in input increments: dy = A |du| (C u - y) + B du,
    integrated exactly per sample for piecewise-linear u (A, C > 0)."""
    v = np.asarray(v, float)
    y = np.empty_like(v)
    y[0] = y0
    for k in range(1, v.size):
        du = v[k] - v[k - 1]
        if du == 0:
            y[k] = y[k - 1]
            continue
        s = 1.0 if du > 0 else -1.0
        # along the step u = u0 + s*x, x in [0, |du|]:  dy/dx = A (C (u0 + s x) - y) + B s
        # steady branch y* = C u - s (C - B)/A; deviation decays as exp(-A x).
        ystar0 = C * v[k - 1] - s * (C - B) / A
        y[k] = ystar0 + C * du + (y[k - 1] - ystar0) * math.exp(-A * abs(du))
    return y


def tendon_sheath_plant(u: np.ndarray, F0_n: float, K_L_n_per_mm: float, mu: float, wrap_deg: float,
                        compliance_mm_per_n: float, n_nodes: int = 40, **_: Any
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quasi-static lumped tendon-sheath (textbook capstan + Hooke).

    The tendon (total compliance c_T, mm/N, relative to the pretension F0) runs through a sheath
    of uniform curvature turning through theta = wrap_deg; a = mu theta.  Tension profile T(s),
    s in [0, 1] from the actuator to the follower, on n_nodes + 1 nodes.  Distal load: a spring
    with pretension, T(1) = F0 + K_L x_out.  Compatibility: u = x_out + c_T int (T - F0) ds.

    When the input pulls, the new proximal tension T0 slides the tendon where T0 e^{-a s}
    exceeds the old tension (capstan decay along the slipping stretch), the rest sticks and
    keeps its tension:  T <- max(T, T0 e^{-a s});  x_out <- max(x_out, (T(1) - F0)/K_L).
    Releasing:  T <- min(T, T0 e^{+a s});  x_out <- min(x_out, (T(1) - F0)/K_L).
    T0 solves the compatibility equation, which is piecewise linear in T0 (breakpoints where
    each node starts slipping) and is solved exactly per sample.  Output: x_out (mm), tensions
    T_in = T(0), T_out = T(1) (N).  Lost motion at a reversal = c_T x (change of mean tension).
    """
    u = np.asarray(u, float)
    N = int(n_nodes)
    s = np.linspace(0.0, 1.0, N + 1)
    w = np.full(N + 1, 1.0 / N)
    w[0] = w[-1] = 0.5 / N
    a = mu * math.radians(wrap_deg)
    cT, F0, KL = compliance_mm_per_n, F0_n, K_L_n_per_mm
    T = np.full(N + 1, F0)
    x = 0.0
    # pulling: node i slips for T0 >= T_i e^{a s_i}; releasing: for T0 <= T_i e^{-a s_i}
    Ep, Er = np.exp(-a * s), np.exp(a * s)
    Ap = cT * w * Ep
    Ap[-1] += Ep[-1] / KL
    Ar = cT * w * Er
    Ar[-1] += Er[-1] / KL
    Cc = np.zeros(N + 1)
    Cc[-1] = -F0 / KL
    # elongation offset so that the initial state is consistent with u[0]
    u_off = u[0] - (x + cT * (w @ (T - F0)))
    y = np.empty_like(u)
    tin = np.empty_like(u)
    tout = np.empty_like(u)
    prev = u[0]
    for k, uk in enumerate(u):
        du = uk - prev
        prev = uk
        if du != 0.0:
            target = uk - u_off + cT * F0  # = sum(slip: A T0 + C) + sum(stick: B)
            B = cT * w * T
            B[-1] += x
            if du > 0:
                bp = T * Er  # breakpoints (pull)
                order = np.argsort(bp)
                A_ = Ap
            else:
                bp = T * Ep
                order = np.argsort(-bp)
                A_ = Ar
            Ao, Bo, Co, bo = A_[order], B[order], Cc[order], bp[order]
            cumA = np.cumsum(Ao)
            cumC = np.cumsum(Co)
            rest = Bo.sum() - np.cumsum(Bo)  # stick part when first j+1 slip
            g = bo * cumA + cumC + rest - target  # value at each breakpoint
            if du > 0:
                idx = np.nonzero(g >= 0)[0]
            else:
                idx = np.nonzero(g <= 0)[0]
            j = (idx[0] - 1) if idx.size else N  # number of slipping nodes - 1 in the segment
            j = max(j, 0)
            T0 = (target - cumC[j] - rest[j]) / cumA[j]
            if du > 0:
                T = np.maximum(T, T0 * Ep)
                x = max(x, (T[-1] - F0) / KL)
            else:
                T = np.minimum(T, T0 * Er)
                x = min(x, (T[-1] - F0) / KL)
        y[k] = x
        tin[k] = T[0]
        tout[k] = T[-1]
    return y, tin, tout


def generic_tensions(v: np.ndarray, y: np.ndarray, F0_n: float, K_L_n_per_mm: float, mu: float,
                     wrap_deg: float, r_s_mm: float, **_: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Load model for plants without a tendon: follower spring T_out = F0 + K_L y, capstan
    state s = (v - z)/r_s (z a centred play of half width r_s on the plant input v, the
    pre-sliding travel), T_in = T_out exp(mu theta s).  Returns (T_in, T_out, s)."""
    z = play_operator_centred(v, r_s_mm, z0=float(v[0]))
    s_state = (v - z) / r_s_mm if r_s_mm > 0 else np.zeros_like(v)
    tout = F0_n + K_L_n_per_mm * np.asarray(y, float)
    tin = tout * np.exp(mu * math.radians(wrap_deg) * s_state)
    return tin, tout, s_state


def simulate_plant(plant: str, v: np.ndarray, params: Mapping[str, Any] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run ``plant`` on the input v (mm) from its virgin/zero state; returns (y, T_in, T_out)."""
    p = plant_defaults(plant)
    p.update(params or {})
    v = np.asarray(v, float)
    if plant == "tendon_sheath":
        return tendon_sheath_plant(v, **p)
    if plant == "play_sum":
        y = play_sum_plant(v, p["P"], p["Q"], w0=0.0)
    elif plant == "bouc_wen":
        y = bouc_wen_plant(v, p["alpha"], p["beta"], p["A"], p["B"], p["C"], p["n"])
    elif plant == "preisach":
        y = preisach_plant(v, **p)
    elif plant == "duhem":
        y = duhem_plant(v, p["A"], p["B"], p["C"])
    else:  # pragma: no cover
        raise ValueError(plant)
    tin, tout, _ = generic_tensions(v, y, **p)
    return y, tin, tout


# ---------------------------------------------------------------------------------------------
# Excitations and prehistory
# ---------------------------------------------------------------------------------------------


def prehistory(loaded: str | None, u0: float = 0.0, duration_s: float = 12.0, excursion_mm: float = 7.0,
               dt: float = DT_S) -> np.ndarray:
    """Input before the run (simulated, not written).  ``None``: rest at u0 (plant stays in its
    virgin state).  ``"above"``: u0 -> u0 + excursion -> u0 (the run starts on the descending
    branch: its first rise meets the full lost motion); ``"below"``: u0 -> u0 - excursion -> u0.
    Raised-cosine shape, peak speed pi*excursion/duration (1.8 mm/s), then 1 s rest."""
    n = int(round(duration_s / dt))
    if loaded is None:
        return np.full(n, u0)
    sgn = {"above": 1.0, "below": -1.0}[loaded]
    n_move = n - int(round(1.0 / dt))
    tau = np.arange(n_move) / n_move
    pre = u0 + sgn * excursion_mm * np.sin(np.pi * tau) ** 2
    return np.concatenate([pre, np.full(n - n_move, u0)])


def source_excitations(kinds: Sequence[str] = ("sine_decay", "triangle_decay", "multisine"), seed: int = 0
                       ) -> list[tuple[np.ndarray, np.ndarray, dict[str, Any]]]:
    """Three 80 s excitations on the 10 ms clock (t_s, u_mm, manifest excitation block).

    * ``sine_decay``: seed 001, 6/4.5/3/1.5 mm, 5 periods each at 0.25 Hz.
    * ``triangle_decay``: 5/4/3/2 mm, 5 periods each, slope 3.5 mm/s (80 s).
    * ``multisine``: random-phase multisine (manifest kind ``mixed_sine``), 0.0125-0.4125 Hz,
      peak scaled to 5 mm, starting at 0 (phases shifted so u(0) = 0 exactly via a sin term).
    * ``sine_decay_small``: 3/2.25/1.5/0.75 mm, 5 periods at 0.25 Hz.
    """
    rl = _riglog()
    rng = np.random.default_rng(seed)
    out = []
    for kind in kinds:
        if kind == "sine_decay":
            ex = rl.make_excitation("sine_decay", DT_S)
        elif kind == "sine_decay_small":
            ex = rl.make_excitation("sine_decay", DT_S, amplitudes_mm=(3.0, 2.25, 1.5, 0.75))
        elif kind == "triangle_decay":
            ex = rl.make_excitation("triangle_decay", DT_S, amplitudes_mm=(5.0, 4.0, 3.0, 2.0), slope_mm_s=3.5)
        elif kind == "multisine":
            freqs = [0.0125, 0.0375, 0.0875, 0.1625, 0.2625, 0.4125]  # periodic in 80 s
            amps = np.array([2.0, 1.6, 1.1, 0.7, 0.45, 0.25])
            ph = rng.uniform(0, 2 * np.pi, len(freqs))
            t = np.arange(int(round(RUN_S / DT_S)) + 1) * DT_S
            raw = sum(a_ * (np.sin(2 * np.pi * f * t + p_) - np.sin(p_)) for a_, f, p_ in zip(amps, freqs, ph))
            scale = 5.0 / np.max(np.abs(raw))
            terms = [{"amplitude": float(a_ * scale), "frequency_hz": f, "phase_rad": float(p_)}
                     for a_, f, p_ in zip(amps, freqs, ph)]
            # constant -sum a sin(p) keeps u(0)=0; the manifest lists the sine terms, and the
            # offset is recorded as a constant term of frequency 0.
            off = -float(sum(tm["amplitude"] * math.sin(tm["phase_rad"]) for tm in terms))
            terms.append({"amplitude": off, "frequency_hz": 0.0, "phase_rad": math.pi / 2})
            u = raw * scale
            ex = rl.Excitation(t, u, {"kind": "mixed_sine", "terms": terms})
        else:
            raise ValueError(f"unknown excitation {kind!r}")
        out.append((np.asarray(ex.t_s, float), np.asarray(ex.u, float), dict(ex.manifest)))
    return out


# ---------------------------------------------------------------------------------------------
# Effect forms
# ---------------------------------------------------------------------------------------------


@dataclass
class Signals:
    """Full-length signals (prehistory + run) handed to effect functions."""

    t: np.ndarray          # s; run starts at t = 0, prehistory has t < 0
    u: np.ndarray          # actuator (proximal) input, mm
    v: np.ndarray | None = None    # plant input after input-stage effects
    y: np.ndarray | None = None    # output, mm
    tin: np.ndarray | None = None  # proximal tension, N
    tout: np.ndarray | None = None  # distal tension, N
    extra: dict[str, Any] = field(default_factory=dict)


def _speed(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.gradient(x, t)


# --- latency -------------------------------------------------------------------------------
def fx_pure_delay(sig: Signals, delay_s: float) -> None:
    """Pure transport delay of the output channel: y'(t) = y(t - d).  Tensions undelayed."""
    sig.y = np.interp(sig.t - delay_s, sig.t, sig.y, left=sig.y[0])


# --- drift ---------------------------------------------------------------------------------
def fx_exponential_creep(sig: Signals, amplitude_mm: float, tau_s: float) -> None:
    """Tendon creep from the run's start: y' = y - A (1 - exp(-t/tau)) (t >= 0)."""
    tt = np.maximum(sig.t, 0.0)
    sig.y = sig.y - amplitude_mm * (1.0 - np.exp(-tt / tau_s))


def fx_linear_creep(sig: Signals, rate_mm_s: float) -> None:
    """Linear creep/drift from the run's start: y' = y - r t (t >= 0)."""
    sig.y = sig.y - rate_mm_s * np.maximum(sig.t, 0.0)


# --- saturation (applied about the output centre c, half range H of the clean output) --------
def fx_soft_tanh(sig: Signals, centre_mm: float, Y_mm: float) -> None:
    """Soft saturation y' = c + Y tanh((y - c)/Y)."""
    sig.y = centre_mm + Y_mm * np.tanh((sig.y - centre_mm) / Y_mm)


def fx_hard_clip(sig: Signals, centre_mm: float, limit_mm: float) -> None:
    """Hard mechanical stops at c +/- limit: y' = clip(y, c - L, c + L)."""
    sig.y = np.clip(sig.y, centre_mm - limit_mm, centre_mm + limit_mm)


def fx_cubic_softening(sig: Signals, centre_mm: float, k3_per_mm2: float) -> None:
    """Cubic softening y' = c + x - k3 x^3, x = y - c (monotone while 3 k3 x^2 < 1)."""
    x = sig.y - centre_mm
    sig.y = centre_mm + x - k3_per_mm2 * x ** 3


# --- rate dependence ------------------------------------------------------------------------
def _lag_with_tension(sig: Signals, delta: np.ndarray, coupling: float) -> None:
    sig.y = sig.y - delta
    sig.tin = sig.tin + coupling * delta


def fx_stribeck(sig: Signals, coulomb_mm: float, stribeck_mm: float, v_s_mm_s: float, v_eps_mm_s: float = 0.05,
                tension_coupling_n_per_mm: float = 2.0) -> None:
    """Speed-dependent sheath friction (Stribeck curve) turned into extra tendon stretch:
    delta = tanh(v/v_eps) (d_c + d_s exp(-(|v|/v_s)^2)), v = du/dt;  y' = y - delta,
    T_in' = T_in + k delta (the friction is felt at the input load cell)."""
    vel = _speed(sig.t, sig.u)
    d = np.tanh(vel / v_eps_mm_s) * (coulomb_mm + stribeck_mm * np.exp(-(np.abs(vel) / v_s_mm_s) ** 2))
    _lag_with_tension(sig, d, tension_coupling_n_per_mm)


def fx_viscous(sig: Signals, b_s: float, tension_coupling_n_per_mm: float = 2.0) -> None:
    """Viscous sheath friction: y' = y - b du/dt  (and T_in' = T_in + k b du/dt)."""
    _lag_with_tension(sig, b_s * _speed(sig.t, sig.u), tension_coupling_n_per_mm)


def fx_nonlinear_damping(sig: Signals, k_mm: float, exponent: float, v_ref_mm_s: float = 1.0,
                         tension_coupling_n_per_mm: float = 2.0) -> None:
    """Nonlinear damping: delta = k sign(v) (|v|/v_ref)^a;  y' = y - delta."""
    vel = _speed(sig.t, sig.u)
    _lag_with_tension(sig, k_mm * np.sign(vel) * (np.abs(vel) / v_ref_mm_s) ** exponent, tension_coupling_n_per_mm)


def fx_relaxation(sig: Signals, tau_s: float) -> None:
    """First-order relaxation (low-pass) of the output: tau dy'/dt = y - y' (exact ZOH)."""
    y = sig.y
    out = np.empty_like(y)
    out[0] = y[0]
    dt = np.diff(sig.t)
    al = np.exp(-dt / tau_s)
    for k in range(1, y.size):
        out[k] = al[k - 1] * out[k - 1] + (1 - al[k - 1]) * y[k]
    sig.y = out


# --- asymmetry ------------------------------------------------------------------------------
def fx_loading_unloading_gain(sig: Signals, centre_mm: float, alpha: float, r_mm: float = 0.25) -> None:
    """Direction-dependent gain: y' = c + (y - c)(1 + alpha s), s = (u - z)/r in [-1, 1] the
    sliding-direction state (z a centred play of half width r on the input).  Loading branch
    gain 1 + alpha, unloading 1 - alpha; the loop closes because s is a state, not sign(du)."""
    z = play_operator_centred(sig.u, r_mm, z0=float(sig.u[0]))
    s = (sig.u - z) / r_mm
    sig.y = centre_mm + (sig.y - centre_mm) * (1.0 + alpha * s)


def fx_one_way_backlash(sig: Signals, b_mm: float, u_ref_mm: float = 0.0) -> None:
    """Slack on the push side only (memoryless: the follower spring takes the slack up):
    v = u for u >= u_ref, v = min(u_ref, u + b) below.  Equals a static dead band of half
    width b/2 centred at u_ref - b/2 (a dead zone plus an offset)."""
    v = sig.v
    sig.v = np.where(v >= u_ref_mm, v, np.minimum(u_ref_mm, v + b_mm))


def fx_pull_push_gain(sig: Signals, centre_mm: float, gain_pull: float, gain_push: float) -> None:
    """Pull side vs push side gain: y' = c + g_pull x (x > 0), c + g_push x (x <= 0)."""
    x = sig.y - centre_mm
    sig.y = centre_mm + np.where(x > 0, gain_pull * x, gain_push * x)


# --- dead zone ------------------------------------------------------------------------------
def fx_input_backlash(sig: Signals, halfwidth_mm: float) -> None:
    """Backlash (centred play, half width r) in front of the plant, started centred."""
    sig.v = play_operator_centred(sig.v, halfwidth_mm, z0=float(sig.v[0]))


def fx_static_dead_band(sig: Signals, halfwidth_mm: float, u_ref_mm: float = 0.0) -> None:
    """Static dead band around u_ref: v = u_ref for |u - u_ref| <= h, else u -/+ h."""
    x = sig.v - u_ref_mm
    sig.v = u_ref_mm + np.sign(x) * np.maximum(np.abs(x) - halfwidth_mm, 0.0)


# --- tendon stretch -------------------------------------------------------------------------
def fx_stretch(sig: Signals, side: str, power: int, c: float, F_ref_n: float) -> None:
    """Extra tendon stretch: y' = y - c (T^p - F_ref^p), T = T_in (input side) or T_out."""
    T = sig.tin if side == "input" else sig.tout
    sig.y = sig.y - c * (T ** power - F_ref_n ** power)


@dataclass(frozen=True)
class Form:
    effect: str
    form: str
    stage: str                    # "input" (before the plant) or "output" (after)
    fn: Callable[..., None]
    strengths: Mapping[str, Mapping[str, float]]
    doc: str = ""


def _F(effect, form, stage, fn, weak, strong, **extra_levels):
    lv = {"weak": weak, "strong": strong, **extra_levels}
    return Form(effect, form, stage, fn, lv, (fn.__doc__ or "").strip())


# Parameters marked "relative" (deficit_frac, ...) are resolved against the clean source output
# by form_params(); the resolved absolute values go into the ground truth.
FORMS: dict[tuple[str, str], Form] = {(f_.effect, f_.form): f_ for f_ in [
    _F("latency", "pure_delay", "output", fx_pure_delay, {"delay_s": 0.05}, {"delay_s": 0.8},
       minimal={"delay_s": 0.02}),
    _F("drift", "exponential_creep", "output", fx_exponential_creep,
       {"amplitude_mm": 0.12, "tau_s": 20.0}, {"amplitude_mm": 0.5, "tau_s": 20.0}),
    _F("drift", "linear_creep", "output", fx_linear_creep, {"rate_mm_s": 0.002}, {"rate_mm_s": 0.008}),
    _F("saturation", "soft_tanh", "output", fx_soft_tanh, {"deficit_frac": 0.04}, {"deficit_frac": 0.15}),
    _F("saturation", "hard_clip", "output", fx_hard_clip, {"deficit_frac": 0.1}, {"deficit_frac": 0.25}),
    _F("saturation", "cubic_softening", "output", fx_cubic_softening, {"deficit_frac": 0.04},
       {"deficit_frac": 0.12}),
    _F("rate_dependence", "stribeck", "output", fx_stribeck,
       {"coulomb_mm": 0.02, "stribeck_mm": 0.1, "v_s_mm_s": 1.0},
       {"coulomb_mm": 0.05, "stribeck_mm": 0.4, "v_s_mm_s": 1.0}),
    _F("rate_dependence", "viscous", "output", fx_viscous, {"b_s": 0.02}, {"b_s": 0.08}),
    _F("rate_dependence", "nonlinear_damping", "output", fx_nonlinear_damping,
       {"k_mm": 0.06, "exponent": 0.5}, {"k_mm": 0.25, "exponent": 0.5}),
    _F("rate_dependence", "relaxation", "output", fx_relaxation, {"tau_s": 0.05}, {"tau_s": 0.4}),
    _F("asymmetry", "loading_unloading_gain", "output", fx_loading_unloading_gain, {"alpha": 0.03},
       {"alpha": 0.1}),
    _F("asymmetry", "one_way_backlash", "input", fx_one_way_backlash, {"b_mm": 0.2}, {"b_mm": 0.8}),
    _F("asymmetry", "pull_push_gain", "output", fx_pull_push_gain, {"gain_pull": 1.0, "gain_push": 0.93},
       {"gain_pull": 1.0, "gain_push": 0.75}),
    _F("dead_zone", "input_backlash", "input", fx_input_backlash, {"halfwidth_mm": 0.1},
       {"halfwidth_mm": 0.4}),
    _F("dead_zone", "static_dead_band", "input", fx_static_dead_band, {"halfwidth_mm": 0.15},
       {"halfwidth_mm": 0.5}),
    _F("tendon_stretch", "linear_input", "output", fx_stretch, {"c": 0.02}, {"c": 0.06}),
    _F("tendon_stretch", "linear_output", "output", fx_stretch, {"c": 0.03}, {"c": 0.1}),
    _F("tendon_stretch", "quadratic_input", "output", fx_stretch, {"c": 0.002}, {"c": 0.006}),
    _F("tendon_stretch", "quadratic_output", "output", fx_stretch, {"c": 0.01}, {"c": 0.03}),
]}
"""Canonical (effect, form) -> Form.  Strength levels ``weak`` and ``strong`` (latency also
``minimal`` = 20 ms)."""

EFFECTS = tuple(dict.fromkeys(k[0] for k in FORMS))


def list_forms() -> list[tuple[str, str]]:
    return list(FORMS)


def form_params(effect: str, form: str, strength: str | Mapping[str, float], *, centre_mm: float = 0.0,
                halfrange_mm: float = 5.0, F_ref_n: float = 5.0) -> dict[str, Any]:
    """Absolute parameters of a form at a strength level (or explicit parameters).

    Saturation forms are given relative to the clean output (centre c, half range H), as the
    fractional deficit d of the peak: tanh: Y with Y tanh(H/Y) = (1-d) H; clip: L = (1-d) H;
    cubic: k3 = d / H^2.  Asymmetry gains act about c.  Stretch forms get side/power/F_ref."""
    fm = FORMS[(effect, form)]
    p = dict(fm.strengths[strength]) if isinstance(strength, str) else dict(strength)
    if effect == "saturation" and "deficit_frac" in p:
        d = float(p.pop("deficit_frac"))
        H = float(halfrange_mm)
        p["centre_mm"] = float(centre_mm)
        if form == "soft_tanh":
            from scipy.optimize import brentq
            p["Y_mm"] = float(brentq(lambda Y: Y * math.tanh(H / Y) - (1 - d) * H, 0.05 * H, 1e4 * H))
        elif form == "hard_clip":
            p["limit_mm"] = (1 - d) * H
        else:
            p["k3_per_mm2"] = d / H ** 2
        p["deficit_frac"] = d
    if form in ("loading_unloading_gain", "pull_push_gain"):
        p.setdefault("centre_mm", float(centre_mm))
    if effect == "tendon_stretch":
        law, end = form.split("_")  # linear|quadratic, input|output
        p.update(side=end, power=1 if law == "linear" else 2,
                 F_ref_n=float(F_ref_n))
    return p


def _call(fm: Form, sig: Signals, p: Mapping[str, Any]) -> None:
    kw = {k: v for k, v in p.items() if k != "deficit_frac"}
    fm.fn(sig, **kw)


def apply_chain(plant: str, t: np.ndarray, u: np.ndarray, effect: str | None = None, form: str | None = None,
                params: Mapping[str, Any] | None = None, plant_params: Mapping[str, Any] | None = None
                ) -> Signals:
    """Input-stage effect -> plant -> tensions -> output-stage effect, on full-length signals.

    ``params`` must be absolute (see :func:`form_params`)."""
    sig = Signals(t=np.asarray(t, float), u=np.asarray(u, float))
    sig.v = sig.u.copy()
    fm = FORMS[(effect, form)] if effect else None
    if fm and fm.stage == "input":
        _call(fm, sig, params or {})
    y, tin, tout = simulate_plant(plant, sig.v, plant_params)
    sig.y, sig.tin, sig.tout = y, tin, tout
    if fm and fm.stage == "output":
        _call(fm, sig, params or {})
    return sig


# ---------------------------------------------------------------------------------------------
# Identifiability
# ---------------------------------------------------------------------------------------------

_PI_CLASS_PLANTS = ("play_sum", "preisach", "tendon_sheath")


def identifiability(effect: str | None, form: str | None, plant: str, channels: Sequence[str]) -> dict[str, Any]:
    """Which effects cannot be told apart on the channels present, and why (ground truth).

    Fields: ``class`` (equivalence-class label), ``identifiable`` (can the effect be told from
    the bare plant at all), ``identifiable_with`` (other (effect, form) pairs, or
    ``["plant", <model class>]``, that produce the same data on these channels),
    ``confusable_with`` (near-equivalent at small strength / on some excitations only),
    ``absorbed_by`` (model classes closed under the effect), ``needs_channels``, ``reason``.

    Physics used:
    * play_b o play_p = play_{p+b} (semigroup of play operators), and a relay behind a play of
      half width b is a relay with thresholds alpha + b, beta - b: a backlash in front of a
      play-sum or a Preisach plane stays in that class (just wider plays / a density moved away
      from the diagonal).  The quasi-static capstan tendon (rate-independent, wiping-out memory)
      behaves as a play-type operator too.
    * A one-way (push-side) slack b is the static dead band of half width b/2 applied to
      u + b/2: a dead zone plus an input offset; shift-invariant plants (plays, Bouc-Wen,
      Duhem, tendon) turn the offset into an output offset, invisible on relative encoders.
    * Y tanh(x/Y) = x - x^3/(3Y^2) + ...: weak tanh saturation and cubic softening coincide.
    * For smooth, slow inputs y(t - d) ~ y - d dy/dt; a first-order lag of time constant tau
      ~ delay tau; viscous lag b du/dt ~ delay b when dy/du ~ 1: latency, relaxation and
      viscous friction form a phase-lag family, separated only at triangle corners (du/dt
      jumps: viscous steps, relaxation decays exponentially, delay shifts) and by the
      unshifted tension channel (latency delays the output only).
    * Stretch proportional to T_out = F0 + K_L y is a pure gain change (the output spring is
      linear): absorbed by any plant gain, with or without load cells.
    * Stretch proportional to T_in = T_out exp(mu theta s), s a play state: without a tension
      channel it is a play-like lost motion plus a gain change, absorbed by a play-sum; with
      the load cell the residual regresses on T_in (and T_in^2 for the quadratic form).
    * Coulomb part of the Stribeck friction = sign-of-velocity offset = a play (absorbed by
      play-type plants); only the speed-dependent part is new, and only on excitations whose
      speed varies (on a constant-slope triangle it is again a constant per direction).
    """
    ch = set(channels)
    has_lc = "loadcell" in ch
    r: dict[str, Any] = {"class": None, "identifiable": True, "identifiable_with": [], "confusable_with": [],
                         "absorbed_by": [], "needs_channels": ["encoder"], "reason": ""}
    if effect is None:
        r.update({"class": "clean", "identifiable": True, "reason": "no effect: the plant alone"})
        return r
    key = (effect, form)
    if key == ("latency", "pure_delay"):
        r.update({"class": "phase_lag",
                  "confusable_with": [["rate_dependence", "relaxation"], ["rate_dependence", "viscous"]],
                  "reason": "y(t-d) ~ y - d dy/dt for slow smooth inputs; separated at triangle corners "
                            "and (with load cells) by the unshifted tension channel"})
    elif effect == "drift":
        r.update({"class": "time_drift",
                  "confusable_with": [["drift", "linear_creep" if form == "exponential_creep" else "exponential_creep"]],
                  "reason": "a function of time since the run start, not of the input; exponential with "
                            "tau >> run or linear differ only by curvature in time"})
    elif key in (("saturation", "soft_tanh"), ("saturation", "cubic_softening")):
        other = "cubic_softening" if form == "soft_tanh" else "soft_tanh"
        r.update({"class": "odd_static_softening", "confusable_with": [["saturation", other]],
                  "reason": "Y tanh(x/Y) = x - x^3/(3 Y^2) + O(x^5): identical to first order in the "
                            "deficit; a single-amplitude run is partly absorbed by negative play weights, "
                            "decaying amplitudes separate it"})
    elif key == ("saturation", "hard_clip"):
        r.update({"class": "hard_stop", "reason": "flat tops at absolute output levels"})
    elif key == ("rate_dependence", "stribeck"):
        r.update({"class": "speed_dependent_friction",
                  "confusable_with": [["rate_dependence", "nonlinear_damping"], ["dead_zone", "input_backlash"]],
                  "reason": "Coulomb part = play (absorbed by play-type plants); the Stribeck drop needs "
                            "runs of varying speed (sine, multisine); on a constant-slope triangle it is a "
                            "constant per direction"})
        if plant in _PI_CLASS_PLANTS:
            r["absorbed_by"] = ["play_sum (Coulomb part only)"]
    elif key == ("rate_dependence", "viscous"):
        r.update({"class": "phase_lag",
                  "confusable_with": [["latency", "pure_delay"], ["rate_dependence", "relaxation"]],
                  "reason": "b du/dt ~ delay b for smooth inputs; steps of 2 b v at triangle corners "
                            "identify it; the input tension carries k b du/dt too"})
    elif key == ("rate_dependence", "nonlinear_damping"):
        r.update({"class": "speed_dependent_friction",
                  "confusable_with": [["rate_dependence", "viscous"], ["rate_dependence", "stribeck"]],
                  "reason": "|v|^a with a = 0.5: between Coulomb (a -> 0, a play) and viscous (a = 1); "
                            "needs several speeds"})
    elif key == ("rate_dependence", "relaxation"):
        r.update({"class": "phase_lag",
                  "confusable_with": [["latency", "pure_delay"], ["rate_dependence", "viscous"]],
                  "reason": "first-order lag ~ delay tau at low frequency; exponential settling after "
                            "triangle corners identifies it"})
    elif key == ("asymmetry", "loading_unloading_gain"):
        r.update({"class": "direction_dependent_gain",
                  "reason": "product of the output and a direction state: not a linear sum of plays"})
    elif key == ("asymmetry", "one_way_backlash"):
        r.update({"class": "static_dead_zone", "identifiable": True,
                  "identifiable_with": [["dead_zone", "static_dead_band"]],
                  "reason": "push-side slack b == static dead band of half width b/2 on u + b/2 (dead "
                            "zone plus offset); the offset is invisible on relative encoders for "
                            "shift-invariant plants"})
        if plant == "preisach":  # fixed relay thresholds: an input offset is not invisible
            r.update({"identifiable_with": [], "confusable_with": [["dead_zone", "static_dead_band"]]})
    elif key == ("asymmetry", "pull_push_gain"):
        r.update({"class": "side_dependent_gain", "confusable_with": [["saturation", "hard_clip"]],
                  "reason": "static kink at the output centre; one-sided, so not odd like saturation"})
    elif key == ("dead_zone", "input_backlash"):
        r.update({"class": "play_width", "absorbed_by": ["play_sum", "preisach"],
                  "confusable_with": [["rate_dependence", "stribeck"]],
                  "reason": "play_b o play_p = play_{p+b}; relay o play = relay with widened thresholds"})
        if plant in _PI_CLASS_PLANTS:
            r.update({"identifiable": False, "identifiable_with": [["plant", "play_sum"]]})
    elif key == ("dead_zone", "static_dead_band"):
        r.update({"class": "static_dead_zone", "identifiable_with": [["asymmetry", "one_way_backlash"]],
                  "reason": "memoryless flat around u = 0 (differs from a play's flat after reversals); "
                            "a push-side slack plus offset gives the same shape"})
        if plant == "preisach":
            r.update({"identifiable_with": [], "confusable_with": [["asymmetry", "one_way_backlash"]]})
    elif key == ("tendon_stretch", "linear_output"):
        r.update({"class": "gain_change", "identifiable": False, "identifiable_with": [["plant", "gain"]],
                  "absorbed_by": ["any plant model with a free gain"], "needs_channels": ["encoder", "loadcell"],
                  "reason": "T_out = F0 + K_L y exactly (linear follower spring): c T_out is a gain change "
                            "and an offset, collinear with y even with the load cell"})
    elif key == ("tendon_stretch", "quadratic_output"):
        r.update({"class": "tension_squared_output", "needs_channels": ["encoder", "loadcell"],
                  "confusable_with": [["plant", "gain"]],
                  "reason": "c (T_out^2 - F0^2) = gain change + c K_L^2 y^2: only the even y^2 part is "
                            "visible; with the load cell it regresses on T_out^2"})
    elif effect == "tendon_stretch":  # input side
        r.update({"class": "tension_proportional" if form == "linear_input" else "tension_squared_input",
                  "needs_channels": ["encoder", "loadcell"],
                  "confusable_with": [["tendon_stretch", "quadratic_input" if form == "linear_input" else "linear_input"]],
                  "reason": "T_in = T_out exp(mu theta s) with s a play state: without the tension channel "
                            "the stretch is a play-like lost motion plus a gain (absorbed by a play-sum); "
                            "with it the residual regresses on T_in"})
        if not has_lc:
            r.update({"identifiable": False, "identifiable_with": [["plant", "play_sum"], ["dead_zone", "input_backlash"]],
                      "absorbed_by": ["play_sum"]})
    else:  # pragma: no cover
        raise ValueError(key)
    if not has_lc and effect == "tendon_stretch":
        r["reason"] += " [no load-cell channel in this source]"
    return r


# ---------------------------------------------------------------------------------------------
# Writers
# ---------------------------------------------------------------------------------------------

NOISE = {"output_sd_mm": 0.002, "counts_per_unit": 1000, "loadcell_sd_n": 0.02}


def _run_chain(plant, t_run, u_run, loaded, effect, form, params, plant_params):
    pre = prehistory(loaded, u0=float(u_run[0]))
    t_pre = (np.arange(pre.size) - pre.size) * DT_S
    t = np.concatenate([t_pre, t_run])
    u = np.concatenate([pre, u_run])
    sig = apply_chain(plant, t, u, effect, form, params, plant_params)
    n0 = pre.size
    return sig.y[n0:], sig.tin[n0:], sig.tout[n0:]


def _ragged_faults(ragged: str | None, run_index: int) -> list[str]:
    """``None``; ``"end"``: every load-cell stream ends 2-5 encoder periods early; ``"gap"``:
    a 3-8-period gap mid-run; ``"mixed"``: run 2 ragged end, run 3 gap."""
    if not ragged:
        return []
    k_end = 2 + run_index % 4
    k_gap = 3 + run_index % 6
    if ragged == "end":
        return [f"ragged_loadcell_end:{k_end}"]
    if ragged == "gap":
        return [f"loadcell_gap:{k_gap}"]
    if ragged == "mixed":
        return {0: [], 1: [f"ragged_loadcell_end:{k_end}"], 2: [f"loadcell_gap:{k_gap}"]}[run_index % 3]
    raise ValueError(f"ragged must be None, 'end', 'gap' or 'mixed', not {ragged!r}")


def write_source(root: str | Path, plant: str, effect: str | None = None, form: str | None = None,
                 strength: str | Mapping[str, float] = "strong", *, loaded: str | None = None,
                 kinds: Sequence[str] = ("sine_decay", "triangle_decay", "multisine"), loadcell: bool = True,
                 loadcell_rate_hz: float | None = 1000.0, ragged: str | None = None, seed: int = 0,
                 source_id: str | None = None, plant_params: Mapping[str, Any] | None = None,
                 run_index_base: int = 1, gzip_files: bool = False, truth_file: bool = True) -> dict[str, Any]:
    """Write one source folder ``<root>/<source_id>/`` holding one run folder per excitation
    (3 x 80 s by default), all from ``plant`` with the hidden effect (``effect``, ``form``) at
    ``strength`` (``"weak"``, ``"strong"``, another level of the form, or explicit params).
    ``effect=None`` writes a clean source.  ``loaded``: None / ``"above"`` / ``"below"``.
    ``ragged``: None / ``"end"`` / ``"gap"`` / ``"mixed"`` load-cell streams.

    Returns the ground-truth dict; with ``truth_file`` it is also written to
    ``<root>/<source_id>.truth.json`` (outside the source folder)."""
    rl = _riglog()
    if effect is not None and (effect, form) not in FORMS:
        raise ValueError(f"unknown (effect, form) {(effect, form)!r}; known {list(FORMS)}")
    root = Path(root)
    sid = source_id or (f"{plant}__{effect}__{form}__{strength}" if effect else f"{plant}__clean__{loaded or 'virgin'}")
    pp = plant_defaults(plant)
    pp.update(plant_params or {})
    exc = source_excitations(kinds, seed=seed)
    # clean outputs (for relative parameters and effect size)
    clean = [_run_chain(plant, t, u, loaded, None, None, None, pp) for t, u, _ in exc]
    ys = np.concatenate([c[0] for c in clean])
    centre = 0.5 * (ys.max() + ys.min())
    half = 0.5 * (ys.max() - ys.min())
    params = None
    if effect is not None:
        params = form_params(effect, form, strength, centre_mm=centre, halfrange_mm=half,
                             F_ref_n=float(pp.get("F0_n", 5.0)))
    rng = np.random.default_rng(seed + 7919)
    channels = ["encoder"] + (["loadcell"] if loadcell else [])
    runs = []
    for i, ((t, u, exman), (y0, _, _)) in enumerate(zip(exc, clean)):
        y, tin, tout = _run_chain(plant, t, u, loaded, effect, form, params, pp) if effect else clean[i]
        d = y - y0
        # size of the effect net of the best affine map of the clean output (gain/offset)
        X = np.column_stack([y0, np.ones_like(y0)])
        resid = d - X @ np.linalg.lstsq(X, d, rcond=None)[0]
        y_meas = y + rng.normal(0.0, NOISE["output_sd_mm"], y.shape)
        idx = run_index_base + i
        kind = exman["kind"]
        rid = rl.run_id_for(CONFIG, kind, idx)
        faults = _ragged_faults(ragged, i) if loadcell else []
        rl.write_run_folder(
            root / sid, rid, t, u, y_meas, configuration=CONFIG, excitation=exman,
            counts_per_unit=NOISE["counts_per_unit"],
            loadcell=(tin, tout) if loadcell else None, loadcell_rate_hz=loadcell_rate_hz,
            loadcell_noise_n=NOISE["loadcell_sd_n"], faults=faults, events=True,
            started_at=rl._start_time(idx), seed=seed * 1000 + idx, gzip_files=gzip_files,
        )
        runs.append({
            "run_id": rid, "excitation": kind, "faults": faults,
            "effect_rms_mm": float(np.sqrt(np.mean(d ** 2))), "effect_peak_mm": float(np.max(np.abs(d))),
            "effect_rms_beyond_gain_mm": float(np.sqrt(np.mean(resid ** 2))),
            "tension_in_range_n": [float(tin.min()), float(tin.max())],
            "tension_out_range_n": [float(tout.min()), float(tout.max())],
        })
    noise_floor = math.hypot(NOISE["output_sd_mm"], 1.0 / NOISE["counts_per_unit"] / math.sqrt(12))
    truth = {
        "source_id": sid, "path": sid, "plant": plant, "plant_params": pp, "loaded_start": loaded,
        "effect": effect, "form": form,
        "strength": None if effect is None else (strength if isinstance(strength, str) else "custom"),
        "stage": FORMS[(effect, form)].stage if effect else None,
        "params": params, "channels": channels, "ragged": ragged if loadcell else None,
        "clean_output_centre_mm": float(centre), "clean_output_halfrange_mm": float(half),
        "identifiability": identifiability(effect, form, plant, channels),
        "noise": dict(NOISE, quantisation_mm=1.0 / NOISE["counts_per_unit"], noise_floor_rms_mm=noise_floor),
        "effect_to_noise": (min(r["effect_rms_mm"] for r in runs) / noise_floor) if effect else 0.0,
        "runs": runs,
        "seed": seed,
    }
    if truth_file:
        root.mkdir(parents=True, exist_ok=True)
        (root / f"{sid}.truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def write_matrix(root: str | Path, plants: Sequence[str] = ("play_sum", "bouc_wen", "preisach", "tendon_sheath"),
                 strengths: Sequence[str] = ("weak", "strong"), seed: int = 0, *,
                 forms: Sequence[tuple[str, str]] | None = None, clean_loaded: Sequence[str | None] = (None, "above"),
                 loaded_every: int = 3, ragged_every: int = 4, loadcell_rate_hz: float | None = 200.0,
                 opaque_ids: bool = True, gzip_files: bool = False) -> list[dict[str, Any]]:
    """Write every form x plant x strength source plus clean sources (one per plant and entry of
    ``clean_loaded``) under ``<root>/sources/`` and the ground-truth manifest
    ``<root>/ground_truth.json`` (list of the per-source truth dicts, returned).

    Source folders are named ``S0001``, ... (``opaque_ids``) so names leak nothing.  Every
    ``loaded_every``-th effect source starts loaded (alternately from above/below); every
    ``ragged_every``-th source has ragged load-cell streams (``mixed``).  Load cells are written
    at ``loadcell_rate_hz`` (200 Hz by default to keep the matrix small; the spec's nominal 1 kHz
    is the default of :func:`write_source`)."""
    root = Path(root)
    src_root = root / "sources"
    items: list[tuple[str, str | None, str | None, str, str | None]] = []
    for plant in plants:
        for lo in clean_loaded:
            items.append((plant, None, None, "none", lo))
    fl = list(forms) if forms is not None else list(FORMS)
    j = 0
    for plant in plants:
        for (eff, frm) in fl:
            for st in strengths:
                j += 1
                lo = (("above", "below")[(j // loaded_every) % 2]) if loaded_every and j % loaded_every == 0 else None
                items.append((plant, eff, frm, st, lo))
    truths = []
    for n, (plant, eff, frm, st, lo) in enumerate(items, start=1):
        sid = f"S{n:04d}" if opaque_ids else None
        rag = "mixed" if ragged_every and n % ragged_every == 0 else None
        tr = write_source(src_root, plant, eff, frm, st if eff else "strong", loaded=lo, ragged=rag,
                          seed=seed + n, source_id=sid, run_index_base=10 * n + 1,
                          loadcell_rate_hz=loadcell_rate_hz, gzip_files=gzip_files, truth_file=False)
        tr["path"] = f"sources/{tr['source_id']}"
        truths.append(tr)
    manifest = {"generator": "cleanroom2.effects", "format_of_runs": "tsm-rig-log/1", "seed": seed,
                "forms": [list(k) for k in fl], "sources": truths}
    (root / "ground_truth.json").write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    return truths
