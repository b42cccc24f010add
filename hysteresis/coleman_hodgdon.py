"""Coleman-Hodgdon backlash-like hysteresis (seed 000, eq. 10-11), GA identification (eq. 26).

The paper's model, with input u (pull distance, delta l) and output y (bending angle alpha)::

    dy/dt = A |du/dt| (C (u - O_u) - (y - O_y)) + B du/dt,   A > 0, B < 0, C > 0     (10-11)

It is rate-independent, and for a fixed input direction d = sgn(du) it is *linear* in y, so one
sample is integrated exactly (no discretisation error, stable at any sample rate)::

    w = y - C u - k,  k = O_y - C O_u,  w* = d (B - C) / A
    w(u + du) = w* + (w - w*) exp(-A |du|)

Along a branch, w tends to -(C-B)/A (loading) or +(C-B)/A (unloading): the two asymptotic
branches are the lines ``y = C u + k -/+ (C - B)/A``, a loop of vertical width 2(C-B)/A and
horizontal width 2(C-B)/(A C). Only k (not O_u and O_y separately) enters the dynamics; we
report the backlash origin as the centre of the training input range ``O_u`` and
``O_y = k + C O_u``, the centre of the loop. The rest state is on the centre line (w = 0).
``scheme="euler"`` gives the paper's explicit discretisation of eq. 16 instead.

Identification: ``method="ga"`` (default, the paper's): scipy's differential evolution (a GA
variant) on the MSE of eq. 26 with a fixed seed and an L-BFGS-B polish, in normalised units
(scale-robust). ``method="varpro"`` (ours): for fixed A the output is linear in (B, C, k), so
those are solved by bounded linear least squares and only A is searched (1-D).
The paper's sign constraint B < 0 (``b_sign="negative"``) bends every branch one way after a
reversal; it forbids the flat reversal of a true backlash (slope 2B - C at a reversal) and the
steep one of a softening loop, so ``b_sign="free"`` lets B in (-inf, C). The default,
``b_sign="auto"``, keeps the paper's bound unless the free form, fitted on the head of the
identification record(s), predicts their last 30 % better by 10 % (``b_sign_`` says which).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from scipy.optimize import differential_evolution, lsq_linear, minimize, minimize_scalar

from hysteresis._blas import single_thread_blas
from hysteresis._numerics import decimation_indices
from hysteresis.base import (
    FloatArray,
    HysteresisError,
    Records,
    StatefulModel,
    as_1d,
    check_records,
    choose_form,
    records_sse,
    register_family,
    state_from,
)

__all__ = ["ColemanHodgdonModel", "ColemanHodgdonState", "ch_simulate", "PAPER_PARAMS"]

PAPER_PARAMS = (0.95, -0.92, 18.53)  # seed 000, section V-B: [A_Ref, B_Ref, C_Ref]


@numba.njit(cache=True, inline="always")
def _ch_advance(
    y: float, up: float, u: float, a_: float, b_: float, c_: float, k: float, euler: bool
) -> float:
    du = u - up
    if du == 0.0:
        return y
    if euler:  # seed 000 eq. 16 (explicit Euler, stable only while A|du| < 2)
        return y + a_ * abs(du) * (c_ * up - y + k) + b_ * du
    d = 1.0 if du > 0.0 else -1.0
    ws = d * (b_ - c_) / a_
    w = y - c_ * up - k
    return c_ * u + k + ws + (w - ws) * math.exp(-a_ * abs(du))


@numba.njit(cache=True)
def _ch_simulate(
    u: FloatArray, a_: float, b_: float, c_: float, k: float, y0: float, u0: float,
    euler: bool, out: FloatArray,
) -> float:
    y = y0
    up = u0
    for i in range(u.size):
        y = _ch_advance(y, up, u[i], a_, b_, c_, k, euler)
        up = u[i]
        out[i] = y
    return y


@numba.njit(cache=True)
def _ch_mse_batch(
    u: FloatArray, y: FloatArray, pop: FloatArray, euler: bool, out: FloatArray
) -> None:
    """MSE (eq. 26) for each column [log10 A, B, C, k] of ``pop`` (normalised units)."""
    for j in range(pop.shape[1]):
        a_ = 10.0 ** pop[0, j]
        b_ = pop[1, j]
        c_ = pop[2, j]
        k = pop[3, j]
        yy = c_ * u[0] + k
        up = u[0]
        acc = 0.0
        for i in range(u.size):
            yy = _ch_advance(yy, up, u[i], a_, b_, c_, k, euler)
            up = u[i]
            e = y[i] - yy
            acc += e * e
        m = acc / u.size
        out[j] = m if m < 1e12 else 1e12  # also maps NaN (Euler blow-up) to the cap


@numba.njit(cache=True)
def _ch_basis(u: FloatArray, a_: float, euler: bool, out: FloatArray) -> None:
    """Responses to (B, C, k) = unit vectors: for fixed A the output is linear in (B, C, k)."""
    for col in range(3):
        b_ = 1.0 if col == 0 else 0.0
        c_ = 1.0 if col == 1 else 0.0
        k = 1.0 if col == 2 else 0.0
        yy = c_ * u[0] + k
        up = u[0]
        for i in range(u.size):
            yy = _ch_advance(yy, up, u[i], a_, b_, c_, k, euler)
            up = u[i]
            out[i, col] = yy


@numba.njit(cache=True)
def _ch_invert(
    yd: FloatArray, a_: float, b_: float, c_: float, k: float, y0: float, u0: float,
    out: FloatArray,
) -> tuple[float, float]:
    """Exact per-step inverse of the exact scheme: for each target, the input increment
    (in the direction that moves y toward it in the long run) solving y(u) = y_d.

    Along one direction ``g(x) = C d x + (w - w*)(exp(-A x) - 1) + const`` has a monotone
    derivative, so there is exactly one root x > 0: bracket by doubling, then Newton with a
    bisection safeguard.
    """
    y = y0
    up = u0
    for i in range(yd.size):
        target = yd[i]
        if target == y:
            out[i] = up
            continue
        d = 1.0 if target > y else -1.0
        ws = d * (b_ - c_) / a_
        w = y - c_ * up - k
        base = c_ * up + k + ws - target  # g(x) = base + C d x + (w - ws) exp(-A x)
        lo = 0.0
        hi = abs(target - y) / c_ + 1.0 / a_
        for _ in range(200):
            if d * (base + c_ * d * hi + (w - ws) * math.exp(-a_ * hi)) > 0.0:
                break
            lo = hi
            hi *= 2.0
        x = 0.5 * (lo + hi)
        for _ in range(100):
            e = math.exp(-a_ * x)
            g = base + c_ * d * x + (w - ws) * e
            if d * g > 0.0:
                hi = x
            else:
                lo = x
            dg = c_ * d - a_ * (w - ws) * e
            xn = x - g / dg if dg != 0.0 else 0.5 * (lo + hi)
            if not (lo < xn < hi):
                xn = 0.5 * (lo + hi)
            if abs(xn - x) <= 1e-15 * (1.0 + abs(x)) or hi - lo <= 1e-15 * (1.0 + hi):
                x = xn
                break
            x = xn
        unew = up + d * x
        y = _ch_advance(y, up, unew, a_, b_, c_, k, False)
        up = unew
        out[i] = up
    return y, up


def ch_simulate(
    u: Any, A: float, B: float, C: float, *, origin: tuple[float, float] = (0.0, 0.0),
    y0: float | None = None, scheme: str = "exact",
) -> FloatArray:
    """Simulate eq. 10-11 along u with backlash origin ``(O_u, O_y)`` from ``y0``
    (default: the centre line, y0 = O_y + C (u[0] - O_u))."""
    uu = as_1d(u, "u")
    _check_params(A, C)
    k = origin[1] - C * origin[0]
    start = C * float(uu[0]) + k if y0 is None else float(y0)
    out = np.empty_like(uu)
    _ch_simulate(uu, float(A), float(B), float(C), k, start, float(uu[0]),
                 _is_euler(scheme), out)
    return out


def _check_params(a_: float, c_: float) -> None:
    if not (a_ > 0 and c_ > 0):
        raise HysteresisError(f"Coleman-Hodgdon needs A > 0 and C > 0, got A={a_}, C={c_}")


def _is_euler(scheme: str) -> bool:
    if scheme not in ("exact", "euler"):
        raise HysteresisError(f"unknown scheme {scheme!r}; use 'exact' or 'euler'")
    return scheme == "euler"


def _normaliser(x: FloatArray, name: str) -> tuple[float, float]:
    lo, hi = float(np.min(x)), float(np.max(x))
    half = 0.5 * (hi - lo)
    if not half > 0:
        raise HysteresisError(f"{name} is constant; cannot identify a hysteresis model from it")
    return 0.5 * (hi + lo), half


#: ``b_sign`` settings: ``auto`` chooses between the paper's bound and the free form.
B_SIGNS = ("auto", "negative", "free")


@dataclass(frozen=True)
class ColemanHodgdonState:
    """Memory of the Coleman-Hodgdon model: the last input ``u`` and output ``y`` (eq. 10's
    state). Frozen: a step returns a new state and never changes the one it was given."""

    u: float
    y: float


@register_family("coleman_hodgdon")
class ColemanHodgdonModel(StatefulModel):
    """Coleman-Hodgdon model of seed 000 (eq. 10-11) behind the common estimator face.

    Hyper-parameters:
        method: ``"ga"`` (paper: differential evolution on eq. 26, seeded, polished) or
            ``"varpro"`` (ours: exact linear stage for B, C, k and a 1-D search over A).
        b_sign: ``"auto"`` (default: the one of the two below that predicts a held-out part of
            the record better, ``b_sign_``), ``"negative"`` (paper: B < 0) or ``"free"``
            (B < C only).
        scheme: ``"exact"`` per-step solution or the paper's ``"euler"`` step of eq. 16.
        fit_max_samples: fit on a stride-decimated record of at most this many samples.
        popsize, maxiter, seed, polish: differential-evolution settings (``method="ga"``).
    """

    def __init__(
        self,
        *,
        method: str = "ga",
        b_sign: str = "auto",
        scheme: str = "exact",
        fit_max_samples: int = 1000,
        popsize: int = 15,
        maxiter: int = 100,
        seed: int = 0,
        polish: bool = True,
    ) -> None:
        self.method = method
        self.b_sign = b_sign
        self.scheme = scheme
        self.fit_max_samples = fit_max_samples
        self.popsize = popsize
        self.maxiter = maxiter
        self.seed = seed
        self.polish = polish

    # -- fitting ------------------------------------------------------------------------
    def fit(self, u: Any, y: Any, **fit_params: Any) -> ColemanHodgdonModel:
        """Identify A, B, C and the backlash origin from input u and output y."""
        if fit_params:
            raise HysteresisError(
                f"ColemanHodgdonModel.fit takes no extra arguments: {sorted(fit_params)}")
        recs = check_records(u, y, min_samples=10)
        if self.b_sign not in B_SIGNS:
            raise HysteresisError(f"b_sign must be one of {B_SIGNS}, got {self.b_sign!r}")
        b_sign = str(self.b_sign)
        if b_sign == "auto":
            params = self.get_params()
            b_sign, _ = choose_form(lambda form: type(self)(**{**params, "b_sign": form}),
                                    ("negative", "free"), recs)
        self.b_sign_ = b_sign
        return self._fit(recs)

    def refit_warm(self, u: Any, y: Any) -> ColemanHodgdonModel:
        """Fit again on a new output ``y`` from the current loop, the sign form kept: with
        ``varpro`` ``A`` is searched on a short grid about its value, with ``ga`` the local
        polish starts from the current parameters (no evolution). A backfitting loop refits
        one input many times against outputs that differ by a small term, and the loop moves
        little between its rounds."""
        self.check_fitted()
        recs = check_records(u, y, min_samples=10)
        return self._fit(recs, warm=(float(self.A_), float(self.B_), float(self.C_),
                                     float(self.origin_y_)))

    def _fit(self, recs: Records, *, warm: tuple[float, float, float, float] | None = None
             ) -> ColemanHodgdonModel:
        b_sign = str(self.b_sign_)
        euler = _is_euler(self.scheme)
        thin = recs.thin(decimation_indices(recs, int(self.fit_max_samples)))
        ud, yd = thin.u, thin.y
        pieces = thin.slices()
        uc, us = _normaliser(ud, "u")
        yc, ys = _normaliser(yd, "y")
        un = (ud - uc) / us
        yn = (yd - yc) / ys
        b_hi = -1e-9 if b_sign == "negative" else 20.0
        z_warm = None
        if warm is not None:  # the current parameters in the normalised units
            a_w, b_w, c_w, oy_w = warm
            z_warm = np.array([math.log10(max(a_w * us, 1e-12)), b_w * us / ys, c_w * us / ys,
                               (oy_w - yc) / ys])
        if self.method == "ga":
            with single_thread_blas():
                z = self._fit_ga(un, yn, euler, b_hi, pieces, warm=z_warm)
        elif self.method == "varpro":
            warm_la = None if z_warm is None else float(z_warm[0])
            with single_thread_blas():
                z = self._fit_varpro(un, yn, euler, b_hi, pieces, warm_la=warm_la)
        else:
            raise HysteresisError(
                f"unknown Coleman-Hodgdon method {self.method!r}; use 'ga' or 'varpro'"
            )
        a_n, b_n, c_n, k_n = 10.0 ** z[0], z[1], z[2], z[3]
        # Back to the original units (see module docstring for the algebra).
        self.A_ = float(a_n / us)
        self.B_ = float(b_n * ys / us)
        self.C_ = float(c_n * ys / us)
        k = float(ys * k_n + yc - self.C_ * uc)
        self.origin_u_ = float(uc)
        self.origin_y_ = float(k + self.C_ * uc)
        self.sse_ = records_sse(self, recs)
        self.n_samples_ = int(recs.u.size)
        return self

    def _fit_ga(self, un: FloatArray, yn: FloatArray, euler: bool, b_hi: float,
                pieces: list[slice], *, warm: FloatArray | None = None) -> FloatArray:
        def batch(pop: FloatArray) -> FloatArray:
            pop2 = np.ascontiguousarray(pop.reshape(4, -1), dtype=np.float64)
            out = np.zeros(pop2.shape[1])
            part = np.empty(pop2.shape[1])
            for sl in pieces:  # each record from its own start; MSE over all samples
                _ch_mse_batch(un[sl], yn[sl], pop2, euler, part)
                out += part * ((sl.stop - sl.start) / un.size)
            return out

        # Normalised units: slopes are O(1); log10 A in [-1.5, 2.5] spans loops that close
        # over 30 to 0.003 half-ranges of input.
        bounds = [(-1.5, 2.5), (-20.0, b_hi), (1e-6, 20.0), (-5.0, 5.0)]
        if warm is not None:  # the polish alone, from there
            lo, hi = np.array(bounds).T
            x = np.clip(warm, lo, hi)
            res_fun = float(batch(x.reshape(4, 1))[0])
        else:
            res = differential_evolution(
                batch, bounds, seed=int(self.seed), popsize=int(self.popsize),
                maxiter=int(self.maxiter), tol=1e-10, atol=0.0, polish=False,
                vectorized=True, updating="deferred", init="sobol",
            )
            x, res_fun = np.asarray(res.x, dtype=np.float64), float(res.fun)
        if self.polish or warm is not None:
            # scipy's own polish stops at its default relative ftol, which on an MSE near
            # zero leaves the 4th digit wrong; polish with tight tolerances instead.
            pol = minimize(lambda z: float(batch(z.reshape(4, 1))[0]), x, method="L-BFGS-B",
                           bounds=bounds, options={"ftol": 1e-15, "gtol": 1e-12,
                                                   "maxiter": 500})
            if float(pol.fun) <= res_fun:
                x = np.asarray(pol.x, dtype=np.float64)
        return x

    def _fit_varpro(self, un: FloatArray, yn: FloatArray, euler: bool, b_hi: float,
                    pieces: list[slice], *, warm_la: float | None = None) -> FloatArray:
        basis = np.empty((un.size, 3))
        lb = np.array([-20.0, 1e-6, -np.inf])
        ub = np.array([b_hi, np.inf, np.inf])

        def solve(la: float) -> tuple[float, FloatArray]:
            for sl in pieces:
                _ch_basis(un[sl], 10.0**la, euler, basis[sl])
            if not np.all(np.isfinite(basis)):
                return math.inf, np.zeros(3)
            res = lsq_linear(basis, yn, bounds=(lb, ub), method="bvls")
            # an active bound can come back a rounding error outside it: clip to the bounds
            x = np.clip(np.asarray(res.x, dtype=np.float64), lb, ub)
            r = basis @ x - yn
            return float(r @ r) / un.size, x

        grid = np.linspace(-1.5, 2.5, 33)
        if warm_la is not None:  # the full grid's spacing, about the last value
            grid = np.unique(np.clip(warm_la + 0.125 * np.arange(-2, 3), -1.5, 2.5))
        vals = [solve(float(g))[0] for g in grid]
        i = int(np.argmin(vals))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        opt = minimize_scalar(lambda la: solve(float(la))[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        la = float(opt.x) if float(opt.fun) <= vals[i] else float(grid[i])
        coef = solve(la)[1]
        return np.array([la, coef[0], coef[1], coef[2]])

    @classmethod
    def from_params(cls, A: float, B: float, C: float, *,
                    origin: tuple[float, float] = (0.0, 0.0),
                    scheme: str = "exact") -> ColemanHodgdonModel:
        """A model with known parameters (the paper's, a plant's), fitted to nothing."""
        _check_params(A, C)
        _is_euler(scheme)
        model = cls(scheme=scheme)
        model.A_, model.B_, model.C_ = float(A), float(B), float(C)
        model.origin_u_, model.origin_y_ = float(origin[0]), float(origin[1])
        model.sse_, model.n_samples_ = 0.0, 0
        return model

    # -- parameters and state -------------------------------------------------------------
    @property
    def params_(self) -> FloatArray:
        """Identified ``[A, B, C]`` (paper order)."""
        self.check_fitted()
        return np.array([self.A_, self.B_, self.C_])

    @property
    def k_(self) -> float:
        """``O_y - C O_u``: the only combination of the origin that enters eq. 10."""
        return float(self.origin_y_ - self.C_ * self.origin_u_)

    def _p(self) -> tuple[float, float, float, float]:
        self.check_fitted()
        return float(self.A_), float(self.B_), float(self.C_), self.k_

    def rate(self, y: float, u: float, v: float) -> float:
        """Eq. 10's right-hand side ``dy/dt`` at output ``y``, input ``u``, input rate ``v``."""
        a_, b_, c_, k = self._p()
        return a_ * abs(v) * (c_ * u + k - y) + b_ * v

    def initial_state(self, u0: float = 0.0) -> ColemanHodgdonState:
        """Rest state on the loop's centre line at input u0."""
        a_, b_, c_, k = self._p()
        return ColemanHodgdonState(float(u0), c_ * float(u0) + k)

    def _state(self, state: Any, u0: float) -> tuple[float, float]:
        """(y, u) of ``state``: a :class:`ColemanHodgdonState`, or a mapping with keys ``u``
        and ``y`` (a state written by hand); None is the rest state at ``u0``."""
        if state is None:
            st = self.initial_state(u0)
            return st.y, st.u
        state = state_from(state, ColemanHodgdonState, "Coleman-Hodgdon")
        return state.y, state.u

    # -- forward and inverse ----------------------------------------------------------------
    def simulate(self, u: Any, state: Any = None) -> tuple[FloatArray, ColemanHodgdonState]:
        """``predict`` that also returns the final state."""
        uu = as_1d(u, "u")
        a_, b_, c_, k = self._p()
        y0, u0 = self._state(state, float(uu[0]))
        out = np.empty_like(uu)
        y = _ch_simulate(uu, a_, b_, c_, k, y0, u0, _is_euler(self.scheme), out)
        return out, ColemanHodgdonState(float(uu[-1]), float(y))

    def predict(self, u: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """Output along u from the centre line at u[0] (or from ``state``); with
        ``return_state`` also the end state (the same face as every family)."""
        y, end = self.simulate(u, state=state)
        return (y, end) if return_state else y

    def step(self, u_k: float, state: Any = None) -> tuple[float, ColemanHodgdonState]:
        """One sample: (y, new state)."""
        a_, b_, c_, k = self._p()
        u = float(u_k)
        y0, u0 = self._state(state, u)
        y = float(_ch_advance(y0, u0, u, a_, b_, c_, k, _is_euler(self.scheme)))
        return y, ColemanHodgdonState(u, y)

    def simulate_inverse(
        self, y_desired: Any, *, state: Any = None
    ) -> tuple[FloatArray, ColemanHodgdonState]:
        """``invert`` that also returns the final state."""
        yd = as_1d(y_desired, "y_desired")
        a_, b_, c_, k = self._p()
        if state is None:
            u0 = (float(yd[0]) - k) / c_  # the centre-line input whose output is y_d[0]
            y0 = float(yd[0])
        else:
            y0, u0 = self._state(state, 0.0)
        out = np.empty_like(yd)
        y, up = _ch_invert(yd, a_, b_, c_, k, y0, u0, out)
        return out, ColemanHodgdonState(float(up), float(y))

    def invert(self, y_desired: Any, *, state: Any = None) -> FloatArray:
        """Exact per-step inverse (of the exact scheme): the input sequence whose model output
        is ``y_desired``; every target is reachable since C > 0."""
        return self.simulate_inverse(y_desired, state=state)[0]

    def invert_step(self, y_desired: float, state: Any = None
                    ) -> tuple[float, ColemanHodgdonState]:
        """One sample of the inverse: (u, new state)."""
        u, st = self.simulate_inverse(np.array([float(y_desired)]), state=state)
        return float(u[0]), st

    # -- loop geometry (derived from eq. 10, used by tests and docs) ------------------------
    def loop_widths(self) -> tuple[float, float]:
        """(vertical, horizontal) distance between the two asymptotic branches."""
        a_, b_, c_, _ = self._p()
        return 2.0 * (c_ - b_) / a_, 2.0 * (c_ - b_) / (a_ * c_)
