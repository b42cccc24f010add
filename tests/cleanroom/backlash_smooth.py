"""Clean-room generator: lost motion in the drive in front of a SMOOTH hysteresis loop.

Provenance
----------
Written from physics only, WITHOUT reading the project's implementation (its hysteresis,
pipelines, rig_io, docs, bench, conf or tests folders).  Sources used: the rig-log specification
(``shared/rig-log-format.md``), the seed papers' README and papers (Coleman-Hodgdon model of
seed 000 eq. 10, the Bouc-Wen model of seed 002, the rig of seed 001), the clean-room writer
``riglog.py`` (imported by file path) and textbook models (Bouc-Wen, Duhem / Coleman-Hodgdon,
play operators, Dahl friction, the capstan law).

What it tests
-------------
Whether an analysis can find lost motion (backlash) in the DRIVE, i.e. between the carriage
(read by the input encoder) and the tendon's end, in front of a smooth, rate-independent
hysteresis loop that is NOT a sum of play operators, from the output encoder and the two load
cells.

Plants (input u = tendon-end travel u_t in mm, output y = follower travel in mm)
    Every loop is calibrated at generation time to be 1.00 mm wide (output, after the gain:
    y_descending(0) - y_ascending(0)) at mid-stroke on a steady +-6 mm sine (0.2 Hz; the plants
    are rate independent, so only the path matters).

    ``bw1``   Bouc-Wen, n = 1:  y = g [a u + (1 - a) z],
              dz/du = A - (beta sign(du z) + gamma) |z|,  a = 0.5, A = 1, beta = 0.65 kappa,
              gamma = 0.35 kappa (kappa solved for the width), g = 0.90.  beta > gamma: the
              slope after a reversal is the largest on the branch (softening loop).
    ``bw2``   Bouc-Wen, n = 2:  same form with |z|^2, a = 0.65, A = 1, beta = gamma = kappa / 2,
              g = 0.85.
    ``duhem`` Coleman-Hodgdon (Duhem) loop, seed 000 eq. 10 written in u:
              dw/du = alpha sign(du) (c u - w) + b,  y = g w,  c = 1, b = 0.7 (slope just after a
              reversal 2b - c = 0.4 > 0, so the output never runs backwards), alpha solved for
              the width, g = 0.92.
    All three are translation invariant in u (shift u by s: y shifts by g a s resp. g c s).
    Orientation: the softening Bouc-Wen loops LEAD (ascending branch above the descending one,
    slope highest just after a reversal: a textbook Bouc-Wen with A > 0 written this way turns
    like a force-displacement loop); the Coleman-Hodgdon loop LAGS (slope lowest, g(2b - c),
    just after a reversal).  Both orientations are recorded in the truth file.

Drive, input load cell and output load cell
    u_c: carriage travel (input encoder).  u_t = E[u_c]: tendon-end travel seen by the plant and
    by the input load cell.  E is the identity (clean) or the hidden effect.
    Input tension (capstan-like, friction state follows the direction of motion of the tendon
    END, not the carriage)::

        T_in = (P0 + k_t u_t) exp(mu_theta s),   ds/du_t = (sign(du_t) - s) / lambda    (Dahl)

    P0 = 5 N, k_t = 0.15 N/mm, mu_theta = 0.2 * pi/2, lambda = 0.06 mm (s turns over from -1 to
    +0.9 along 0.18 mm of tendon-end travel).  s is a function of the tendon end's PATH only:
    while the end stands still (dead travel, dead band) T_in does not change at all; there is no
    speed dependence that would relax it at rest.  s starts at 0 at rest, and wherever the
    pre-stroke leaves it for a loaded start.
    Output tension: a return-spring follower, T_out = F0 + k_r y, F0 = 5 N, k_r = 0.15 N/mm.

Hidden effects (one per source, two strengths)
    ``dead_zone``         symmetric backlash of total dead travel d after every reversal: a play
                          operator on u_c of half-width d/2, centred at rest.
    ``one_way_backlash``  the gap sits entirely on the pulling side: the one-sided play
                          u_t = max(u_c - d, min(u_c, u_t)) with u_t = u_c at rest, so loading
                          (pulling) from rest loses the whole gap d (a centred gap loses d/2).
                          A kinematic gap that is taken up at every pull start must re-open at
                          the release start (a tendon end under positive tension cannot drift),
                          so after the first pull this operator is exactly a centred play of
                          width d shifted by -d/2, i.e. (the plants being translation invariant)
                          a symmetric dead zone plus a constant output offset.  That is why it
                          is NOT identifiable as its own class.
    ``dead_band``         a static dead band of half-width b around the carriage's rest:
                          u_t = 0 for |u_c| < b, u_t = u_c - sign(u_c) b outside.
    Sizes are solved at generation time so that the effect's RMS on the held-out runs (the
    noise-free output with the effect minus the clean output of the same plant started at rest)
    is 3x (``weak``) and 8x (``strong``) the output noise (0.01 mm); the achieved oracle is
    written to the truth file, with the symmetric dead zone d' plus constant output offset that
    best stands in for each effect (plant known) and its residual in noise sd: ~0 for the
    one-way backlash (not separable), the whole effect or nearly so for the dead band.

Runs (one configuration per source, the same for its three runs; all 80 s, start and end at rest)
    ``sine_decay``       6, 4.5, 3, 1.5 mm, 5 periods each at 0.25 Hz (identification);
    ``triangle_decay``   same amplitudes, 8 periods each at 6 mm/s (held out);
    ``trapezoid_decay``  same amplitudes, 5 periods each at 5 mm/s, 0.5 s dwells (held out).
    Simulated at 1 kHz (tendon-end steps <= 0.0095 mm, RK4 in u per step); the encoders are
    written at 100 Hz (every 10th sample, output noise 0.01 mm white), the load cells at 1 kHz
    (tension noise 0.02 N white on each).
    Starts: effect sources at rest; per plant one clean source at rest and one started loaded
    (before the record the carriage strokes 0 -> +6 -> 0 mm, unrecorded, so the plant, and the
    friction state, sit on the descending loop edge when recording begins).

Output
    ``generate(outdir, seed=0)`` writes 24 source folders ``bs-<10 hex>`` (hash of seed, plant
    and tag, so a name reveals nothing), each with three run folders, and
    ``backlash_smooth_truth.json`` beside them.  CLI: ``python backlash_smooth.py OUTDIR [--seed N]``.

The configuration (curve angle, radius) of each source is a label drawn from the 24 standard
shapes; the physics here does not depend on it.
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
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

# ---------------------------------------------------------------------------------------------
# riglog (clean-room writer) by file path
# ---------------------------------------------------------------------------------------------


def _load_riglog() -> Any:
    env = os.environ.get("CLEANROOM_RIGLOG")
    if env:
        p = Path(env)
        if p.is_dir():
            p = p / "riglog.py"
    else:
        p = Path(__file__).resolve().parent / "riglog.py"
    if not p.is_file():
        raise FileNotFoundError(f"riglog.py not found at {p} (set CLEANROOM_RIGLOG)")
    name = "_cleanroom_riglog_bs"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, p)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()

# ---------------------------------------------------------------------------------------------
# Constants
# ---------------------------------------------------------------------------------------------

FINE_DT = 0.001  # simulation / load-cell clock (s)
ENC_EVERY = 10  # encoder = every 10th fine sample (100 Hz)
OUTPUT_NOISE_MM = 0.01
TENSION_NOISE_N = 0.02
TARGETS = {"weak": 3.0, "strong": 8.0}  # effect RMS on held-out runs, in output-noise sd
LOOP_WIDTH_MM = 1.0
AMPS = (6.0, 4.5, 3.0, 1.5)

DRIVE = {
    "P0_n": 5.0,  # input preload
    "k_t_n_per_mm": 0.15,  # spring term in u_t
    "mu_theta": 0.2 * math.pi / 2.0,  # capstan exponent (mu = 0.2 over a quarter turn)
    "lambda_mm": 0.06,  # Dahl friction-state travel (e-folding)
    "F0_n": 5.0,  # output spring preload
    "k_r_n_per_mm": 0.15,  # return-spring rate of the follower
}

PLANTS: dict[str, dict[str, Any]] = {
    "bw1": {"kind": "bw", "n": 1.0, "a": 0.5, "A": 1.0, "beta_share": 0.65, "gain": 0.90},
    "bw2": {"kind": "bw", "n": 2.0, "a": 0.65, "A": 1.0, "beta_share": 0.5, "gain": 0.85},
    "duhem": {"kind": "duhem", "c": 1.0, "b": 0.7, "gain": 0.92},
}

EFFECTS = ("dead_zone", "one_way_backlash", "dead_band")

RUN_KINDS = ("sine_decay", "triangle_decay", "trapezoid_decay")
HELD_OUT = (1, 2)  # indices into RUN_KINDS

IDENTIFIABILITY = {
    None: {"identifiable": None, "expected_class": None, "identifiable_reason": "clean source"},
    "dead_zone": {
        "identifiable": True,
        "expected_class": "dead_zone",
        "identifiable_reason": (
            "after every reversal the output AND the input tension stand still for the same "
            "carriage travel d, while these smooth loops have a non-zero slope right after a "
            "reversal (Bouc-Wen g[a+(1-a)(A+(beta-gamma)|z|)], Coleman-Hodgdon g(2b-c)), so no "
            "refit of the loop reproduces it"
        ),
    },
    "one_way_backlash": {
        "identifiable": False,
        "expected_class": "dead_zone or asymmetry",
        "identifiable_reason": (
            "a one-sided play [u_c-d, u_c] is a centred play of width d on u_c-d/2; the plants are "
            "translation invariant in u, so it equals a symmetric dead zone plus a constant output "
            "offset except for a transient of the first pull from rest that fades within that stroke"
        ),
    },
    "dead_band": {
        "identifiable": True,
        "expected_class": "dead_band",
        "identifiable_reason": (
            "its lost motion is tied to the carriage position (every crossing of rest, both "
            "directions, every amplitude), not to reversals: a memoryless odd step that neither a "
            "drive play (anchored at reversals) nor a refit of these smooth loops (smooth through "
            "rest) can make; caveat: a general Preisach/play-sum plant could absorb it"
        ),
    },
}


# ---------------------------------------------------------------------------------------------
# Plants: vectorised over lanes (rows), integrated in u with RK4 per input step
# ---------------------------------------------------------------------------------------------


def _rhs(p: dict[str, Any], x: np.ndarray, u: np.ndarray, sg: np.ndarray) -> np.ndarray:
    """dx/du of the plant's internal state x on a step of direction sg = sign(du)."""
    if p["kind"] == "bw":
        ax = np.abs(x)
        pw = ax if p["n"] == 1.0 else (ax * ax if p["n"] == 2.0 else ax ** p["n"])
        return p["A"] - (p["beta"] * np.sign(sg * x) + p["gamma"]) * pw
    # Coleman-Hodgdon: dw/du = alpha sign(du) (c u - w) + b
    return p["alpha"] * sg * (p["c"] * u - x) + p["b"]


def _output(p: dict[str, Any], x: np.ndarray, u: np.ndarray) -> np.ndarray:
    if p["kind"] == "bw":
        return p["gain"] * (p["a"] * u + (1.0 - p["a"]) * x)
    return p["gain"] * x


def _with_scale(name: str, scale: float | np.ndarray) -> dict[str, Any]:
    """Plant parameters with the width-setting scale (kappa for Bouc-Wen, alpha for Duhem)."""
    p = dict(PLANTS[name])
    if p["kind"] == "bw":
        p["kappa"] = scale
        p["beta"] = p["beta_share"] * scale
        p["gamma"] = (1.0 - p["beta_share"]) * scale
    else:
        p["alpha"] = scale
    return p


def simulate(
    p: dict[str, Any],
    uc: np.ndarray,
    *,
    hl: np.ndarray,
    hr: np.ndarray,
    band: np.ndarray,
    x0: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    zt0: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Drive + plant on lanes.

    uc: (L, N) carriage path.  The drive is a static dead band of half-width ``band`` around 0
    followed by a play with band [v - hl, v + hr] (hl = hr = d/2: centred backlash; hl = d, hr = 0:
    one-sided gap on the pulling side; 0, 0: rigid).  Returns u_t, the plant output y (noise
    free), the friction state s and the final states (x, s, zt).
    """
    uc = np.atleast_2d(np.asarray(uc, dtype=float))
    L, N = uc.shape
    hl = np.broadcast_to(np.asarray(hl, float), (L,)).copy()
    hr = np.broadcast_to(np.asarray(hr, float), (L,)).copy()
    band = np.broadcast_to(np.asarray(band, float), (L,)).copy()
    v = np.where(np.abs(uc) < band[:, None], 0.0, uc - np.sign(uc) * band[:, None])
    lam = DRIVE["lambda_mm"]
    x = np.zeros(L) if x0 is None else np.array(x0, dtype=float)
    s = np.zeros(L) if s0 is None else np.array(s0, dtype=float)
    zt = v[:, 0].copy() if zt0 is None else np.array(zt0, dtype=float)
    ut = np.empty((L, N))
    xs = np.empty((L, N))
    ss = np.empty((L, N))
    ut[:, 0] = zt
    xs[:, 0] = x
    ss[:, 0] = s
    vT = np.ascontiguousarray(v.T)
    mn, mx, sign, absf, expf = np.minimum, np.maximum, np.sign, np.abs, np.exp
    for k in range(1, N):
        vk = vT[k]
        zn = mn(vk + hr, mx(vk - hl, zt))
        h = zn - zt
        sg = sign(h)
        # Dahl friction state of the tendon end: exact along the step, frozen when h == 0
        s = sg + (s - sg) * expf(-absf(h) / lam)
        # RK4 of the plant in u
        h2 = 0.5 * h
        k1 = _rhs(p, x, zt, sg)
        k2 = _rhs(p, x + h2 * k1, zt + h2, sg)
        k3 = _rhs(p, x + h2 * k2, zt + h2, sg)
        k4 = _rhs(p, x + h * k3, zn, sg)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        zt = zn
        ut[:, k] = zt
        xs[:, k] = x
        ss[:, k] = s
    return {"ut": ut, "y": _output(p, xs, ut), "s": ss, "x": x, "s_end": s, "zt_end": zt}


def _width_of(name: str, scales: np.ndarray) -> dict[str, np.ndarray]:
    """Output width at u = 0 (desc - asc) and input width at the mid output of the steady
    +-6 mm loop (0 -> 6, then 4 cycles; last cycle measured), for each scale."""
    step = 0.005
    up = np.arange(0.0, 6.0, step)
    cyc = np.concatenate([6.0 - step * np.arange(round(12.0 / step)), -6.0 + step * np.arange(round(12.0 / step))])
    path = np.concatenate([up] + [cyc] * 3 + [np.array([6.0])])
    L = len(scales)
    p = _with_scale(name, np.asarray(scales, float))
    r = simulate(p, np.tile(path, (L, 1)), hl=0.0, hr=0.0, band=0.0)
    last = path.size - 1 - cyc.size
    seg = slice(last, path.size)
    u = path[seg]
    y = r["y"][:, seg]
    n_half = cyc.size // 2
    ud, yd = u[: n_half + 1][::-1], y[:, : n_half + 1][:, ::-1]  # descending, reversed to ascending u
    ua, ya = u[n_half:], y[:, n_half:]
    # signed: > 0 when the output lags (descending branch above), < 0 when it leads
    w_out = np.array([np.interp(0.0, ud, yd[i]) - np.interp(0.0, ua, ya[i]) for i in range(L)])
    w_in = []
    for i in range(L):
        ymid = 0.5 * (ya[i, -1] + ya[i, 0])
        w_in.append(np.interp(ymid, ya[i], ua) - np.interp(ymid, yd[i], ud))
    return {"out": w_out, "in": np.array(w_in)}


def calibrate_plants() -> dict[str, dict[str, Any]]:
    """Solve each plant's scale so that its loop is LOOP_WIDTH_MM wide (output, at u = 0)."""
    out: dict[str, dict[str, Any]] = {}
    for name in PLANTS:
        grid = np.geomspace(0.05, 5.0, 40)
        w = np.abs(_width_of(name, grid)["out"])
        # the width rises, peaks (loop not saturated) and then falls with the scale: use the
        # falling side (a saturated, well-formed loop)
        k = int(np.argmax(w))
        g, wg = grid[k:], w[k:]
        order = np.argsort(wg)
        sc = float(np.exp(np.interp(LOOP_WIDTH_MM, wg[order], np.log(g[order]))))
        fine = np.array([sc * f for f in (0.97, 0.99, 1.0, 1.01, 1.03)])
        wf = np.abs(_width_of(name, fine)["out"])
        order = np.argsort(wf)
        sc = float(np.exp(np.interp(LOOP_WIDTH_MM, wf[order], np.log(fine[order]))))
        chk = _width_of(name, np.array([sc]))
        p = _with_scale(name, sc)
        p = {k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in p.items()}
        p["loop_width_output_mm"] = float(abs(chk["out"][0]))
        p["loop_width_input_mm"] = float(abs(chk["in"][0]))
        p["loop_orientation"] = (
            "lagging (descending branch above the ascending one, slope lowest just after a reversal)"
            if chk["out"][0] > 0
            else "leading (ascending branch above the descending one, softening: slope highest just after a reversal)"
        )
        out[name] = p
    return out


# ---------------------------------------------------------------------------------------------
# Excitations
# ---------------------------------------------------------------------------------------------


def excitations(dt: float = FINE_DT) -> list[Any]:
    """The three 80 s runs on the fine clock (riglog's excitation builder, spec labels)."""
    return [
        riglog.make_excitation("sine_decay", dt, amplitudes_mm=AMPS, periods_per_amplitude=5, frequency_hz=0.25),
        riglog.make_excitation("triangle_decay", dt, amplitudes_mm=AMPS, periods_per_amplitude=8, slope_mm_s=6.0),
        riglog.make_excitation(
            "trapezoid_decay", dt, amplitudes_mm=AMPS, periods_per_amplitude=5, slope_mm_s=5.0, dwell_s=0.5
        ),
    ]


def _drive_params(effect: str | None, size: float) -> tuple[float, float, float]:
    """(hl, hr, band) of the drive for an effect of physical size ``size`` (mm)."""
    if effect is None:
        return 0.0, 0.0, 0.0
    if effect == "dead_zone":
        return size / 2.0, size / 2.0, 0.0
    if effect == "one_way_backlash":
        return size, 0.0, 0.0
    if effect == "dead_band":
        return 0.0, 0.0, size
    raise ValueError(effect)


def _rms_noise_sd(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a))) / OUTPUT_NOISE_MM)


def calibrate_sizes(p: dict[str, Any], exs: list[Any]) -> dict[str, dict[str, float]]:
    """Effect sizes (mm) whose held-out RMS is TARGETS x output noise (solved on a 200 Hz
    path, then re-measured exactly on the 1 kHz simulation by the caller)."""
    sub = 5  # 200 Hz path; the plants are rate independent, RK4 steps <= 0.05 mm
    grid = np.geomspace(0.004, 1.2, 14)
    lanes_u, lanes_d, tags = [], [], []
    for j in HELD_OUT:
        u = exs[j].u[::sub]
        lanes_u.append(u)
        lanes_d.append(_drive_params(None, 0.0))
        tags.append((None, 0.0, j))
        for eff in EFFECTS:
            for g in grid:
                lanes_u.append(u)
                lanes_d.append(_drive_params(eff, float(g)))
                tags.append((eff, float(g), j))
    n = min(x.size for x in lanes_u)
    U = np.array([x[:n] for x in lanes_u])
    D = np.array(lanes_d)
    r = simulate(p, U, hl=D[:, 0], hr=D[:, 1], band=D[:, 2])
    enc = ENC_EVERY // sub
    y = r["y"][:, ::enc]
    clean = {j: y[i] for i, (e, _, j) in enumerate(tags) if e is None}
    out: dict[str, dict[str, float]] = {}
    for eff in EFFECTS:
        rms = []
        for g in grid:
            diffs = [y[i] - clean[j] for i, (e, gg, j) in enumerate(tags) if e == eff and gg == g]
            rms.append(_rms_noise_sd(np.concatenate(diffs)))
        rms = np.array(rms)
        out[eff] = {}
        for strength, target in TARGETS.items():
            out[eff][strength] = float(np.exp(np.interp(np.log(target), np.log(rms), np.log(grid))))
    return out


def dead_zone_fits(
    p: dict[str, Any], exs: list[Any], targets: list[tuple[str | None, float]]
) -> list[dict[str, float]]:
    """For each target drive (effect, size): the symmetric dead zone d' plus a constant output
    offset that best reproduces its output on the held-out runs (noise free, 200 Hz path,
    least squares over a fine grid of d' refined by a parabola); residual RMS in noise sd."""
    sub = 5
    own = [s_ for e, s_ in targets if e in ("dead_zone", "one_way_backlash")]
    grid = np.unique(np.concatenate([[0.0], np.geomspace(0.005, 0.8, 48), own]))
    lanes_u, lanes_d = [], []
    for j in HELD_OUT:
        u = exs[j].u[::sub]
        for eff, size in targets:
            lanes_u.append(u)
            lanes_d.append(_drive_params(eff, size))
        for g in grid:
            lanes_u.append(u)
            lanes_d.append(_drive_params("dead_zone", float(g)))
    D = np.array(lanes_d)
    r = simulate(p, np.array(lanes_u), hl=D[:, 0], hr=D[:, 1], band=D[:, 2])
    y = r["y"][:, :: ENC_EVERY // sub]
    per = len(targets) + grid.size
    out = []
    for ti in range(len(targets)):
        res = []
        for gi in range(grid.size):
            diff = np.concatenate(
                [y[k * per + ti] - y[k * per + len(targets) + gi] for k in range(len(HELD_OUT))]
            )
            res.append((_rms_noise_sd(diff - diff.mean()), float(diff.mean())))
        rr = np.array([x[0] for x in res])
        k = int(np.argmin(rr))
        d_best, r_best, off = float(grid[k]), float(rr[k]), res[k][1]
        if 0 < k < grid.size - 1 and r_best > 1e-6:
            # the squared residual is close to quadratic in d' near its minimum
            xs = grid[k - 1 : k + 2]
            c2, c1, c0 = np.polyfit(xs, rr[k - 1 : k + 2] ** 2, 2)
            if c2 > 0:
                xm = -c1 / (2 * c2)
                r2 = c0 - c1 * c1 / (4 * c2)
                if xs[0] <= xm <= xs[2] and r2 < r_best**2:
                    d_best, r_best = float(xm), float(math.sqrt(max(r2, 0.0)))
        out.append({"dead_zone_mm": round(d_best, 5), "offset_mm": round(off, 6), "residual_noise_sd": round(r_best, 4)})
    return out


# ---------------------------------------------------------------------------------------------
# Sources
# ---------------------------------------------------------------------------------------------


def source_name(seed: int, plant: str, tag: str) -> str:
    return "bs-" + hashlib.sha256(f"backlash_smooth|{seed}|{plant}|{tag}".encode()).hexdigest()[:10]


def _source_specs(plant: str) -> list[dict[str, Any]]:
    specs = [
        {"plant": plant, "tag": "clean_rest", "effect": None, "strength": None, "start": "rest"},
        {"plant": plant, "tag": "clean_loaded", "effect": None, "strength": None, "start": "loaded"},
    ]
    for eff in EFFECTS:
        for strength in TARGETS:
            specs.append(
                {"plant": plant, "tag": f"{eff}_{strength}", "effect": eff, "strength": strength, "start": "rest"}
            )
    return specs


def _prestroke_state(p: dict[str, Any]) -> tuple[float, float, float]:
    """Plant state, friction state and tendon-end position after an unrecorded 0 -> +6 -> 0 stroke."""
    step = 0.002
    path = np.concatenate([np.arange(0.0, 6.0, step), np.arange(6.0, 0.0, -step), [0.0]])
    r = simulate(p, path[None, :], hl=0.0, hr=0.0, band=0.0)
    return float(r["x"][0]), float(r["s_end"][0]), float(r["zt_end"][0])


def _plant_job(args: tuple[str, dict[str, Any], int, str, list[tuple[int, int]]]) -> dict[str, Any]:
    """Simulate and write the 8 sources of one plant; return their truth entries."""
    plant, p, seed, outdir, cfg_pairs = args
    t0 = time.perf_counter()
    exs = excitations()
    sizes = calibrate_sizes(p, exs)
    specs = _source_specs(plant)
    x_loaded, s_loaded, _ = _prestroke_state(p)

    lanes_u, lanes_d, x0, s0, keys = [], [], [], [], []
    for si, sp in enumerate(specs):
        size = 0.0 if sp["effect"] is None else sizes[sp["effect"]][sp["strength"]]
        sp["size_mm"] = None if sp["effect"] is None else float(size)
        for j, ex in enumerate(exs):
            lanes_u.append(ex.u)
            lanes_d.append(_drive_params(sp["effect"], size))
            loaded = sp["start"] == "loaded"
            x0.append(x_loaded if loaded else 0.0)
            s0.append(s_loaded if loaded else 0.0)
            keys.append((si, j))
    n = min(x.size for x in lanes_u)
    assert all(x.size == n for x in lanes_u), "runs must share one length"
    D = np.array(lanes_d)
    r = simulate(p, np.array(lanes_u), hl=D[:, 0], hr=D[:, 1], band=D[:, 2], x0=np.array(x0), s0=np.array(s0))
    y_fine, ut, s = r["y"], r["ut"], r["s"]
    lane = {k: i for i, k in enumerate(keys)}

    # how well a symmetric dead zone + constant output offset stands in for each effect
    fit_targets = [(sp["effect"], sp["size_mm"]) for sp in specs if sp["effect"] is not None]
    fits = dict(zip(fit_targets, dead_zone_fits(p, exs, fit_targets), strict=True))

    # oracle: effect minus clean-at-rest, noise free, on the encoder clock
    clean_si = 0
    truth: dict[str, Any] = {}
    rest_clean_enc = {j: y_fine[lane[(clean_si, j)], ::ENC_EVERY] for j in range(len(exs))}
    for si, sp in enumerate(specs):
        name = source_name(seed, plant, sp["tag"])
        per_run = {}
        held = []
        for j, ex in enumerate(exs):
            d = y_fine[lane[(si, j)], ::ENC_EVERY] - rest_clean_enc[j] if sp["effect"] else np.zeros(n // ENC_EVERY + 1)
            per_run[ex.manifest["kind"]] = round(_rms_noise_sd(d), 4)
            if j in HELD_OUT:
                held.append(d)
        oracle = {
            "held_out_rms_noise_sd": round(_rms_noise_sd(np.concatenate(held)), 4),
            "held_out_rms_mm": round(_rms_noise_sd(np.concatenate(held)) * OUTPUT_NOISE_MM, 6),
            "per_run_rms_noise_sd": per_run,
            "target_noise_sd": TARGETS.get(sp["strength"]) if sp["strength"] else 0.0,
            "best_symmetric_dead_zone_plus_offset": fits.get((sp["effect"], sp["size_mm"])),
            "definition": "RMS over the triangle_decay and trapezoid_decay runs (100 Hz) of the noise-free "
            "output with the effect minus the clean output of the same plant started at rest, / 0.01 mm; "
            "best_symmetric_dead_zone_plus_offset: the centred drive play d' and constant output offset "
            "that best reproduce the effect's output on the same runs (plant known), residual RMS / 0.01 mm",
        }
        ca, rr = cfg_pairs[si]
        cfg = {"curve_angle_deg": ca, "radius_mm": rr}
        runs = []
        for j, ex in enumerate(exs):
            i = lane[(si, j)]
            rng = np.random.default_rng([seed, list(PLANTS).index(plant), si, j])
            t_enc = ex.t_s[::ENC_EVERY]
            u_enc = ex.u[::ENC_EVERY]
            y_enc = y_fine[i, ::ENC_EVERY] + rng.normal(0.0, OUTPUT_NOISE_MM, t_enc.size)
            t_in = (DRIVE["P0_n"] + DRIVE["k_t_n_per_mm"] * ut[i]) * np.exp(DRIVE["mu_theta"] * s[i])
            t_out = DRIVE["F0_n"] + DRIVE["k_r_n_per_mm"] * y_fine[i]
            t_in = t_in + rng.normal(0.0, TENSION_NOISE_N, t_in.size)
            t_out = t_out + rng.normal(0.0, TENSION_NOISE_N, t_out.size)
            rid = riglog.run_id_for(cfg, ex.manifest["kind"], j + 1)
            started = _dt.datetime(2026, 3, 2, 9, 0, tzinfo=_dt.UTC) + _dt.timedelta(
                minutes=40 * (list(PLANTS).index(plant) * 8 + si) + 5 * j
            )
            riglog.write_run_folder(
                Path(outdir) / name, rid, t_enc, u_enc, y_enc, configuration=cfg, excitation=ex.manifest,
                loadcell=(t_in, t_out), loadcell_noise_n=0.0, events=True, started_at=started,
                seed=int(rng.integers(0, 2**31)),
            )
            runs.append(rid)
        ident = IDENTIFIABILITY[sp["effect"]]
        entry = {
            "plant": plant,
            "effect": sp["effect"],
            "strength": sp["strength"],
            "size_mm": sp["size_mm"],
            "size_meaning": {
                None: None,
                "dead_zone": "total dead travel d of the carriage after every reversal (play half-width d/2)",
                "one_way_backlash": "gap d, all on the pulling side at rest (one-sided play [u_c-d, u_c])",
                "dead_band": "half-width b: |u_c| < b passes nothing (2b of carriage travel lost per crossing)",
            }[sp["effect"]],
            "start": sp["start"],
            "configuration": cfg,
            "runs": runs,
            **ident,
            "oracle": oracle,
        }
        if sp["effect"] == "one_way_backlash":
            el = p["a"] if p["kind"] == "bw" else p["c"]
            entry["equivalent_output_offset_mm"] = round(-p["gain"] * el * sp["size_mm"] / 2.0, 6)
        truth[name] = entry
    return {"plant": plant, "sources": truth, "sizes": sizes, "seconds": time.perf_counter() - t0}


def generate(outdir: str | Path, seed: int = 0, workers: int = 2) -> dict[str, Any]:
    """Write the 24 sources and ``backlash_smooth_truth.json`` under ``outdir``; return the truth."""
    t0 = time.perf_counter()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    plants = calibrate_plants()
    rng = np.random.default_rng(seed)
    configs = [(a, r) for a in riglog.STANDARD_CURVE_ANGLES_DEG for r in riglog.STANDARD_RADII_MM]
    perm = rng.permutation(len(configs))
    jobs = []
    for pi, name in enumerate(plants):
        pairs = [tuple(int(v) for v in configs[perm[pi * 8 + k]]) for k in range(8)]
        jobs.append((name, plants[name], seed, str(outdir), pairs))
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(_plant_job, jobs))
    else:
        results = [_plant_job(j) for j in jobs]
    sources: dict[str, Any] = {}
    for res in results:
        sources.update(res["sources"])
    truth = {
        "generator": "backlash_smooth (clean room, physics only)",
        "format": riglog.FORMAT,
        "seed": seed,
        "noise": {"output_sd_mm": OUTPUT_NOISE_MM, "tension_sd_n": TENSION_NOISE_N},
        "clocks": {"encoder_hz": 100, "loadcell_hz": 1000, "simulation_hz": 1000},
        "plants": plants,
        "drive": {
            **DRIVE,
            "input_tension": "T_in = (P0 + k_t u_t) exp(mu_theta s), ds/du_t = (sign(du_t) - s)/lambda",
            "output_tension": "T_out = F0 + k_r y",
            "friction_turnover_mm": round(DRIVE["lambda_mm"] * math.log(19.0), 4),
        },
        "held_out_runs": [RUN_KINDS[j] for j in HELD_OUT],
        "sources": dict(sorted(sources.items())),
        "generation_seconds": round(time.perf_counter() - t0, 2),
    }
    (outdir / "backlash_smooth_truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return truth


def _main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    truth = generate(a.outdir, seed=a.seed, workers=a.workers)
    print(f"{'source':14s} {'plant':6s} {'effect':17s} {'str':6s} {'size_mm':>8s} {'start':7s} "
          f"{'ident':6s} {'oracle_sd':>9s} {'dz+off_fit_sd':>13s}")
    order = sorted(
        truth["sources"].items(),
        key=lambda kv: (kv[1]["plant"], str(kv[1]["effect"]), str(kv[1]["strength"]), kv[1]["start"]),
    )
    for name, s in order:
        size = "" if s["size_mm"] is None else f"{s['size_mm']:.4f}"
        fit = s["oracle"]["best_symmetric_dead_zone_plus_offset"]
        fit_s = "" if fit is None else f"{fit['residual_noise_sd']:.3f}"
        print(f"{name:14s} {s['plant']:6s} {s['effect']!s:17s} {s['strength']!s:6s} {size:>8s} "
              f"{s['start']:7s} {s['identifiable']!s:6s} {s['oracle']['held_out_rms_noise_sd']:9.3f} {fit_s:>13s}")
    print(f"generated in {truth['generation_seconds']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
