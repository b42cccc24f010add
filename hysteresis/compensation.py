"""Hysteresis compensation: inverse feed-forward, vision feedback, AME-PD and "ours".

Pure and plant-agnostic: a *plant* is any callable ``step(command) -> Mapping[str, float]``
that advances the rig by one control tick (the virtual rig's ``VirtualRig.step``, or a stand-in
plant in a test) and returns at least the key named by ``output_key``. Nothing here touches
files, MLflow or the virtual rig's internals.

The schemes (papers in ``../shared/seeds``):

* **inverse feed-forward** (seed 001 section 4.6-4.7, seed 002 eq. 4): run a model's inverse on
  the desired output and play the resulting input open loop (:func:`run_open_loop`);
* the per-step **Gamma inverse** Gamma_k^{-1} with the LSQ_Opt solvers of Table 4.4
  (Nelder-Mead, an interior-point solver, bounded scalar search) and our exact piecewise-linear
  solution (:func:`gamma_step_inverse`, :func:`gamma_inverse`);
* **vision feedback** (seed 002 baseline "Feedback Com"): an integral loop closed on a 30 Hz,
  delayed, noisy camera (:class:`CameraModel`, :func:`run_vision_feedback`);
* **PD / AME-PD** (seed 000 eq. 19-25) with the UKF active estimation of the model error of the
  Coleman-Hodgdon reference model (eq. 12-18): the family
  :class:`~hysteresis.coleman_hodgdon.ColemanHodgdonModel` and the filter
  :class:`~hysteresis.ukf.ActiveModelUKF` (:func:`model_error_ukf`, :func:`run_ame_pd`);
* **ours** (:func:`run_inverse_with_error_correction`): the exact Gamma inverse with an online
  estimate of the model's output error (a scalar random-walk Kalman filter on the residual of the
  delayed measurement against the model's own prediction, i.e. the UKF idea of seed 000 moved
  to the output side), so the inverse aims at ``desired - estimated error``.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from scipy import optimize

from hysteresis.base import HysteresisError, Steppable, as_1d, check_inverse_reach
from hysteresis.coleman_hodgdon import ColemanHodgdonModel
from hysteresis.gamma import GammaModel, GammaState
from hysteresis.metrics import error_statistics
from hysteresis.play import gamma_at
from hysteresis.ukf import PAPER_P0, PAPER_Q0, PAPER_R0, ActiveModelUKF

FloatArray = npt.NDArray[np.float64]
StepFn = Callable[[float], Mapping[str, float]]

__all__ = [
    "CameraModel", "FamilyStepper", "GAMMA_METHODS", "InverseStepper", "LoopResult",
    "StrokeLimits", "UKF_DEFAULTS", "as_stepper", "camera_frames",
    "estimate_model_error", "model_error_ukf",
    "gamma_inverse", "gamma_step_inverse", "mixed_sine_profile", "reduction",
    "run_ame_pd", "run_inverse_with_error_correction", "run_open_loop", "run_vision_feedback",
    "seed000_target", "seed002_motion", "segment_statistics", "sine_profile", "triangle_profile",
]


# ---------------------------------------------------------------------------------------------
# Results and small helpers
# ---------------------------------------------------------------------------------------------
@dataclass
class LoopResult:
    """Time series of one compensation run (all arrays the same length, one per tick)."""

    scheme: str
    t_s: FloatArray
    desired: FloatArray
    command: FloatArray
    output: FloatArray
    measured: FloatArray  # what the controller saw at each tick (NaN: nothing new)
    extra: dict[str, FloatArray] = field(default_factory=dict)

    def error(self) -> FloatArray:
        """Tracking error ``output - desired`` (seed 001 sign: measured minus model/target)."""
        return self.output - self.desired

    def statistics(self, *, skip_s: float = 0.0) -> dict[str, float]:
        """:func:`hysteresis.metrics.error_statistics` of output vs desired after ``skip_s``."""
        keep = self.t_s >= self.t_s[0] + skip_s
        return error_statistics(self.output[keep], self.desired[keep])


@dataclass(frozen=True)
class StrokeLimits:
    """The rig's input stroke; every command is clipped into ``[low, high]``."""

    low: float = -math.inf
    high: float = math.inf

    def __post_init__(self) -> None:
        if not self.low < self.high:
            raise HysteresisError(
                f"stroke limits must satisfy low < high, got {self.low}, {self.high}"
            )

    def clip(self, value: float) -> float:
        return min(max(value, self.low), self.high)

    def contains(self, values: Any) -> bool:
        arr = np.asarray(values, dtype=np.float64)
        return bool(np.all((arr >= self.low - 1e-12) & (arr <= self.high + 1e-12)))


def reduction(before: float, after: float) -> float:
    """Relative reduction in percent, ``100 (1 - after / before)``."""
    return float("nan") if before == 0 else 100.0 * (1.0 - after / before)


def _output(sample: Mapping[str, float], key: str) -> float:
    try:
        return float(sample[key])
    except KeyError:
        raise HysteresisError(
            f"the plant's step() returned no {key!r}; it returned {sorted(sample)}"
        ) from None


def _ticks(n: int, dt_s: float) -> FloatArray:
    return np.arange(n, dtype=np.float64) * dt_s


def _check_dt(dt_s: float) -> None:
    if not (dt_s > 0 and math.isfinite(dt_s)):
        raise HysteresisError(f"dt_s must be a positive finite number, got {dt_s}")


# ---------------------------------------------------------------------------------------------
# Desired profiles
# ---------------------------------------------------------------------------------------------
def mixed_sine_profile(t_s: Any) -> FloatArray:
    """Seed 001 eq. 4.11 (mm):
    7 sin(pi t/4) + 2 sin(1.1 pi t/4) - 4 sin(0.2 pi t/4) + sin(0.45 pi t/4)."""
    t = np.asarray(t_s, dtype=np.float64)
    w = math.pi / 4.0
    return np.asarray(
        7 * np.sin(w * t) + 2 * np.sin(1.1 * w * t) - 4 * np.sin(0.2 * w * t)
        + np.sin(0.45 * w * t),
        dtype=np.float64,
    )


def sine_profile(
    t_s: Any, *, amplitudes: Sequence[float] = (6.0, 4.5, 3.0, 1.5), periods_per_amplitude: int = 5,
    frequency_hz: float = 0.25,
) -> FloatArray:
    """Seed 001 decaying sinusoid (Fig. 4.8), ``periods_per_amplitude`` periods per amplitude."""
    t = np.asarray(t_s, dtype=np.float64)
    seg = periods_per_amplitude / frequency_hz
    idx = np.minimum((t // seg).astype(int), len(amplitudes) - 1)
    amp = np.asarray(amplitudes, dtype=np.float64)[idx]
    out = amp * np.sin(2 * math.pi * frequency_hz * t)
    return np.asarray(np.where(t < seg * len(amplitudes), out, 0.0), dtype=np.float64)


def triangle_profile(
    t_s: Any, *, amplitudes: Sequence[float] = (6.0, 4.5, 3.0, 1.5), periods_per_amplitude: int = 1,
    slope_mm_s: float = 6.0,
) -> FloatArray:
    """Seed 001 triangle wave of slope ``slope_mm_s`` (Fig. 4.9a), decaying amplitudes, from 0."""
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros_like(t)
    t0 = 0.0
    for a in amplitudes:
        period = 4.0 * a / slope_mm_s
        for _ in range(periods_per_amplitude):
            m = (t >= t0) & (t < t0 + period)
            ph = (t[m] - t0) / period  # 0..1: up to +a, down to -a, back to 0
            out[m] = a * np.where(ph < 0.25, 4 * ph, np.where(ph < 0.75, 2 - 4 * ph, 4 * ph - 4))
            t0 += period
    return out


def seed000_target(t_s: Any) -> FloatArray:
    """Seed 000 eq. 32: alpha_d(t) = -50 cos(pi t / 50) + 80 (deg)."""
    t = np.asarray(t_s, dtype=np.float64)
    return np.asarray(-50.0 * np.cos(math.pi * t / 50.0) + 80.0, dtype=np.float64)


def seed002_motion(
    t_s: Any, *, omega_rad_s: float | None, amplitude: float = 30.0, offset: float = 30.0,
) -> FloatArray:
    """Seed 002 motions: ``amplitude sin(omega t) + offset``; ``omega=None`` is the non-periodic
    motion, the normalised sum of the three periodic ones (omega 0.25, 0.5, 1 rad/s)."""
    t = np.asarray(t_s, dtype=np.float64)
    if omega_rad_s is not None:
        return np.asarray(amplitude * np.sin(omega_rad_s * t) + offset, dtype=np.float64)
    parts = [np.sin(w * t + ph) for w, ph in ((0.25, 0.0), (0.5, 1.0), (1.0, 2.0))]
    mix = np.sum(parts, axis=0)
    mix = mix - mix[0]  # start at the offset, like the periodic motions
    scale = float(np.max(np.abs(mix))) or 1.0
    return np.asarray(amplitude * mix / scale + offset, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# Open-loop runs (no compensation, or an inverse feed-forward input)
# ---------------------------------------------------------------------------------------------
def run_open_loop(
    step: StepFn, command: Any, *, desired: Any, dt_s: float = 0.01, output_key: str = "output",
    stroke: StrokeLimits | None = None, scheme: str = "open_loop",
) -> LoopResult:
    """Play ``command`` (clipped to ``stroke``) through the plant, one tick per sample (all at
    once through ``step.many(commands)`` where the step function has it)."""
    _check_dt(dt_s)
    u = as_1d(command, "command")
    yd = as_1d(desired, "desired")
    if u.shape != yd.shape:
        raise HysteresisError(f"command and desired differ in length: {u.size} vs {yd.size}")
    lim = stroke or StrokeLimits()
    applied = np.clip(u, lim.low, lim.high)
    # the whole command is known in advance: a plant that can take it at once (``step.many``,
    # e.g. the virtual rig) runs it in one call; its readings are those of tick by tick
    many = getattr(step, "many", None)
    rows = many(applied) if callable(many) else [step(float(c)) for c in applied]
    y = np.array([_output(r, output_key) for r in rows], dtype=np.float64)
    t = _ticks(u.size, dt_s)
    return LoopResult(scheme, t, yd, applied, y, np.full_like(y, np.nan))


# ---------------------------------------------------------------------------------------------
# Table 4.4: the per-step inverse Gamma_k^{-1} of the complex play operator (seed 001 eq.
# 4.8-4.9, the family hysteresis.gamma.GammaModel) by each LSQ_Opt solver and by ours
# ---------------------------------------------------------------------------------------------
GAMMA_METHODS = ("exact", "bounded", "nelder-mead", "slsqp", "interior-point")


def gamma_step_inverse(
    model: GammaModel, target: float, state: GammaState, *, method: str = "exact",
    bounds: tuple[float, float] | None = None, tol: float = 1e-6,
) -> tuple[float, GammaState]:
    """One step of Gamma_k^{-1} (seed 001 Fig. 4.25-4.33): the input ``v_k`` whose output from
    ``state`` (W_{k-1}) is ``target``, started at the previous input ``state.u``; returns
    ``(v_k, W_k)``. The result is clamped into ``bounds`` (default: 50 input units either side
    of the previous input).

    ``method``: ``exact`` (ours: the model's breakpoint inverse, the root of the
    piecewise-linear map nearest the previous input), ``bounded`` (FMINBND: golden section +
    parabolic interpolation on ``bounds``), ``nelder-mead`` (FMINSEARCH), ``slsqp`` and
    ``interior-point`` (FMINCON-like constrained solvers; SciPy's ``trust-constr`` is its
    interior-point method).
    """
    v_prev = float(state.u)
    lo, hi = bounds if bounds is not None else (v_prev - 50.0, v_prev + 50.0)
    if method == "exact":
        v, new_state = model.invert_step(target, state, method="exact")
        if lo <= v <= hi:
            return v, new_state
        v = min(max(v, lo), hi)
    else:
        v = _solver_step(model, target, state, method=method, bounds=(lo, hi), tol=tol)
    return v, model.step(v, state)[1]


def _solver_step(model: GammaModel, target: float, state: GammaState, *, method: str,
                 bounds: tuple[float, float], tol: float) -> float:
    """Table 4.4's LSQ_Opt solvers on ``(Gamma(v | W_{k-1}) - target)^2`` from ``state.u``."""
    v_prev = float(state.u)
    lo, hi = bounds
    # the compiled operator, not model.step: the table times the solvers, not model overhead
    w, p, q = (np.ascontiguousarray(a, dtype=np.float64)
               for a in (state.w, model.thresholds_, model.weights_))
    offset = float(model.offset_)

    def cost(x: Any) -> float:
        y = gamma_at(float(np.asarray(x).ravel()[0]), w, p, q, offset)
        return (y - target) ** 2

    if method == "bounded":
        res = optimize.minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                       options={"xatol": tol})
        return float(res.x)
    if method == "nelder-mead":
        # The default simplex (5 % of x0) cannot leave a backlash plateau; start it one
        # largest play wide, as a tuned FMINSEARCH would be.
        width = float(np.max(model.thresholds_)) or 1.0
        res = optimize.minimize(cost, x0=[v_prev], method="Nelder-Mead",
                                options={"xatol": tol, "fatol": tol**2,
                                         "initial_simplex": [[v_prev], [v_prev + width]]})
        return float(res.x[0])
    if method == "slsqp":
        res = optimize.minimize(cost, x0=[v_prev], method="SLSQP", bounds=[(lo, hi)],
                                options={"ftol": tol**2})
        return float(res.x[0])
    if method == "interior-point":
        with warnings.catch_warnings():  # quasi-Newton noise on the piecewise-linear map
            warnings.simplefilter("ignore", UserWarning)
            res = optimize.minimize(cost, x0=[v_prev], method="trust-constr",
                                    bounds=[(lo, hi)], options={"xtol": tol, "gtol": tol**2})
        return float(res.x[0])
    raise HysteresisError(
        f"unknown inverse method {method!r}; known: {', '.join(GAMMA_METHODS)}"
    )


def gamma_inverse(
    model: GammaModel, desired: Any, *, method: str = "exact",
    stroke: StrokeLimits | None = None, v0: float = 0.0, max_steps: int | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Recursive inverse of a whole desired trajectory from ``model.initial_state(v0)``;
    returns ``(inputs, seconds_per_step)``.

    The search of step k starts at ``v_{k-1}`` (Fig. 4.32); ``max_steps`` stops early (timing
    the slow solvers on a prefix)."""
    if not isinstance(model, GammaModel):
        raise HysteresisError(
            f"{type(model).__name__} is not a Gamma model; Table 4.4's solvers invert Gamma_n")
    model.check_fitted()
    yd = as_1d(desired, "desired")
    if max_steps is not None:
        yd = yd[:max_steps]
    check_inverse_reach(model, desired=yd)
    lim = stroke or StrokeLimits()
    pmax = float(np.max(model.thresholds_))
    slope = max(abs(float(model.weights_.sum())), 1e-6)
    state = model.initial_state(v0)
    y_prev, _ = model.step(v0, state)
    out = np.empty_like(yd)
    times = np.empty_like(yd)
    for k, target in enumerate(yd):
        # Search interval for the bracketing solvers: the input may have to cross the largest
        # play (a reversal) plus the step in output over the outer slope, with a margin.
        half = 1.5 * pmax + 3.0 * abs(float(target) - y_prev) / slope + 1e-3
        lo = max(lim.low, state.u - half)
        hi = min(lim.high, state.u + half)
        t0 = time.perf_counter()
        out[k], state = gamma_step_inverse(model, float(target), state, method=method,
                                           bounds=(lo, hi))
        times[k] = time.perf_counter() - t0
        y_prev = float(target)
    return out, times


# ---------------------------------------------------------------------------------------------
# A camera: 30 Hz frames, stamped late, noisy (seed 002; the rig log format's camera stream)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraModel:
    """Frames every ``1/rate_hz`` s of the true output, delivered ``latency_s`` late with
    Gaussian noise ``noise_std``; ``rate_hz=None`` means every tick, no latency, no noise."""

    rate_hz: float | None = 30.0
    latency_s: float = 0.045
    noise_std: float = 0.0
    seed: int = 0


class _Camera:
    def __init__(self, model: CameraModel, dt_s: float) -> None:
        self.model = model
        self.dt_s = dt_s
        self.rng = np.random.default_rng(model.seed)
        self.queue: deque[tuple[float, float, float]] = deque()  # (t_available, t_capture, value)
        self.next_frame = 0.0

    def observe(self, t: float, true_value: float) -> tuple[float, float] | None:
        """Feed the truth at tick time ``t``; return a newly delivered (t_capture, value)."""
        m = self.model
        if m.rate_hz is None:
            return t, true_value
        if t + 1e-12 >= self.next_frame:
            noise = m.noise_std * float(self.rng.standard_normal()) if m.noise_std else 0.0
            noisy = true_value + noise
            self.queue.append((t + m.latency_s, t, noisy))
            self.next_frame += 1.0 / m.rate_hz
        delivered = None
        while self.queue and self.queue[0][0] <= t + 1e-12:
            _, tc, val = self.queue.popleft()
            delivered = (tc, val)
        return delivered


def camera_frames(values: Any, camera: CameraModel, *, dt_s: float = 0.01) -> FloatArray:
    """What an offline analysis gets from the camera: the frames placed at their capture ticks
    (NaN elsewhere). ``values`` is the true signal on the control grid; latency only decides
    which frames have arrived by the end of the record."""
    vv = as_1d(values, "values")
    cam = _Camera(camera, dt_s)
    out = np.full(vv.size, np.nan)
    for k, val in enumerate(vv):
        got = cam.observe(k * dt_s, float(val))
        if got is not None:
            out[min(max(int(round(got[0] / dt_s)), 0), k)] = got[1]
    return out


# ---------------------------------------------------------------------------------------------
# Vision feedback (seed 002 baseline "Feedback Com")
# ---------------------------------------------------------------------------------------------
def run_vision_feedback(
    step: StepFn, desired: Any, *, dt_s: float = 0.01, camera: CameraModel = CameraModel(),
    gain: float = 0.3, kp: float = 0.0, feedforward: Any = None, output_key: str = "output",
    stroke: StrokeLimits | None = None,
) -> LoopResult:
    """Command = feed-forward (default: the desired itself) + a correction closed on the camera.

    At each delivered frame the error against the desired *at the frame's capture time* is
    integrated, ``c += gain * e`` (a per-frame integrator, robust to the frame latency) and a
    proportional part ``kp * e`` is added. Without a frame the command holds its correction.
    """
    _check_dt(dt_s)
    yd = as_1d(desired, "desired")
    ff = yd if feedforward is None else as_1d(feedforward, "feedforward")
    if ff.shape != yd.shape:
        raise HysteresisError("feedforward and desired differ in length")
    if not 0.0 <= gain < 2.0:
        raise HysteresisError(f"gain must be in [0, 2) for a stable integrator, got {gain}")
    lim = stroke or StrokeLimits()
    cam = _Camera(camera, dt_s)
    n = yd.size
    u = np.empty(n)
    y = np.empty(n)
    seen = np.full(n, np.nan)
    integ = 0.0
    prop = 0.0
    for k in range(n):
        u[k] = lim.clip(float(ff[k]) + integ + prop)
        y[k] = _output(step(float(u[k])), output_key)
        got = cam.observe(k * dt_s, y[k])
        if got is not None:
            tc, val = got
            seen[k] = val
            e = float(yd[min(int(round(tc / dt_s)), n - 1)]) - val
            integ += gain * e
            # Anti-windup: the correction cannot push the command beyond the stroke.
            integ = min(max(integ, lim.low - float(ff[k])), lim.high - float(ff[k]))
            prop = kp * e
    return LoopResult("vision_feedback", _ticks(n, dt_s), yd, u, y, seen)


# ---------------------------------------------------------------------------------------------
# UKF active estimation of the model error (seed 000 eq. 12-18): the reference model is the
# Coleman-Hodgdon family (hysteresis.coleman_hodgdon), the filter hysteresis.ukf's
# ---------------------------------------------------------------------------------------------
#: Seed 000 eq. 29, as the UKF module has them.
UKF_DEFAULTS: dict[str, Any] = {"P0": PAPER_P0, "Q": PAPER_Q0, "R": PAPER_R0}


def model_error_ukf(reference: ColemanHodgdonModel, *, dt_s: float,
                    **ukf_kw: Any) -> ActiveModelUKF:
    """The seed 000 estimator around ``reference``; ``P0``/``Q`` may be given as diagonals."""
    _check_dt(dt_s)
    kw = {**UKF_DEFAULTS, **ukf_kw}
    unknown = sorted(set(kw) - set(UKF_DEFAULTS))
    if unknown:
        raise HysteresisError(f"unknown UKF settings {unknown}; use P0, Q, R")

    def matrix(x: Any) -> FloatArray:
        m = np.asarray(x, dtype=np.float64)
        return np.diag(m) if m.ndim == 1 else m

    return ActiveModelUKF(reference, dt=dt_s, P0=matrix(kw["P0"]), Q=matrix(kw["Q"]),
                          R=float(kw["R"]))


def estimate_model_error(
    reference: ColemanHodgdonModel, pull: Any, alpha_meas: Any, *, dt_s: float,
    alpha0: float | None = None, **ukf_kw: Any,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Offline run of the estimator over a recorded pull/angle pair (seed 000 section V.C).

    ``alpha_meas`` may hold NaN where no measurement arrived (a 30 Hz camera on the 100 Hz
    loop): the UKF then only predicts with the model. ``alpha0`` is the angle at rest (default:
    the first finite measurement). Returns ``(alpha_model, alpha_est, f_h)``: the reference model
    alone (eq. 10), the UKF's enhanced estimate alpha_EstM (eq. 16-18) and the model error."""
    ll = as_1d(pull, "l")
    aa = np.asarray(alpha_meas, dtype=np.float64)
    if aa.ndim != 1 or ll.shape != aa.shape:
        raise HysteresisError("pull and alpha_meas differ in shape")
    finite = np.flatnonzero(np.isfinite(aa))
    if alpha0 is None:
        if finite.size == 0:
            raise HysteresisError("alpha_meas has no finite measurement")
        alpha0 = float(aa[finite[0]])
    res = model_error_ukf(reference, dt_s=dt_s, **ukf_kw).run(ll, aa, y0=float(alpha0))
    return res.model, res.estimate, res.f_h


def segment_statistics(measured: Any, estimate: Any) -> dict[str, float]:
    """Seed 000 eq. 27-31: mean |Err| and Var (population) of ``measured - estimate``."""
    s = error_statistics(measured, estimate)
    return {"abs_err": s["mean_abs_error"], "var": s["var_error"]}


# ---------------------------------------------------------------------------------------------
# PD and AME-PD (seed 000 eq. 19-25)
# ---------------------------------------------------------------------------------------------
def run_ame_pd(
    step: StepFn, desired: Any, reference: ColemanHodgdonModel | None, *, dt_s: float = 0.01,
    kp: float = 0.02,
    kd: float = 0.05, kc: float = 0.06, control_every: int = 1, camera: CameraModel | None = None,
    output_key: str = "output", stroke: StrokeLimits | None = None, l0: float = 0.0,
    ukf_kw: Mapping[str, Any] | None = None,
) -> LoopResult:
    """Velocity-command tracking of ``desired`` (angles) by pulling the tendon (the command is
    the pull position, integrated from the controller's velocity).

    PD: ``v = kp e + kd (e - e_prev)/Ts`` (eq. 21) - pass ``reference=None`` or ``kc=0``.
    AME-PD: ``+ kc * e_hat_{k+1}`` (eq. 24-25), the error predicted one controller period ahead
    by the UKF-enhanced reference model (eq. 22-23). The controller runs every
    ``control_every`` ticks (Ts = control_every * dt_s) on the newest measurement (``camera``
    delays/decimates it; default: the output every tick).
    """
    _check_dt(dt_s)
    if control_every < 1:
        raise HysteresisError(f"control_every must be >= 1, got {control_every}")
    yd = as_1d(desired, "desired")
    lim = stroke or StrokeLimits()
    ts = dt_s * control_every
    cam = _Camera(camera or CameraModel(rate_hz=None), dt_s)
    ame = reference if kc != 0.0 else None  # None: plain PD
    n = yd.size
    u = np.empty(n)
    y = np.empty(n)
    seen = np.full(n, np.nan)
    fh_log = np.full(n, np.nan)
    est_log = np.full(n, np.nan)
    pull = lim.clip(l0)
    v = 0.0
    e_prev: float | None = None
    latest: float | None = None
    ukf: ActiveModelUKF | None = None
    for k in range(n):
        u[k] = pull
        y[k] = _output(step(float(pull)), output_key)
        got = cam.observe(k * dt_s, y[k])
        if got is not None:
            latest = got[1]
            seen[k] = latest
        if k % control_every == 0 and latest is not None:
            a_est, fh = latest, 0.0
            if ame is not None:
                if ukf is None:
                    ukf = model_error_ukf(ame, dt_s=ts, **dict(ukf_kw or {}))
                    ukf.reset(float(pull), y0=latest)
                else:
                    # time update over the last control period (the pull it moved), then the
                    # newest measurement
                    a_est, fh = ukf.step(float(pull), latest)
                est_log[k], fh_log[k] = a_est, fh
            e = float(yd[k]) - latest
            v = kp * e + (kd * (e - e_prev) / ts if e_prev is not None else 0.0)
            e_prev = e
            if ame is not None:
                a_hat = a_est + ts * (ame.rate(a_est, pull, v) + fh)
                e_hat = float(yd[min(k + control_every, n - 1)]) - a_hat
                v = v + kc * e_hat
        pull = lim.clip(pull + v * dt_s)
    scheme = "ame_pd" if ame is not None else "pd"
    return LoopResult(scheme, _ticks(n, dt_s), yd, u, y, seen,
                      {"f_h": fh_log, "alpha_est": est_log})


# ---------------------------------------------------------------------------------------------
# Ours: exact Gamma inverse + online model-error estimate
# ---------------------------------------------------------------------------------------------
class InverseStepper(Protocol):
    """A model's inverse, one tick at a time, with the model state carried inside."""

    def reset(self, u0: float) -> None: ...

    def inverse(self, target: float, *, low: float, high: float) -> tuple[float, float]:
        """Commit one step: the command in ``[low, high]`` and the model's output for it."""
        ...


class FamilyStepper:
    """Any fitted family exposing ``initial_state(u0)``, ``step(u, state) -> (y, state)`` and
    ``invert_step(y, state) -> (u, state)`` (e.g. the Gamma and Bouc-Wen families)."""

    def __init__(self, model: Any) -> None:
        if not isinstance(model, Steppable):
            missing = [m for m in ("initial_state", "step", "invert_step")
                       if not callable(getattr(model, m, None))]
            raise HysteresisError(
                f"{type(model).__name__} has no {'(), '.join(missing)}(); it cannot be "
                "stepped online (a Steppable: every StatefulModel family is one)")
        self.model = model
        self.reset(0.0)

    def _forward(self, u: float, state: Any) -> tuple[float, Any]:
        y, st = self.model.step(u, state)
        return float(y), st

    def reset(self, u0: float) -> None:
        self.state = self.model.initial_state(u0)

    def inverse(self, target: float, *, low: float, high: float) -> tuple[float, float]:
        prev = self.state
        u, st = self.model.invert_step(target, prev)
        u = float(u)
        if not low <= u <= high or not math.isfinite(u):
            u = min(max(u, low), high) if math.isfinite(u) else min(max(0.0, low), high)
        y, self.state = self._forward(u, prev)  # re-run: the state of the applied command
        return u, y


def as_stepper(model: Any) -> InverseStepper:
    """Wrap a stepper, or a step-able fitted family (a Gamma fit among them)."""
    if callable(getattr(model, "inverse", None)) and callable(getattr(model, "reset", None)):
        return model  # type: ignore[no-any-return]
    return FamilyStepper(model)


def run_inverse_with_error_correction(
    step: StepFn, desired: Any, model: Any, *, dt_s: float = 0.01,
    camera: CameraModel | None = None, process_var: float = 1e-3, meas_var: float = 1e-2,
    output_key: str = "output", stroke: StrokeLimits | None = None, v0: float = 0.0,
    correct: bool = True, max_step: float | None = None,
    identified_range: tuple[float, float] | None = None,
) -> LoopResult:
    """Our compensator: ``u_k = M^{-1}(desired_k - f_hat)`` with a model's exact step inverse
    (``model``: a fitted :class:`~hysteresis.gamma.GammaModel` - the Gamma operator - or any
    stepper/step-able family).

    ``f_hat`` is a random-walk Kalman estimate of the model's output error
    ``f = measured - M(u)``; each delivered measurement is compared with the model's own
    prediction *at the measurement's capture time* (so the camera's latency does not enter the
    loop: the correction is open loop on the estimate, like seed 000's enhancement, and cannot
    destabilise the plant). ``correct=False`` is the plain exact-inverse feed-forward.
    ``max_step`` bounds the command change per tick (default: unbounded but within the stroke).
    ``identified_range``: the model's identification input range; with it (and always for
    the total weight) :func:`hysteresis.base.check_inverse_reach` refuses a weighted-play model
    that cannot reach the targets before anything is driven.
    """
    _check_dt(dt_s)
    yd = as_1d(desired, "desired")
    # Before the first command: a model that cannot reach the targets is refused, not driven.
    check_inverse_reach(getattr(model, "model", model),
                        identified_range=identified_range, desired=yd)
    lim = stroke or StrokeLimits()
    cam = _Camera(camera or CameraModel(rate_hz=None), dt_s)
    stepper = as_stepper(model)
    stepper.reset(v0)
    n = yd.size
    u = np.empty(n)
    y = np.empty(n)
    ymodel = np.empty(n)
    seen = np.full(n, np.nan)
    fh_log = np.empty(n)
    v_prev = v0
    f_hat, P = 0.0, 1.0
    for k in range(n):
        target = float(yd[k]) - (f_hat if correct else 0.0)
        low, high = lim.low, lim.high
        if max_step is not None:
            low, high = max(low, v_prev - max_step), min(high, v_prev + max_step)
        v, ymodel[k] = stepper.inverse(target, low=low, high=high)
        u[k] = v
        v_prev = v
        y[k] = _output(step(float(v)), output_key)
        got = cam.observe(k * dt_s, y[k])
        if got is not None:
            tc, val = got
            seen[k] = val
            kc = min(max(int(round(tc / dt_s)), 0), k)
            P += process_var
            gain = P / (P + meas_var)
            f_hat += gain * (val - ymodel[kc] - f_hat)
            P *= 1.0 - gain
        fh_log[k] = f_hat
    return LoopResult("ours" if correct else "exact_ff", _ticks(n, dt_s), yd, u, y, seen,
                      {"model_output": ymodel, "f_hat": fh_log})


def with_lead_in(yd: np.ndarray, *, start: float, lead_s: float, dt_s: float) -> np.ndarray:
    """Prepend a smooth move from the rig's rest value ``start`` to ``yd[0]`` over ``lead_s``
    at the control period ``dt_s`` (the papers' motions start away from rest; statistics skip
    this lead-in)."""
    n = int(round(lead_s / dt_s))
    if n <= 0:
        return yd
    x = np.arange(n) / n
    ramp = start + (float(yd[0]) - start) * (3 * x**2 - 2 * x**3)
    return np.concatenate([ramp, yd])
