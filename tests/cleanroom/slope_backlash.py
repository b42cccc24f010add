"""Clean-room generator of ``tsm-rig-log/1`` sources with one hidden effect each.

Written only from ``../shared/rig-log-format.md`` (the raw-run format),
``../shared/seeds/README.md``, the thesis ``../shared/seeds/001_9db1eb7439089598.txt`` (the
bench rig, its 10 ms loop, the decaying sinusoid / triangle / trapezoid excitations, the play
operator of eq. 4.7-4.9), the ViO-Com letter ``../shared/seeds/002_2b9594ed99c85a30.txt`` (the
Bouc-Wen model, eq. 2-3) and textbook physics.  Run folders are written with the sibling
clean-room writer ``riglog.py``, loaded by file path.

What it makes
-------------
A *source* is a folder of run folders.  Each source holds three 80 s runs of ONE plant on the
``tsm-bench`` rig, all starting at the rest position (input 0 mm):

* ``sine_decay``  - identification run: 6, 4.5, 3, 1.5 mm, 5 periods each at 0.25 Hz (80 s);
* ``triangle_decay`` - held out: same amplitudes, 6 mm/s, 8 periods each (80 s);
* ``trapezoid_decay`` - held out: same amplitudes, 6 mm/s, 5 periods each, 0.75 s dwells (80 s).

Plants (input ``u`` and output ``x`` in mm, loop about 0.7-1.1 mm wide at mid-stroke):

* ``play_sum``: ``x = sum_i q_i F_{r_i}[u]``, 4-6 symmetric play (backlash) operators
  ``F_r[u]_k = max(u_k - r, min(u_k + r, F_r[u]_{k-1}))`` with radii 0.1-1.2 mm and positive
  weights ``q_i`` (sum 0.85-0.95);
* ``bouc_wen``: ``x = a u + (1 - a) z``, ``dz = A du - beta |du| |z|^(n-1) z - gamma du |z|^n``,
  n = 1 or 2, a ~ 0.8, integrated with sub-steps.  ``A = -1`` (with beta > 0, gamma/beta in
  [-0.4, 0.2]) makes ``z`` the negative of the textbook dissipative state, so the output lags
  the input as a tendon-sheath's does (a counter-clockwise loop, like the play sum's) instead
  of leading it; output about +-4.2 mm for +-6 mm in.

Rig physics shared by all sources: output tension from the follower's (almost) constant-force
spring ``T_out = F0 + k_s y``; input tension from the capstan (Euler-Eytelwein) law
``T_in = T_out exp(mu theta s)`` with theta the sheath's curve angle and ``s`` a Dahl-type
friction state that turns over smoothly with input travel,
``ds/du = (sign(du) - s) / delta``, so ``s -> +1`` while pulling and ``-> -1`` while releasing.
Encoders: 1 um counts, Gaussian noise 0.007 mm on the output and 0.5 um on the input; load
cells: 0.01 N noise, written at 1 kHz.

Hidden effects, each ``weak`` or ``strong``:

* ``slope_backlash`` - an asymmetric backlash on the plant's output in the Tao-Kokotovic form
  (backlash with different slopes): ``y`` follows the loading branch ``m_l (x - c_l)`` while
  ``x`` rises and the unloading branch ``m_u (x - c_u)`` while ``x`` falls, and is held in
  between; ``m_l = 1 + g``, ``m_u = 1 - g`` (g = 0.04 weak, 0.12 strong).  The branches cross
  just above the top of the output's range (the pulled, taut end: the follower loads one way),
  so the held gap ``2 g (x* - x)`` is widest at the released end; ``c_l, c_u`` also keep the
  band centred on ``y = x``, and ``y`` starts inside the band (on ``y = x`` at rest).
* ``linear_input_stretch`` - tendon stretch linear in the input tension on the input side: the
  plant sees ``u - k (T_in - T_in(0))``, with ``k`` (mm/N) set so that the stretch at the
  source's largest input tension is 0.15 mm (weak) or 0.5 mm (strong).

Clean sources (no effect) start at rest or *loaded*: before recording, a hidden 6 mm pull and
release (6 mm/s) leaves every plant state on the released edge of its loop and the capstan
state at ``s = -1``; the run then starts at the rest position (``write_source`` also takes
``start='loaded'`` together with an effect).

Per plant: 2 effects x 2 strengths (from rest) + 2 clean (rest, loaded) = 6 sources, 12 in
all.  The plant (and the sheath configuration) depends only on ``(seed, plant)``, so every
source of one plant shares it and the clean rest source is the baseline of the others.
Folder names are opaque (``sb-<8 hex>``); ``slope_backlash_truth.json`` in the root maps each
to ``{plant, effect, form, strength, parameters, start, ...}``.

Use::

    truth = write_all(root, seed=0)                       # 12 sources + truth JSON
    path = write_source(root, "bouc_wen", "slope_backlash", "strong", start="rest", seed=0)
    check(root)                                           # read back and print a table

or ``python slope_backlash.py [root] [--seed N]`` (writes, reads back and prints).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import importlib.util
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "PLANTS",
    "EFFECTS",
    "STRENGTHS",
    "STARTS",
    "TRUTH_FILE",
    "play_operator",
    "play_sum",
    "bouc_wen",
    "capstan_state",
    "tao_kokotovic_backlash",
    "write_source",
    "write_all",
    "read_run",
    "check",
]


def _load_riglog() -> Any:
    """Import the sibling ``riglog.py`` by file path (registered so its dataclasses work)."""
    name = "_cleanroom_riglog_for_slope_backlash"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("riglog.py"))
    if spec is None or spec.loader is None:
        raise ImportError("cannot load riglog.py next to slope_backlash.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


riglog = _load_riglog()

PLANTS = ("play_sum", "bouc_wen")
EFFECTS = ("slope_backlash", "linear_input_stretch")
STRENGTHS = ("weak", "strong")
STARTS = ("rest", "loaded")
TRUTH_FILE = "slope_backlash_truth.json"

# Effect strengths.
SLOPE_G = {"weak": 0.04, "strong": 0.12}  # m_l = 1 + g, m_u = 1 - g
STRETCH_AT_MAX_MM = {"weak": 0.15, "strong": 0.5}  # k * (max T_in - T_in(0))
CROSSING_MARGIN_MM = 0.2  # branches cross this far above the output's maximum

# Rig (seed 001: 10 ms loop, linear encoders, load cells, constant-force spring).
DT_S = riglog.ENCODER_DT_S
F0_N = 5.0  # constant-force spring pretension
K_SPRING_N_PER_MM = 0.05  # residual rate of the constant-force spring
MU = 0.2  # tendon-sheath friction coefficient
DAHL_TRAVEL_MM = 0.25  # input travel over which the friction state turns over (1/e)
COUNTS_PER_MM = 1000  # 1 um encoder resolution
OUTPUT_NOISE_MM = 0.007
INPUT_NOISE_MM = 0.0005
LOADCELL_NOISE_N = 0.01
PRELOAD_PULL_MM = 6.0  # hidden pull before a "loaded" run
PRELOAD_SPEED_MM_S = 6.0

AMPLITUDES_MM = (6.0, 4.5, 3.0, 1.5)
RUNS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("sine_decay", "identification", {"periods_per_amplitude": 5, "frequency_hz": 0.25}),
    ("triangle_decay", "held_out", {"periods_per_amplitude": 8, "slope_mm_s": 6.0}),
    (
        "trapezoid_decay",
        "held_out",
        {"periods_per_amplitude": 5, "slope_mm_s": 6.0, "dwell_s": 0.75},
    ),
)


# ---------------------------------------------------------------------------------------------
# Plants and effects (textbook forms)
# ---------------------------------------------------------------------------------------------


def play_operator(u: np.ndarray, r: float, w0: float = 0.0) -> np.ndarray:
    """Symmetric play (backlash) operator of radius ``r``:
    w_k = max(u_k - r, min(u_k + r, w_{k-1}))."""
    w = np.empty(len(u))
    prev = float(w0)
    for k, uk in enumerate(np.asarray(u, dtype=float).tolist()):
        prev = max(uk - r, min(uk + r, prev))
        w[k] = prev
    return w


def play_sum(u: np.ndarray, radii: list[float], weights: list[float]) -> np.ndarray:
    """Weighted sum of play operators, all relaxed (w = u[0]) at the first sample."""
    u = np.asarray(u, dtype=float)
    return sum(q * play_operator(u, r, float(u[0])) for r, q in zip(radii, weights, strict=True))


def bouc_wen(
    u: np.ndarray,
    a: float,
    A: float,
    beta: float,
    gamma: float,
    n: int,
    z0: float = 0.0,
    substeps: int = 8,
) -> np.ndarray:
    """Bouc-Wen loop x = a u + (1 - a) z, dz = A du - beta |du| |z|^(n-1) z - gamma du |z|^n
    (explicit Euler, ``substeps`` per sample)."""
    u = np.asarray(u, dtype=float)
    z = float(z0)
    zs = np.empty(u.size)
    zs[0] = z
    du_all = (np.diff(u) / substeps).tolist()
    for k, du in enumerate(du_all, start=1):
        if du != 0.0:
            adu = abs(du)
            for _ in range(substeps):
                az = abs(z)
                zn1 = az ** (n - 1)
                z += A * du - beta * adu * zn1 * z - gamma * du * zn1 * az
        zs[k] = z
    return a * u + (1.0 - a) * zs


def capstan_state(u: np.ndarray, travel: float = DAHL_TRAVEL_MM, s0: float = 0.0) -> np.ndarray:
    """Dahl-type friction state in [-1, 1]: ds/du = (sign(du) - s) / travel (exact per step)."""
    u = np.asarray(u, dtype=float)
    s = float(s0)
    out = np.empty(u.size)
    out[0] = s
    for k, du in enumerate(np.diff(u).tolist(), start=1):
        if du > 0.0:
            s = 1.0 + (s - 1.0) * math.exp(-du / travel)
        elif du < 0.0:
            s = -1.0 + (s + 1.0) * math.exp(du / travel)
        out[k] = s
    return out


def tao_kokotovic_backlash(
    x: np.ndarray, m_l: float, c_l: float, m_u: float, c_u: float, y0: float | None = None
) -> np.ndarray:
    """Backlash with different slopes: loading branch m_l (x - c_l) while x rises, unloading
    branch m_u (x - c_u) while x falls, y held in between.  Valid where m_l (x - c_l) <=
    m_u (x - c_u); ``y0`` defaults to ``x[0]`` clipped into the band."""
    x = np.asarray(x, dtype=float)
    lower = m_l * (x - c_l)
    upper = m_u * (x - c_u)
    prev = float(np.clip(x[0] if y0 is None else y0, lower[0], upper[0]))
    y = np.empty(x.size)
    for k, (lo, hi) in enumerate(zip(lower.tolist(), upper.tolist(), strict=True)):
        prev = min(hi, max(lo, prev))
        y[k] = prev
    return y


# ---------------------------------------------------------------------------------------------
# Parameters
# ---------------------------------------------------------------------------------------------


def _hash_int(*parts: Any) -> int:
    digest = hashlib.sha256("|".join(map(str, parts)).encode()).hexdigest()
    return int(digest[:15], 16)


def _plant_parameters(plant: str, seed: int) -> dict[str, Any]:
    """The plant of ``(seed, plant)``: nominal values jittered by a seeded generator."""
    rng = np.random.default_rng(_hash_int("plant", seed, plant))
    if plant == "play_sum":
        n = int(rng.integers(4, 7))
        radii = np.linspace(0.1, 1.1, n) * rng.uniform(0.9, 1.1, n)
        raw = np.linspace(1.0, 0.3, n) * rng.uniform(0.85, 1.15, n)
        weights = raw / raw.sum() * rng.uniform(0.85, 0.95)
        return {
            "radii_mm": [round(float(r), 4) for r in np.sort(radii)],
            "weights": [round(float(q), 4) for q in weights],
        }
    if plant == "bouc_wen":
        # A < 0: z = -w with w the textbook dissipative Bouc-Wen state, so x lags u (the loop
        # turns like a tendon-sheath's).  z saturates at z_s = (|A| / (beta - gamma))^(1/n); just
        # after a reversal dz/du = -2 |A| / (1 - gamma/beta), so x keeps moving forwards there
        # as long as a > 2 (1 - a) / (1 - gamma/beta).
        n = int(rng.integers(1, 3))
        a = float(rng.uniform(0.76, 0.82))
        z_sat = float(rng.uniform(2.1, 2.6))
        ratio = float(rng.uniform(-0.4, 0.2))  # gamma / beta
        beta = 1.0 / (z_sat**n * (1.0 - ratio))
        return {
            "a": round(a, 4),
            "A": -1.0,
            "beta": round(beta, 5),
            "gamma": round(ratio * beta, 5),
            "n": n,
        }
    raise ValueError(f"unknown plant {plant!r}; known: {PLANTS}")


def _configuration(plant: str, seed: int) -> dict[str, int]:
    rng = np.random.default_rng(_hash_int("configuration", seed, plant))
    return {
        "curve_angle_deg": int(rng.choice([60, 75, 90])),
        "radius_mm": int(rng.choice(riglog.STANDARD_RADII_MM)),
    }


def _run_plant(plant: str, p: dict[str, Any], u: np.ndarray) -> np.ndarray:
    if plant == "play_sum":
        return play_sum(u, p["radii_mm"], p["weights"])
    return bouc_wen(u, p["a"], p["A"], p["beta"], p["gamma"], p["n"])


# ---------------------------------------------------------------------------------------------
# Simulation of one run
# ---------------------------------------------------------------------------------------------


def _hidden_pull(dt: float = DT_S) -> np.ndarray:
    """Input before a loaded run: 0 -> +6 mm -> 0 at 6 mm/s, ending just before the run's t = 0."""
    t_ramp = PRELOAD_PULL_MM / PRELOAD_SPEED_MM_S
    t = np.arange(0.0, 2 * t_ramp + 0.5, dt)
    return np.interp(t, [0.0, t_ramp, 2 * t_ramp], [0.0, PRELOAD_PULL_MM, 0.0])[:-1]


def _simulate(
    u: np.ndarray,
    plant: str,
    pp: dict[str, Any],
    theta: float,
    effect: str | None,
    ep: dict[str, Any],
) -> dict[str, np.ndarray]:
    """Noise-free plant + effect + tensions on the (possibly pre-extended) input ``u``."""
    s = capstan_state(u)
    capstan = np.exp(MU * theta * s)

    def finish(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        y = x
        if effect == "slope_backlash":
            y = tao_kokotovic_backlash(x, ep["m_l"], ep["c_l"], ep["m_u"], ep["c_u"])
        t_out = F0_N + K_SPRING_N_PER_MM * y
        return y, t_out * capstan, t_out

    u_plant = u
    x = _run_plant(plant, pp, u_plant)
    y, t_in, t_out = finish(x)
    if effect == "linear_input_stretch":
        t_ref = float(t_in[0])
        for _ in range(4):  # fixed point: the stretch barely changes the spring tension
            u_plant = u - ep["k_mm_per_n"] * (t_in - t_ref)
            x = _run_plant(plant, pp, u_plant)
            y, t_in, t_out = finish(x)
    return {"u": u, "u_plant": u_plant, "x": x, "y": y, "t_in": t_in, "t_out": t_out}


def loop_width(
    t: np.ndarray, u: np.ndarray, y: np.ndarray, t0: float = 4.0, t1: float = 20.0
) -> float:
    """Mean y at falling zero crossings of u minus mean y at rising ones, for t0 <= t < t1."""
    sel = (t >= t0) & (t < t1)
    uu, yy = u[sel], y[sel]
    k = np.nonzero(np.sign(uu[:-1]) != np.sign(uu[1:]))[0]
    k = k[uu[k] != uu[k + 1]]
    frac = uu[k] / (uu[k] - uu[k + 1])
    y_cross = yy[k] + frac * (yy[k + 1] - yy[k])
    rising = uu[k + 1] > uu[k]
    if not rising.any() or rising.all():
        return float("nan")
    return float(y_cross[~rising].mean() - y_cross[rising].mean())


# ---------------------------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------------------------


def _folder_name(
    plant: str, effect: str | None, strength: str | None, start: str, seed: int
) -> str:
    return (
        "sb-"
        + hashlib.sha256(f"sb|{seed}|{plant}|{effect}|{strength}|{start}".encode()).hexdigest()[:8]
    )


def _validate(plant: str, effect: str | None, strength: str | None, start: str) -> None:
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; known: {PLANTS}")
    if effect is not None and effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; known: {EFFECTS} or None")
    if effect is not None and strength not in STRENGTHS:
        raise ValueError(f"strength must be one of {STRENGTHS} for an effect")
    if effect is None and strength is not None:
        raise ValueError("a clean source (effect=None) takes strength=None")
    if start not in STARTS:
        raise ValueError(f"unknown start {start!r}; known: {STARTS}")


def _effect_parameters(
    effect: str | None, strength: str | None, base: list[dict[str, np.ndarray]]
) -> tuple[dict[str, Any], str | None, str | None]:
    """Effect parameters fitted to the clean simulation ``base`` of the source's runs."""
    if effect == "slope_backlash":
        g = SLOPE_G[str(strength)]
        x_max = max(float(b["x"].max()) for b in base)
        x_min = min(float(b["x"].min()) for b in base)
        x_star = x_max + CROSSING_MARGIN_MM  # the branches cross just above the pulled end
        m_l, m_u = 1.0 + g, 1.0 - g
        # m_l c_l = g x*, m_u c_u = -g x*: branches meet at x*, band centred on y = x
        ep = {
            "g": g,
            "m_l": m_l,
            "m_u": m_u,
            "c_l": g * x_star / m_l,
            "c_u": -g * x_star / m_u,
            "x_cross_mm": x_star,
            "x_max_mm": x_max,
            "x_min_mm": x_min,
            "gap_at_x_min_mm": 2 * g * (x_star - x_min),
            "gap_at_x_max_mm": 2 * g * (x_star - x_max),
            "y0": "x[0] (on y = x, inside the band)",
        }
        equation = (
            "y = m_l (x - c_l) while x rises, m_u (x - c_u) while x falls, held in between;"
            " x = plant output"
        )
        return ep, "tao_kokotovic_backlash", equation
    if effect == "linear_input_stretch":
        t_ref = float(base[0]["t_in"][0])
        t_max = max(float(b["t_in"].max()) for b in base)
        target = STRETCH_AT_MAX_MM[str(strength)]
        ep = {
            "k_mm_per_n": target / (t_max - t_ref),
            "t_in_ref_n": t_ref,
            "t_in_max_n": t_max,
            "stretch_at_max_mm": target,
        }
        return ep, "linear_in_input_tension", "plant input = u - k (T_in - T_in(0))"
    return {}, None, None


def _write_runs(
    dest: Path,
    runs: list[tuple[str, str, Any]],
    sims: list[dict[str, np.ndarray]],
    n_pre: int,
    cfg: dict[str, int],
    seed: int,
) -> list[dict[str, Any]]:
    """Add encoder noise and write the recorded part (after any hidden pull) of each run."""
    rng = np.random.default_rng(_hash_int("noise", seed, dest.name))
    t0 = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.UTC)
    t0 += _dt.timedelta(hours=_hash_int(dest.name) % 200)
    info = []
    for i, ((kind, role, ex), sim) in enumerate(zip(runs, sims, strict=True)):
        u, y = sim["u"][n_pre:], sim["y"][n_pre:]
        run_id = riglog.run_id_for(cfg, kind, i + 1)
        riglog.write_run_folder(
            dest,
            run_id,
            ex.t_s,
            u + rng.normal(0.0, INPUT_NOISE_MM, u.size),
            y + rng.normal(0.0, OUTPUT_NOISE_MM, y.size),
            configuration=cfg,
            excitation=ex.manifest,
            counts_per_unit=COUNTS_PER_MM,
            loadcell=(sim["t_in"][n_pre:], sim["t_out"][n_pre:]),
            loadcell_noise_n=LOADCELL_NOISE_N,
            events=True,
            started_at=t0 + _dt.timedelta(minutes=5 * i),
            seed=_hash_int("loadcell", seed, dest.name, i),
        )
        width = loop_width(ex.t_s, u, y) if kind == "sine_decay" else None
        info.append(
            {
                "run_id": run_id,
                "kind": kind,
                "role": role,
                "loop_width_mm": None if width is None else round(width, 4),
            }
        )
    return info


def _make_source(
    root: str | Path, plant: str, effect: str | None, strength: str | None, start: str, seed: int
) -> tuple[Path, dict[str, Any]]:
    _validate(plant, effect, strength, start)
    pp = _plant_parameters(plant, seed)
    cfg = _configuration(plant, seed)
    theta = math.radians(cfg["curve_angle_deg"])
    pre = _hidden_pull() if start == "loaded" else np.zeros(0)
    n_pre = pre.size
    runs = [
        (kind, role, riglog.make_excitation(kind, DT_S, amplitudes_mm=AMPLITUDES_MM, **kw))
        for kind, role, kw in RUNS
    ]
    inputs = [np.concatenate([pre, ex.u]) for *_, ex in runs]

    base = [_simulate(u, plant, pp, theta, None, {}) for u in inputs]
    ep, form, equation = _effect_parameters(effect, strength, base)
    sims = base if effect is None else [_simulate(u, plant, pp, theta, effect, ep) for u in inputs]

    # effect size as a reader sees it: outputs relative to their first recorded sample
    diffs = []
    for sim, b in zip(sims, base, strict=True):
        y, y_b = sim["y"][n_pre:], b["y"][n_pre:]
        diffs.append((y - y[0]) - (y_b - y_b[0]))
    rms = float(np.sqrt(np.mean(np.concatenate(diffs) ** 2)))

    dest = Path(root) / _folder_name(plant, effect, strength, start, seed)
    dest.mkdir(parents=True, exist_ok=True)
    run_info = _write_runs(dest, runs, sims, n_pre, cfg, seed)
    plant_width = loop_width(runs[0][2].t_s, base[0]["u"][n_pre:], base[0]["x"][n_pre:])
    rig = {
        "pretension_n": F0_N,
        "spring_rate_n_per_mm": K_SPRING_N_PER_MM,
        "mu": MU,
        "wrap_angle_deg": cfg["curve_angle_deg"],
        "dahl_travel_mm": DAHL_TRAVEL_MM,
        "counts_per_mm": COUNTS_PER_MM,
        "output_noise_mm": OUTPUT_NOISE_MM,
        "input_noise_mm": INPUT_NOISE_MM,
        "loadcell_noise_n": LOADCELL_NOISE_N,
    }
    preload = {"pull_mm": PRELOAD_PULL_MM, "speed_mm_s": PRELOAD_SPEED_MM_S}
    entry = {
        "plant": plant,
        "effect": effect,
        "form": form,
        "strength": strength,
        "start": start,
        "parameters": {
            "plant": pp,
            "effect": {k: (round(v, 6) if isinstance(v, float) else v) for k, v in ep.items()}
            or None,
            "equation": equation,
            "rig": rig,
            "preload": preload if start == "loaded" else None,
        },
        "configuration": cfg,
        "runs": run_info,
        "plant_loop_width_mm": round(plant_width, 4),
        "effect_rms_mm": round(rms, 5),
        "effect_over_noise": round(rms / OUTPUT_NOISE_MM, 2),
        "seed": seed,
    }
    return dest, entry


def write_source(
    root: str | Path,
    plant: str,
    effect: str | None,
    strength: str | None,
    start: str = "rest",
    seed: int = 0,
) -> Path:
    """Write one source ``<root>/sb-<hex>/`` (three run folders) and merge its ground truth into
    ``<root>/slope_backlash_truth.json``.  ``effect=None`` (and ``strength=None``) is clean."""
    path, entry = _make_source(root, plant, effect, strength, start, seed)
    truth_path = Path(root) / TRUTH_FILE
    truth = json.loads(truth_path.read_text(encoding="utf-8")) if truth_path.exists() else {}
    truth[path.name] = entry
    truth_path.write_text(
        json.dumps(dict(sorted(truth.items())), indent=2) + "\n", encoding="utf-8"
    )
    return path


def write_all(root: str | Path, seed: int = 0) -> dict[str, Any]:
    """Write all 12 sources under ``root`` and ``root/slope_backlash_truth.json``;
    return the truth (folder name -> entry)."""
    Path(root).mkdir(parents=True, exist_ok=True)
    truth: dict[str, Any] = {}
    for plant in PLANTS:
        specs = [(e, s, "rest") for e in EFFECTS for s in STRENGTHS] + [
            (None, None, "rest"),
            (None, None, "loaded"),
        ]
        for effect, strength, start in specs:
            path, entry = _make_source(root, plant, effect, strength, start, seed)
            truth[path.name] = entry
    truth = dict(sorted(truth.items()))
    (Path(root) / TRUTH_FILE).write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


# ---------------------------------------------------------------------------------------------
# Read-back check (spec section 1)
# ---------------------------------------------------------------------------------------------


def read_run(run_dir: str | Path) -> dict[str, Any]:
    """Read a run folder per the spec: positions (mm, relative to the first sample) and
    tensions (N)."""
    run_dir = Path(run_dir)
    man = json.loads((run_dir / "manifest.json").read_text(encoding="utf-8"))
    if man.get("format") != "tsm-rig-log/1":
        raise ValueError(f"{run_dir}: unknown format {man.get('format')!r}")
    enc_ch = man["channels"]["encoder"]
    enc = pd.read_csv(run_dir / "encoder.csv", engine="pyarrow")
    bits = int(enc_ch["counter_bits"])

    def unwrap(c: pd.Series) -> np.ndarray:
        raw = c.to_numpy(dtype=np.int64)
        step = ((np.diff(raw) + (1 << (bits - 1))) % (1 << bits)) - (1 << (bits - 1))
        return np.concatenate([[0], np.cumsum(step)])

    out = {
        "manifest": man,
        "t_s": enc["t_ns"].to_numpy(dtype=np.int64) / 1e9,
        "u": enc_ch["input_sign"] * unwrap(enc["input_counts"]) / enc_ch["counts_per_unit"],
        "y": enc_ch["output_sign"] * unwrap(enc["output_counts"]) / enc_ch["counts_per_unit"],
    }
    if (run_dir / "loadcell.csv").exists():
        lc = pd.read_csv(run_dir / "loadcell.csv", engine="pyarrow")
        cal = man["channels"]["loadcell"]
        out["lc_t_s"] = lc["t_ns"].to_numpy(dtype=np.int64) / 1e9
        for side in ("input", "output"):
            raw = lc[f"{side}_mv_per_v"].to_numpy(dtype=float)
            out[f"tension_{side}_n"] = (raw - cal[side]["zero_mv_per_v"]) * cal[side][
                "newton_per_mv_per_v"
            ]
    return out


def _read_source(src: Path) -> dict[str, dict[str, Any]]:
    runs = {}
    for d in sorted(p for p in src.iterdir() if p.is_dir()):
        r = read_run(d)
        runs[r["manifest"]["excitation"]["kind"]] = r
    return runs


def _dwell_noise(run: dict[str, Any]) -> float:
    """Output noise (mm): scatter of y about its mean in each dwell of a trapezoid run."""
    still = np.abs(np.gradient(run["u"])) < 1e-3
    still = np.convolve(still, np.ones(15), "same") >= 15  # well inside a dwell
    cuts = np.nonzero(np.diff(still.astype(int)))[0] + 1
    pieces = zip(np.split(run["y"], cuts), np.split(still, cuts), strict=True)
    resid = [y - y.mean() for y, flag in pieces if flag[0] and y.size > 5]
    return float(np.std(np.concatenate(resid)))


_COLUMNS = (
    ("source", 12, "s"),
    ("plant", 9, "s"),
    ("effect", 21, "s"),
    ("strength", 8, "s"),
    ("start", 6, "s"),
    ("loop_width_mm", 13, ".3f"),
    ("noise_mm", 8, ".4f"),
    ("effect_over_noise_read", 22, ".1f"),
    ("effect_over_noise_true", 22, ".1f"),
    ("ok", 3, "s"),
)


def check(root: str | Path) -> list[dict[str, Any]]:
    """Read every source back per the spec and print loop width, noise and effect size.

    ``loop_width_mm`` is measured on the identification run (6 mm part), ``noise_mm`` in the
    trapezoid dwells, ``effect_over_noise_read`` is the RMS of (y - y of the same plant's clean
    rest source) with both noises removed, over the noise; ``effect_over_noise_true`` is the
    generator's noise-free value.  ``ok``: strong > 10, weak > 3."""
    root = Path(root)
    truth = json.loads((root / TRUTH_FILE).read_text(encoding="utf-8"))
    data = {name: _read_source(root / name) for name in truth}
    baseline = {
        e["plant"]: name
        for name, e in truth.items()
        if e["effect"] is None and e["start"] == "rest"
    }
    print(" ".join(f"{c:>{w}}" if f != "s" else f"{c:{w}}" for c, w, f in _COLUMNS))
    rows = []
    for name, e in truth.items():
        runs = data[name]
        sine = runs["sine_decay"]
        noise = _dwell_noise(runs["trapezoid_decay"])
        eff = float("nan")
        if e["plant"] in baseline:
            base = data[baseline[e["plant"]]]
            ms = np.mean(np.concatenate([(runs[k]["y"] - base[k]["y"]) ** 2 for k in runs]))
            eff = math.sqrt(max(ms - 2 * noise**2, 0.0)) / noise
        need = {"strong": 10.0, "weak": 3.0}.get(e["strength"], 0.0)
        row = {
            "source": name,
            "plant": e["plant"],
            "effect": e["effect"] or "-",
            "strength": e["strength"] or "-",
            "start": e["start"],
            "loop_width_mm": loop_width(sine["t_s"], sine["u"], sine["y"]),
            "noise_mm": noise,
            "effect_over_noise_read": eff,
            "effect_over_noise_true": e["effect_over_noise"],
            "ok": "yes" if e["effect_over_noise"] > need or e["effect"] is None else "NO",
        }
        rows.append(row)
        print(" ".join(f"{row[c]:{w}{f}}" for c, w, f in _COLUMNS))
    return rows


if __name__ == "__main__":
    import argparse
    import tempfile
    import time

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "root", nargs="?", default=None, help="output folder (default: a new temporary one)"
    )
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    out_root = Path(args.root or tempfile.mkdtemp(prefix="slope_backlash_"))
    t_start = time.perf_counter()
    write_all(out_root, seed=args.seed)
    print(f"wrote 12 sources to {out_root} in {time.perf_counter() - t_start:.1f} s")
    check(out_root)
