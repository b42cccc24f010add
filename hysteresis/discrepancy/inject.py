"""A second, independent source of test data: known effects added to plain model plants.

The virtual rig simulates a tendon-sheath mechanism with its own physics; the candidate terms
of :mod:`.effects` were written against it. To check that the workflow names effects it was not
built on, this module makes runs another way: a *plain plant* (a Gamma play sum, a Preisach
plane or a Bouc-Wen model fitted once to one reference play loop, or a textbook Bouc-Wen of its
own softening shape, ``bouc_wen_loop``) is driven by three 80 s excitations, from rest or from a
loaded start (a stroke to the far side and back before the run), and one effect form is
injected, coded here from its physical description and not from the candidate's term
(:data:`SIZES` keys ``effect`` or ``effect:form``):

* ``time_delay``: the output is read ``tau`` late (``:long``: up to 0.9 s);
* ``dead_zone``: an actuator backlash before the plant (and the tendon); ``:dead_band``: a
  static band around the rest position;
* ``rate_dependence``: lost motion that grows with the sliding speed (a backlash whose width
  follows ``|v|``); ``:viscous``, ``:power`` (``|v|^0.5``), ``:relaxation`` (a Maxwell
  element): a force with the carriage's speed lowers the reading; ``:stribeck``: a friction
  force of the Stribeck law (static excess fading exponentially with the speed) does;
* ``tendon_elongation``: the tendon stretches as ``k T^2`` before the plant sees the motion;
  ``:linear_input``: as ``k T``; ``:linear_output``,
  ``:square_output``: with the output tension (the follower's return spring, not recorded);
* ``drift``: a creep ``c (1 - exp(-t / tau))``; ``:linear``: ``c t``;
* ``asymmetry``: a backlash that opens on loading only (the loop shifts from the first motion
  on); ``:loading_gain``: branches of different slope; ``:pull_push_gain``: a larger gain on
  the pull side of rest;
* ``saturation``: a soft (tanh) stop near the top; ``:hard``: a hard stop; ``:cubic``: cubic
  softening.

A source may start loaded (``start``) and its load-cell stream may be ragged (ending a few
samples early, or with a short gap: :func:`ragged_tension`).

Each run carries an input tension (the tendon's end, after any backlash: a linear spring
preload plus a friction step that follows the direction of motion) and white noise of known
size on the output. :data:`NOT_IDENTIFIABLE` and :func:`identifiable` are the ground truth of
what the runs can single out. Pure arrays in, :class:`~.runs.RunData` out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any

import numpy as np

from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.runs import RunData

#: The plants: three made to reproduce one reference play loop (Gamma, Preisach, Bouc-Wen
#: fitted to it) and a textbook Bouc-Wen of its own softening shape (``bouc_wen_loop``).
REFERENCE_PLANTS = ("gamma", "preisach", "bouc_wen")
PLANTS = (*REFERENCE_PLANTS, "bouc_wen_loop")
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
    if family not in REFERENCE_PLANTS:
        raise HysteresisError(f"unknown plant {family!r}; known: {', '.join(REFERENCE_PLANTS)}")
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
#: Time constant of the first-order relaxation form (s): a Maxwell element's viscous force.
RELAXATION_S = 1.0
#: The Stribeck form's friction law: the Coulomb level's share of the static friction, the
#: speed over which the static excess fades (exponentially, the law's exponent 1; mm/s) and
#: the speed below which the contact sticks (the sign's smooth turn; mm/s).
STRIBECK_COULOMB_SHARE = 0.3
STRIBECK_SPEED_MM_S = 0.8
STRIBECK_STICK_MM_S = 0.1
#: The follower's return spring, which sets the output tension of the output-side stretch.
OUTPUT_PRELOAD_N = 4.0
OUTPUT_SPRING_N_MM = 0.5

#: Physical size of each effect form at strength 1 (strength 2 doubles it). A key names the
#: effect and its form (``effect:form``); the bare effect name is its first form.
SIZES: dict[str, float] = {
    "time_delay": 0.12,                     # s
    "time_delay:long": 0.45,                # s (strength 2: 0.9 s, a compliant drive's lag)
    "dead_zone": 0.5,                       # mm, total width of an actuator backlash
    "dead_zone:dead_band": 0.6,             # mm, total width of a static band around rest
    "rate_dependence": 0.5,                 # mm of extra lost motion at the fastest speed
    "rate_dependence:viscous": 0.06,        # mm per (mm/s) of input speed
    "rate_dependence:power": 0.25,          # mm at the identification sine's top speed
    "rate_dependence:relaxation": 0.08,     # mm per (mm/s), relaxing with RELAXATION_S
    "tendon_elongation": 0.5,               # mm of stretch at the largest tension (T^2, input)
    "tendon_elongation:linear_input": 0.5,  # mm at the largest tension, T_in, input travel
    "tendon_elongation:linear_output": 0.4,  # mm at T_out = TENSION_TOP_N, T_out, on the reading
    "tendon_elongation:square_output": 0.4,  # the same, T_out^2
    "drift": 0.4,                           # mm, exponential creep (30 s)
    "drift:linear": 0.4,                    # mm over the 80 s run, linear creep
    "asymmetry": 0.35,                      # mm, one-way backlash
    "asymmetry:loading_gain": 0.08,         # loading slope 1 + g times the unloading one
    "asymmetry:pull_push_gain": 0.08,       # gain 1 + g on the pull side of rest
    "saturation": 0.12,                     # fraction of the output's range clipped softly
    "saturation:hard": 0.12,                # fraction of the output's range, a hard stop
    "saturation:cubic": 0.05,               # cubic softening: shortfall at the largest output
    # (later forms last: a source's start and load-cell stream follow its place in the list)
    "rate_dependence:stribeck": 0.12,       # mm, the friction's offset at the slowest slide
}
#: Every effect form of :data:`SIZES` (``effect:form``; the bare name is the first form).
FORMS: tuple[str, ...] = tuple(SIZES)
#: The form's name for a bare effect key.
FIRST_FORM = {"time_delay": "latency", "dead_zone": "backlash",
              "rate_dependence": "speed_friction", "tendon_elongation": "square_input",
              "drift": "exponential", "asymmetry": "one_way_backlash", "saturation": "soft"}


#: Forms the runs cannot single out (ground truth for scoring), with the reason: the answer
#: expected is the class, or a clean verdict with the effect inside the base.
NOT_IDENTIFIABLE: dict[str, str] = {
    "asymmetry": "a one-way backlash is a dead zone plus an offset, after the load cell",
    "dead_zone:dead_band": "a static band is a one-way backlash about a shifted rest",
    "tendon_elongation:linear_output": "the output tension follows the output: a gain change",
    "tendon_elongation:square_output": "without the output tension, a static output curvature",
}


def identifiable(key: str, family: str) -> bool:
    """Can the runs of ``family`` with effect form ``key`` name it (name and form)? A
    backlash in front of a plant with a play loop is a wider play."""
    if key == "dead_zone":
        return family not in REFERENCE_PLANTS
    return key not in NOT_IDENTIFIABLE


#: Injected forms named otherwise by the workflow (a long latency is a latency).
SAME_FORM = {"time_delay:long": "latency", "saturation:hard": "hard_stop"}


def effect_and_form(key: str) -> tuple[str, str]:
    """``("drift", "linear")`` for ``drift:linear``, ``("drift", "exponential")`` for
    ``drift``, ``("time_delay", "latency")`` for ``time_delay:long``."""
    name, _, form = key.partition(":")
    return name, SAME_FORM.get(key) or form or FIRST_FORM[name]


def _lowpass(x: FloatArray, tau_s: float, dt: float) -> FloatArray:
    """First-order low-pass (exact discretisation), from the first value."""
    a = float(np.exp(-dt / tau_s))
    out = np.empty_like(x)
    s = float(x[0])
    for k in range(x.size):
        s = a * s + (1.0 - a) * x[k]
        out[k] = s
    return out


def _bouc_wen_loop(u: FloatArray) -> FloatArray:
    """A textbook Bouc-Wen plant (n = 1), not fitted to any loop: ``y = 0.4 u + 0.6 z``,
    ``dz = du (A - (beta sign(du z) + gamma) |z|)``: a softening loop, unlike a play sum."""
    big_a, beta, gamma = 1.0, 0.6, 0.2
    z = np.empty_like(u)
    h = 0.0
    for k in range(u.size):
        du = float(u[k] - u[k - 1]) if k else 0.0
        # sub-steps: z is stiff near zero on a coarse input step
        for _ in range(4):
            d = du / 4.0
            h += d * (big_a - (beta * np.sign(d * h) + gamma) * abs(h))
        z[k] = h
    return np.asarray(0.4 * u + 0.6 * z, dtype=np.float64)


def _plant_output(family: str, u: FloatArray) -> FloatArray:
    if family == "bouc_wen_loop":
        return _bouc_wen_loop(u)
    return np.asarray(plant(family).predict(u), dtype=np.float64)


def _prehistory(start: str) -> FloatArray:
    """Input before the run for a plant that does not start at rest: a stroke to the far side
    and back to 0, so the run starts at a band edge (``loaded``: the last motion a pull)."""
    if start == "rest":
        return np.zeros(0)
    if start not in ("loaded", "unloaded"):
        raise HysteresisError(f"start must be rest, loaded or unloaded, got {start!r}")
    s = np.sin(np.linspace(0.0, np.pi, int(4.0 * RATE_HZ)))
    return np.asarray((-1.0 if start == "loaded" else 1.0) * AMPLITUDES_MM[0] * s,
                      dtype=np.float64)


def _drive(uf: FloatArray, tf: FloatArray, m: int, effects: Mapping[str, float]
           ) -> tuple[FloatArray, FloatArray]:
    """The plant's input after the drive's effects (actuator backlash first, then the
    tendon) and the input tension."""
    def size(key: str) -> float:
        return SIZES[key] * effects[key] if key in effects else 0.0

    zero = np.zeros_like(uf)
    ut = uf.copy()
    if size("dead_zone"):
        h = 0.5 * size("dead_zone")
        ut = _play(ut, zero + h, zero + h)
    if size("dead_zone:dead_band"):
        h = 0.5 * size("dead_zone:dead_band")  # a static band around the rest position 0
        ut = np.sign(ut) * np.maximum(np.abs(ut) - h, 0.0)
    # The tendon's tension: preload + spring + friction following the direction of motion.
    vel = np.gradient(ut, tf)
    dirn = np.tanh(vel / 0.5)
    tension = 2.0 + 0.4 * (ut - ut[m:].min()) + 0.6 * dirn
    t_start = float(tension[m])  # the run's first reading (the load cell reads newtons)
    if size("tendon_elongation"):
        ut = ut - size("tendon_elongation") * (tension**2 - t_start**2) / TENSION_TOP_N**2
    # a linear spring ahead of the sheath
    ut = ut - size("tendon_elongation:linear_input") * (tension - t_start) / TENSION_TOP_N
    if size("rate_dependence"):
        lost = size("rate_dependence") * np.tanh(np.abs(vel) / FRICTION_SPEED_MM_S)
        ut = _play(ut, lost, lost)
    if size("asymmetry"):
        ut = _play(ut, zero + size("asymmetry"), zero)
    return ut, tension


def _follower(family: str, y: FloatArray, effects: Mapping[str, float]) -> FloatArray:
    """The follower's effects on the plant's output: gains that differ by direction or side,
    and the stops."""
    def size(key: str) -> float:
        return SIZES[key] * effects[key] if key in effects else 0.0

    ref = _plant_output(family, excitation("sine_decay"))
    top_ref, span = float(ref.max()), float(np.ptp(ref))
    if size("asymmetry:loading_gain"):
        # the output follows the plant 1 + g as steeply loading as unloading (1 - g), held in
        # between (a backlash whose two branches differ in slope, as in Do et al.'s model)
        g = size("asymmetry:loading_gain")
        h = g * float(np.max(np.abs(ref)))
        y = _play(y, h - g * y, h - g * y)
    if size("asymmetry:pull_push_gain"):
        g = size("asymmetry:pull_push_gain")  # the pull side of rest (output > 0) amplified
        y = np.where(y > 0.0, (1.0 + g) * y, y)
    if size("saturation"):
        top = top_ref - size("saturation") * span
        soft = 0.05 * span
        y = np.where(y > top, top + soft * np.tanh((y - top) / soft), y)
    if size("saturation:hard"):
        y = np.minimum(y, top_ref - size("saturation:hard") * span)
    if size("saturation:cubic"):
        half = 0.5 * span
        y = y - size("saturation:cubic") * half * (y / half) ** 3
    return np.asarray(y, dtype=np.float64)


def _reading(y: FloatArray, uf: FloatArray, tf: FloatArray, tension: FloatArray, m: int,
             effects: Mapping[str, float]) -> FloatArray:
    """The reading's effects that depend on the drive's speed or on a tension."""
    def size(key: str) -> float:
        return SIZES[key] * effects[key] if key in effects else 0.0

    speed_in = np.gradient(uf, tf)  # the carriage's speed (a damper on the input side)
    vt = 2 * np.pi * 0.25 * AMPLITUDES_MM[0]  # the identification sine's top speed
    y = y - size("rate_dependence:viscous") * speed_in
    y = y - size("rate_dependence:power") * np.sign(speed_in) * np.abs(speed_in / vt) ** 0.5
    if size("rate_dependence:stribeck"):
        law = STRIBECK_COULOMB_SHARE + (1.0 - STRIBECK_COULOMB_SHARE) \
            * np.exp(-np.abs(speed_in) / STRIBECK_SPEED_MM_S)
        y = y - size("rate_dependence:stribeck") * np.tanh(speed_in / STRIBECK_STICK_MM_S) * law
    if size("rate_dependence:relaxation"):
        dt = float(tf[1] - tf[0])
        y = y - size("rate_dependence:relaxation") * _lowpass(speed_in, RELAXATION_S, dt)
    # the output tension: the follower's return spring (not recorded by these runs)
    t_out = OUTPUT_PRELOAD_N + OUTPUT_SPRING_N_MM * y
    y = y - size("tendon_elongation:linear_output") * (t_out - t_out[m]) / TENSION_TOP_N
    y = y - size("tendon_elongation:square_output") * (t_out**2 - t_out[m] ** 2) \
        / TENSION_TOP_N**2
    return np.asarray(y, dtype=np.float64)


#: Ragged load-cell streams: ``end``, the stream stops a few samples before the encoders
#: (2-5, by run); ``gap``, a dropout of 3-8 samples mid-run; ``mixed``, the second run ends
#: early and the third has a gap (as a lab's logger leaves them).
RAGGED = ("end", "gap", "mixed")


def ragged_tension(tension: FloatArray, ragged: str | None, run_index: int) -> FloatArray:
    """The load-cell stream as a logger leaves it, missing samples NaN (see :data:`RAGGED`;
    ``run_index``: the run's place in its source). What is done with them (filled within a
    limit, or the channel dropped) is the stage's rule, not the injector's: a
    :class:`~.runs.RunData` holds complete channels only."""
    if ragged is None:
        return tension
    if ragged not in RAGGED:
        raise HysteresisError(f"ragged must be one of {', '.join(RAGGED)}, got {ragged!r}")
    kind = ragged if ragged != "mixed" else (None, "end", "gap")[run_index % 3]
    out = np.asarray(tension, dtype=np.float64).copy()
    if kind == "end":
        out[out.size - (2 + run_index % 4):] = np.nan
    elif kind == "gap":
        mid = out.size // 2
        out[mid:mid + 3 + run_index % 6] = np.nan
    return out


def inject(family: str, effects: Mapping[str, float], kind: str, *, seed: int = 0,
           start: str = "rest") -> RunData:
    """One run of ``kind`` through the plain ``family`` plant with ``effects`` (``effect`` or
    ``effect:form`` -> strength) injected; output noise :data:`NOISE_MM`. ``start``: the
    plant's state at the run's start (``loaded``: after a pull; ``unloaded``: after a
    release; the drive and the load cell start there too)."""
    for name in effects:
        if name not in SIZES:
            raise HysteresisError(f"unknown effect {name!r}; known: {', '.join(SIZES)}")
    if family not in PLANTS:
        raise HysteresisError(f"unknown plant {family!r}; known: {', '.join(PLANTS)}")
    t = _time()
    u = excitation(kind)
    pre = _prehistory(start)
    m = pre.size
    uf = np.r_[pre, u]  # the drive's whole travel, the run after its prehistory
    tf = np.arange(uf.size) / RATE_HZ
    rng = np.random.default_rng([seed, EXCITATIONS.index(kind), PLANTS.index(family)])
    ut, tension = _drive(uf, tf, m, effects)
    y = _follower(family, _plant_output(family, ut), effects)
    y = _reading(y, uf, tf, tension, m, effects)
    y, tension = y[m:], tension[m:]
    for key in ("time_delay", "time_delay:long"):
        if key in effects:
            y = np.interp(t - SIZES[key] * effects[key], t, y, left=float(y[0]))
    if "drift" in effects:
        y = y + SIZES["drift"] * effects["drift"] * (1.0 - np.exp(-t / 30.0))
    if "drift:linear" in effects:
        y = y + SIZES["drift:linear"] * effects["drift:linear"] * t / DURATION_S
    y = y + NOISE_MM * rng.standard_normal(u.size)
    tension = tension + TENSION_NOISE_N * rng.standard_normal(u.size)
    role = "identification" if kind == "sine_decay" else "heldout"
    return RunData(run_id=f"{family}-{kind}", t=t, u=u, y=y, tension=tension,
                   config={"plant": family}, excitation=kind, role=role)


def injected_runs(family: str, effects: Mapping[str, float] | None = None, *,
                  seed: int = 0, kinds: Sequence[str] = EXCITATIONS,
                  start: str = "rest") -> list[RunData]:
    """The three runs (one identifies, two are held out) of one source; ``start``: every
    run's starting state (see :func:`inject`)."""
    return [inject(family, dict(effects or {}), k, seed=seed, start=start) for k in kinds]
