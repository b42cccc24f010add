"""Clean-room sources for judging the *form* of a hidden effect: near and far form pairs.

What it makes
-------------
Raw ``tsm-rig-log/1`` sources (one folder of three 80 s runs each) from two textbook
hysteresis plants with exactly one hidden effect per source, and a ground-truth file
``form_pairs_truth.json`` that says, for every source, whether the effect's *form* can be told
apart from the other forms of the same effect on these records:

* plants (input u = proximal tendon displacement in mm, output y = distal displacement in mm):
  ``play_sum``, a Prandtl-Ishlinskii sum of seven play operators with positive weights, radii
  0 to 1.5 mm and unit overall gain (loop about 1 mm wide at +-6 mm), and ``bouc_wen``, a
  Bouc-Wen loop (n = 1) written as y = a u + (1 - a) z, about 1 mm wide at +-6 mm;
* runs: identification = decaying sine (6, 4.5, 3, 1.5 mm, 0.25 Hz, 80 s); held out = a
  decaying triangle at 6 mm/s (8 periods per amplitude, 80 s) and a decaying trapezoid at
  2.5 mm/s with 2 s dwells (2 periods per amplitude, 80 s).  The two held-out speeds differ on
  purpose: on a triangle or trapezoid every rate law is a function of one or two speed levels,
  so only two different speeds (and the dwells) let the rate forms show their shape;
* output noise: Gaussian, sd 0.01 mm on the output encoder (the encoder records position from
  the first sample, so that sample's noise is a constant offset of the run, about 0.01 mm);
  load cells (1 kHz) from a capstan picture (output tension from a constant-force spring plus
  a small rate, input tension e^{+-mu theta} times it with the sign of the speed);
* effects and their forms (applied to the plant's output, noise-free):

  - drift: ``exponential_creep`` y += A (1 - exp(-t/tau)); ``linear_creep`` y += B t / T_run
  - saturation (about the output centre c): ``soft_tanh`` y -> c + Y tanh((y - c)/Y);
    ``hard_clip`` y -> clip(y, c - L, c + L), L near the top of the range;
    ``cubic_softening`` y -= k (y - c)^3
  - rate_dependence (v = du/dt): ``viscous`` y -= c v; ``nonlinear_damping``
    y -= c sign(v) |v / v_ref|^a; ``relaxation`` y -= c (first-order low-pass of v, time
    constant T)

  Each effect has *near* sources (another form reproduces it within the noise: exponential
  creep with tau = 400 s on an 80 s run, a tanh stop with a large Y, a = 1.05 damping, a
  relaxation with T = 5 ms, linear creep and viscous damping which are limits of other forms)
  and *far* sources (tau = 8 s, a hard clip, a tanh stop with a small Y, a = 0.5, T = 1 s).

Ground truth (an oracle independent of any product code): for every source and every OTHER form
of the same effect, that form's closed-form contribution alpha * g(t; theta) (free linear
coefficient alpha, the nonlinear parameter theta by a bounded grid + 1-D search) is fitted by
least squares to the true contribution d = y_with_effect - y_plain on the two held-out runs
together.  Its misfit RMS, in units of the noise sd, gives the verdict: < 0.5 indistinguishable,
> 2 distinguishable, borderline between; ``separable`` is false if any alternative is
indistinguishable, true if all are distinguishable, else null.

Written from: textbook physics (play operators / Prandtl-Ishlinskii, Bouc-Wen, creep, stops,
damping laws, capstan friction), the rig-log specification ``../shared/rig-log-format.md``, the
seeds' README ``../shared/seeds/README.md`` and ``riglog.py`` beside this file (found by the
``CLEANROOM_RIGLOG`` environment variable if set), whose writers produce the run folders.  The
project's implementation, tests and docs were not read.

Usage::

    python tests/cleanroom/form_pairs.py OUT_DIR [--seed N]

API: ``write_all(root, seed=0) -> truth dict``; ``write_source(root, plant, effect, form,
params, seed)`` for one source.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

__all__ = [
    "NOISE_SD_MM",
    "FORMS",
    "EFFECT_FORMS",
    "SOURCES",
    "PLANTS",
    "play_sum_plant",
    "bouc_wen_plant",
    "run_excitations",
    "effect_contribution",
    "fit_alternative",
    "oracle",
    "write_source",
    "write_all",
]

NOISE_SD_MM = 0.01
T_RUN_S = 80.0
TRUTH_FILE = "form_pairs_truth.json"
INDISTINGUISHABLE_BELOW = 0.5  # misfit RMS in noise sd
DISTINGUISHABLE_ABOVE = 2.0
CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
V_REF_MM_S = 5.0  # reference speed of the nonlinear damping law (only rescales its coefficient)


# ---------------------------------------------------------------------------------------------
# riglog (imported by file path, so this module works from any working directory)
# ---------------------------------------------------------------------------------------------


def _load_riglog() -> Any:
    path = Path(os.environ.get("CLEANROOM_RIGLOG") or Path(__file__).with_name("riglog.py"))
    name = "_form_pairs_riglog"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load riglog from {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses look their module up while the class is built
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()


# ---------------------------------------------------------------------------------------------
# Plants (rate-independent, started relaxed at u = 0)
# ---------------------------------------------------------------------------------------------

# Play radii spread to 1.5 mm; weights positive and summing to 1 (unit gain on large strokes).
# Loop width at u = 0 on the +-6 mm loop is 2 sum(w r) = 1.05 mm.
PLAY_RADII_MM = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
PLAY_WEIGHTS = (0.4, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1)

# Bouc-Wen, n = 1: dz = A du - beta |du| z - gamma du |z|; z saturates at A / (beta + gamma)
# = 1.25 mm, so the loop of y = a u + (1 - a) z is (1 - a) * ~2.45 mm ~ 1 mm wide.
BW_A, BW_BETA, BW_GAMMA, BW_LINEAR = 1.0, 0.4, 0.4, 0.6


def _play(u: np.ndarray, r: float) -> np.ndarray:
    """Play (backlash) operator of half-width r, state 0 at the start (u[0] = 0, relaxed)."""
    z = np.empty_like(u)
    zk = 0.0
    for k, uk in enumerate(u):
        zk = min(uk + r, max(uk - r, zk))
        z[k] = zk
    return z


def play_sum_plant(u: np.ndarray) -> np.ndarray:
    """Prandtl-Ishlinskii: y = sum_i w_i P_{r_i}[u]."""
    return sum((w * _play(u, r) for w, r in zip(PLAY_WEIGHTS, PLAY_RADII_MM)), np.zeros_like(u))


def bouc_wen_plant(u: np.ndarray, substeps: int = 4) -> np.ndarray:
    """Bouc-Wen (n = 1), integrated in the input (rate-independent), RK2 on sub-steps of du."""
    z = np.empty_like(u)
    zk = 0.0

    def rate(zz: float, du: float) -> float:
        return BW_A * du - BW_BETA * abs(du) * zz - BW_GAMMA * du * abs(zz)

    z[0] = zk
    for k in range(1, u.size):
        h = (u[k] - u[k - 1]) / substeps
        for _ in range(substeps):
            mid = zk + 0.5 * rate(zk, h)
            zk = zk + rate(mid, h)
        z[k] = zk
    return BW_LINEAR * u + (1.0 - BW_LINEAR) * z


PLANTS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "play_sum": play_sum_plant,
    "bouc_wen": bouc_wen_plant,
}
PLANT_DESCRIPTIONS = {
    "play_sum": {
        "kind": "prandtl_ishlinskii",
        "radii_mm": list(PLAY_RADII_MM),
        "weights": list(PLAY_WEIGHTS),
    },
    "bouc_wen": {
        "kind": "bouc_wen",
        "n": 1,
        "A": BW_A,
        "beta": BW_BETA,
        "gamma": BW_GAMMA,
        "a": BW_LINEAR,
    },
}


# ---------------------------------------------------------------------------------------------
# Excitations: three 80 s runs per source
# ---------------------------------------------------------------------------------------------

# (role, riglog kind, keywords).  All last 80 s at the 10 ms encoder period.
RUNS: tuple[tuple[str, str, dict[str, float]], ...] = (
    ("identification", "sine_decay", {}),
    ("held_out", "triangle_decay", {"slope_mm_s": 6.0, "periods_per_amplitude": 8}),
    (
        "held_out",
        "trapezoid_decay",
        {"slope_mm_s": 2.5, "periods_per_amplitude": 2, "dwell_s": 2.0},
    ),
)


@dataclass(frozen=True)
class Run:
    role: str
    kind: str
    t: np.ndarray
    u: np.ndarray
    v: np.ndarray  # du/dt, mm/s
    manifest: dict[str, Any]


@cache
def run_excitations() -> tuple[Run, ...]:
    runs = []
    for role, kind, kw in RUNS:
        ex = riglog.make_excitation(kind, riglog.ENCODER_DT_S, **kw)
        runs.append(Run(role, kind, ex.t_s, ex.u, np.gradient(ex.u, ex.t_s), dict(ex.manifest)))
    return tuple(runs)


@cache
def _plain_outputs(plant: str) -> tuple[np.ndarray, ...]:
    """Noise-free plant outputs of the three runs (the same for every source of one plant)."""
    return tuple(PLANTS[plant](r.u) for r in run_excitations())


def output_centre(plant: str) -> float:
    """Centre of the output range on the identification run (the saturation's centre c)."""
    y = _plain_outputs(plant)[0]
    return 0.5 * float(y.max() + y.min())


def output_half_range(plant: str) -> float:
    y = _plain_outputs(plant)[0]
    return 0.5 * float(y.max() - y.min())


# ---------------------------------------------------------------------------------------------
# Effect forms: contribution = alpha * g(context; theta)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Ctx:
    """What a form's shape may depend on, for one run."""

    t: np.ndarray
    v: np.ndarray
    x: np.ndarray  # plain output about the centre, y - c
    dt: float


def _low_pass(v: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """First-order low-pass, exact for a sampled step input, state 0 before the run."""
    b = math.exp(-dt / tau)
    return np.asarray(lfilter([1.0 - b], [1.0, -b], v), dtype=float)


@dataclass(frozen=True)
class Form:
    """One physical form of one effect.

    ``shape(ctx, theta)`` is g; the contribution is alpha * g.  ``coef`` names alpha in the
    source parameters (None: alpha is 1 by the form's definition, free only when fitting);
    ``nonlin`` names theta, searched in ``bounds`` (on a log scale if ``log``).
    """

    effect: str
    shape: Callable[[Ctx, float], np.ndarray]  # theta is nan for a form without one
    coef: str | None
    nonlin: str | None = None
    bounds: tuple[float, float] | None = None
    log: bool = True


# Search bounds reach each form's limits on purpose: tau to 4000 s (50 runs long, where an
# exponential is a line), Y to 300 mm (a tanh that is a cubic), a through 1 (viscous), T down
# to 2 ms (a relaxation that is viscous).  A form that is the limit of another is then judged
# as the other would be by an honest fit, not separated by an arbitrary bound.
FORMS: dict[str, Form] = {
    "exponential_creep": Form(
        "drift", lambda c, tau: 1.0 - np.exp(-c.t / tau), "A_mm", "tau_s", (0.5, 4000.0)
    ),
    "linear_creep": Form("drift", lambda c, _: c.t / T_RUN_S, "B_mm"),
    "soft_tanh": Form(
        "saturation", lambda c, y: y * np.tanh(c.x / y) - c.x, None, "Y_mm", (0.3, 300.0)
    ),
    # the clip level is searched up to past the range, where the clip does nothing
    "hard_clip": Form(
        "saturation", lambda c, lv: np.clip(c.x, -lv, lv) - c.x, None, "L_mm", (0.3, 8.0), False
    ),
    "cubic_softening": Form("saturation", lambda c, _: -(c.x**3), "k_per_mm2"),
    "viscous": Form("rate_dependence", lambda c, _: -c.v, "c_s"),
    "nonlinear_damping": Form(
        "rate_dependence",
        lambda c, a: -np.sign(c.v) * np.abs(c.v / V_REF_MM_S) ** a,
        "c_mm",
        "a",
        (0.2, 3.0),
        False,
    ),
    "relaxation": Form(
        "rate_dependence", lambda c, tau: -_low_pass(c.v, tau, c.dt), "c_s", "T_s", (0.002, 30.0)
    ),
}
EFFECT_FORMS: dict[str, tuple[str, ...]] = {}
for _name, _form in FORMS.items():
    EFFECT_FORMS.setdefault(_form.effect, ())
    EFFECT_FORMS[_form.effect] += (_name,)


def _contexts(plant: str, roles: tuple[str, ...] = ("held_out",)) -> list[Ctx]:
    c = output_centre(plant)
    out = []
    for run, y in zip(run_excitations(), _plain_outputs(plant)):
        if run.role in roles:
            out.append(Ctx(run.t, run.v, y - c, float(run.t[1] - run.t[0])))
    return out


def _shape(form: str, ctxs: list[Ctx], theta: float | None) -> np.ndarray:
    th = math.nan if theta is None else theta
    return np.concatenate([FORMS[form].shape(c, th) for c in ctxs])


def effect_contribution(form: str, params: Mapping[str, float], ctx: Ctx) -> np.ndarray:
    """True contribution d = y_with_effect - y_plain of ``form`` with ``params`` on one run."""
    f = FORMS[form]
    alpha = 1.0 if f.coef is None else float(params[f.coef])
    theta = math.nan if f.nonlin is None else float(params[f.nonlin])
    return alpha * f.shape(ctx, theta)


# ---------------------------------------------------------------------------------------------
# Oracle: best fit of every other form to the true contribution
# ---------------------------------------------------------------------------------------------


def _ls_misfit(g: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """Least-squares alpha for d ~ alpha g and the RMS of what is left."""
    # elementwise sums, not ``@``: a threaded BLAS dot on 16k samples is slower on a busy machine
    gg = float(np.sum(g * g))
    alpha = float(np.sum(g * d)) / gg if gg > 0 else 0.0
    return alpha, float(np.sqrt(np.mean((d - alpha * g) ** 2)))


def fit_alternative(form: str, ctxs: list[Ctx], d: np.ndarray) -> dict[str, Any]:
    """Fit ``form`` (alpha free, theta by a 64-point grid then a bounded 1-D search between the
    grid neighbours of the best point) to ``d`` on the runs ``ctxs``; misfit RMS in mm."""
    f = FORMS[form]
    if f.nonlin is None:
        alpha, mis = _ls_misfit(_shape(form, ctxs, None), d)
        return {"misfit_rms_mm": mis, "alpha": alpha, "theta": None}
    lo, hi = f.bounds  # type: ignore[misc]
    to_x = (lambda th: math.log(th)) if f.log else (lambda th: th)
    from_x = (lambda x: math.exp(x)) if f.log else (lambda x: x)
    grid = np.linspace(to_x(lo), to_x(hi), 64)

    def cost(x: float) -> float:
        return _ls_misfit(_shape(form, ctxs, from_x(x)), d)[1]

    costs = [cost(x) for x in grid]
    i = int(np.argmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(
        cost, bounds=(a, b), method="bounded", options={"xatol": 1e-4 * (grid[1] - grid[0])}
    )
    x_best = float(res.x) if res.fun < costs[i] else float(grid[i])
    theta = from_x(x_best)
    alpha, mis = _ls_misfit(_shape(form, ctxs, theta), d)
    return {"misfit_rms_mm": mis, "alpha": alpha, "theta": theta}


def _verdict(misfit_sd: float) -> str:
    if misfit_sd < INDISTINGUISHABLE_BELOW:
        return "indistinguishable"
    if misfit_sd > DISTINGUISHABLE_ABOVE:
        return "distinguishable"
    return "borderline"


def oracle(
    plant: str, form: str, params: Mapping[str, float], noise_sd: float = NOISE_SD_MM
) -> dict[str, Any]:
    """Contribution RMS on the held-out runs and each other form's misfit and verdict."""
    ctxs = _contexts(plant)
    d = np.concatenate([effect_contribution(form, params, c) for c in ctxs])
    alts: dict[str, Any] = {}
    for other in EFFECT_FORMS[FORMS[form].effect]:
        if other == form:
            continue
        fit = fit_alternative(other, ctxs, d)
        alts[other] = {
            "misfit_rms_mm": round(fit["misfit_rms_mm"], 6),
            "misfit_in_noise_sd": round(fit["misfit_rms_mm"] / noise_sd, 3),
            "verdict": _verdict(fit["misfit_rms_mm"] / noise_sd),
            "best_fit": {
                "alpha": round(fit["alpha"], 6),
                "theta": None if fit["theta"] is None else round(fit["theta"], 6),
            },
        }
    verdicts = {a["verdict"] for a in alts.values()}
    separable = (
        False
        if "indistinguishable" in verdicts
        else (True if verdicts == {"distinguishable"} else None)
    )
    return {
        "contribution_rms_mm": round(float(np.sqrt(np.mean(d**2))), 6),
        "alternatives": alts,
        "separable": separable,
    }


# ---------------------------------------------------------------------------------------------
# Source list: near (another form reproduces it) and far (forms clearly differ) per plant
# ---------------------------------------------------------------------------------------------

# (plant, effect, form, params, design).  Saturation scales are given relative to each plant's
# half range h (L_frac, Y_frac: times h; k_rel: k = k_rel / h^2) so that "near the top" and
# "nearly cubic" mean the same on both plants; _resolve turns them into mm.  A tanh stop of
# scale Y is y - x^3/(3 Y^2) + 2 x^5/(15 Y^4) - ...: with Y = 2 h the x^5 term that tells it
# from a cubic stays within the noise while the cubic part is well above it.
_COMMON: tuple[tuple[str, str, dict[str, float], str], ...] = (
    ("drift", "exponential_creep", {"A_mm": 1.5, "tau_s": 400.0}, "near"),
    ("drift", "exponential_creep", {"A_mm": 0.3, "tau_s": 8.0}, "far"),
    ("saturation", "soft_tanh", {"Y_frac": 2.0}, "near"),
    ("saturation", "cubic_softening", {"k_rel": 0.08}, "near"),
    ("saturation", "hard_clip", {"L_frac": 0.8}, "far"),
    ("rate_dependence", "nonlinear_damping", {"c_mm": 0.12, "a": 1.05}, "near"),
    ("rate_dependence", "nonlinear_damping", {"c_mm": 0.4, "a": 0.5}, "far"),
    ("rate_dependence", "relaxation", {"c_s": 0.025, "T_s": 0.005}, "near"),
    ("rate_dependence", "relaxation", {"c_s": 0.08, "T_s": 1.0}, "far"),
)
_EXTRA = {
    "play_sum": (
        ("drift", "linear_creep", {"B_mm": 0.3}, "near"),
        ("saturation", "soft_tanh", {"Y_frac": 0.45}, "far"),
    ),
    "bouc_wen": (
        ("rate_dependence", "viscous", {"c_s": 0.025}, "near"),
        ("saturation", "hard_clip", {"L_frac": 0.7}, "far"),
    ),
}
SOURCES: tuple[tuple[str, str | None, str | None, dict[str, float], str], ...] = tuple(
    (plant, eff, form, dict(p), design)
    for plant in ("play_sum", "bouc_wen")
    for eff, form, p, design in _COMMON + _EXTRA[plant]
) + (("play_sum", None, None, {}, "clean"), ("bouc_wen", None, None, {}, "clean"))


def _resolve(plant: str, form: str | None, params: Mapping[str, float]) -> dict[str, float]:
    """Add the centre c and turn a clip fraction into a level in mm."""
    p = {k: float(v) for k, v in params.items()}
    if form is not None and FORMS[form].effect == "saturation":
        half = output_half_range(plant)
        p.setdefault("centre_mm", round(output_centre(plant), 6) + 0.0)  # no "-0.0"
        # scales given relative to the plant's half range h (the two plants' ranges differ)
        if "L_frac" in p:
            p["L_mm"] = round(p.pop("L_frac") * half, 4)
        if "Y_frac" in p:
            p["Y_mm"] = round(p.pop("Y_frac") * half, 4)
        if "k_rel" in p:  # k = k_rel / h^2: the cubic's size at the range ends is k_rel * h
            p["k_per_mm2"] = round(p.pop("k_rel") / half**2, 8)
    if form == "nonlinear_damping":
        p.setdefault("v_ref_mm_s", V_REF_MM_S)
    return p


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _folder_name(
    seed: int, plant: str, effect: str | None, form: str | None, params: Mapping[str, float]
) -> str:
    """Opaque, seeded, deterministic: fp-<6 hex> of a hash of everything that defines the source."""
    key = json.dumps([seed, plant, effect, form, sorted(params.items())], sort_keys=True)
    return "fp-" + hashlib.sha256(key.encode()).hexdigest()[:6]


def _tensions(y: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Capstan picture: output tension from the constant-force spring (5 N) plus a small rate;
    input tension e^{+-mu theta} times it, the sign turning over with the speed (90 deg wrap)."""
    f_out = 5.0 + 0.25 * (y - y[0])
    mu_theta = 0.2 * math.radians(CONFIGURATION["curve_angle_deg"])
    f_in = f_out * np.exp(mu_theta * np.tanh(v / 0.5))
    return f_in, f_out


def write_source(
    root: str | Path,
    plant: str,
    effect: str | None,
    form: str | None,
    params: Mapping[str, float] | None = None,
    seed: int = 0,
    *,
    design: str | None = None,
    update_truth: bool = True,
) -> tuple[str, dict[str, Any]]:
    """Write one source folder ``<root>/fp-xxxxxx/`` (three run folders) and return
    ``(folder_name, truth_entry)``.  With ``update_truth`` the entry is merged into
    ``<root>/form_pairs_truth.json``.  ``effect``/``form`` None: a clean source."""
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; known: {sorted(PLANTS)}")
    if (effect is None) != (form is None):
        raise ValueError("effect and form are both given or both None")
    if form is not None and FORMS[form].effect != effect:
        raise ValueError(f"form {form!r} is not a form of {effect!r}")
    p = _resolve(plant, form, params or {})
    name = _folder_name(seed, plant, effect, form, p)
    src = Path(root) / name
    rng = np.random.default_rng(int(hashlib.sha256(name.encode()).hexdigest()[:12], 16) + seed)
    c = output_centre(plant)
    run_ids = []
    for i, (run, y_plain) in enumerate(zip(run_excitations(), _plain_outputs(plant))):
        y = y_plain.copy()
        if form is not None:
            y = y + effect_contribution(
                form, p, Ctx(run.t, run.v, y_plain - c, float(run.t[1] - run.t[0]))
            )
        y_meas = y + rng.normal(0.0, NOISE_SD_MM, y.shape)
        f_in, f_out = _tensions(y, run.v)
        rid = riglog.run_id_for(CONFIGURATION, run.kind, i + 1)
        riglog.write_run_folder(
            src,
            rid,
            run.t,
            run.u,
            y_meas,
            configuration=CONFIGURATION,
            excitation=run.manifest,
            loadcell=(f_in, f_out),
            loadcell_noise_n=0.01,
            events=True,
            started_at=f"2026-03-02T10:{15 + 5 * i:02d}:00Z",
            seed=int(rng.integers(2**31)),
        )
        run_ids.append({"run_id": rid, "role": run.role, "kind": run.kind})
    entry: dict[str, Any] = {
        "plant": plant,
        "plant_parameters": PLANT_DESCRIPTIONS[plant],
        "effect": effect,
        "form": form,
        "parameters": p,
        "design": design,
        "noise_sd_mm": NOISE_SD_MM,
        "runs": run_ids,
    }
    if form is None:
        entry.update({"contribution_rms_mm": 0.0, "alternatives": {}, "separable": None})
    else:
        entry.update(oracle(plant, form, p))
    if update_truth:
        path = Path(root) / TRUTH_FILE
        truth = json.loads(path.read_text(encoding="utf-8")) if path.exists() else {}
        truth[name] = entry
        path.write_text(json.dumps(truth, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return name, entry


def write_all(root: str | Path, seed: int = 0) -> dict[str, Any]:
    """Write every source of ``SOURCES`` under ``root`` and ``root/form_pairs_truth.json``."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    truth: dict[str, Any] = {}
    for plant, effect, form, params, design in SOURCES:
        name, entry = write_source(
            root, plant, effect, form, params, seed, design=design, update_truth=False
        )
        if name in truth:
            raise RuntimeError(f"folder name collision {name}")
        truth[name] = entry
    (root / TRUTH_FILE).write_text(
        json.dumps(truth, indent=2, sort_keys=True) + "\n", encoding="utf-8"
    )
    return truth


def _summary_line(name: str, e: Mapping[str, Any]) -> str:
    alts = ", ".join(f"{k} {v['misfit_in_noise_sd']:.2f}sd" for k, v in e["alternatives"].items())
    return (
        f"{name}  {e['plant']:<8}  {str(e['effect']):<15}  {str(e['form']):<17}  "
        f"separable={str(e['separable']):<5}  rms={e['contribution_rms_mm'] / e['noise_sd_mm']:.1f}sd  {alts}"
    )


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(
        description="Write the form-pair clean-room sources and their truth."
    )
    ap.add_argument("out_dir")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    truth = write_all(args.out_dir, args.seed)
    for name, e in truth.items():
        print(_summary_line(name, e))
    print(f"{len(truth)} sources in {args.out_dir} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
