"""Synthetic TSM-like runs with each named effect applied by hand (test helper, no rig needed).

The clean plant is a smooth backlash (the output approaches u - s r exponentially with input
travel) - close to, but not inside, the play-operator families.
"""

from __future__ import annotations

import numpy as np

from hysteresis.discrepancy._ops import play, shift
from hysteresis.discrepancy.runs import RunData

DT = 0.04  # 25 Hz keeps the tests fast


def sine_decay(amps=(6.0, 4.5, 3.0, 1.5), periods=3, f=0.25):
    t, u, t0 = [], [], 0.0
    for a in amps:
        tt = np.arange(0, periods / f, DT)
        t.append(tt + t0)
        u.append(a * np.sin(2 * np.pi * f * tt))
        t0 += periods / f
    return np.concatenate(t), np.concatenate(u)


def triangle_decay(amps=(6.0, 4.5, 3.0, 1.5), periods=2, slope=6.0, dwell=0.0):
    pts_t, pts_u, t = [0.0], [0.0], 0.0
    for a in amps:
        for _ in range(periods):
            for target in (a, -a):
                t += abs(target - pts_u[-1]) / slope
                pts_t.append(t); pts_u.append(target)
                if dwell:
                    t += dwell
                    pts_t.append(t); pts_u.append(target)
    t += abs(pts_u[-1]) / slope
    pts_t.append(t); pts_u.append(0.0)
    tt = np.arange(0, t, DT)
    return tt, np.interp(tt, pts_t, pts_u)


def smooth_backlash(t, u, *, r=0.8, a=4.0, gain=0.95, rate=0.0, asym=0.0):
    """Play operator with rounded corners: the output relaxes towards the play state with input
    travel (rate 1/a mm), so it is near, but not inside, the play-operator families."""
    v = np.gradient(u, t)
    y = np.zeros_like(u)
    z = 0.0
    for k in range(1, u.size):
        du = u[k] - u[k - 1]
        s = 1.0 if du > 0 else -1.0
        rr = r * (1.0 + 0.5 * rate * np.tanh(abs(v[k]) / 5.0)) * (1.0 + 0.3 * asym * s)
        z = min(max(z, u[k] - rr), u[k] + rr) if s > 0 else max(min(z, u[k] + rr), u[k] - rr)
        y[k] = y[k - 1] + (1.0 - np.exp(-a * abs(du))) * (gain * z - y[k - 1])
    return y


def make_run(kind, effects=None, *, config=(90, 30), seed=0, role=None):
    """One run with the named effects at the given strengths (1 = the rig's nominal size)."""
    effects = effects or {}
    rng = np.random.default_rng(seed + 7 * config[0] + config[1])
    if kind == "sine":
        t, u = sine_decay()
    elif kind == "triangle":
        t, u = triangle_decay()
    else:
        t, u = triangle_decay(slope=4.0, dwell=1.0, periods=1)
    r = 0.3 + 0.8 * config[0] / 90 * (1.0 + 0.2 * 30 / config[1])
    dz = 0.4 * effects.get("dead_zone", 0.0)
    u_drive = play(u, 0.5 * dz, z0=0.0) if dz else u
    y = smooth_backlash(t, u_drive, r=r, rate=effects.get("rate_dependence", 0.0),
                        asym=effects.get("asymmetry", 0.0))
    t_out = np.full_like(u, 4.0)
    t_in = 4.0 + 1.5 * (u_drive - y) + 0.3 * np.abs(u_drive)
    if "tendon_elongation" in effects:
        y = y - 0.02 * effects["tendon_elongation"] * (t_in**2 - 16.0)
    if "saturation" in effects:
        y = np.minimum(y, 6.0 * (1.0 - 0.3 * effects["saturation"]) - 1.8)
    if "drift" in effects:
        y = y + 0.3 * effects["drift"] * (1.0 - np.exp(-t / 60.0))
    if "time_delay" in effects:
        y = shift(t, y, 0.05 * effects["time_delay"])
    y = y + rng.normal(0.0, 0.003, y.size)
    return RunData(
        run_id=f"{kind}_{config[0]}_{config[1]}", t=t, u=u, y=y, tension=t_in, tension_out=t_out,
        config={"curve_angle_deg": config[0], "radius_mm": config[1]}, excitation=kind,
        role=role or ("identification" if kind == "sine" else "heldout"),
    )


def make_runs(effects=None, configs=((90, 30), (45, 60))):
    return [make_run(k, effects, config=c) for c in configs for k in ("sine", "triangle", "trapezoid")]
