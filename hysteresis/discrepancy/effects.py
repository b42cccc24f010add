"""The candidate library: one physical hypothesis per named effect of the virtual rig.

Each candidate states the signature it leaves in the base model's residual and owns a model
term that composes with any base family:

* an *input-side* term transforms the input before the base sees it (``time_delay``,
  ``dead_zone``, ``tendon_elongation``): the base is refitted on the transformed input;
* an *output-side* term adds features whose coefficients are fitted jointly with the base
  (``rate_dependence`` on non-Gamma bases, ``drift``, ``asymmetry``, ``saturation``).

Terms with a nonlinear parameter ``theta`` (a delay, a width, a knee) are searched on a grid
that is scaled to the identification run, then refined; their linear coefficients come from the
joint fit. :class:`ComposedModel` is base family + terms, fitted jointly by backfitting.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, replace
from functools import cache, partial
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.discrepancy._ops import FloatArray, play, scaled_play, scaled_play_bank, shift
from hysteresis.discrepancy.bases import FrozenShapeModel
from hysteresis.discrepancy.runs import RunData
from hysteresis.lag import delay_grid

BoolArray = npt.NDArray[np.bool_]

EFFECT_NAMES = (
    "rate_dependence", "tendon_elongation", "time_delay", "drift", "asymmetry",
    "saturation", "dead_zone",
)

NO_THETA = float("nan")
Ctx = dict[str, float]


class Effect:
    """A candidate effect: its name, its signature, and its composable model term."""

    name: str = ""
    signature: str = ""
    term: str = ""
    side: str = "output"  # "input" or "output"
    #: Output-side features computed from the base's own prediction (not only from the run).
    uses_base: bool = False
    n_linear: int = 0
    has_theta: bool = False
    #: Number of nonlinear parameters in ``theta`` (a float, or a tuple when more than one).
    n_theta: int = 1
    #: The term changes the follower's motion itself (it happens inside the mechanism, so an
    #: end-of-stroke stop clips it), rather than offsetting the reading of the output.
    before_stop: bool = False
    #: Input-side terms apply in this order along the drive (0: at the actuator).
    input_stage: int = 0
    #: The last component of theta is refined from this many grid points (the best of each
    #: of the best prefixes): where the other components set a shape, a coarse step of the
    #: last one can rank the shapes wrongly.
    refine_starts: int = 1
    #: The physical form a parameter without a form tag stands for (the term's first form).
    first_form: str = ""
    #: The effect's other forms, each given as a parameter tuple ``(form, p1, ..., pk)`` (the
    #: last component refined): form -> (side, number of linear coefficients, reads the
    #: base's prediction). The grid search chooses the form with its parameters.
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {}
    #: The name a form is reported under, where it differs from its tag.
    labels: ClassVar[dict[str, str]] = {}
    #: form -> the simpler form it contains as a limit (taken unless the record tells them
    #: apart, :data:`NEST_MARGIN`).
    nests: ClassVar[dict[str, str]] = {}
    #: The forms besides the first for which the effect's load-cell claim (:mod:`.evidence`)
    #: holds: a backlash claims a dead travel at the reversals, a static band about the rest
    #: does not.
    claim_forms: ClassVar[tuple[str, ...]] = ()
    #: Forms whose term at coefficient 1 is the effect itself (an operator on the base's
    #: prediction, not a small correction to it): their backfitting starts there
    #: (:meth:`ComposedModel._backfit`).
    unit_forms: ClassVar[tuple[str, ...]] = ()

    def claims(self, forms: set[str]) -> bool:
        """Does the load-cell claim hold for a fit whose configurations took ``forms``?"""
        return forms <= {self.first_form, *self.claim_forms}

    def form(self, theta: Any) -> str:
        """The physical form ``theta`` stands for."""
        if isinstance(theta, tuple) and theta and isinstance(theta[0], str):
            return theta[0]
        return self.first_form

    def label(self, form: str) -> str:
        """The name form tag ``form`` is reported under."""
        return self.labels.get(form, form)

    def reported_form(self, theta: Any) -> str:
        """The physical form ``theta`` stands for, as reported."""
        return self.label(self.form(theta))

    def _spec(self, theta: Any) -> tuple[str, int, bool] | None:
        return self.forms.get(self.form(theta)) if self.form(theta) != self.first_form \
            else None

    def side_of(self, theta: Any) -> str:
        spec = self._spec(theta)
        return self.side if spec is None else spec[0]

    def n_linear_of(self, theta: Any) -> int:
        spec = self._spec(theta)
        return self.n_linear if spec is None else spec[1]

    def uses_base_of(self, theta: Any) -> bool:
        spec = self._spec(theta)
        return self.uses_base if spec is None else spec[2]

    def before_stop_of(self, theta: Any) -> bool:
        return self.before_stop and self._spec(theta) is None

    def operator_of(self, theta: Any) -> bool:
        return self.operator and self._spec(theta) is None

    def form_grid(self, ident: RunData) -> list[Any]:
        """Grid points of the forms other than the first (``(form, ...)`` tuples)."""
        return []

    def compare_grid(self, ident: RunData) -> list[Any]:
        """Grid points of forms the search does not try but the held-out runs judge once the
        effect is named (a form that clean records hold too, so that searched it names the
        effect where there is none)."""
        return []

    def delayed(self, run: RunData, theta: Any) -> RunData:
        """The run as the model sees it with this term: channels made late by a latency
        (identity for every other term)."""
        return run

    def available(self, run: RunData) -> bool:
        return True

    @property
    def n_params(self) -> int:
        return self.n_linear + (self.n_theta if self.has_theta else 0)

    def grid(self, ident: RunData) -> list[float]:
        return [NO_THETA]

    def context(self, ident: RunData) -> Ctx:
        """Constants taken from the identification run and reused on every other run."""
        return {}

    def bounds(self, ident: RunData) -> tuple[float, float] | None:
        g = [x for x in self.grid(ident) if np.isfinite(x)]
        return (min(g), max(g)) if g else None

    def transform_input(self, run: RunData, u: FloatArray, theta: Any, ctx: Ctx, *,
                        friction: FloatArray | None = None) -> FloatArray:
        """Input-side terms: the input the base sees. ``friction``: the operator terms'
        friction factor over time (None: constant)."""
        return u

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        """Output-side feature columns. ``y_base``: the prediction the term acts on."""
        return np.empty((run.n, 0))

    #: Acts on a Gamma base's play operators (their widths scaled by :meth:`scale`) instead of
    #: transforming the input; with any other base the input-side form is used.
    operator: bool = False

    def operator_grid(self, ident: RunData) -> list[Any]:
        return self.grid(ident)

    def scale(self, run: RunData, theta: Any) -> FloatArray:
        """Factor on every play operator's width (operator form only)."""
        return np.ones(run.n)

    def describe(self) -> dict[str, str]:
        return {"signature": self.signature, "term": self.term, "side": self.side}


#: Stribeck speeds v_S of the ``stribeck`` form, as fractions of the identification run's top
#: speed (the static excess fades over a few v_S).
STRIBECK_SPEEDS = (0.05, 0.12, 0.3)
#: Speed (fraction of the top speed) below which the contact counts as sticking: the width of
#: the ``stribeck`` form's turn of direction (the runs' own still-speed, :attr:`RunData.v_eps`).
STRIBECK_EPS = 0.02


class RateDependence(Effect):
    name = "rate_dependence"
    signature = (
        "velocity-dependent friction: loops widen with sliding speed, saturating above a speed "
        "scale; residual opposes the motion while the tendon slides, larger on faster runs, "
        "nearly absent on slow ones"
    )
    term = ("play-operator bases (Gamma): every play's half-width scales with the friction's "
            "speed law, r_i (1 + g tanh(|v| / v0)), so a play widens only while it slides and "
            "relaxes when the speed drops (g, v0 on a grid, g refined; weights refitted exactly); "
            "other bases: y = base(u - c tanh(v / v0)), the input lagging by a speed-dependent "
            "amount (c, v0 on a grid, c refined)")
    side = "input"
    operator = True
    #: Largest loop widening the speed-scaled plays may fit (friction at most doubling).
    g_max = 1.0
    has_theta = True
    n_theta = 2
    first_form = "speed_friction"
    #: a speed law of the sheath's friction (Stribeck-like, viscous, |v|^a damping) raises
    #: the friction the two load cells read; a first-order relaxation of the output (a
    #: viscoelastic lag in the transmission) need not change the tension ratio at all. The
    #: Stribeck form's excess is static friction, at the slow ends of the strokes, right
    #: after the reversals the reading leaves out while the slip front runs through the
    #: sheath (:func:`.friction.friction_reading`), and it falls with the speed: the
    #: reading's test (higher when faster) cannot show it.
    claim_forms = ("viscous", "power")
    #: viscous: c v; power: c sign(v) |v / v_top|^a (nonlinear damping); stribeck: a
    #: friction force of the Stribeck law reaching the output through the tendon's compliance,
    #: d(v) (c_C + c_S exp(-(|v| / v_S)^2)) with d(v) = tanh(v / v_eps) the sliding direction
    #: (Coulomb level c_C and the static excess c_S fitted linearly, v_S on the grid): a
    #: step at every reversal, larger where the slide is slow; relaxation: c times
    #: the speed through a first-order lag of time constant T (a Maxwell element's force).
    #: lag (reported as relaxation): the follower's motion itself relaxes, c (LP_T(M) - M)
    #: with M the model's motion (c = 1: a first-order lag of time constant T of the output,
    #: a viscoelastic transmission), which holds still where the plays hold the output.
    #: slip (reported as speed_friction, bases without play operators): the lost motion
    #: itself grows with the speed, a backlash on the input of half-width c tanh(|v| / v0)
    #: that holds the input at a reversal as the friction does (the play-scaled form of a
    #: Gamma base), where the shifted input above follows the speed's sign at once.
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {
        "viscous": ("output", 1, False), "power": ("output", 1, False),
        "stribeck": ("output", 2, False),
        "relaxation": ("output", 1, False), "lag": ("output", 1, True),
        "slip": ("input", 0, False)}
    labels: ClassVar[dict[str, str]] = {"lag": "relaxation", "slip": "speed_friction"}
    #: sign(v) |v / v_top|^a with a = 1 is the viscous term
    nests: ClassVar[dict[str, str]] = {"power": "viscous"}

    def grid(self, ident: RunData) -> list[Any]:
        vmax = float(np.percentile(np.abs(ident.v), 99))
        span = float(np.ptp(ident.u))
        return [(f * vmax, c * span) for f in (0.3, 0.8, 3.0)
                for c in (0.003, 0.01, 0.025, 0.05, 0.08)] \
            + [("slip", f * vmax, c * span) for f in (0.25, 0.5, 1.0, 3.0)
               for c in (0.003, 0.01, 0.025, 0.05, 0.1)] + self.form_grid(ident)

    def form_grid(self, ident: RunData) -> list[Any]:
        return [("viscous", 0.0), ("power", 0.5), ("power", 2.0),
                *[("stribeck", f) for f in STRIBECK_SPEEDS], ("relaxation", 0.3),
                ("relaxation", 1.0), ("relaxation", 3.0), ("lag", 0.1), ("lag", 0.3),
                ("lag", 1.0)]

    def operator_grid(self, ident: RunData) -> list[Any]:
        """(1, v0, g) for the speed-scaled play operators (the leading 1 tags the form; g, the
        last component, is refined), and the other forms."""
        vmax = float(np.percentile(np.abs(speed(ident)), 99))
        return [(1.0, f * vmax, g) for f in (0.3, 0.5, 0.8, 1.2)
                for g in (0.15, 0.3, 0.6, self.g_max)] + self.form_grid(ident)

    def context(self, ident: RunData) -> Ctx:
        return {"v_top": max(float(np.percentile(np.abs(ident.v), 99)), 1e-12)}

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        form, p = theta[0], float(theta[-1])
        if form == "lag":
            return np.asarray((lowpass(y_base, p, run.dt) - y_base)[:, None], dtype=np.float64)
        v = run.v / ctx["v_top"]
        if form == "stribeck":
            slide = np.tanh(v / STRIBECK_EPS)
            return np.column_stack([slide, slide * np.exp(-(np.abs(v) / p) ** 2)])
        if form == "viscous":
            x = v
        elif form == "power":
            x = np.sign(v) * np.abs(v) ** p
        else:
            x = lowpass(v, p, run.dt)
        return np.asarray(x[:, None], dtype=np.float64)

    def transform_input(self, run: RunData, u: FloatArray, theta: Any, ctx: Ctx, *,
                        friction: FloatArray | None = None) -> FloatArray:
        if self.form(theta) == "slip":
            _, v0, c = theta
            half = c * np.tanh(np.abs(speed(run)) / v0)
            return scaled_play(u, half, z0=float(u[0]))
        v0, c = theta
        return np.asarray(u - c * np.tanh(run.v / v0), dtype=np.float64)

    def scale(self, run: RunData, theta: Any) -> FloatArray:
        """Friction factor 1 + g tanh(|v| / v0) of the speed-scaled play operators."""
        _, v0, g = theta
        return np.asarray(1.0 + g * np.tanh(np.abs(speed(run)) / v0), dtype=np.float64)


def speed(run: RunData) -> FloatArray:
    """Input speed for the friction law, causal: the speed the contact has been sliding at over
    the last sample (a backward difference; friction remembers past sliding, it does not see
    the next sample). The decimation's moving average already smooths the servo's steps."""
    if run.n < 2:
        return np.zeros(run.n)
    v = np.empty(run.n)
    v[1:] = np.diff(run.u) / np.diff(run.t)
    v[0] = v[1]
    return v


def _input_tension(run: RunData) -> FloatArray:
    if run.tension is None:
        raise HysteresisError(f"run {run.run_id}: tendon_elongation needs a tension channel")
    return run.tension


class TendonElongation(Effect):
    name = "tendon_elongation"
    signature = (
        "extra load-dependent compliance: the tendon stretches by c T^2 per unit length, so the "
        "tendon passes on less of the input travel the harder it is pulled; the shortfall "
        "follows the tension profile (stiff at low tension, soft at high), not the sliding "
        "speed, and it vanishes while friction holds the output"
    )
    term = ("y = base(u - c s [w (T_in^2 - T_in(0)^2) + (1 - w) mean_{r in [0, R]} "
            "(exp(2 play_r(ln T_in)) - start)]), c >= 0: the stretch eats input travel before "
            "the friction of the sheath sees it, so while the plays hold the output the stretch "
            "only delays it (s: the direction in which pulling moves the input). Under capstan "
            "friction the tension at wrap angle theta is exp(play_{mu theta}(ln T_in)), so the "
            "mean over thresholds spreads T^2 along the friction path (R = mu x total wrap, a "
            "fraction of the identification run's ln T_in range); w, the share of tendon at the "
            "input tension (free end, straight lead-in); (R, w, c) on a grid, c refined")
    side = "input"
    input_stage = 1  # the tendon, after the actuator's backlash
    refine_starts = 3
    has_theta = True
    n_theta = 3
    first_form = "square_input"
    #: square_output: c (T_out^2 - T_out(0)^2) on the reading (a compliance at the follower's
    #: side), with the output load cell. Stretches linear in a tension are not searched: a
    #: tendon-sheath's own tendon is such a spring, in every clean record (on clean
    #: virtual-rig runs one linear in the input tension took 23 % of the free Gamma's held-out
    #: error; searched along the capstan path, it was named first on the virtual rig's
    #: friction asymmetry with a dead zone), and the output tension follows the output
    #: through the follower's spring, so a term linear in it is a gain (with a free sign it
    #: also took up a speed-dependent friction the output load cell feels, on clean-room
    #: runs).
    #: reading (reported as square_input): c (T_in^2 - T_in(0)^2) on the reading itself, a
    #: stretch by the input tension's square between the friction and the output's sensor
    #: (the friction does not hold it back).
    #: linear_input (compared only, :meth:`compare_grid`): input travel u - c s (T_in -
    #: T_in(0)) / T_top, a spring linear in the input tension ahead of the sheath. Once a
    #: stretch is named, the held-out runs judge it against the square law.
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {
        "square_output": ("output", 1, False), "reading": ("output", 1, False),
        "linear_input": ("input", 0, False)}
    labels: ClassVar[dict[str, str]] = {"reading": "square_input"}
    #: Play thresholds averaged over the friction path (the profile's quadrature).
    n_profile = 8
    #: Profiles kept for the refinement of c (a run's few (R, w) points).
    n_cached_profiles = 16

    def __init__(self) -> None:
        self._profiles: dict[tuple[Any, ...], tuple[FloatArray, FloatArray]] = {}

    def available(self, run: RunData) -> bool:
        return run.tension is not None

    def grid(self, ident: RunData) -> list[Any]:
        # (R, w, c): friction path R (fraction of the ln T_in span), share w of the tendon at
        # the input tension (with w = 1 the path does not matter), stretch c at the largest
        # tension (fraction of the input span; refined). c >= 0: a stretch can only shorten.
        span = float(np.ptp(ident.u))
        shapes = [(r, w) for r in (0.1, 0.35, 1.0) for w in (0.0, 0.5)] + [(0.1, 1.0)]
        return [(r, w, c * span) for r, w in shapes
                for c in (0.03, 0.08, 0.17, 0.35, 0.7)] + self.form_grid(ident)

    def form_grid(self, ident: RunData) -> list[Any]:
        out: list[Any] = [("reading", 0.0)]
        if ident.tension_out is not None:
            out += [("square_output", 0.0)]
        return out

    def compare_grid(self, ident: RunData) -> list[Any]:
        # c: stretch at the largest tension, a fraction of the input span (refined)
        span = float(np.ptp(ident.u))
        return [("linear_input", c * span) for c in (0.01, 0.03, 0.08, 0.17, 0.35)]

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        form = theta[0]
        if form == "reading":
            t_in = run.tension if run.tension is not None else np.zeros(run.n)
            x = (t_in**2 - t_in[0] ** 2) / ctx["tension_scale"]
            return np.asarray(x[:, None], dtype=np.float64)
        t = run.tension_out
        if t is None:
            raise HysteresisError(f"run {run.run_id}: form {form} of tendon_elongation needs "
                                  "the output tension")
        x = (t**2 - t[0] ** 2) / ctx["tension_scale"]
        return np.asarray(x[:, None], dtype=np.float64)

    def profile(self, run: RunData, big_r: float, w: float, ctx: Ctx, *,
                friction: FloatArray | None = None) -> FloatArray:
        """The tendon's T^2 profile, from 0 at the run's start, per unit of the largest T^2."""
        tension = _input_tension(run)
        if friction is not None:
            return self._profile(tension, big_r, w, ctx, friction)
        # The search refines the stretch c with (R, w) fixed: the profile does not depend on
        # c, so the last few are kept (keyed by the tension array itself, held alive here).
        key = (id(tension), float(big_r), float(w), tuple(sorted(ctx.items())))
        hit = self._profiles.get(key)
        if hit is not None and hit[0] is tension:
            return hit[1]
        out = self._profile(tension, big_r, w, ctx, None)
        out.setflags(write=False)
        self._profiles[key] = (tension, out)
        while len(self._profiles) > self.n_cached_profiles:
            self._profiles.pop(next(iter(self._profiles)))
        return out

    def _profile(self, tension: FloatArray, big_r: float, w: float, ctx: Ctx,
                 friction: FloatArray | None) -> FloatArray:
        lt = np.log(np.maximum(tension, ctx["t_floor"]))
        near = np.exp(2.0 * lt)
        path = np.zeros(tension.size)
        for r in np.linspace(0.0, big_r * ctx["log_span"], self.n_profile):
            # Tension at one point of the friction path (capstan: a play in log tension). A
            # speed law scales the friction all along the tendon, so the path with it.
            if friction is None:
                lp = play(lt, float(r), z0=float(lt[0]))
            else:
                lp = scaled_play(lt, float(r) * friction, z0=float(lt[0]))
            p = np.exp(2.0 * lp)
            path += p - p[0]
        out = w * (near - near[0]) + (1.0 - w) * path / self.n_profile
        return np.asarray(out / ctx["tension_scale"], dtype=np.float64)

    def transform_input(self, run: RunData, u: FloatArray, theta: Any, ctx: Ctx, *,
                        friction: FloatArray | None = None) -> FloatArray:
        if self.form(theta) == "linear_input":
            t = _input_tension(run)
            stretch = float(theta[-1]) * (t - t[0]) / ctx["tension_top"]
            return np.asarray(u - ctx["pull_sign"] * stretch, dtype=np.float64)
        big_r, w, c = theta
        stretch = c * self.profile(run, big_r, w, ctx, friction=friction)
        return np.asarray(u - ctx["pull_sign"] * stretch, dtype=np.float64)

    def context(self, ident: RunData) -> Ctx:
        t = ident.tension if ident.tension is not None else np.ones(2)
        # Floor for the log: a slack tendon reads ~0 N (load-cell noise may go negative).
        floor = max(0.02 * float(np.percentile(np.abs(t), 99)), 1e-6)
        lt = np.log(np.maximum(t, floor))
        return {"tension_scale": max(float(np.max(t**2)), 1e-12),
                "tension_top": max(float(np.max(np.abs(t))), 1e-12), "t_floor": floor,
                "log_span": max(float(np.ptp(lt)), 1e-9), "pull_sign": ident.pull_sign}


class TimeDelay(Effect):
    name = "time_delay"
    signature = (
        "latency of the output: residual cross-correlates with the input velocity at a non-zero "
        "lag, concentrated where the output moves fastest"
    )
    term = ("y(t) = M(t - tau), tau >= 0: the whole model M sees the record tau late (the "
            "input, and the tensions and speed its other terms read)")
    side = "input"
    has_theta = True
    first_form = "latency"

    def grid(self, ident: RunData) -> list[float]:
        # the range the record can show (seconds on a long compliant drive), not a fixed cap
        return delay_grid(ident.u, ident.y, ident.dt)

    def delayed(self, run: RunData, theta: Any) -> RunData:
        """The output is read late, so the model must see every channel it uses equally late:
        the input, and the tensions behind a friction or elongation term."""
        def late(x: FloatArray | None) -> FloatArray | None:
            return None if x is None else shift(run.t, x, float(theta))

        return replace(run, u=shift(run.t, run.u, float(theta)), tension=late(run.tension),
                       tension_out=late(run.tension_out))


class Drift(Effect):
    name = "drift"
    signature = (
        "slow creep or thermal offset of the output: residual trends with time since the start, "
        "the same in every phase and at every amplitude"
    )
    term = ("exponential: c * (1 - exp(-t / tau)) (t = time since the start of the run, tau on "
            "a grid); linear creep: c t")
    n_linear = 1
    has_theta = True
    first_form = "exponential"
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {"linear": ("output", 1, False)}
    #: c (1 - exp(-t / tau)) = (c / tau) t - ... : a linear creep as tau outgrows the record
    #: (on the injector's linear creep a tau of 10 records won by noise on two plants)
    nests: ClassVar[dict[str, str]] = {"exponential": "linear"}

    def grid(self, ident: RunData) -> list[Any]:
        dur = float(np.max(ident.ts))  # the longest identification record
        return [f * dur for f in (0.05, 0.1, 0.25, 0.5, 1.0, 1.5, 3.0, 10.0)] + \
            self.form_grid(ident)

    def form_grid(self, ident: RunData) -> list[Any]:
        return [("linear", 0.0)]

    def context(self, ident: RunData) -> Ctx:
        return {"duration": max(float(np.max(ident.ts)), 1e-12)}

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        if self.form(theta) == "linear":
            return np.asarray((run.ts / ctx["duration"])[:, None], dtype=np.float64)
        return np.asarray((1.0 - np.exp(-run.ts / float(theta)))[:, None], dtype=np.float64)


class Asymmetry(Effect):
    name = "asymmetry"
    signature = (
        "direction-dependent friction: more lost motion pulling than releasing (or the reverse); "
        "the loop centre shifts by a constant from the first motion on, width about the same"
    )
    term = ("one-way backlash: c * m(t), m = 0 before the first motion, 1 after (a loop-centre "
            "shift born at once); loading_gain: c (y_base - pivot) s_w(t), the branches steeper "
            "one way about a pivot (the recorded range's bottom, centre or top); s_w the "
            "loading state, +-1, turning over along an input travel 2 w after a reversal (w "
            "on a grid, refined; w = 0: the direction of motion); pull_push_gain: "
            "c (y_base - kink) on the pull side of a kink only, the kink at centre + k half "
            "(k on a grid, refined: the plant's rest, off the recorded range's centre when one "
            "side's gain differs); held_gain (reported as loading_gain): c (B_g(y_base) - "
            "y_base), B_g a backlash with different slopes (Tao and Kokotovic): the output "
            "follows a branch 1 + g as steep one way as the other (1 - g), both through a "
            "pivot at the recorded range's top or bottom, and is held in between (a play of "
            "half-width g |y_base - pivot|); g on a grid, refined")
    n_linear = 1
    before_stop = True
    first_form = "one_way_backlash"
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {
        "loading_gain": ("output", 1, True), "pull_push_gain": ("output", 1, True),
        "held_gain": ("output", 1, True)}
    labels: ClassVar[dict[str, str]] = {"held_gain": "loading_gain"}
    unit_forms: ClassVar[tuple[str, ...]] = ("held_gain",)
    #: Slope differences g of the held form (refined): the branches 1 + g and 1 - g.
    held_slopes: ClassVar[tuple[float, ...]] = (0.03, 0.06, 0.12, 0.25)
    #: Input travel over which the loading/unloading state turns over after a reversal, as
    #: fractions of the identification input's half-range (refined): 0 is the direction of
    #: motion itself; a friction contact or a follower's slack turns over along a travel.
    #: Not wider: over a longer travel the state is the lost motion of a backlash (on the
    #: virtual rig's dead zone a width of 0.2 took the backlash's place).
    turn_widths: ClassVar[tuple[float, ...]] = (0.0, 0.03, 0.07, 0.15)

    @staticmethod
    def direction_state(run: RunData, width: float) -> FloatArray:
        """Loading (+1) or unloading (-1) state, turning over linearly along an input travel
        of ``2 width`` after each reversal (a play of half-width ``width`` on the input,
        read as its normalised lag); ``width`` 0: the direction of motion."""
        if width <= 0.0:
            return run.s
        return np.asarray((run.u - play(run.u, width)) / width, dtype=np.float64)

    def grid(self, ident: RunData) -> list[Any]:
        return [NO_THETA, *self.form_grid(ident)]

    def form_grid(self, ident: RunData) -> list[Any]:
        # the pull/push kink sits at the plant's rest, which a side's gain moves off the
        # recorded range's centre (a push side at 0.75 moves it by 0.14 of the half-range)
        # the held form's pivot at the range's top (loading the steeper) or bottom
        return [*[("loading_gain", k, w) for k in (-1.0, 0.0, 1.0) for w in self.turn_widths],
                *[("pull_push_gain", k) for k in (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3)],
                *[("held_gain", k, g) for k in (-1.0, 1.0) for g in self.held_slopes]]

    def context(self, ident: RunData) -> Ctx:
        return {"centre": 0.5 * float(ident.y.max() + ident.y.min()),
                "half": 0.5 * float(np.ptp(ident.y)),
                "input_half": max(0.5 * float(np.ptp(ident.u)), 1e-12)}

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        form = self.form(theta)
        if form == "loading_gain":
            # the branches' slopes differ by direction about a pivot, the loading state
            # turning over after each reversal
            s = self.direction_state(run, float(theta[-1]) * ctx["input_half"])
            pivot = ctx["centre"] + float(theta[1]) * ctx["half"]
            return np.asarray(((y_base - pivot) * s)[:, None], dtype=np.float64)
        if form == "held_gain":
            # held between two branches through the pivot: the gap between them grows with
            # the distance from it (pivot at the top: loading the steeper)
            pivot = ctx["centre"] + float(theta[1]) * ctx["half"]
            gap = float(theta[-1]) * np.abs(y_base - pivot)
            held = scaled_play(y_base, gap, z0=float(y_base[0]))
            return np.asarray((held - y_base)[:, None], dtype=np.float64)
        if form == "pull_push_gain":
            kink = ctx["centre"] + float(theta[-1]) * ctx.get("half", 0.0)
            return np.asarray(np.maximum(y_base - kink, 0.0)[:, None], dtype=np.float64)
        return np.abs(run.s)[:, None]


class Saturation(Effect):
    name = "saturation"
    signature = (
        "stiffening or a stop near the end of stroke: residual only at the largest outputs, "
        "clipping the loop tips, absent at small amplitude"
    )
    term = ("-c1 relu(y_base - y_hi) - c2 relu(y_lo - y_base); knees y_hi/y_lo at a fraction of "
            "the identification half-range about its centre (grid); c = 1 is a hard stop")
    n_linear = 2
    has_theta = True
    uses_base = True
    first_form = "hard_stop"
    #: soft: a tanh-like stop, the excess e beyond the knee becoming s tanh(e / s) (s a tenth
    #: of the half-range); tanh (reported as soft): the whole stroke through Y tanh(x / Y)
    #: about the centre, Y on a grid (refined): a soft stop with no knee, whose fifth-order
    #: term tells it from a cubic softening when the stroke reaches well into it; cubic:
    #: softening c (y - centre)^3 on each side.
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {
        "soft": ("output", 2, True), "tanh": ("output", 2, True), "cubic": ("output", 2, True)}
    labels: ClassVar[dict[str, str]] = {"tanh": "soft"}
    #: Y tanh(x / Y) = x - x^3 / (3 Y^2) + O(x^5): a cubic softening as Y grows
    nests: ClassVar[dict[str, str]] = {"tanh": "cubic"}
    softness = 0.1

    def grid(self, ident: RunData) -> list[Any]:
        return [0.5, 0.7, 0.8, 0.9, 0.95, 1.0, *self.form_grid(ident)]

    def form_grid(self, ident: RunData) -> list[Any]:
        return [("soft", 0.6), ("soft", 0.8), ("soft", 0.9), ("cubic", 0.0),
                ("tanh", 0.7), ("tanh", 1.0), ("tanh", 1.5), ("tanh", 2.5)]

    def features(self, run: RunData, theta: Any, y_base: FloatArray, ctx: Ctx) -> FloatArray:
        form = self.form(theta)
        if form == "cubic":
            x = (y_base - ctx["centre"]) / ctx["half"]
            return ctx["half"] * np.column_stack([np.maximum(x, 0.0) ** 3,
                                                  np.minimum(x, 0.0) ** 3])
        if form == "tanh":
            # the shortfall x - Y tanh(x / Y) on each side (c = 1: exactly a tanh stop)
            big_y = float(theta[-1]) * ctx["half"]
            x = y_base - ctx["centre"]
            short = x - big_y * np.tanh(x / big_y)
            return np.column_stack([np.maximum(short, 0.0), np.minimum(short, 0.0)])
        knee = float(theta[-1]) if form == "soft" else float(theta)
        hi = ctx["centre"] + knee * ctx["half"]
        lo = ctx["centre"] - knee * ctx["half"]
        up, down = np.maximum(y_base - hi, 0.0), np.maximum(lo - y_base, 0.0)
        if form == "soft":
            s = self.softness * ctx["half"]
            up, down = up - s * np.tanh(up / s), down - s * np.tanh(down / s)
        return np.column_stack([up, down])

    def context(self, ident: RunData) -> Ctx:
        return {"centre": 0.5 * float(ident.y.max() + ident.y.min()),
                "half": 0.5 * float(np.ptp(ident.y))}


class DeadZone(Effect):
    name = "dead_zone"
    signature = (
        "actuator-side backlash (lost motion): after every reversal the output waits for a "
        "fixed input travel; residual is a direction-dependent step of the same size at every "
        "amplitude and speed, born at the reversals"
    )
    term = ("backlash: y = base(play_{d/2}(u)), d = dead-zone width; dead_band: a static band "
            "of width d around the input's rest (the centre of its range) passes nothing")
    side = "input"
    has_theta = True
    first_form = "backlash"
    forms: ClassVar[dict[str, tuple[str, int, bool]]] = {"dead_band": ("input", 0, False)}

    def grid(self, ident: RunData) -> list[Any]:
        span = float(np.ptp(ident.u))
        return [f * span for f in (0.005, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.15)] + \
            self.form_grid(ident)

    def form_grid(self, ident: RunData) -> list[Any]:
        span = float(np.ptp(ident.u))
        return [("dead_band", f * span) for f in (0.01, 0.03, 0.06, 0.1)]

    def context(self, ident: RunData) -> Ctx:
        return {"rest": 0.5 * float(ident.u.max() + ident.u.min())}

    def transform_input(self, run: RunData, u: FloatArray, theta: Any, ctx: Ctx, *,
                        friction: FloatArray | None = None) -> FloatArray:
        if self.form(theta) == "dead_band":
            x = u - ctx["rest"]
            half = 0.5 * float(theta[1])
            return np.asarray(ctx["rest"] + np.sign(x) * np.maximum(np.abs(x) - half, 0.0),
                              dtype=np.float64)
        return play(u, 0.5 * theta, z0=float(u[0]))


CANDIDATES: dict[str, Effect] = {
    e.name: e
    for e in (RateDependence(), TendonElongation(), TimeDelay(), Drift(), Asymmetry(),
              Saturation(), DeadZone())
}
assert tuple(CANDIDATES) == EFFECT_NAMES


def candidate(name: str) -> Effect:
    try:
        return CANDIDATES[name]
    except KeyError:
        known = ", ".join(EFFECT_NAMES)
        raise HysteresisError(f"unknown effect {name!r}; known: {known}") from None


# -- composition -----------------------------------------------------------------------

BaseFactory = Callable[[], HysteresisModel]


@dataclass(frozen=True)
class Term:
    """An effect with its nonlinear parameter and its identification-run constants."""

    effect: Effect
    theta: Any = NO_THETA
    ctx: tuple[tuple[str, float], ...] = ()

    @property
    def context(self) -> Ctx:
        return dict(self.ctx)

    @property
    def form(self) -> str:
        """The physical form, as reported."""
        return self.effect.reported_form(self.theta)

    @property
    def side(self) -> str:
        return self.effect.side_of(self.theta)

    @property
    def n_linear(self) -> int:
        return self.effect.n_linear_of(self.theta)

    @property
    def uses_base(self) -> bool:
        return self.effect.uses_base_of(self.theta)

    @property
    def before_stop(self) -> bool:
        return self.effect.before_stop_of(self.theta)

    @property
    def operator(self) -> bool:
        return self.effect.operator_of(self.theta)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.effect.name, "form": self.form,
                "theta": _theta_json(self.theta),
                "context": self.context}


def _theta_json(theta: Any) -> Any:
    if isinstance(theta, tuple):
        return [x if isinstance(x, str) else float(x) for x in theta]
    return None if not np.isfinite(theta) else float(theta)


def lowpass(x: FloatArray, tau_s: float, dt: float) -> FloatArray:
    """First-order lag of time constant ``tau_s`` (exact for a sampled step), from ``x[0]``."""
    from scipy.signal import lfilter

    a = float(np.exp(-dt / max(tau_s, 1e-12)))
    out, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * float(x[0])])
    return np.asarray(out, dtype=np.float64)


#: Base families fitted in closed form (least squares): a backfitting round costs little.
FAST_FAMILIES = ("gamma", "linear", "play_sum", "affine")
#: Start positions in the band (as Gamma's ``START_POSITIONS``, finer) a base whose play
#: widths follow a channel is tried at: one solve each, on the identification run.
WIDTH_START_POSITIONS = tuple(float(x) for x in np.linspace(0.0, 1.0, 9))
#: Extra backfitting rounds for a term reading a fast base's prediction (see
#: :meth:`ComposedModel._rounds`).
FAST_ROUNDS = 5
#: Backfitting steps, as a multiple of :meth:`ComposedModel._rounds`, with a unit form's
#: coefficient held at 1 (:attr:`Effect.unit_forms`): between the branches the output is held
#: and does not follow the base, so the alternation contracts slowly there. A held gain of 0.16
#: on a Bouc-Wen plant and base at its true slopes: 1.7x the noise left after 8 steps, 1.0x
#: after 24.
UNIT_ROUNDS = 3
#: An iterative base that can fit again from its current shape (``refit_warm``: Bouc-Wen,
#: Preisach, Coleman-Hodgdon) does so in the backfitting rounds after the first, instead of a
#: search from its grid or its evolution.
WARM_BACKFIT = True


class ComposedModel:
    """Base family + effect terms, fitted jointly on one run.

    Input-side terms transform the input (in order); the base is fitted on the transformed
    input. Output-side terms add features whose coefficients are fitted jointly with the base
    by backfitting (alternate: base on ``y - g``, coefficients on ``y - base``; accelerated,
    :meth:`_backfit`), which converges to the joint least-squares solution for bases that are
    themselves least-squares fits and terms that do not read the base's prediction.
    """

    def __init__(self, base_factory: BaseFactory, terms: Sequence[Term] = (), *,
                 iterations: int = 8, tol: float = 1e-5) -> None:
        self.base_factory = base_factory
        self.terms = tuple(terms)
        self.iterations = iterations
        self.tol = tol
        self._gamma: bool | None = None
        self._widths: str | None = None

    def _input(self, run: RunData, friction: FloatArray | None = None) -> FloatArray:
        """The input the base sees: the input-side terms in the order the mechanism applies
        them (the carriage's backlash before the tendon's stretch), whatever order they joined
        in. ``friction``: the operator terms' factor when the caller has it already."""
        u = run.u
        inputs = [t for t in self.terms if t.side == "input" and not self._on_operators(t)]
        if inputs and friction is None:
            friction = self._friction(run)
        for term in sorted(inputs, key=lambda t: t.effect.input_stage):
            u = term.effect.transform_input(run, u, term.theta, term.context, friction=friction)
        return u

    def _on_operators(self, term: Term) -> bool:
        """Does ``term`` act on the base's play operators (a Gamma base) instead of its input?"""
        if not term.operator:
            return False
        if self._gamma is None:
            self._gamma = is_gamma(self.base_factory())
        return self._gamma

    def _scaled_design(self, run: RunData, base: HysteresisModel,
                       setup: tuple[FloatArray, float] | None = None) -> FloatArray:
        """The Gamma base's play-operator columns with time-varying thresholds.

        Column i is ``w_i = play_{p_i f(t) / 2}(u) - p_i / 2``: with ``f = 1`` exactly the Gamma
        operator ``min(u, max(u - p_i, w))`` from the zero state; ``f`` is the product of the
        operator terms' friction factors. ``setup``: the base's (thresholds, start position)
        on ``run`` when the caller has them (else the fitted ones, else the base's choice).
        """
        f = self._friction(run)
        u = self._input(run, f)
        own = self._width_factor(run)
        if own is not None:
            f = own if f is None else f * own
        if f is None:
            f = np.ones(run.n)
        if setup is not None:
            p, pos = setup
        elif hasattr(self, "op_thresholds_"):
            p, pos = self.op_thresholds_, self.op_start_position_
        else:
            p, pos = _gamma_setup(base, run)
        a = scaled_play_bank(u, f, p, _play_starts(base, float(u[0]), p, pos))
        if getattr(base, "fit_offset", False):
            a = np.column_stack([a, np.ones(run.n)])
        return a

    def _widths_channel(self) -> str:
        """The run channel the base's play widths follow ('': widths fixed; a
        :class:`.bases.TensionWidthGamma` base)."""
        if self._widths is None:
            self._widths = str(getattr(self.base_factory(), "widths_follow", "") or "")
        return self._widths

    def _width_factor(self, run: RunData) -> FloatArray | None:
        """The base's own width factor on ``run``: its channel over the fitted reference
        (the identification run's median), never below zero (None: widths fixed)."""
        channel = self._widths_channel()
        if not channel:
            return None
        x = getattr(run, channel, None)
        if x is None:
            raise HysteresisError(f"run {run.run_id}: the base's play widths follow "
                                  f"{channel}, which this run does not carry")
        return np.asarray(np.maximum(x, 0.0) / self.width_ref_, dtype=np.float64)

    def _width_setup(self, base: HysteresisModel, run: RunData) -> tuple[FloatArray, float]:
        """(thresholds, start position) of a base whose widths follow a channel: the base's
        thresholds, and the start position (of :data:`WIDTH_START_POSITIONS`) its plays of
        those widths fit ``run`` best with, the base alone (the plain plays' choice is not
        the scaled plays': on a capstan loop started relaxed it took a quarter band for a
        half, 0.022 mm against 0.014 left). The start the record shows, as every base's."""
        from hysteresis.gamma import START_GAIN, solve_play_weights

        p, _ = _gamma_setup(base, run)
        own = self._width_factor(run)
        assert own is not None
        offset = [np.ones(run.n)] if getattr(base, "fit_offset", False) else []
        sse: list[float] = []
        for pos in WIDTH_START_POSITIONS:
            start = _play_starts(base, float(run.u[0]), p, pos)
            a = np.column_stack([scaled_play_bank(run.u, own, p, start), *offset])
            x, _ = solve_play_weights(a, run.y, n_weights=p.size,
                                      constraint=_weight_constraint(base))
            sse.append(float(np.sum((run.y - a @ x) ** 2)))
        k = int(np.argmin(sse))
        if sse[k] > (1.0 - START_GAIN) * sse[0]:
            k = 0
        return p, float(WIDTH_START_POSITIONS[k])

    def _set_width_ref(self, run: RunData) -> None:
        channel = self._widths_channel()
        if not channel:
            return
        x = getattr(run, channel, None)
        ref = float(np.median(x)) if x is not None else float("nan")
        if not ref > 0.0:
            raise HysteresisError(f"run {run.run_id}: the base's play widths follow {channel}, "
                                  "which this run does not carry or carries at or below zero")
        self.width_ref_ = ref

    def _friction(self, run: RunData) -> FloatArray | None:
        """Product of the operator terms' friction factors (None: no such term)."""
        f = None
        for term in self.terms:
            if self._on_operators(term):
                s = term.effect.scale(run, term.theta)
                f = s if f is None else f * s
        return f

    def _fit_operators(self, run: RunData) -> ComposedModel:
        """Exact (constrained) least squares of the speed-scaled Gamma and the features."""
        from hysteresis.gamma import solve_play_weights

        base = self.base_factory()
        for stale in ("op_thresholds_", "op_start_position_", "op_weights_"):
            self.__dict__.pop(stale, None)
        setup = self._width_setup(base, run) if self._widths_channel() \
            else _gamma_setup(base, run)
        a = self._scaled_design(run, base, setup)
        n_w = int(setup[0].size)
        uses_base = any(t.uses_base for t in self.terms if t.n_linear > 0)
        yb = run.y
        x = np.zeros(a.shape[1])
        coef: FloatArray | None = None  # no estimate before the first solve
        fixed: dict[int, FloatArray] = {}
        for _ in range(self._rounds(base) if uses_base else 1):
            phi = self._features(run, yb, coef, fixed=fixed)
            full = np.column_stack([a, phi])
            x, _ = solve_play_weights(full, run.y, n_weights=n_w,
                                      constraint=_weight_constraint(base))
            yb = a @ x[: a.shape[1]]
            coef = x[a.shape[1]:]
        self.base_ = base
        self.op_thresholds_, self.op_start_position_ = setup
        self.op_weights_ = np.asarray(x[: a.shape[1]], dtype=np.float64)
        self.coef_ = np.asarray(x[a.shape[1]:], dtype=np.float64)
        return self

    def _rounds(self, base: HysteresisModel) -> int:
        """Backfitting steps at most. A term that reads the base's own prediction (a stop, a
        gain by direction or side) couples the two fits, and the alternation then converges
        slowly even accelerated (:class:`_Anderson`). A base fitted in closed form gets
        :data:`FAST_ROUNDS` x more (the tolerance ends it early); an iterative one keeps the
        count, since each of its steps is a full fit."""
        coupled = any(t.uses_base for t in self.terms if t.n_linear > 0)
        fast = getattr(base, "family", "") in FAST_FAMILIES
        return self.iterations * (FAST_ROUNDS if coupled and fast else 1)

    def _features(self, run: RunData, y_base: FloatArray,
                  coef: FloatArray | None = None, *,
                  fixed: dict[int, FloatArray] | None = None) -> FloatArray:
        """The output terms' feature columns, in term order. A term that reads the base's
        prediction (a stop) reads the follower's motion: the base plus the contributions of
        the terms that act inside the mechanism (``before_stop``, weighted by ``coef``, the
        current estimate of all coefficients; None: not known yet). ``fixed``: the columns of
        the terms that do not read the base, kept from an earlier call on the same run
        (filled on the first; a backfitting step asks for them twice, every step)."""
        out = [t for t in self.terms if t.n_linear > 0]
        cols: dict[int, FloatArray] = {}
        motion = y_base
        start = 0
        for i, t in enumerate(out):
            n = t.n_linear
            if not t.uses_base:
                if fixed is None:
                    cols[i] = t.effect.features(run, t.theta, y_base, t.context)
                else:
                    if i not in fixed:
                        fixed[i] = t.effect.features(run, t.theta, y_base, t.context)
                    cols[i] = fixed[i]
                if coef is not None and t.before_stop:
                    motion = motion + cols[i] @ coef[start:start + n]
            start += n
        for i, t in enumerate(out):
            if t.uses_base:
                cols[i] = t.effect.features(run, t.theta, motion, t.context)
        return np.hstack([cols[i] for i in range(len(out))]) if out else np.empty((run.n, 0))

    def _seen(self, run: RunData) -> RunData:
        """The run as the model sees it: a latency delays every channel it reads (the
        input, the tensions, the speed and direction derived from them), not only the input
        of the base; the measured output stays as it is."""
        for term in self.terms:
            run = term.effect.delayed(run, term.theta)
        return run

    def fit(self, run: RunData) -> ComposedModel:
        run = self._seen(run)
        self._set_width_ref(run)
        if self._widths_channel() or any(self._on_operators(t) for t in self.terms):
            return self._fit_operators(run)
        u = self._input(run)
        y = run.y
        out_terms = [t for t in self.terms if t.n_linear > 0]
        if out_terms and not any(t.uses_base for t in out_terms):
            joint = _joint_linear(self.base_factory(), u, y, self._features(run, y))
            if joint is not None:
                base = self.base_factory()
                base.fit(u, y - self._features(run, y) @ joint)
                self.base_, self.coef_ = base, joint
                return self
        base = self.base_factory()
        base.fit(u, y)
        coef = np.zeros(0)
        if out_terms:
            base, coef = self._backfit(run, u, y, base)
        self.base_ = base
        self.coef_ = np.asarray(coef, dtype=np.float64)
        return self

    def _backfit(self, run: RunData, u: FloatArray, y: FloatArray,
                 base: HysteresisModel) -> tuple[HysteresisModel, FloatArray]:
        """Backfitting of the base and the output terms' coefficients from ``base`` (fitted
        on ``y`` alone), :meth:`_alternate`. A term whose coefficient 1 is the effect itself
        (:attr:`Effect.unit_forms`) is fitted from that coefficient: from the base fitted on
        ``y`` alone, which has bent towards the effect, the free alternation stops at a
        fraction of it (a held loading gain of 0.16 behind a Preisach plant: coefficient 0.23,
        9x the base's clean floor left, where the term at 1 leaves the floor)."""
        return self._alternate(run, u, y, base, self._unit_columns())

    def _unit_columns(self) -> BoolArray | None:
        """Which feature columns belong to a term of a unit form (None: none do)."""
        mask = [t.effect.form(t.theta) in t.effect.unit_forms
                for t in self.terms if t.n_linear > 0 for _ in range(t.n_linear)]
        return np.asarray(mask, dtype=bool) if any(mask) else None

    def _alternate(self, run: RunData, u: FloatArray, y: FloatArray, base: HysteresisModel,
                   unit: BoolArray | None) -> tuple[HysteresisModel, FloatArray]:
        """Alternate the coefficients on ``y - base`` and the base on ``y - terms``, the
        alternation accelerated (:class:`_Anderson`); ``unit``: columns held at coefficient
        1 in a first alternation, all free after it. A base that can re-solve its linear
        weights with its structure kept (``refit_weights``: Gamma's thresholds and start
        position) does so inside the alternation, and is fitted in full once at its end;
        should that full fit choose another structure, the alternation runs once more from
        it."""
        refit = hasattr(base, "refit_weights")
        warm_fits = WARM_BACKFIT and hasattr(base, "refit_warm")
        st = _BackfitState(base, np.zeros_like(y))
        held: list[BoolArray | None] = [unit]

        def coefficients(phi: FloatArray, r: FloatArray) -> FloatArray:
            mask = held[0]
            if mask is None:
                return _lstsq(phi, r)
            coef = np.ones(phi.shape[1])
            if not mask.all():
                coef[~mask] = _lstsq(phi[:, ~mask], r - phi[:, mask].sum(axis=1))
            return coef

        fixed: dict[int, FloatArray] = {}

        def step(yb: FloatArray) -> tuple[FloatArray, float]:
            phi = self._features(run, yb, st.known, fixed=fixed)
            coef = coefficients(phi, y - yb)
            st.g = phi @ coef
            if refit:
                st.base.refit_weights(u, y - st.g)  # type: ignore[attr-defined]
            elif warm_fits:
                # from the last round's shape: the shape moves little between rounds, and a
                # search from the grid each round was most of an iterative base's time
                st.base.refit_warm(u, y - st.g)  # type: ignore[attr-defined]
            else:
                st.base = self.base_factory()
                st.base.fit(u, y - st.g)
            out = np.asarray(st.base.predict(u), dtype=np.float64)
            st.known = coef
            return out, float(np.sum((y - out - self._features(run, out, coef, fixed=fixed)
                                      @ coef) ** 2))

        yb = np.asarray(base.predict(u), dtype=np.float64)
        if unit is not None:
            yb = _Anderson(step, UNIT_ROUNDS * self._rounds(st.base), self.tol).solve(yb)
            held[0] = None
        for _ in range(2 if refit else 1):
            yb = _Anderson(step, self._rounds(st.base), self.tol).solve(yb)
            if not refit:
                break
            full = self.base_factory()
            full.fit(u, y - st.g)
            y_full = np.asarray(full.predict(u), dtype=np.float64)
            same = np.allclose(y_full, yb, rtol=0.0, atol=1e-9 * (1.0 + float(np.ptp(y))))
            st.base, yb = full, y_full
            if same:
                break
        phi = self._features(run, yb, st.known, fixed=fixed)
        return st.base, _lstsq(phi, y - yb)

    def predict(self, run: RunData) -> FloatArray:
        if not hasattr(self, "base_"):
            raise HysteresisError("ComposedModel is not fitted yet; call fit(run) first")
        if run.whole is not None:  # a later segment: from the state its record's input left
            full = self.predict(run.whole)
            seg = full[run.offset:run.offset + run.n]
            if run.rezeroed:
                # the run's output is zeroed at its first sample, where the mechanism stood in
                # whatever state the earlier runs left: the prediction is the change from there
                seg = seg - seg[0] + run.y[0]
            return np.asarray(seg, dtype=np.float64)
        run = self._seen(run)
        if hasattr(self, "op_weights_"):
            yo = self._scaled_design(run, self.base_) @ self.op_weights_
            if self.coef_.size:
                yo = yo + self._features(run, yo, self.coef_) @ self.coef_
            return np.asarray(yo, dtype=np.float64)
        u = self._input(run)
        yb = self.base_.predict(u)
        if self.coef_.size:
            yb = yb + self._features(run, yb, self.coef_) @ self.coef_
        return np.asarray(yb, dtype=np.float64)

    @property
    def n_params(self) -> int:
        return sum(t.effect.n_params for t in self.terms)


@dataclass
class _BackfitState:
    """What a backfitting step leaves for the next: the base, the terms' contribution ``g``
    it was fitted against and their coefficients (``known``: none before the first step)."""

    base: HysteresisModel
    g: FloatArray
    known: FloatArray | None = None


class _Anderson:
    """Anderson acceleration of a fixed-point iteration ``x -> step(x)`` (the backfitting
    alternation, whose plain form contracts by about 0.8 a round when a term reads the
    base's prediction: 40 plain rounds to fit a known tanh stop exactly).

    Each round mixes the last :attr:`memory` steps by the least squares of their residuals
    ``step(x) - x`` (Walker and Ni, 2011, type II). ``step`` also returns the squared error
    of its output: a round that does not lower the best error drops the history and steps
    plainly from the best step's output (a safeguarded Anderson), and :attr:`patience` such
    rounds in a row end the search (a term that reads the base's prediction makes the
    alternation's fixed point differ from the least squares, and past the best point it may
    climb). Ends too when the error changes by at most ``tol``
    of itself, or after ``rounds`` steps. Returns the best step's output, its step run last
    (the step's side effects, a base refitted in place, belong to it)."""

    memory = 4
    patience = 2

    def __init__(self, step: Callable[[FloatArray], tuple[FloatArray, float]], rounds: int,
                 tol: float) -> None:
        self.step, self.rounds, self.tol = step, rounds, tol

    def solve(self, x: FloatArray) -> FloatArray:
        outs: list[FloatArray] = []
        resids: list[FloatArray] = []
        best_sse, best_x, best_out = np.inf, x, x
        worse = 0
        last_x = x
        for _ in range(self.rounds):
            out, sse = self.step(x)
            last_x = x
            if sse <= best_sse:
                converged = np.isfinite(best_sse) and best_sse - sse <= self.tol * best_sse
                best_sse, best_x, best_out, worse = sse, x, out, 0
                if converged:
                    break
                outs.append(out)
                resids.append(out - x)
                outs, resids = outs[-self.memory - 1:], resids[-self.memory - 1:]
                x = self._mixed(outs, resids)
            else:
                worse += 1
                if worse >= self.patience:
                    break
                # the mixed point overshot: a plain step from the best one, not from the
                # point that overshot (from there the plain steps climbed back too slowly
                # to beat the best within the patience: a held gain stopped at 3x the floor)
                outs, resids = [best_out], [best_out - best_x]
                x = best_out
        if last_x is not best_x:
            best_out, _ = self.step(best_x)
        return best_out

    @staticmethod
    def _mixed(outs: list[FloatArray], resids: list[FloatArray]) -> FloatArray:
        if len(outs) < 2:
            return outs[-1]
        d_res = np.column_stack([b - a for a, b in zip(resids[:-1], resids[1:], strict=True)])
        d_out = np.column_stack([b - a for a, b in zip(outs[:-1], outs[1:], strict=True)])
        gamma, *_ = np.linalg.lstsq(d_res, resids[-1], rcond=None)
        mixed = outs[-1] - d_out @ gamma
        return mixed if np.all(np.isfinite(mixed)) else outs[-1]


def _gamma_setup(base: HysteresisModel, run: RunData) -> tuple[FloatArray, float]:
    """The Gamma base's play thresholds and start position on ``run``: those its own fit of
    the run uses, so a term is compared with the base alone on the same plays."""
    setup = getattr(base, "play_setup", None)
    if setup is None:
        raise HysteresisError(f"{type(base).__name__} has no play-operator thresholds")
    p, pos = setup(run.u, run.y)
    return np.asarray(p, dtype=np.float64), float(pos)


def _play_starts(base: HysteresisModel, u0: float, p: FloatArray, pos: float) -> FloatArray:
    """Every play's output before the first input ``u0``: the Gamma base's start at band
    position ``pos``, within each play's band ``[u0 - p_i, u0]``."""
    start = np.asarray(base.start_outputs(u0, p, pos),  # type: ignore[attr-defined]
                       dtype=np.float64)
    return np.asarray(np.minimum(u0, np.maximum(u0 - p, start)), dtype=np.float64)


def is_gamma(base: HysteresisModel) -> bool:
    """A Gamma-family base (play-operator design matrix, exact least-squares fit)?"""
    return getattr(base, "family", "") == "gamma" and hasattr(base, "play_setup")


def _joint_linear(base: HysteresisModel, u: FloatArray, y: FloatArray,
                  phi: FloatArray) -> FloatArray | None:
    """Exact joint least squares for a base that is linear in its parameters.

    A base exposing ``design_matrix(u)`` (the Gamma family: play-operator columns, optional
    offset, optional sum-to-one constraint on the weights) is solved together with the term's
    features in one (constrained) least-squares problem; returns the features' coefficients,
    or ``None`` when the base is not of that kind (backfitting is used instead).
    """
    design = getattr(base, "design_matrix", None)
    if design is None or getattr(base, "family", "") != "gamma":
        return None
    from hysteresis.gamma import solve_play_weights

    a = np.asarray(design(u, y), dtype=np.float64)
    n_w = a.shape[1]
    if getattr(base, "fit_offset", False):
        a = np.column_stack([a, np.ones(u.size)])
    full = np.column_stack([a, phi])
    x, _ = solve_play_weights(full, y, n_weights=n_w,
                              constraint=_weight_constraint(base))
    return np.asarray(x[a.shape[1]:], dtype=np.float64)


def _lstsq(a: FloatArray, b: FloatArray) -> FloatArray:
    """Least squares through the (tiny) normal equations: a few columns, many rows."""
    ata = a.T @ a
    ridge = 1e-12 * float(np.trace(ata)) + 1e-300
    return np.asarray(np.linalg.solve(ata + ridge * np.eye(a.shape[1]), a.T @ b), dtype=np.float64)


def _sse(model: ComposedModel, run: RunData) -> float:
    return float(np.sum((run.y - model.predict(run)) ** 2))


#: The fits of the current :func:`memoised_fits` block (None: outside one, nothing is kept).
_FITS: ContextVar[dict[Any, ComposedModel] | None] = ContextVar("discrepancy_fits", default=None)


@contextmanager
def memoised_fits() -> Iterator[None]:
    """Within the block, :func:`fit_with_effect` hands back the model it already fitted for the
    same base factory, earlier terms, effect and identification run: a workflow's later rounds
    (:func:`fit_joint` fits each candidate alone again) and its pair search repeat about a
    sixth of its fits. The models are fitted once and never refitted, so sharing them is
    safe; the block bounds how long they are kept."""
    token = _FITS.set({})
    try:
        yield
    finally:
        _FITS.reset(token)


def fit_with_effect(base_factory: BaseFactory, fixed: Sequence[Term], effect: Effect,
                    ident: RunData, *, refine: bool = True,
                    iterations: int = 8) -> ComposedModel:
    """Add ``effect`` to ``fixed`` terms and fit jointly on ``ident``.

    The effect's nonlinear parameter is chosen by a grid search on the identification SSE,
    refined by a bounded scalar search between the grid neighbours of the best point.
    """
    def fit() -> ComposedModel:
        return _fit_with_effect(base_factory, fixed, effect, ident, refine=refine,
                                iterations=iterations)

    fits = _FITS.get()
    if fits is None:
        return fit()
    # objects by identity (the memo holds them, so no id is reused), parameters by value
    key = (base_factory, effect, ident, refine, iterations,
           tuple((t.effect, t.theta, t.ctx) for t in fixed))
    try:
        hit = fits.get(key)
    except TypeError:  # an unhashable factory or parameter: fitted, not kept
        return fit()
    if hit is None:
        hit = fits[key] = fit()
    return hit


def _fit_with_effect(base_factory: BaseFactory, fixed: Sequence[Term], effect: Effect,
                     ident: RunData, *, refine: bool, iterations: int) -> ComposedModel:
    ctx = tuple(sorted(effect.context(ident).items()))
    # A slow base (Bouc-Wen, Coleman-Hodgdon, Preisach: an iterative fit) searches the
    # effect's parameter with its fast screening base and is fitted with the forms it found
    # (:func:`_form_on_base`).
    screen = _screen_of(base_factory, ident)
    search = screen or _searching(base_factory)

    built: dict[Any, ComposedModel] = {}

    def build(theta: Any, factory: BaseFactory = search) -> ComposedModel:
        # the refinement's best point was fitted inside its search: kept, not fitted again
        key = (theta, factory is search)
        hit = built.get(key)
        if hit is None:
            m = ComposedModel(factory, [*fixed, Term(effect, theta, ctx)], iterations=iterations)
            hit = built[key] = m.fit(ident)
        return hit

    grid = effect.grid(ident)
    if effect.operator and is_gamma(search()):
        grid = effect.operator_grid(ident)
    fits = [build(th) for th in grid]
    sses = [_sse(m, ident) for m in fits]
    best = int(np.argmin(sses))
    model = fits[best]
    # a term without a parameter of its first form may still have forms that carry one
    if refine and len(grid) > 1 and (effect.has_theta or any(isinstance(g, tuple)
                                                             for g in grid)):
        model = _refined(effect, grid, sses, model, build, ident)
    model = _prefer_nested(effect, grid, fits, sses, model, ident)
    if screen is not None:
        return _form_on_base(base_factory, search, model, effect, ident, iterations)
    return model


def _prefix(g: Any) -> tuple[Any, ...]:
    """Every component of a grid point but the last (the one refined)."""
    return tuple(g[:-1]) if isinstance(g, tuple) else ()


def _refine_starts(effect: Effect, grid: Sequence[Any], sses: Sequence[float]) -> list[int]:
    """The grid points the refinement starts from: the first form's best point of each of its
    ``refine_starts`` best prefixes (the other components), and the best point of every other
    form that comes near the best fit (a form's points do not take the first form's places)."""
    starts: list[int] = []
    order = [int(i) for i in np.argsort(sses, kind="stable")]
    for i in order:
        if effect.form(grid[i]) != effect.first_form:
            continue
        if all(_prefix(grid[i]) != _prefix(grid[j]) for j in starts):
            starts.append(i)
        if len(starts) == effect.refine_starts:
            break
    best = order[0]
    for form in {effect.form(g) for g in grid} - {effect.first_form}:
        i = next(i for i in order if effect.form(grid[i]) == form)
        if sses[i] <= FORM_REFINE_FACTOR * sses[best]:
            starts.append(i)
    return starts


def _refined(effect: Effect, grid: Sequence[Any], sses: Sequence[float],
             model: ComposedModel, build: Callable[[Any], ComposedModel],
             ident: RunData) -> ComposedModel:
    """Refine the last component of theta between its grid neighbours (the others fixed),
    from each of :func:`_refine_starts`; the best fit of all, or ``model`` (the grid's)."""
    best_sse = min(sses)
    for i in _refine_starts(effect, grid, sses):
        th = grid[i]
        prefix = _prefix(th)
        line = sorted(float(g[-1]) if isinstance(g, tuple) else float(g) for g in grid
                      if _prefix(g) == prefix)
        last = float(th[-1]) if isinstance(th, tuple) else float(th)
        if not np.isfinite(last):  # a form without a parameter (NO_THETA)
            continue
        k = line.index(last)
        lo, hi = line[max(k - 1, 0)], line[min(k + 1, len(line) - 1)]
        if hi <= lo:
            continue

        def make(x: float, th: Any = th, prefix: tuple[Any, ...] = prefix) -> Any:
            return (*prefix, float(x)) if isinstance(th, tuple) else float(x)

        res = minimize_scalar(lambda x, make=make: _sse(build(make(x)), ident),
                              bounds=(lo, hi), method="bounded",
                              options={"maxiter": 8, "xatol": 1e-3 * (hi - lo)})
        if float(res.fun) < best_sse:
            model, best_sse = build(make(float(res.x))), float(res.fun)
    return model


#: A form that nests a simpler one (a tanh stop: a cubic softening as its scale grows) is
#: taken only when it fits the identification run better than the simpler form's best by
#: more than this fraction of the squared error: within it the record cannot tell them apart
#: (a cubic softening of 5 % at the top, 10 um noise: the tanh fitted 0.16 % better).
NEST_MARGIN = 0.02


def _prefer_nested(effect: Effect, grid: Sequence[Any], fits: Sequence[ComposedModel],
                   sses: Sequence[float], model: ComposedModel,
                   ident: RunData) -> ComposedModel:
    """The simpler nested form's best grid fit when ``model``'s form nests it and does not
    fit the identification run :data:`NEST_MARGIN` better; else ``model``."""
    simpler = effect.nests.get(effect.form(model.terms[-1].theta))
    points = [i for i, g in enumerate(grid) if simpler and effect.form(g) == simpler]
    if not points:
        return model
    i = min(points, key=lambda j: sses[j])
    return fits[i] if sses[i] <= (1.0 + NEST_MARGIN) * _sse(model, ident) else model


#: A form other than an effect's first is refined when its best grid point fits the
#: identification run within this factor of the best point's squared error.
FORM_REFINE_FACTOR = 1.25


def only_forms(effect: Effect, keep: Callable[[Any], bool], *,
               compared: bool = False) -> Effect:
    """``effect`` searched over the grid points ``keep`` accepts only (a shallow copy); with
    ``compared``, among them the compared-only forms (:meth:`Effect.compare_grid`)."""
    one = copy.copy(effect)
    grid, operator_grid, extra = effect.grid, effect.operator_grid, effect.compare_grid
    vars(one).update(
        grid=lambda ident: [g for g in [*grid(ident), *(extra(ident) if compared else [])]
                            if keep(g)],
        operator_grid=lambda ident: [g for g in operator_grid(ident) if keep(g)])
    return one


def _only_form(effect: Effect, form: str) -> Effect:
    """``effect`` searched over the grid points of one ``form`` only."""
    return only_forms(effect, lambda g: effect.form(g) == form)


@cache  # one copy per candidate: the fits memoised for it are found again in later rounds
def claiming(effect: Effect) -> Effect:
    """``effect`` searched over the forms that make its load-cell claim only."""
    return only_forms(effect, lambda g: effect.claims({effect.reported_form(g)}))


#: The forms the real base is fitted with: the screen's choice and every form whose best
#: screened point fits the identification run within this factor of the screen's best (SSE:
#: the near ties). A refit of an iterative base with a term costs seconds (a Coleman-Hodgdon
#: base: about 1.3 s, eight evolutionary searches of its backfitting), and one for every form
#: within 2x tripled a workflow's time (a long latency on a Bouc-Wen loop: 34 s -> 98 s CPU).
FORM_ON_BASE_FACTOR = 1.25
#: ... and only for a term that leaves less than this share of the screen's squared error
#: without it: where it changes nothing, its forms tie and none is worth the refits.
FORM_WEIGHED_BELOW = 0.9


def _form_on_base(base_factory: BaseFactory, screen: BaseFactory, found: ComposedModel,
                  effect: Effect, ident: RunData, iterations: int) -> ComposedModel:
    """The real base fitted with the screened search's terms (``found``, ``effect``'s term
    last) and with each other form of ``effect`` that the screen fits nearly as well
    (:data:`FORM_ON_BASE_FACTOR`) at its own best screened point; the form the real base fits
    best on the identification run (a nested simpler form unless the other fits
    :data:`NEST_MARGIN` better).

    The screening base is a play sum, and the form it prefers need not be the one the real
    base needs: on a textbook Bouc-Wen loop with a viscous reading the viscous and the
    ``|v|^a`` forms fitted the screen alike (0.0202 mm RMSE each), the Bouc-Wen 0.0122 and
    0.0128 mm; a non-negative screen at rest had taken a 3 s relaxation there, which the
    Bouc-Wen fitted 3.5x worse than the viscous form."""
    fixed, term = list(found.terms[:-1]), found.terms[-1]
    screened = {effect.form(term.theta): (found, _sse(found, ident))}
    without = _sse(ComposedModel(screen, fixed, iterations=iterations).fit(ident), ident)
    # a term that barely changes the screen's fit has no form worth a refit of the real base
    weighed = screened[effect.form(term.theta)][1] < FORM_WEIGHED_BELOW * without
    for form in dict.fromkeys(effect.form(g) for g in effect.grid(ident)):
        if weighed and form not in screened:
            alt = fit_with_effect(screen, fixed, _only_form(effect, form), ident,
                                  iterations=iterations)
            screened[form] = (alt, _sse(alt, ident))
    top = min(sse for _, sse in screened.values())
    fits = {form: ComposedModel(base_factory,
                                [*fixed, Term(effect, m.terms[-1].theta, m.terms[-1].ctx)],
                                iterations=iterations).fit(ident)
            for form, (m, sse) in screened.items()
            if form == effect.form(term.theta) or sse <= FORM_ON_BASE_FACTOR * top}
    sses = {f: _sse(m, ident) for f, m in fits.items()}
    best = min(sses, key=lambda f: sses[f])
    simpler = effect.nests.get(best)
    if simpler in sses and sses[simpler] <= (1.0 + NEST_MARGIN) * sses[best]:
        best = simpler
    if _sse(found, ident) > SCREEN_EXACT_FACTOR ** 2 * sses[best]:
        return _walked(base_factory, fits[best], effect, ident, iterations)
    return fits[best]


def _walked(base_factory: BaseFactory, model: ComposedModel, effect: Effect, ident: RunData,
            iterations: int) -> ComposedModel:
    """``model`` with its last term's parameter moved along its grid line (the same form
    and other components) while the real base fits the identification run better: where the
    screen fits the run only roughly, its best point may sit a grid step or two off."""
    fixed, term = list(model.terms[:-1]), model.terms[-1]
    last = term.theta[-1] if isinstance(term.theta, tuple) else term.theta
    if not isinstance(last, float) or not np.isfinite(last):
        return model
    prefix = _prefix(term.theta)
    line = sorted({float(g[-1]) if isinstance(g, tuple) else float(g)
                   for g in effect.grid(ident)
                   if effect.form(g) == effect.form(term.theta) and _prefix(g) == prefix})

    def fit(x: float) -> ComposedModel:
        theta = (*prefix, x) if isinstance(term.theta, tuple) else x
        return ComposedModel(base_factory, [*fixed, Term(effect, theta, term.ctx)],
                             iterations=iterations).fit(ident)

    best, best_sse = model, _sse(model, ident)
    for side in ([x for x in reversed(line) if x < last], [x for x in line if x > last]):
        for x in side:
            m = fit(x)
            if (sse := _sse(m, ident)) >= best_sse:
                break
            best, best_sse = m, sse
    return best


#: The screening base stands in for the real one on a run only where its plain fit's RMSE is
#: within this factor of the real base's: a play sum that cannot draw the loop ranks an
#: effect's parameters by its own misfit (on a textbook Bouc-Wen loop with a 0.12 s latency,
#: a non-negative play sum at rest, 4.4x worse than the Bouc-Wen on the plain run, ranked
#: 0.04 s first and 0.12 s third); beyond it the real base's own plain fit, its shape frozen,
#: screens instead.
SCREEN_TRUST_FACTOR = 3.0
#: Where the screen with the terms found fits the identification run within this factor
#: (RMSE) of the real base with them, their parameters are taken as they are; beyond it the
#: real base walks the new term's parameter along its grid (:func:`_walked`).
SCREEN_EXACT_FACTOR = 1.5
#: The play sums a screen may be: where the plays start (at rest, part or all the way after a
#: pull or a release) and whether a weight may be negative (a loop that turns the other way
#: near its tips, as a textbook Bouc-Wen's does).
SCREEN_STARTS = (0.0, 1.0, -1.0, 0.5, -0.5)


class ScreenedFactory:
    """A base factory whose effect parameters are searched with a fast ``screen`` base (see
    :func:`fit_with_effect`) where one fits the run about as well (:meth:`screen_for`);
    calling it makes the real base. ``screen`` is the play-sum class, made with the start
    and weight signs that fit each identification run best."""

    def __init__(self, base: BaseFactory, screen: Callable[..., HysteresisModel], *,
                 unseen: Mapping[str, str] | None = None) -> None:
        self.base = base
        self.screen = screen
        #: effect -> the form of it the screen cannot see, which the real base searches
        #: itself (:func:`fit_joint`)
        self.unseen = dict(unseen or {})
        self._screens: dict[RunData, BaseFactory] = {}

    def __call__(self) -> HysteresisModel:
        return self.base()

    def screen_for(self, ident: RunData) -> BaseFactory:
        """The play sum that fits ``ident`` best (plain, on the identification SSE), when it
        comes within :data:`SCREEN_TRUST_FACTOR` of the real base's RMSE; else the real base's
        plain fit with its shape frozen (:class:`.bases.FrozenShapeModel`)."""
        if ident in self._screens:
            return self._screens[ident]
        plain = ComposedModel(self.base, []).fit(ident)
        real = _sse(plain, ident)
        # where no play sum draws the loop (a loaded textbook Bouc-Wen: 3.9x the real base's
        # RMSE): the real base searching every grid point itself took minutes
        frozen: BaseFactory = partial(FrozenShapeModel, fitted=plain.base_)
        best, best_sse = frozen, np.inf
        for signed in (False, True):
            for start in SCREEN_STARTS:
                f = partial(self.screen, signed=signed, start=start)
                sse = _sse(ComposedModel(f, []).fit(ident), ident)
                if sse < 0.98 * best_sse:  # the first (at rest, weights >= 0) unless beaten
                    best, best_sse = f, sse
        chosen = best if best_sse <= SCREEN_TRUST_FACTOR ** 2 * real else frozen
        self._screens[ident] = chosen
        return chosen


def _screen_of(base_factory: BaseFactory, ident: RunData) -> BaseFactory | None:
    """The screening base that searches ``base_factory``'s effect parameters on ``ident``
    (None: a base fast enough to search them itself)."""
    if isinstance(base_factory, ScreenedFactory):
        return base_factory.screen_for(ident)
    return None


def screened_sse(base_factory: BaseFactory, fixed: Sequence[Term], effect: Effect,
                 ident: RunData, *, iterations: int = 8) -> float | None:
    """The identification SSE of ``effect`` added to ``fixed`` on a slow base's screening
    base (the search :func:`fit_joint` makes before it refits the real base), or None for a
    base fast enough to search itself."""
    screen = _screen_of(base_factory, ident)
    if screen is None:
        return None
    return _sse(fit_joint(screen, fixed, effect, ident, iterations=iterations), ident)


def _searching(base_factory: BaseFactory) -> BaseFactory:
    """The factory a search fits: a screened factory's real base, unwrapped."""
    return base_factory.base if isinstance(base_factory, ScreenedFactory) else base_factory


def retune(base_factory: BaseFactory, model: ComposedModel, ident: RunData, *,
           iterations: int = 8) -> ComposedModel:
    """Re-search the nonlinear parameter of every earlier term with the newest one in place.

    Terms join one at a time, and each earlier term's nonlinear parameter (a delay, a width, a
    speed law) was chosen while the newest effect was still unexplained, so it may have
    stretched to cover part of it: a speed-widened loop covers a latency, and the correct
    delay added on top then overshoots. One coordinate pass over the earlier terms (each
    re-searched on its grid with all the others in place, kept only if the identification SSE
    drops), then the newest term once more if any of them moved, makes the refit joint in the
    nonlinear parameters as well as the linear ones. Only the identification run is used.
    """
    terms = list(model.terms)
    best, best_sse = model, _sse(model, ident)
    moved_any = False
    for j in range(len(terms)):
        newest = j == len(terms) - 1
        if not terms[j].effect.has_theta or (newest and not moved_any):
            continue
        others = terms[:j] + terms[j + 1:]
        trial = fit_with_effect(base_factory, others, terms[j].effect, ident,
                                iterations=iterations)
        cand = ComposedModel(base_factory, [*terms[:j], trial.terms[-1], *terms[j + 1:]],
                             iterations=iterations).fit(ident)
        sse = _sse(cand, ident)
        if sse < best_sse:
            best, best_sse, terms = cand, sse, list(cand.terms)
            moved_any = True
    return best


def fit_joint(base_factory: BaseFactory, fixed: Sequence[Term], effect: Effect, ident: RunData,
              *, iterations: int = 8) -> ComposedModel:
    """``effect`` added to the ``fixed`` terms with every nonlinear parameter searched again,
    from two starting points; the better on the identification SSE.

    :func:`retune` is a coordinate search, and where two terms can trade one effect between
    them (a delay and a dead zone both hold the output back after a reversal) it stays in the
    basin of the order the terms came in: the earlier term keeps the share it took alone. So the
    candidate is also fitted *first*, the earlier terms are searched again on top of it, and the
    two joint fits compete on the identification run. The terms keep their order (the newest
    last), which the composed model does not depend on.

    A screened base (an iterative fit: Bouc-Wen, Preisach, Coleman-Hodgdon) runs the whole
    search on its fast screening base and is fitted with the terms found (and the new term's
    near-tie forms, :func:`_form_on_base`): the search compares dozens of parameter sets,
    each a refit of the base. Where no play sum fits the run within
    :data:`SCREEN_TRUST_FACTOR` of the base, the base's plain fit with its shape frozen
    screens (:meth:`ScreenedFactory.screen_for`).
    """
    screen = _screen_of(base_factory, ident)
    if screen is not None:
        found = fit_joint(screen, fixed, effect, ident, iterations=iterations)
        on_base = _form_on_base(base_factory, screen, found, effect, ident, iterations)
        unseen = getattr(base_factory, "unseen", {}).get(effect.name)
        if fixed or unseen is None or not any(effect.form(g) == unseen
                                              for g in effect.grid(ident)):
            return on_base
        # a form the screen cannot see (a backlash in front of a play sum is a wider play, so
        # every width fits it alike) is searched on the real base itself: on a textbook
        # Bouc-Wen loop behind a 1 mm backlash the screen's width left 11x the noise, the
        # Bouc-Wen's own search 1.0x (16 fits, 1.5 s)
        own = fit_with_effect(_searching(base_factory), fixed, _only_form(effect, unseen),
                              ident, iterations=iterations)
        return own if _sse(own, ident) < _sse(on_base, ident) else on_base
    on_top = retune(base_factory, fit_with_effect(base_factory, fixed, effect, ident,
                                                  iterations=iterations), ident,
                    iterations=iterations)
    if not fixed:
        return on_top
    first = fit_with_effect(base_factory, [], effect, ident, iterations=iterations)
    for term in fixed:
        first = fit_with_effect(base_factory, first.terms, term.effect, ident,
                                iterations=iterations)
    first = retune(base_factory, first, ident, iterations=iterations)
    reordered = ComposedModel(base_factory, [*first.terms[1:], first.terms[0]],
                              iterations=iterations).fit(ident)
    return reordered if _sse(reordered, ident) < _sse(on_top, ident) else on_top


def _weight_constraint(base: Any) -> str:
    """The constraint a play-sum base's weights were (or will be) solved under: the one its
    fit chose (``constraint_``), else its setting (``auto`` solves as its physical form)."""
    return str(getattr(base, "weight_constraint", None) or getattr(base, "constraint", "free"))
