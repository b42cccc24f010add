"""A second, independent source of test data: known effects added to plain model plants.

The virtual rig simulates a tendon-sheath mechanism with its own physics; the candidate terms
of :mod:`.effects` were written against it. To check that the workflow names effects it was not
built on, this module makes runs another way: a *plain plant* (a Gamma play sum, a Preisach
plane or a Bouc-Wen model, each a fixed model of the hysteresis family, not fitted to any rig)
is driven by three 80 s excitations and one effect is injected, coded here from its physical
description and not from the candidate's term:

* ``time_delay``: the output is read ``tau`` late;
* ``dead_zone``: an actuator backlash of total width ``d`` before the plant (and the tendon);
* ``rate_dependence``: the plant's input lags by a lost motion that grows with the sliding speed
  (friction rising with speed): a backlash whose width follows ``|v|``;
* ``tendon_elongation``: the tendon stretches as ``k T^2`` before the plant sees the motion;
* ``drift``: a slow creep ``c (1 - exp(-t / tau))`` added to the reading;
* ``asymmetry``: friction higher one way: a backlash that opens on loading only (the loop
  shifts by a constant from the first motion on);
* ``saturation``: an end-of-stroke stop: the output is clipped softly near its top.

Each run carries an input tension (the tendon's end, after any backlash: a linear spring
preload plus a friction step that follows the direction of motion) and white noise of known
size on the output. Pure arrays in, :class:`~.runs.RunData` out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any

import numpy as np

from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.runs import RunData

PLANTS = ("gamma", "preisach", "bouc_wen")
INJECTED = ("rate_dependence", "tendon_elongation", "time_delay", "drift", "asymmetry",
            "saturation", "dead_zone")
#: Analysis rate of the generated runs (Hz) and the length of each run (s).
RATE_HZ = 25.0
DURATION_S = 80.0
#: Output noise (mm) and input-tension noise (N), white.
NOISE_MM = 0.01
TENSION_NOISE_N = 0.02
AMPLITUDES_MM = (6.0, 4.5, 3.0, 1.5)


def _time() -> FloatArray:
    return np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)


def _envelope(t: FloatArray) -> FloatArray:
    """Decaying amplitude: four equal blocks of :data:`AMPLITUDES_MM`."""
    idx = np.minimum((t / (DURATION_S / len(AMPLITUDES_MM))).astype(int), len(AMPLITUDES_MM) - 1)
    return np.asarray(np.array(AMPLITUDES_MM)[idx], dtype=np.float64)


def excitation(kind: str) -> FloatArray:
    """Input (mm) of one 80 s run: ``sine_decay`` (identifies), ``triangle_decay`` and
    ``trapezoid_decay`` (held out); all start and end at rest near 0."""
    t = _time()
    a = _envelope(t)
    if kind == "sine_decay":
        x = np.sin(2 * np.pi * 0.25 * t)
    elif kind == "triangle_decay":
        x = 2.0 / np.pi * np.arcsin(np.sin(2 * np.pi * 0.2 * t))
    elif kind == "trapezoid_decay":
        x = np.clip(1.6 * 2.0 / np.pi * np.arcsin(np.sin(2 * np.pi * 0.15 * t)), -1.0, 1.0)
    else:
        raise HysteresisError(f"unknown excitation {kind!r}")
    ramp = np.clip(t / 2.0, 0.0, 1.0)  # start from rest
    return np.asarray(a * x * ramp, dtype=np.float64)


EXCITATIONS = ("sine_decay", "triangle_decay", "trapezoid_decay")


def _reference_loop(u: FloatArray) -> FloatArray:
    """The loop the plain plants are made to resemble: unit gain, a mix of narrow and wide
    backlash (a sheath's friction distributed along the tendon)."""
    from hysteresis.discrepancy._ops import play

    widths = (0.0, 0.3, 0.7, 1.2, 1.8)
    weights = (0.3, 0.25, 0.2, 0.15, 0.1)
    return np.asarray(sum(w * play(u, r) for w, r in zip(weights, widths, strict=True)),
                      dtype=np.float64)


@cache
def plant(family: str) -> HysteresisModel:
    """A plain plant of ``family``: the family's model made once to reproduce the reference
    loop on a slow sine (then fixed)."""
    from hysteresis.base import make_family

    t = np.arange(0.0, 60.0, 1.0 / RATE_HZ)
    u = 6.0 * np.sin(2 * np.pi * 0.1 * t) * np.clip(t / 10.0, 0.0, 1.0)
    y = _reference_loop(u)
    # the thesis' own Gamma setting: a plant fixed once, whatever the family's defaults
    params: dict[str, Any] = {"gamma": {"n_operators": 7, "max_threshold": 2.0,
                                        "constraint": "sum_to_one", "fit_offset": False,
                                        "start_state": "zero"},
                              "preisach": {}, "bouc_wen": {}}.get(family, {})
    if family not in PLANTS:
        raise HysteresisError(f"unknown plant {family!r}; known: {', '.join(PLANTS)}")
    return make_family(family, **params).fit(u, y)


def _play(u: FloatArray, up: FloatArray, down: FloatArray) -> FloatArray:
    """Backlash with (time-varying) distances ``up`` (input ahead of the output) and ``down``
    (behind); written here on its own so the injector shares no code with the terms."""
    z = np.empty_like(u)
    s = float(u[0])
    for k in range(u.size):
        if u[k] - up[k] > s:
            s = u[k] - up[k]
        elif u[k] + down[k] < s:
            s = u[k] + down[k]
        z[k] = s
    return z


#: Speed scale of the friction's speed law (mm/s): half the identification sine's top speed.
#: One law for every run: a scale taken from each run's own speeds would give the held-out
#: runs a different friction law from the identifying one.
FRICTION_SPEED_MM_S = 4.7
#: Largest tendon tension of the drive's law (N): the stretch's normaliser, fixed for the same
#: reason.
TENSION_TOP_N = 7.4

#: Physical size of each effect at strength 1 (strength 2 doubles it).
SIZES: dict[str, float] = {
    "time_delay": 0.12,         # s
    "dead_zone": 0.5,           # mm, total width
    "rate_dependence": 0.5,     # mm of extra lost motion at the fastest speed
    "tendon_elongation": 0.5,   # mm of stretch at the largest tension
    "drift": 0.4,               # mm
    "asymmetry": 0.35,          # mm, one-way backlash
    "saturation": 0.12,         # fraction of the output's half-range clipped at the top
}


def inject(family: str, effects: Mapping[str, float], kind: str, *, seed: int = 0) -> RunData:
    """One run of ``kind`` through the plain ``family`` plant with ``effects`` (name ->
    strength) injected; output noise :data:`NOISE_MM`."""
    for name in effects:
        if name not in SIZES:
            raise HysteresisError(f"unknown effect {name!r}; known: {', '.join(SIZES)}")
    t = _time()
    u = excitation(kind)
    rng = np.random.default_rng([seed, EXCITATIONS.index(kind), PLANTS.index(family)])
    zero = np.zeros_like(u)
    # The drive: actuator backlash first, then the tendon.
    ut = u.copy()
    if "dead_zone" in effects:
        h = 0.5 * SIZES["dead_zone"] * effects["dead_zone"]
        ut = _play(ut, zero + h, zero + h)
    # The tendon's tension: preload + spring + friction following the direction of motion.
    vel = np.gradient(ut, t)
    dirn = np.tanh(vel / 0.5)
    tension = 2.0 + 0.4 * (ut - ut.min()) + 0.6 * dirn
    if "tendon_elongation" in effects:
        k = SIZES["tendon_elongation"] * effects["tendon_elongation"]
        ut = ut - k * (tension**2 - tension[0] ** 2) / TENSION_TOP_N**2
    if "rate_dependence" in effects:
        width = SIZES["rate_dependence"] * effects["rate_dependence"]
        lost = width * np.tanh(np.abs(vel) / FRICTION_SPEED_MM_S)
        ut = _play(ut, lost, lost)
    if "asymmetry" in effects:
        a = SIZES["asymmetry"] * effects["asymmetry"]
        ut = _play(ut, zero + a, zero)
    y = np.asarray(plant(family).predict(ut), dtype=np.float64)
    if "saturation" in effects:
        ref = np.asarray(plant(family).predict(excitation("sine_decay")), dtype=np.float64)
        top = float(ref.max()) - SIZES["saturation"] * effects["saturation"] * float(np.ptp(ref))
        soft = 0.05 * float(np.ptp(ref))
        y = np.where(y > top, top + soft * np.tanh((y - top) / soft), y)
    if "time_delay" in effects:
        tau = SIZES["time_delay"] * effects["time_delay"]
        y = np.interp(t - tau, t, y, left=float(y[0]))
    if "drift" in effects:
        c = SIZES["drift"] * effects["drift"]
        y = y + c * (1.0 - np.exp(-t / 30.0))
    y = y + NOISE_MM * rng.standard_normal(u.size)
    tension = tension + TENSION_NOISE_N * rng.standard_normal(u.size)
    role = "identification" if kind == "sine_decay" else "heldout"
    return RunData(run_id=f"{family}-{kind}", t=t, u=u, y=y, tension=tension,
                   config={"plant": family}, excitation=kind, role=role)


def injected_runs(family: str, effects: Mapping[str, float] | None = None, *,
                  seed: int = 0, kinds: Sequence[str] = EXCITATIONS) -> list[RunData]:
    """The three runs (one identifies, two are held out) of one source."""
    return [inject(family, dict(effects or {}), k, seed=seed) for k in kinds]
