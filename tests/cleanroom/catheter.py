"""Clean-room, physics-based, rate-dependent tendon-driven catheter plant.

Written from textbook physics and the column layout in
``../shared/real-data/tendon-catheter/README.md`` (no real data was read or copied), for
testing a hysteresis pipeline against a plant it was not built around.

Plant (all lumped, tensions in N relative to the pretension T_pre, lengths in mm)::

    q            actuator tendon displacement (input, 0..~5.8 mm)
    q_b          after the actuator/tendon slack: centred backlash of half width b
    x            lumped tendon node inside the sheath (where the sheath friction acts)
    T_p = k1 (q_b - x)                       proximal tendon segment (Hooke)
    T_d = k2 (x - delta)                     distal tendon segment (Hooke)
    T_d = k_b delta (1 + eps (delta/d_ref)^2)   bending section: moment balance T_d r = M(theta),
                                             stiffening elastic backbone, delta = r_sec * dtheta
    theta = theta0 + dtheta                  tip bending angle (output, deg; 30 at rest)

The distal part is quasi-static (no inertia), so delta = H(x) is a static monotone map solved
once on a table.  The node x moves only when the net force on it, T_p - T_d, exceeds the
sheath friction, which is capstan-like (proportional to the mean tendon tension, Coulomb law
with the normal force set by tension times wrap) and velocity dependent (Stribeck bump at low
speed plus viscous term)::

    F_fric(v) = sign(v) mu_eff Tbar (1 + s_st exp(-(|v|/v_s)^2)) + c_v v,
    Tbar = T_pre + (T_p + T_d)/2
    stick  if |T_p - T_d| <= mu_eff Tbar (1 + s_st)     (static friction)
    slide  with v solving  T_p - T_d = F_fric(v)          (massless node: first-order ODE)

The friction curve F(|v|) must be non-decreasing (c_v >= 0.86 mu_eff Tbar s_st / v_s, true for
every variant here over the tension range reached), so a sliding speed is unique and sliding
stops as soon as |T_p - T_d| falls to the static level.  The viscous term makes the loop wider and the lag larger at higher frequency (0.1 -> 0.5 Hz);
the Coulomb part and the slack give the rate-independent backlash.  The motor current is a
proxy of the proximal tension plus motor friction.  Runs start at rest (q = 0, x = 0, tensions
at pretension, node stuck).

Excitations as described in the real data's README: 7-cycle decaying sinusoids of tendon
displacement at k x 0.1 Hz (k = 1..5), ~500 Hz with slightly irregular timestamps;
``data_1_k`` decays towards mid-stroke, ``data_2_k`` decays back to zero; both start at 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "CatheterParams",
    "VARIANTS",
    "variant",
    "timestamps",
    "decaying_sine",
    "distal_map",
    "simulate",
    "loop_width_deg",
    "write_catheter_runs",
    "COLUMNS",
]

COLUMNS = ["Time", "Tendon Disp.", "Motor Curr.", "Pos x", "Pos y", "Pos z", "Angle x", "Angle y", "Angle z"]


@dataclass(frozen=True)
class CatheterParams:
    """Plant parameters (defaults give ~30..93 deg over 0..5.8 mm at 0.1 Hz)."""

    backlash_halfwidth_mm: float = 0.25   # actuator coupling / tendon slack (total 0.5 mm)
    k1_n_per_mm: float = 4.0              # proximal tendon segment stiffness
    k2_n_per_mm: float = 8.0              # distal tendon segment stiffness
    kb_n_per_mm: float = 1.95             # bending stiffness in tendon coordinates (M / r^2)
    stiffening: float = 0.15              # eps: kb (1 + eps (delta/d_ref)^2)
    d_ref_mm: float = 3.0
    r_sec_mm: float = 2.5                 # tendon offset from the backbone: delta = r dtheta
    theta0_deg: float = 30.0              # rest angle (pre-curved tip)
    t_pre_n: float = 1.0                  # tendon pretension
    mu_eff: float = 0.2                   # Coulomb coefficient x wrap (capstan-like, on Tbar)
    stribeck_excess: float = 0.25         # s_st: static friction excess at v -> 0
    v_stribeck_mm_s: float = 3.0
    viscous_n_s_per_mm: float = 0.25      # c_v
    # measurement model
    bend_length_mm: float = 50.0
    current_offset: float = 60.0          # Motor Curr. raw units
    current_per_n: float = 18.0
    current_friction: float = 10.0        # motor/gearbox friction, x tanh(dq/dt / 0.5 mm/s)
    current_noise: float = 2.0
    angle_noise_deg: float = 0.08
    pos_noise_mm: float = 0.05
    disp_quantum_mm: float = 0.0005


VARIANTS: dict[str, dict[str, float]] = {
    "default": {},
    "strong_rate": {"viscous_n_s_per_mm": 0.8},               # loops widen much more with frequency
    "weak_rate": {"viscous_n_s_per_mm": 0.06, "stribeck_excess": 0.1},  # nearly rate independent
    "coulomb_only": {"viscous_n_s_per_mm": 0.02, "stribeck_excess": 0.0},
    "big_backlash": {"backlash_halfwidth_mm": 0.6},
    "stiff_tendon": {"k1_n_per_mm": 12.0, "k2_n_per_mm": 20.0, "kb_n_per_mm": 2.6},
    "strong_stribeck": {"stribeck_excess": 0.6, "v_stribeck_mm_s": 2.0, "viscous_n_s_per_mm": 0.4},
}
"""Named parameter variants (overrides of :class:`CatheterParams`)."""


def variant(name: str = "default", **overrides: float) -> CatheterParams:
    return replace(CatheterParams(), **{**VARIANTS[name], **overrides})


# ---------------------------------------------------------------------------------------------
# Excitation
# ---------------------------------------------------------------------------------------------


def timestamps(duration_s: float, rate_hz: float = 500.0, jitter: float = 0.05, rng: np.random.Generator | None = None,
               hiccup_prob: float = 0.002) -> np.ndarray:
    """Irregular sample times from 0 to >= duration: nominal 1/rate with +/- jitter (fraction
    of the period, Gaussian) and rare hiccups (a sample 1.5-2.5 periods late)."""
    rng = rng or np.random.default_rng(0)
    dt0 = 1.0 / rate_hz
    n = int(math.ceil(duration_s * rate_hz * 1.02)) + 10
    dts = dt0 * (1.0 + jitter * rng.standard_normal(n))
    hic = rng.random(n) < hiccup_prob
    dts[hic] = dt0 * rng.uniform(1.5, 2.5, hic.sum())
    dts = np.clip(dts, 0.3 * dt0, None)
    t = np.concatenate([[0.0], np.cumsum(dts)])
    return t[t <= duration_s + 1e-9]


def decaying_sine(t: np.ndarray, frequency_hz: float, family: int, stroke_mm: float = 6.0, cycles: int = 7
                  ) -> np.ndarray:
    """7-cycle decaying sinusoid from rest (q(0) = 0), linear envelope env = 1 - t/T:

    * family 1 (``data_1``): q = m + env ((h - m) - h cos(2 pi f t)), m = h = stroke/2:
      oscillation decays towards mid-stroke m.
    * family 2 (``data_2``): q = env h (1 - cos(2 pi f t)): decays back to 0.

    With stroke 6 mm the first peak is ~5.8 mm (family 1) / ~5.6 mm (family 2).
    """
    T = cycles / frequency_hz
    env = np.clip(1.0 - t / T, 0.0, 1.0)
    h = 0.5 * stroke_mm
    m = h if family == 1 else 0.0
    q = m + env * ((h - m) - h * np.cos(2 * np.pi * frequency_hz * t))
    return np.maximum(q, 0.0)


# ---------------------------------------------------------------------------------------------
# Plant
# ---------------------------------------------------------------------------------------------


def distal_map(p: CatheterParams, x_max: float = 15.0, n: int = 3001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table of the quasi-static distal solution: node x -> (delta, T_d).

    k2 (x - delta) = kb delta (1 + eps (delta/d_ref)^2), solved for delta on a grid of delta
    (monotone in delta, so x(delta) is tabulated and inverted by interpolation).  Slack: the
    total tension T_pre + T_d cannot go below 0 (delta >= -T_pre / kb about)."""
    d = np.linspace(-p.t_pre_n / p.kb_n_per_mm, x_max, n)
    td = p.kb_n_per_mm * d * (1.0 + p.stiffening * (d / p.d_ref_mm) ** 2)
    x = d + td / p.k2_n_per_mm
    return x, d, td


def _friction(v: float, mu_tbar: float, p: CatheterParams) -> tuple[float, float]:
    """|F|(|v|) for |v| >= 0 and its derivative."""
    e = math.exp(-(v / p.v_stribeck_mm_s) ** 2)
    f = mu_tbar * (1.0 + p.stribeck_excess * e) + p.viscous_n_s_per_mm * v
    df = mu_tbar * p.stribeck_excess * e * (-2.0 * v / p.v_stribeck_mm_s ** 2) + p.viscous_n_s_per_mm
    return f, df


def _slide_speed(net_abs: float, mu_tbar: float, p: CatheterParams, v0: float) -> float:
    """Solve F(|v|) = |net| for |v| > 0: safeguarded Newton in a bisection bracket."""
    lo, hi = 0.0, max(1e-6, (net_abs - mu_tbar) / max(p.viscous_n_s_per_mm, 1e-9)) + 1e-6
    # F(hi) >= mu_tbar + c_v hi >= net_abs; F(lo) = mu_tbar (1 + s) > net_abs (we are sliding)
    v = min(max(v0, lo), hi)
    for _ in range(40):
        f, df = _friction(v, mu_tbar, p)
        g = f - net_abs
        if abs(g) < 1e-9:
            break
        if g > 0:
            hi = v
        else:
            lo = v
        vn = v - g / df if df > 0 else 0.5 * (lo + hi)
        v = vn if lo < vn < hi else 0.5 * (lo + hi)
        if hi - lo < 1e-10:
            break
    return v


def simulate(t: np.ndarray, q: np.ndarray, p: CatheterParams | None = None, max_substep_s: float = 0.001
             ) -> dict[str, np.ndarray]:
    """Simulate the catheter on the (irregular) clock t for tendon displacement q (mm).

    Returns a dict of arrays: theta_deg (tip angle), t_prox_n / t_dist_n (total tensions),
    x_mm (sheath node), qb_mm (after the slack), v_mm_s (node speed), delta_mm."""
    p = p or CatheterParams()
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    xs, ds, _ = distal_map(p)
    b = p.backlash_halfwidth_mm
    kb, eps, dref, k1 = p.kb_n_per_mm, p.stiffening, p.d_ref_mm, p.k1_n_per_mm
    n = t.size
    out = {k: np.empty(n) for k in ("theta_deg", "t_prox_n", "t_dist_n", "x_mm", "qb_mm", "v_mm_s", "delta_mm")}
    # at rest: slack centred on q[0]; node at the equilibrium k1 (q_b - x) = T_d(x)
    qb = float(q[0])
    xg = np.linspace(xs[0], max(qb, 0.0) + 1.0, 2001)
    x = float(xg[np.argmin(np.abs(k1 * (qb - xg) - np.interp(xg, xs, ds) * kb))])
    q_prev = float(q[0])
    v = 0.0
    for k in range(n):
        if k:
            dt_total = t[k] - t[k - 1]
            m = max(1, int(math.ceil(dt_total / max_substep_s)))
            h = dt_total / m
            for j in range(m):
                qi = q_prev + (q[k] - q_prev) * (j + 1) / m  # input linear within the interval
                qb = min(qi + b, max(qi - b, qb))
                delta = float(np.interp(x, xs, ds))
                td = kb * delta * (1.0 + eps * (delta / dref) ** 2)
                tp = max(k1 * (qb - x), -p.t_pre_n)  # a tendon cannot push
                net = tp - td
                mu_tbar = p.mu_eff * max(p.t_pre_n + 0.5 * (tp + td), 0.0)
                if abs(net) <= mu_tbar * (1.0 + p.stribeck_excess):
                    v = 0.0  # static friction holds (F(|v|) is monotone: no slower sliding state)
                else:
                    v = math.copysign(_slide_speed(abs(net), mu_tbar, p, abs(v)), net)
                x += v * h
        q_prev = q[k]
        delta = float(np.interp(x, xs, ds))
        td = p.kb_n_per_mm * delta * (1.0 + p.stiffening * (delta / p.d_ref_mm) ** 2)
        tp = max(p.k1_n_per_mm * (qb - x), -p.t_pre_n)
        out["theta_deg"][k] = p.theta0_deg + math.degrees(delta / p.r_sec_mm)
        out["t_prox_n"][k] = p.t_pre_n + tp
        out["t_dist_n"][k] = p.t_pre_n + td
        out["x_mm"][k] = x
        out["qb_mm"][k] = qb
        out["v_mm_s"][k] = v
        out["delta_mm"][k] = delta
    return out


def loop_width_deg(q: np.ndarray, theta: np.ndarray, t: np.ndarray, t_from: float, t_to: float) -> float:
    """Vertical loop width at mid-range of q within [t_from, t_to): mean angle on the unloading
    branch minus on the loading branch, near the q mid-point of that window."""
    sl = (t >= t_from) & (t < t_to)
    qq, th = q[sl], theta[sl]
    dq = np.gradient(qq)
    mid = 0.5 * (qq.max() + qq.min())
    tol = 0.05 * (qq.max() - qq.min())
    near = np.abs(qq - mid) < tol
    up = th[near & (dq > 0)]
    dn = th[near & (dq < 0)]
    if up.size == 0 or dn.size == 0:
        return float("nan")
    return float(dn.mean() - up.mean())


# ---------------------------------------------------------------------------------------------
# Writer
# ---------------------------------------------------------------------------------------------


def _frequency_for(family: int, k: int, mislabel_2_4: bool) -> float:
    if mislabel_2_4 and family == 2 and k == 4:
        return 0.3
    return 0.1 * k


def write_catheter_runs(folder: str | Path, seed: int = 0, params: CatheterParams | None = None, *,
                        variant_name: str | None = None, ks: tuple[int, ...] = (1, 2, 3, 4, 5),
                        families: tuple[int, ...] = (1, 2), rate_hz: float = 500.0, stroke_mm: float = 6.0,
                        mislabel_2_4: bool = False, write_truth: bool = True) -> list[Path]:
    """Write ``data_{family}_{k}.txt`` files (CSV with header, the real data's column layout)
    into ``folder``: 7-cycle decaying sinusoids at k x 0.1 Hz, ~500 Hz irregular clock.

    Columns: ``Time`` (s), ``Tendon Disp.`` (mm, input, quantised), ``Motor Curr.`` (raw integer
    units: offset + per_N x proximal tension + motor friction x tanh(dq/dt/0.5) + noise),
    ``Pos x/y/z`` (tip of a constant-curvature section of ``bend_length_mm`` bent by the angle,
    tracker noise), ``Angle x`` (bending angle, deg, the output), ``Angle y/z`` (small noise
    about constants).  ``mislabel_2_4`` reproduces the README's quirk (data_2_4 is 0.3 Hz).

    With ``write_truth`` a ``catheter_truth.json`` (parameters, frequencies, noise-free loop
    widths) is written beside the data files.  Returns the file paths."""
    import json

    if params is None:
        params = variant(variant_name or "default")
    p = params
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    truth: dict[str, Any] = {"generator": "cleanroom2.catheter", "params": asdict(p),
                             "variant": variant_name or "custom/default", "seed": seed, "files": {}}
    for fam in families:
        for k in ks:
            rng = np.random.default_rng([seed, fam, k])
            f = _frequency_for(fam, k, mislabel_2_4)
            T = 7.0 / f
            t = timestamps(T, rate_hz, rng=rng)
            q = decaying_sine(t, f, fam, stroke_mm)
            sim = simulate(t, q, p)
            th = sim["theta_deg"]
            n = t.size
            dq = np.gradient(q, t)
            q_meas = np.round(q / p.disp_quantum_mm) * p.disp_quantum_mm
            cur = np.rint(p.current_offset + p.current_per_n * sim["t_prox_n"]
                          + p.current_friction * np.tanh(dq / 0.5) + rng.normal(0, p.current_noise, n)).astype(int)
            ang = th + rng.normal(0, p.angle_noise_deg, n)
            thr = np.radians(np.maximum(th, 1e-6))
            L = p.bend_length_mm
            px = L * (1 - np.cos(thr)) / thr + rng.normal(0, p.pos_noise_mm, n)
            pz = L * np.sin(thr) / thr + rng.normal(0, p.pos_noise_mm, n)
            py = 0.3 + rng.normal(0, p.pos_noise_mm, n)
            ay = 0.4 + rng.normal(0, p.angle_noise_deg, n)
            az = -1.2 + rng.normal(0, p.angle_noise_deg, n)
            df = pd.DataFrame({
                "Time": np.round(t, 4), "Tendon Disp.": np.round(q_meas, 4), "Motor Curr.": cur,
                "Pos x": np.round(px, 4), "Pos y": np.round(py, 4), "Pos z": np.round(pz, 4),
                "Angle x": np.round(ang, 4), "Angle y": np.round(ay, 4), "Angle z": np.round(az, 4),
            }, columns=COLUMNS)
            path = folder / f"data_{fam}_{k}.txt"
            df.to_csv(path, index=False, lineterminator="\n")
            paths.append(path)
            per = 1.0 / f
            widths = [loop_width_deg(q, th, t, c * per, (c + 1) * per) for c in range(7)]
            truth["files"][path.name] = {
                "family": fam, "frequency_hz": round(f, 6), "duration_s": float(t[-1]), "samples": int(n),
                "angle_range_deg": [float(th.min()), float(th.max())],
                "loop_width_deg_per_cycle": widths,
                "noise": {"angle_sd_deg": p.angle_noise_deg, "disp_quantum_mm": p.disp_quantum_mm},
            }
    if write_truth:
        (folder / "catheter_truth.json").write_text(json.dumps(truth, indent=1) + "\n", encoding="utf-8")
    return paths
