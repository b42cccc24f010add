"""Clean-room ground-truth generator: tendon-sheath bench runs from *other* hysteresis plants.

Provenance
----------
Written only from these files (nothing else in the repository was opened):

* ``../shared/rig-log-format.md`` -- the ``tsm-rig-log/1`` raw format (run folders, manifest
  fields, excitation kinds, encoder / load-cell conventions, "bad input" list);
* ``../shared/seeds/README.md`` and section 3.1 of
  ``../shared/seeds/001_9db1eb7439089598.txt`` -- the bench (input and follower modules,
  linear encoders, load cells on both sides, constant-force spring, 10 ms loop, decaying
  sine / triangle / trapezoid excitations);
* ``riglog.py`` (beside this file) -- the clean-room raw-format writer, imported by file
  path and used for excitations (``make_excitation``), run ids (``run_id_for``) and writing
  (``write_run_folder``);
* textbook physics: Maxwell-slip / elasto-slip friction (Iwan 1966; Lampaert, Al-Bender &
  Swevers 2003), Dahl friction (Dahl 1968/1976), the capstan (Euler-Eytelwein) law, and the
  play (backlash) operator.

What it writes
--------------
``write_all(root)`` writes 18 *sources* (2 plants x 9 variants), each a folder
``root/<source_id>/`` holding three 80 s ``tsm-bench`` run folders of the SAME plant and
hidden effect (``sine_decay`` 6/4.5/3/1.5 mm x 5 periods at 0.25 Hz, ``triangle_decay`` same
amplitudes x 8 periods at 6 mm/s, ``trapezoid_decay`` x 5 periods at 6 mm/s with 0.75 s dwell),
encoder at 100 Hz, load cells at 1 kHz, ``events.csv`` with start/stop.  Source ids are opaque
(``op-<8 hex>``) so the folder name does not give the answer away; the truth is written to
``root/other_plants_truth.json`` (outside every source folder).

Notation: u = proximal tendon displacement (mm, + = pull), y = distal follower displacement
(mm, same direction), both in physical coordinates with the relaxed rest position at 0.  The
encoders store positions relative to the first sample (spec), so a "loaded" start shows up in
the data only through the state, not through an offset.

Play operator (half-width r, initial output p0)::

    P_r[u](k) = min(u_k + r, max(u_k - r, P_r[u](k-1))),   P_r[u](-1) = p0

Plant 1 -- ``maxwell_slip`` (generalised Maxwell-slip / elasto-slip, rate independent)
    N = 6 parallel elements, element i = spring k_i (N/mm) in series with a Coulomb slider of
    break-away force f_i (N); element deflection delta_i = u - x_i is limited to
    |delta_i| <= Delta_i = f_i / k_i (slider sticks inside, slides at the limit)::

        delta_i = u - P_{Delta_i}[u]            (stick/slip of element i)
        F_fr    = sum_i k_i delta_i             (friction force carried by the sheath)
        L       = F_fr / K = sum_i w_i delta_i, w_i = k_i / K   (lost motion, tendon stretch)
        y       = g (u - L)

    with K the effective tendon stiffness.  Delta = (0.14, 0.36, 0.64, 1.00, 1.43, 2.00) mm,
    w = (0.25, 0.20, 0.17, 0.13, 0.10, 0.07) (sum 0.92, so the output barely moves just after
    a reversal), g = 0.95; the branch is piecewise linear with a slope that rises in six
    steps as the elements break away.  Loop width at u = 0 for +-6 mm:
    2 g sum w_i Delta_i = 1.19 mm.  Friction mobilisation s = L / sum_i w_i Delta_i in [-1, 1].
    Start "rest": delta_i = 0; "loaded" (as after a pull): delta_i = +Delta_i.

Plant 2 -- ``dahl`` (Dahl friction with exponent alpha, integrated in displacement, so rate
    independent; smooth branches)::

        dz/du = (1/x_c) |1 - z sgn(du)|^alpha sgn(1 - z sgn(du)),     z = F_fr / F_c in [-1, 1]
        y     = g (u - a z)

    a = F_c / K = 0.95 mm (lost motion at full slip), x_c = 1.1 a 2^alpha = 2.956 mm
    (so dy/du >= 0.09 g right after a reversal), alpha = 1.5, g = 0.95.  alpha = 1 was avoided
    on purpose: Dahl with alpha = 1 is a Bouc-Wen model (n = 1, beta = A, gamma = 0).  It is
    integrated exactly between samples with w = 1 - z sgn(du)::

        w_new = (w^(1-alpha) + (alpha - 1) |du| / x_c)^(1/(1-alpha))

    Loop width at u = 0 for +-6 mm about 1.2 mm.  Mobilisation s = z.  Start "rest": z = 0;
    "loaded": z = +1.

Tendon tensions (capstan / Euler-Eytelwein, consistent with the plant state)::

    T_out = F0 + k_s y + K (y_free - y)        (follower load cell; last term = reaction of a
                                                stop / limiting spring, saturation effects only)
    T_in  = T_out exp(mu theta s)              (input load cell; s = friction mobilisation)

F0 = 5 N (constant-force spring), k_s = 0.05 N/mm, mu = 0.2, theta = curve angle (rad) of the
sheath configuration.  K = F0 (exp(mu theta) - 1) / L_max, so the sheath friction at full slip,
K L_max, equals the capstan tension difference at full pull.

Hidden effects (at most one per source; applied to the plant output y_p unless stated)

* ``None`` (clean): y = y_p.
* ``asymmetry/loading_unloading_gain``: y = (1 + eps lam) y_p with the direction state
  lam = (u - P_h[u]) / h in [-1, 1] (normalised play of half-width h on the input: it turns
  over linearly along 2 h of input travel after each reversal); loading gain 1 + eps,
  unloading gain 1 - eps.  eps = 0.04, h = 0.25 mm.  lam(0) = 0 at rest, +1 loaded.
* ``asymmetry/pull_push_gain``: y = (1 + eps) y_p for y_p >= 0 (pull side of rest),
  (1 - eps) y_p for y_p < 0 (push side).  eps = 0.04.
* ``saturation/hard_stop``: y = min(y_p, y_stop), y_stop = 4.5 mm (reached only during the
  6 mm amplitude block); the stop reaction K (y_p - y) adds to the tendon tension.
* ``saturation/soft``: y = Y tanh(y_p / Y), Y = 9 mm; reaction K (y_p - y) as above.
* ``dead_zone/input_backlash``: the plant is driven by u_b = P_b[u], b = 0.2 mm (total dead
  band 0.4 mm), u_b(0) = u(0) at rest and u(0) - b loaded.
* ``drift/linear_creep``: y = y_p + c t, c = -0.004 mm/s (-0.32 mm over an 80 s run, the
  follower creeping back as the tendon creeps); tensions unaffected.
* ``time_delay/latency``: y(t) = y_p(t - tau) (first value held), tau = 0.15 s; the load cells
  are not delayed.

Sensor noise: Gaussian, 3 um RMS on each encoder (then quantised to 0.1 um counts), 0.015 N RMS
on each load cell at 1 kHz.

``identifiable`` says whether the effect can be told apart from the plant's own hysteresis
using the input/output data of the three runs.  It is False only for ``maxwell_slip`` +
``dead_zone/input_backlash``: plays compose (P_r o P_b = P_{r+b}), so a backlash in front of a
Maxwell-slip plant is exactly another Maxwell-slip plant (every threshold widened by b, the
linear part replaced by a play of half-width b); no input/output data can separate them.
``dahl`` + ``dead_zone/input_backlash`` is marked identifiable but is the weakest case: a
refitted Dahl plant absorbs most of it (noise-free residual about 16 um RMS, peaks about
0.1 mm in the flat stretch just after each reversal).

Usage: ``python tests/cleanroom/other_plants.py OUTDIR [--seed N]``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import importlib.util
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

_HERE = Path(__file__).resolve().parent


def _load_riglog() -> Any:
    name = "_cleanroom_riglog_for_other_plants"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, _HERE / "riglog.py")
    if spec is None or spec.loader is None:  # pragma: no cover
        raise ImportError("cannot load riglog.py next to other_plants.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()

__all__ = [
    "PLANTS",
    "EFFECTS",
    "STARTS",
    "SOURCE_PLAN",
    "play",
    "simulate",
    "run_excitations",
    "source_id_for",
    "write_source",
    "write_all",
]

PLANTS = ("maxwell_slip", "dahl")
STARTS = ("rest", "loaded")
EFFECTS: tuple[tuple[str | None, str | None], ...] = (
    (None, None),
    ("asymmetry", "loading_unloading_gain"),
    ("asymmetry", "pull_push_gain"),
    ("saturation", "hard_stop"),
    ("saturation", "soft"),
    ("dead_zone", "input_backlash"),
    ("drift", "linear_creep"),
    ("time_delay", "latency"),
)

# ---------------------------------------------------------------------------------------------
# Parameters (fixed: the ground truth is the same for every seed; the seed only drives noise)
# ---------------------------------------------------------------------------------------------

CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
PRETENSION_N = 5.0  # F0, constant-force spring on the follower
SPRING_RATE_N_PER_MM = 0.05  # k_s, residual rate of the constant-force spring
MU = 0.2  # sheath friction coefficient

MAXWELL = {
    "gain": 0.95,
    "thresholds_mm": (0.14, 0.36, 0.64, 1.00, 1.43, 2.00),  # Delta_i = f_i / k_i
    "weights": (0.25, 0.20, 0.17, 0.13, 0.10, 0.07),  # w_i = k_i / K
}
DAHL = {"gain": 0.95, "a_mm": 0.95, "alpha": 1.5}
DAHL["x_c_mm"] = 1.1 * DAHL["a_mm"] * 2.0 ** DAHL["alpha"]

EFFECT_PARAMS: dict[str, dict[str, float]] = {
    "loading_unloading_gain": {"eps": 0.04, "loading_gain": 1.04, "unloading_gain": 0.96, "turnover_half_width_mm": 0.25},
    "pull_push_gain": {"eps": 0.04, "pull_gain": 1.04, "push_gain": 0.96, "about_y_mm": 0.0},
    "hard_stop": {"y_stop_mm": 4.5},
    "soft": {"y_sat_mm": 9.0},
    "input_backlash": {"half_width_mm": 0.2, "dead_band_mm": 0.4},
    "linear_creep": {"rate_mm_per_s": -0.004},
    "latency": {"latency_s": 0.15},
}

ENCODER_NOISE_MM = 0.003
LOADCELL_NOISE_N = 0.015

# excitation kind -> make_excitation keywords giving an 80 s run
RUN_EXCITATIONS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("sine_decay", {"periods_per_amplitude": 5, "frequency_hz": 0.25}),
    ("triangle_decay", {"periods_per_amplitude": 8, "slope_mm_s": 6.0}),
    ("trapezoid_decay", {"periods_per_amplitude": 5, "slope_mm_s": 6.0, "dwell_s": 0.75}),
)

# (plant, effect, form, start): clean at both starts; each effect once per plant, the start
# alternating so that every effect is seen from rest (one plant) and loaded (the other).
SOURCE_PLAN: tuple[tuple[str, str | None, str | None, str], ...] = tuple(
    [(p, None, None, s) for p in PLANTS for s in STARTS]
    + [
        (p, e, f, STARTS[(i + j) % 2])
        for j, p in enumerate(PLANTS)
        for i, (e, f) in enumerate(EFFECTS[1:])
    ]
)

_NOT_IDENTIFIABLE = {
    ("maxwell_slip", "input_backlash"): (
        "plays compose (P_r o P_b = P_{r+b}): a backlash before a Maxwell-slip plant is exactly "
        "another Maxwell-slip plant with every threshold widened by b"
    ),
}


# ---------------------------------------------------------------------------------------------
# Operators and plants
# ---------------------------------------------------------------------------------------------


def play(u: np.ndarray, r: float, p0: float | None = None) -> np.ndarray:
    """Play (backlash) operator of half-width ``r``; ``p0`` initial output (default u[0])."""
    u = np.asarray(u, dtype=float)
    out = np.empty_like(u)
    p = float(u[0]) if p0 is None else float(p0)
    lo, hi = (u - r).tolist(), (u + r).tolist()
    for k in range(u.size):
        if p < lo[k]:
            p = lo[k]
        elif p > hi[k]:
            p = hi[k]
        out[k] = p
    return out


def _maxwell_slip(u: np.ndarray, loaded: bool) -> tuple[np.ndarray, np.ndarray]:
    """y_p and mobilisation s of the Maxwell-slip plant driven by u."""
    g = MAXWELL["gain"]
    lost = np.zeros_like(u)
    lmax = 0.0
    for d, w in zip(MAXWELL["thresholds_mm"], MAXWELL["weights"]):
        delta0 = d if loaded else 0.0
        delta = u - play(u, d, p0=float(u[0]) - delta0)
        lost += w * delta
        lmax += w * d
    return g * (u - lost), lost / lmax


def _dahl(u: np.ndarray, loaded: bool) -> tuple[np.ndarray, np.ndarray]:
    """y_p and mobilisation s = z of the Dahl plant driven by u (exact between samples)."""
    g, a, alpha, xc = DAHL["gain"], DAHL["a_mm"], DAHL["alpha"], DAHL["x_c_mm"]
    z = np.empty_like(u)
    zp = 1.0 if loaded else 0.0
    du = np.diff(u, prepend=u[0]).tolist()
    e = 1.0 - alpha
    for k, d in enumerate(du):
        if d != 0.0:
            s = 1.0 if d > 0 else -1.0
            w0 = 1.0 - zp * s
            if w0 <= 0.0:
                w = 0.0
            elif alpha == 1.0:
                w = w0 * math.exp(-abs(d) / xc)
            else:
                w = (w0**e + (alpha - 1.0) * abs(d) / xc) ** (1.0 / e)
            zp = s * (1.0 - w)
        z[k] = zp
    return g * (u - a * z), z


def _lost_motion_max_mm(plant: str) -> float:
    if plant == "maxwell_slip":
        return float(sum(w * d for d, w in zip(MAXWELL["thresholds_mm"], MAXWELL["weights"])))
    return float(DAHL["a_mm"])


def _capstan_factor(configuration: dict[str, Any]) -> float:
    theta = math.radians(float(configuration.get("curve_angle_deg") or 90.0))
    return MU * theta


def _tendon_stiffness(plant: str, configuration: dict[str, Any]) -> float:
    """K = F0 (exp(mu theta) - 1) / L_max (N/mm)."""
    return PRETENSION_N * (math.exp(_capstan_factor(configuration)) - 1.0) / _lost_motion_max_mm(plant)


def _form_key(effect: str | None, form: str | None) -> str | None:
    if effect in (None, "clean", "none") and form in (None, "clean", "none"):
        return None
    for e, f in EFFECTS[1:]:
        if effect == e and form == f:
            return f
    raise ValueError(f"unknown effect/form {effect!r}/{form!r}; known: {[x for x in EFFECTS if x[0]]}")


def simulate(
    plant: str,
    effect: str | None,
    form: str | None,
    start: str,
    t: np.ndarray,
    u: np.ndarray,
    configuration: dict[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Noise-free physical signals: ``y`` (with the effect), ``y_plant`` (no effect, same
    input path), ``s`` (friction mobilisation), ``t_in``/``t_out`` (N)."""
    if plant not in PLANTS:
        raise ValueError(f"unknown plant {plant!r}; known: {PLANTS}")
    if start not in STARTS:
        raise ValueError(f"start must be one of {STARTS}")
    key = _form_key(effect, form)
    cfg = dict(configuration or CONFIGURATION)
    loaded = start == "loaded"
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    ub = u
    if key == "input_backlash":
        b = EFFECT_PARAMS["input_backlash"]["half_width_mm"]
        ub = play(u, b, p0=float(u[0]) - (b if loaded else 0.0))
    y_p, s = (_maxwell_slip if plant == "maxwell_slip" else _dahl)(ub, loaded)
    y_now = y_p.copy()  # real-time output (before a measurement delay)
    reaction = np.zeros_like(y_p)
    k_t = _tendon_stiffness(plant, cfg)
    if key == "loading_unloading_gain":
        pr = EFFECT_PARAMS[key]
        h = pr["turnover_half_width_mm"]
        lam = (u - play(u, h, p0=float(u[0]) - (h if loaded else 0.0))) / h
        y_now = (1.0 + pr["eps"] * lam) * y_p
    elif key == "pull_push_gain":
        eps = EFFECT_PARAMS[key]["eps"]
        y_now = np.where(y_p >= 0.0, (1.0 + eps) * y_p, (1.0 - eps) * y_p)
    elif key == "hard_stop":
        y_now = np.minimum(y_p, EFFECT_PARAMS[key]["y_stop_mm"])
        reaction = k_t * (y_p - y_now)
    elif key == "soft":
        ys = EFFECT_PARAMS[key]["y_sat_mm"]
        y_now = ys * np.tanh(y_p / ys)
        reaction = k_t * (y_p - y_now)
    elif key == "linear_creep":
        y_now = y_p + EFFECT_PARAMS[key]["rate_mm_per_s"] * (t - t[0])
    t_out = PRETENSION_N + SPRING_RATE_N_PER_MM * y_now + reaction
    t_in = t_out * np.exp(_capstan_factor(cfg) * s)
    y = y_now
    if key == "latency":
        tau = EFFECT_PARAMS[key]["latency_s"]
        y = np.interp(t - tau, t, y_now, left=float(y_now[0]))
    return {"y": y, "y_plant": y_p, "s": s, "t_in": t_in, "t_out": t_out, "u_plant": ub}


def run_excitations() -> list[Any]:
    """The three 80 s excitations of every source (riglog ``Excitation`` objects)."""
    return [riglog.make_excitation(kind, riglog.ENCODER_DT_S, **kw) for kind, kw in RUN_EXCITATIONS]


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def source_id_for(plant: str, effect: str | None, form: str | None, start: str, seed: int = 0) -> str:
    """Opaque, deterministic folder name ``op-<8 hex>`` (does not reveal the truth)."""
    key = f"other_plants|{plant}|{effect}|{form}|{start}|{seed}"
    return "op-" + hashlib.sha1(key.encode("utf-8")).hexdigest()[:8]


def _seed_int(*parts: Any) -> int:
    return int.from_bytes(hashlib.sha1("|".join(map(str, parts)).encode("utf-8")).digest()[:4], "little")


def write_source(
    root: Path | str,
    plant: str,
    effect: str | None,
    form: str | None,
    start: str = "rest",
    seed: int = 0,
) -> dict[str, Any]:
    """Write one source ``root/<source_id>/`` (three run folders) and return its truth dict."""
    root = Path(root)
    if effect in ("clean", "none"):
        effect = None
    if form in ("clean", "none"):
        form = None
    key = _form_key(effect, form)
    sid = source_id_for(plant, effect, form, start, seed)
    src = root / sid
    cfg = dict(CONFIGURATION)
    base = _seed_int(seed, sid)
    t0 = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=base % (24 * 60))
    run_ids = []
    for i, ex in enumerate(run_excitations()):
        rng = np.random.default_rng([seed, base, i])
        sim = simulate(plant, effect, form, start, ex.t_s, ex.u, cfg)
        u_meas = ex.u + rng.normal(0.0, ENCODER_NOISE_MM, ex.u.shape)
        y_meas = sim["y"] + rng.normal(0.0, ENCODER_NOISE_MM, ex.u.shape)
        rid = riglog.run_id_for(cfg, ex.manifest["kind"], i + 1)
        riglog.write_run_folder(
            src,
            rid,
            ex.t_s,
            u_meas,
            y_meas,
            rig="tsm-bench",
            configuration=cfg,
            excitation=ex.manifest,
            counter_start_input=int(rng.integers(-200_000, 200_000)),
            counter_start_output=int(rng.integers(-200_000, 200_000)),
            loadcell=(sim["t_in"], sim["t_out"]),
            loadcell_noise_n=LOADCELL_NOISE_N,
            events=True,
            started_at=t0 + _dt.timedelta(minutes=3 * i),
            seed=int(rng.integers(0, 2**31 - 1)),
        )
        run_ids.append(rid)

    params: dict[str, Any] = {
        "effect": dict(EFFECT_PARAMS[key]) if key else {},
        "plant": (
            {**{k: (list(v) if isinstance(v, tuple) else v) for k, v in MAXWELL.items()},
             "tendon_stiffness_n_per_mm": _tendon_stiffness(plant, cfg),
             "element_stiffness_n_per_mm": [w * _tendon_stiffness(plant, cfg) for w in MAXWELL["weights"]],
             "element_breakaway_n": [w * d * _tendon_stiffness(plant, cfg)
                                     for d, w in zip(MAXWELL["thresholds_mm"], MAXWELL["weights"])],
             "loop_width_full_mm": 2 * MAXWELL["gain"] * _lost_motion_max_mm(plant)}
            if plant == "maxwell_slip"
            else {**DAHL, "tendon_stiffness_n_per_mm": _tendon_stiffness(plant, cfg),
                  "coulomb_force_n": DAHL["a_mm"] * _tendon_stiffness(plant, cfg)}
        ),
        "start_state": (
            {"delta_i_mm": list(MAXWELL["thresholds_mm"]) if start == "loaded" else [0.0] * len(MAXWELL["weights"])}
            if plant == "maxwell_slip"
            else {"z": 1.0 if start == "loaded" else 0.0}
        ),
        "tension": {"pretension_n": PRETENSION_N, "spring_rate_n_per_mm": SPRING_RATE_N_PER_MM, "mu": MU,
                    "wrap_angle_deg": cfg["curve_angle_deg"]},
        "noise": {"encoder_mm": ENCODER_NOISE_MM, "loadcell_n": LOADCELL_NOISE_N},
        "configuration": cfg,
        "runs": run_ids,
    }
    ident_note = _NOT_IDENTIFIABLE.get((plant, key or ""), "")
    return {
        "source": sid,
        "plant": plant,
        "start": start,
        "effect": effect,
        "form": form,
        "params": params,
        "identifiable": not ident_note,
        "note": ident_note,
    }


def write_all(root: Path | str, *, seed: int = 0) -> list[dict[str, Any]]:
    """Write every source of ``SOURCE_PLAN`` under ``root`` and ``root/other_plants_truth.json``."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    truth = [write_source(root, p, e, f, s, seed=seed) for p, e, f, s in SOURCE_PLAN]
    (root / "other_plants_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    truth = write_all(args.outdir, seed=args.seed)
    for d in truth:
        print(f"{d['source']}  {d['plant']:<12} {d['start']:<6} {d['effect'] or '-'}/{d['form'] or '-'}")
    print(f"{len(truth)} sources -> {args.outdir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
