"""Bouc-Wen hysteresis (seed 002, eq. 2-5) with a fast, reliable identification and two inverses.

The paper's model (exact form, eq. 2-3)::

    y = alpha * u + beta * h                                   (2)
    dh/dt = A du/dt - B |du/dt| |h|^(n-1) h - C du/dt |h|^n    (3)

Eq. 3 is rate-independent: dividing by du/dt gives ``dh/du = A - (B d sgn(h) + C) |h|^n`` with
``d = sgn(du)``, so we integrate in the *input* (RK4 with sub-steps sized from the local Lipschitz
constant, hence stable at any sample rate and for any input speed). An optional ``offset`` is
added to eq. 2 (``fit_offset=True``, the default) because rig records need not pass through the
origin; ``fit_offset=False`` is the paper's exact six-parameter form.

Identification ("varpro", ours, the default): the six parameters are redundant (h can be
rescaled: ``(A, B, C, beta) -> (sA, B s^(1-n), C s^(1-n), beta/s)`` leaves y unchanged), which is
what makes the paper's raw BFGS fragile. We fix the scale so the ultimate |h| is 1 and search only
the three shape parameters (log saturation width, unloading ratio ``r = (B-C)/(B+C)``, ``n``) by
bounded L-BFGS-B with exact gradients (forward sensitivities) from a small grid of starts; alpha,
beta and the offset are solved exactly by linear least squares for every shape (variable
projection). Data are normalised internally, so mm, degrees or any scale fit the same way.
The paper's raw-parameter optimisers (BFGS on eq. 5, GA, PSO, ...) live in
:mod:`hysteresis.optimisers` and are reachable through ``method``.

Inverses: ``"feedforward"`` is eq. 4 (``u_c = (y_d - beta h)/alpha`` with h driven by y_d);
``"exact"`` solves ``alpha u + beta h(u) + offset = y_d`` per step for u with the state carried.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize

from hysteresis._blas import single_thread_blas
from hysteresis.base import (
    FloatArray,
    HysteresisError,
    HysteresisModel,
    as_1d,
    check_pair,
    register_family,
)

__all__ = ["BoucWenModel", "bw_simulate", "canonical_params"]

# RK4 sub-step size in units of 1/L (L = local Lipschitz constant of dh/du); 0.5 keeps RK4 well
# inside its stability region and its error far below measurement noise.
_STEP_L = 0.5
_H_LIMIT = 1e8  # |h| above this means the parameters make eq. 3 blow up
PAPER_PENALTY = 999999.0  # MSE returned for a blown-up simulation (as the authors' code does)


# ---------------------------------------------------------------------------------------------
# numba kernels (paper form, original units)
# ---------------------------------------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def _rate(h: float, d: float, a_: float, b_: float, c_: float, n: float) -> float:
    """dh/du of eq. 3 for input direction d (+1/-1); |h|^(n-1) h written as sgn(h)|h|^n."""
    ah = abs(h)
    if ah == 0.0:
        return a_
    sg = 1.0 if h > 0.0 else -1.0
    an: float = ah**n
    return a_ - (b_ * d * sg + c_) * an


@numba.njit(cache=True)
def _lip_ultimate(a_: float, b_: float, c_: float, n: float) -> float:
    """Lipschitz constant of dh/du at the ultimate |h| = (A/(B+C))^(1/n) (0 if unbounded)."""
    g = b_ + c_
    if g > 0.0 and a_ > 0.0 and n > 0.0:
        hu: float = (a_ / g) ** (1.0 / n)
        hun: float = hu ** (n - 1.0)
        return abs(n) * (abs(b_) + abs(c_)) * hun
    return 0.0


@numba.njit(cache=True)
def _advance(
    h: float, du: float, a_: float, b_: float, c_: float, n: float, max_sub: int, lip_u: float
) -> float:
    """Integrate eq. 3 over an input increment ``du`` from state h (RK4, adaptive sub-steps).

    The sub-step count keeps |step| * L below 0.5, with L the larger of the Lipschitz constants
    at the current h and at the ultimate value ``lip_u`` (h moves toward it), capped at max_sub.
    """
    if du == 0.0:
        return h
    d = 1.0 if du > 0.0 else -1.0
    nsub = 1
    if max_sub > 1:
        ah = abs(h)
        lip = lip_u
        if ah > 0.0:
            lip = max(lip, abs(n) * (abs(b_) + abs(c_)) * ah**n / ah)
        nsub = 1 + int(abs(du) * lip / _STEP_L)
        if nsub > max_sub:
            nsub = max_sub
    dx = du / nsub
    for _ in range(nsub):
        k1 = _rate(h, d, a_, b_, c_, n)
        k2 = _rate(h + 0.5 * dx * k1, d, a_, b_, c_, n)
        k3 = _rate(h + 0.5 * dx * k2, d, a_, b_, c_, n)
        k4 = _rate(h + dx * k3, d, a_, b_, c_, n)
        h = h + dx * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        if not (abs(h) < _H_LIMIT):  # also catches NaN
            return math.nan
    return h


@numba.njit(cache=True)
def _simulate(
    u: FloatArray,
    a_: float, b_: float, c_: float, n: float, alpha: float, beta: float, offset: float,
    h0: float, u0: float, max_sub: int, out: FloatArray,
) -> float:
    """Fill ``out`` with eq. 2 along u from state (h0, u0); return the final h (NaN: blown up)."""
    h = h0
    up = u0
    lip_u = _lip_ultimate(a_, b_, c_, n)
    for k in range(u.size):
        h = _advance(h, u[k] - up, a_, b_, c_, n, max_sub, lip_u)
        if math.isnan(h):
            for j in range(k, u.size):
                out[j] = math.nan
            return math.nan
        up = u[k]
        out[k] = alpha * up + beta * h + offset
    return h


@numba.njit(cache=True)
def _mse_paper(
    u: FloatArray, y: FloatArray,
    a_: float, b_: float, c_: float, n: float, alpha: float, beta: float, max_sub: int,
) -> float:
    """Eq. 5 (MSE) of the paper's six-parameter model from h = 0; penalty if it blows up."""
    h = 0.0
    up = u[0]
    acc = 0.0
    lip_u = _lip_ultimate(a_, b_, c_, n)
    for k in range(u.size):
        h = _advance(h, u[k] - up, a_, b_, c_, n, max_sub, lip_u)
        if math.isnan(h):
            return PAPER_PENALTY
        up = u[k]
        e = y[k] - (alpha * up + beta * h)
        acc += e * e
    mse = acc / u.size
    if not (mse < PAPER_PENALTY):
        return PAPER_PENALTY
    return mse


# ---------------------------------------------------------------------------------------------
# numba kernel: canonical normalised form with forward sensitivities (for our identification)
# ---------------------------------------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def _crate(
    h: float, d: float, w: float, r: float, n: float, s0: float, s1: float, s2: float
) -> tuple[float, float, float, float]:
    """dh/du and d(sensitivities)/du in the canonical form ``dh/du = 1 - m (|h|/w)^n``.

    m = 1 when |h| grows (loading, d*sgn(h) > 0) and m = -r when it shrinks (unloading).
    Sensitivities s = dh/d(log w, r, n).
    """
    ah = abs(h)
    if ah == 0.0:
        return 1.0, 0.0, 0.0, 0.0
    sg = 1.0 if h > 0.0 else -1.0
    loading = d * sg > 0.0
    m = 1.0 if loading else -r
    a = ah / w
    an = a**n
    f = 1.0 - m * an
    dfdh = -m * n * an / ah * sg  # = -m n a^(n-1) sgn(h) / w
    df_lw = n * m * an
    df_r = 0.0 if loading else an
    df_n = -m * an * math.log(a)
    return f, dfdh * s0 + df_lw, dfdh * s1 + df_r, dfdh * s2 + df_n


@numba.njit(cache=True)
def _canon_sens(
    u: FloatArray, lw: float, r: float, n: float, max_sub: int, h_out: FloatArray, s_out: FloatArray
) -> bool:
    """Simulate the canonical state h and its sensitivities along u (from h = 0)."""
    w = math.exp(lw)
    h = 0.0
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    up = u[0]
    for k in range(u.size):
        du = u[k] - up
        up = u[k]
        if du != 0.0:
            d = 1.0 if du > 0.0 else -1.0
            a = abs(h) / w
            # |d(dh/du)/dh| = |m| n a^(n-1) / w: loading drives a toward 1 (bound n/w);
            # unloading shrinks a, so the current a bounds it until h crosses zero.
            an1 = a ** (n - 1.0) if a > 0.0 else 0.0
            lip = n / w * max(1.0, an1, abs(r) * an1)
            nsub = 1 + int(abs(du) * lip / _STEP_L)
            if nsub > max_sub:
                nsub = max_sub
            dx = du / nsub
            for _ in range(nsub):
                f1, a1, b1, c1 = _crate(h, d, w, r, n, s0, s1, s2)
                f2, a2, b2, c2 = _crate(
                    h + 0.5 * dx * f1, d, w, r, n,
                    s0 + 0.5 * dx * a1, s1 + 0.5 * dx * b1, s2 + 0.5 * dx * c1,
                )
                f3, a3, b3, c3 = _crate(
                    h + 0.5 * dx * f2, d, w, r, n,
                    s0 + 0.5 * dx * a2, s1 + 0.5 * dx * b2, s2 + 0.5 * dx * c2,
                )
                f4, a4, b4, c4 = _crate(
                    h + dx * f3, d, w, r, n, s0 + dx * a3, s1 + dx * b3, s2 + dx * c3
                )
                h += dx * (f1 + 2.0 * f2 + 2.0 * f3 + f4) / 6.0
                s0 += dx * (a1 + 2.0 * a2 + 2.0 * a3 + a4) / 6.0
                s1 += dx * (b1 + 2.0 * b2 + 2.0 * b3 + b4) / 6.0
                s2 += dx * (c1 + 2.0 * c2 + 2.0 * c3 + c4) / 6.0
            if not (abs(h) < _H_LIMIT and abs(s0) + abs(s1) + abs(s2) < 1e12):
                return False
        h_out[k] = h
        s_out[k, 0] = s0
        s_out[k, 1] = s1
        s_out[k, 2] = s2
    return True


# ---------------------------------------------------------------------------------------------
# numba kernels: inverses
# ---------------------------------------------------------------------------------------------
@numba.njit(cache=True)
def _invert_exact(
    yd: FloatArray,
    a_: float, b_: float, c_: float, n: float, alpha: float, beta: float, offset: float,
    h0: float, u0: float, max_sub: int, scale: float, out: FloatArray,
) -> tuple[float, float]:
    """Per-step exact inverse: for each y_d find the u nearest the previous input with
    ``alpha u + beta h(u) + offset = y_d`` (h integrated from the carried state).

    Scans outward in the direction that raises/lowers y in the long run (sign of alpha) with
    growing steps until the residual changes sign, then bisects (Illinois false position).
    If no sign change is found within a wide search, the input with the smallest residual is
    used (the desired output is out of the model's reach).
    """
    h = h0
    up = u0
    lip_u = _lip_ultimate(a_, b_, c_, n)
    dirsign = 1.0 if alpha >= 0.0 else -1.0
    for k in range(yd.size):
        target = yd[k]
        g0 = alpha * up + beta * h + offset - target
        if g0 == 0.0:
            out[k] = up
            continue
        d = -dirsign if g0 > 0.0 else dirsign  # move u so that y moves toward the target
        step = max(abs(g0 / alpha) if alpha != 0.0 else scale, 1e-9 * scale)
        lo = 0.0
        glo = g0
        best_x = 0.0
        best_g = abs(g0)
        found = False
        hi = 0.0
        ghi = g0
        x = min(step * 0.5, scale)
        for _ in range(80):
            hx = _advance(h, d * x, a_, b_, c_, n, max_sub, lip_u)
            if math.isnan(hx):
                break
            gx = alpha * (up + d * x) + beta * hx + offset - target
            if abs(gx) < best_g:
                best_g = abs(gx)
                best_x = x
            if gx * g0 <= 0.0:
                hi = x
                ghi = gx
                found = True
                break
            lo = x
            glo = gx
            x = x * 1.6 + 1e-12 * scale
            if x > 1e3 * scale:
                break
        if found:
            side = 0
            for _ in range(100):
                xm = (lo * ghi - hi * glo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
                if not (lo < xm < hi):
                    xm = 0.5 * (lo + hi)
                hm = _advance(h, d * xm, a_, b_, c_, n, max_sub, lip_u)
                gm = alpha * (up + d * xm) + beta * hm + offset - target
                if gm * glo > 0.0:
                    lo = xm
                    glo = gm
                    if side == -1:
                        ghi *= 0.5
                    side = -1
                else:
                    hi = xm
                    ghi = gm
                    if side == 1:
                        glo *= 0.5
                    side = 1
                if hi - lo < 1e-13 * scale or gm == 0.0:
                    break
            x = hi if abs(ghi) < abs(glo) else lo
        else:
            x = best_x
        unew = up + d * x
        h = _advance(h, unew - up, a_, b_, c_, n, max_sub, lip_u)
        up = unew
        out[k] = up
    return h, up


@numba.njit(cache=True)
def _invert_feedforward(
    yd: FloatArray,
    a_: float, b_: float, c_: float, n: float, alpha: float, beta: float, offset: float,
    h0: float, u0: float, max_sub: int, out: FloatArray,
) -> tuple[float, float]:
    """Eq. 4: ``u_c = (y_d - beta h - offset)/alpha`` with h driven by the desired signal."""
    h = h0
    up = u0
    lip_u = _lip_ultimate(a_, b_, c_, n)
    for k in range(yd.size):
        h = _advance(h, yd[k] - up, a_, b_, c_, n, max_sub, lip_u)
        up = yd[k]
        out[k] = (yd[k] - beta * h - offset) / alpha
    return h, up


# ---------------------------------------------------------------------------------------------
# public helpers
# ---------------------------------------------------------------------------------------------
def bw_simulate(
    u: Any, params: Any, *, offset: float = 0.0, h0: float = 0.0, u0: float | None = None,
    max_substeps: int = 200,
) -> FloatArray:
    """Simulate eq. 2-3 for ``params = [A, B, C, n, alpha, beta]`` (paper form) from state h0."""
    uu = as_1d(u, "u")
    p = np.asarray(params, dtype=np.float64)
    if p.shape != (6,):
        raise HysteresisError(f"params must be [A, B, C, n, alpha, beta], got shape {p.shape}")
    out = np.empty_like(uu)
    a_, b_, c_, n, alpha, beta = (float(v) for v in p)
    _simulate(uu, a_, b_, c_, n, alpha, beta, float(offset), float(h0),
              float(uu[0] if u0 is None else u0), int(max_substeps), out)
    return out


def paper_mse(u: FloatArray, y: FloatArray, params: Any, *, max_substeps: int = 200) -> float:
    """Eq. 5 for the paper's six parameters (999999 when the simulation blows up)."""
    p = np.asarray(params, dtype=np.float64)
    if not np.all(np.isfinite(p)):
        return PAPER_PENALTY
    a_, b_, c_, n, alpha, beta = (float(v) for v in p)
    return float(_mse_paper(u, y, a_, b_, c_, n, alpha, beta, int(max_substeps)))


def canonical_params(params: Any) -> FloatArray:
    """Rescale h so that A = 1: ``[1, B A^(n-1), C A^(n-1), n, alpha, beta A]`` (same output).

    Two parameter vectors describe the same model iff their canonical forms agree, which is
    what a parameter-recovery check must compare (eq. 2-3 are invariant under h -> s h).
    """
    a_, b_, c_, n, alpha, beta = (float(v) for v in np.asarray(params, dtype=np.float64))
    if a_ <= 0:
        raise HysteresisError(f"canonical form needs A > 0, got A = {a_}")
    s = a_ ** (n - 1.0)
    return np.array([1.0, b_ * s, c_ * s, n, alpha, beta * a_])


def decimation_index(u: FloatArray, max_samples: int) -> npt.NDArray[np.intp]:
    """Indices of a rate-independent decimation: every k-th sample plus the input's turning
    points (so the decimated record sees the same reversals), at most about ``max_samples``
    (turning points are dropped first if a noisy input has too many of them)."""
    n = u.size
    stride = max(1, math.ceil(n / max(10, int(max_samples))))
    idx = np.arange(0, n, stride)
    if stride == 1:
        return idx
    du = np.diff(u)
    tol = 1e-6 * float(np.ptp(u))
    nz = np.flatnonzero(np.abs(du) > tol)
    if nz.size > 1:
        sgn = np.sign(du[nz])
        turns = nz[1:][sgn[1:] != sgn[:-1]]  # first sample of each new direction
        if turns.size <= max_samples // 2:
            idx = np.union1d(idx, np.concatenate([turns, np.array([n - 1])]))
    return idx


def _normaliser(x: FloatArray, name: str) -> tuple[float, float]:
    lo, hi = float(np.min(x)), float(np.max(x))
    half = 0.5 * (hi - lo)
    if not half > 0:
        raise HysteresisError(f"{name} is constant; cannot identify a hysteresis model from it")
    return 0.5 * (hi + lo), half


# ---------------------------------------------------------------------------------------------
# the estimator
# ---------------------------------------------------------------------------------------------
_RAW_METHODS = ("bfgs", "nelder-mead", "powell", "cg", "tnc", "cobyla", "slsqp", "ga", "pso")


@register_family("bouc_wen")
class BoucWenModel(HysteresisModel):
    """Bouc-Wen model of seed 002 (eq. 2-4) behind the common estimator face.

    Hyper-parameters:
        method: ``"varpro"`` (ours: canonical shape search + exact linear stage) or one of the
            paper's raw optimisers ``"bfgs"`` (the paper's choice), ``"nelder-mead"``,
            ``"powell"``, ``"cg"``, ``"tnc"``, ``"cobyla"``, ``"slsqp"``, ``"ga"``, ``"pso"``.
        fit_offset: add a constant to eq. 2 (False = the paper's exact form).
        fit_max_samples: fit on a stride-decimated record of at most this many samples (the
            model is rate-independent, so decimation only drops intermediate points).
        n_starts: local L-BFGS-B refinements started from the best grid points (varpro).
        n_max: upper bound of the exponent n (varpro).
        inverse: default inverse, ``"exact"`` (per-step root solve) or ``"feedforward"`` (eq. 4).
        max_substeps: cap on RK4 sub-steps per sample.
        seed: seed of the stochastic raw optimisers (GA, PSO).
    """

    def __init__(
        self,
        *,
        method: str = "varpro",
        fit_offset: bool = True,
        fit_max_samples: int = 1000,
        n_starts: int = 2,
        n_max: float = 12.0,
        inverse: str = "exact",
        max_substeps: int = 200,
        seed: int = 0,
    ) -> None:
        self.method = method
        self.fit_offset = fit_offset
        self.fit_max_samples = fit_max_samples
        self.n_starts = n_starts
        self.n_max = n_max
        self.inverse = inverse
        self.max_substeps = max_substeps
        self.seed = seed

    # -- fitting ------------------------------------------------------------------------
    def fit(self, u: Any, y: Any, **fit_params: Any) -> BoucWenModel:
        """Identify A, B, C, n, alpha, beta (and offset) from input u and output y.

        ``fit_params`` may carry ``x0`` (initial [A, B, C, n, alpha, beta]) for the raw methods.
        """
        unknown = sorted(set(fit_params) - {"x0"})
        if unknown:
            raise HysteresisError(f"BoucWenModel.fit takes only x0, got {unknown}")
        uu, yy = check_pair(u, y)
        if uu.size < 10:
            raise HysteresisError(f"need at least 10 samples to fit Bouc-Wen, got {uu.size}")
        if self.method not in ("varpro", *_RAW_METHODS):
            raise HysteresisError(
                f"unknown Bouc-Wen method {self.method!r}; use 'varpro' or one of {_RAW_METHODS}"
            )
        keep = decimation_index(uu, int(self.fit_max_samples))
        ud, yd = uu[keep], yy[keep]
        if self.method == "varpro":
            with single_thread_blas():
                params, offset = self._fit_varpro(ud, yd)
        else:
            from hysteresis.optimisers import fit_raw

            if self.fit_offset:
                raise HysteresisError(
                    f"method {self.method!r} fits the paper's exact form; set fit_offset=False"
                )
            res = fit_raw(ud, yd, method=self.method, x0=fit_params.get("x0"),
                          seed=self.seed, max_substeps=self.max_substeps)
            params, offset = res.x, 0.0
        a_, b_, c_, n, alpha, beta = (float(v) for v in params)
        self.A_, self.B_, self.C_, self.n_ = a_, b_, c_, n
        self.alpha_, self.beta_, self.offset_ = alpha, beta, float(offset)
        pred = self.predict(uu)
        finite = bool(np.all(np.isfinite(pred)))
        self.train_mse_ = float(np.mean((yy - pred) ** 2)) if finite else math.inf
        return self

    def _fit_varpro(self, u: FloatArray, y: FloatArray) -> tuple[FloatArray, float]:
        uc, us = _normaliser(u, "u")
        yc, ys = _normaliser(y, "y")
        if not self.fit_offset:
            # The paper's exact form has no constant term: scale only, never shift.
            uc, us = 0.0, float(np.max(np.abs(u)))
            yc, ys = 0.0, max(float(np.max(np.abs(y))), 1e-300)
        un = (u - uc) / us
        yn = (y - yc) / ys
        max_sub = int(self.max_substeps)
        h = np.empty_like(un)
        s = np.empty((un.size, 3))
        cols = [un, h] + ([np.ones_like(un)] if self.fit_offset else [])
        phi = np.empty((un.size, len(cols)))
        phi[:, 0] = un
        if self.fit_offset:
            phi[:, 2] = 1.0

        def objective(z: FloatArray) -> tuple[float, FloatArray]:
            ok = _canon_sens(un, float(z[0]), float(z[1]), float(z[2]), max_sub, h, s)
            if not ok:
                return 1e3, np.zeros(3)
            phi[:, 1] = h
            coef, *_ = np.linalg.lstsq(phi, yn, rcond=None)
            e = yn - phi @ coef
            mse = float(e @ e) / un.size
            grad = (-2.0 / un.size) * coef[1] * (e @ s)
            return mse, grad

        bounds = [(math.log(1e-3), math.log(4.0)), (-1.0, 30.0), (1.0, float(self.n_max))]
        grid = [
            np.array([lw, r, n])
            for lw in (math.log(0.03), math.log(0.15), math.log(0.6))
            for r in (0.0, 4.0)
            for n in (1.5, 4.0)
        ]
        scored = sorted(grid, key=lambda z: objective(z)[0])
        best_z, best_f = scored[0], objective(scored[0])[0]
        for z0 in scored[: max(1, int(self.n_starts))]:
            res = minimize(objective, z0, jac=True, method="L-BFGS-B", bounds=bounds,
                           options={"maxiter": 200, "ftol": 1e-12, "gtol": 1e-9})
            if float(res.fun) < best_f:
                best_z, best_f = np.asarray(res.x, dtype=np.float64), float(res.fun)
        # Final linear stage at the best shape.
        objective(best_z)
        coef, *_ = np.linalg.lstsq(phi, yn, rcond=None)
        lw, r, n = (float(v) for v in best_z)
        w = math.exp(lw)
        a_ = 1.0 / (w * us)  # ultimate |h| = 1 in original units
        b_ = a_ * (1.0 + r) / 2.0
        c_ = a_ * (1.0 - r) / 2.0
        alpha = ys * float(coef[0]) / us
        beta = ys * float(coef[1]) * w
        c0 = float(coef[2]) if self.fit_offset else 0.0
        offset = yc + ys * c0 - alpha * uc
        return np.array([a_, b_, c_, n, alpha, beta]), offset

    # -- parameters ---------------------------------------------------------------------
    @property
    def params_(self) -> FloatArray:
        """Identified ``[A, B, C, n, alpha, beta]`` (paper order)."""
        self.check_fitted()
        return np.array([self.A_, self.B_, self.C_, self.n_, self.alpha_, self.beta_])

    def _p(self) -> tuple[float, float, float, float, float, float, float]:
        self.check_fitted()
        return (float(self.A_), float(self.B_), float(self.C_), float(self.n_),
                float(self.alpha_), float(self.beta_), float(self.offset_))

    # -- state and step-wise API ----------------------------------------------------------
    def initial_state(self, u0: float = 0.0) -> dict[str, float]:
        """Rest state (h = 0) at input u0. States are ``{"u": last input, "h": eq. 3 state}``."""
        return {"u": float(u0), "h": 0.0}

    def _state(self, state: Any, u0: float) -> tuple[float, float]:
        if state is None:
            return 0.0, u0
        try:
            return float(state["h"]), float(state["u"])
        except (KeyError, TypeError) as exc:
            raise HysteresisError(
                f"Bouc-Wen state must be a mapping with keys 'u' and 'h', got {state!r}"
            ) from exc

    def simulate(self, u: Any, *, state: Any = None) -> tuple[FloatArray, dict[str, float]]:
        """``predict`` that also returns the final state (to continue a simulation)."""
        uu = as_1d(u, "u")
        a_, b_, c_, n, alpha, beta, off = self._p()
        h0, u0 = self._state(state, float(uu[0]))
        out = np.empty_like(uu)
        h = _simulate(uu, a_, b_, c_, n, alpha, beta, off, h0, u0, int(self.max_substeps), out)
        return out, {"u": float(uu[-1]), "h": float(h)}

    def predict(self, u: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """Output of eq. 2 along u, from rest (h = 0 at u[0]) or from ``state``; with
        ``return_state`` also the end state (the same face as every family)."""
        y, end = self.simulate(u, state=state)
        return (y, end) if return_state else y

    def step(self, u: float, state: Any = None) -> tuple[float, dict[str, float]]:
        """One sample: returns (y, new state). ``state=None`` starts at rest at this input."""
        a_, b_, c_, n, alpha, beta, off = self._p()
        h0, u0 = self._state(state, float(u))
        h = float(_advance(h0, float(u) - u0, a_, b_, c_, n, int(self.max_substeps),
                           _lip_ultimate(a_, b_, c_, n)))
        return alpha * float(u) + beta * h + off, {"u": float(u), "h": h}

    def invert(
        self, y_desired: Any, *, state: Any = None, method: str | None = None
    ) -> FloatArray:
        """Input sequence that makes the model produce ``y_desired``.

        ``method``: ``"exact"`` (per-step root solve, state carried) or ``"feedforward"`` (eq. 4);
        defaults to the ``inverse`` hyper-parameter. The rest state starts at the input whose
        rest output is ``y_desired[0]``.
        """
        return self.simulate_inverse(y_desired, state=state, method=method)[0]

    def simulate_inverse(
        self, y_desired: Any, *, state: Any = None, method: str | None = None
    ) -> tuple[FloatArray, dict[str, float]]:
        """``invert`` that also returns the final state."""
        yd = as_1d(y_desired, "y_desired")
        a_, b_, c_, n, alpha, beta, off = self._p()
        how = self.inverse if method is None else method
        if alpha == 0.0:
            raise HysteresisError("alpha_ = 0: the Bouc-Wen model has no inverse")
        out = np.empty_like(yd)
        if how == "exact":
            h0, u0 = self._state(state, (float(yd[0]) - off) / alpha)
            scale = max(abs(1.0 / a_), float(np.ptp(yd)) / abs(alpha), 1e-9)
            h, up = _invert_exact(yd, a_, b_, c_, n, alpha, beta, off, h0, u0,
                                  int(self.max_substeps), scale, out)
        elif how == "feedforward":
            h0, u0 = self._state(state, float(yd[0]))
            h, up = _invert_feedforward(yd, a_, b_, c_, n, alpha, beta, off, h0, u0,
                                        int(self.max_substeps), out)
        else:
            raise HysteresisError(f"unknown inverse {how!r}; use 'exact' or 'feedforward'")
        return out, {"u": float(up), "h": float(h)}

    def invert_step(
        self, y_desired: float, state: Any = None, *, method: str | None = None
    ) -> tuple[float, dict[str, float]]:
        """One sample of the inverse: returns (u, new state) with the state of the *model*."""
        u, st = self.simulate_inverse(np.array([float(y_desired)]), state=state, method=method)
        return float(u[0]), st
