"""Bouc-Wen numerics (seed 002 eq. 2-5): the numba kernels, simulation and the paper's MSE.

Shared by the estimator (:mod:`hysteresis.bouc_wen`) and the paper's raw optimisers
(:mod:`hysteresis._bw_raw`), so neither imports the other's module.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from hysteresis.base import FloatArray, HysteresisError, as_1d

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
def _bracket(h: float, up: float, d: float, g0: float, step: float, target: float,
             a_: float, b_: float, c_: float, n: float, alpha: float, beta: float,
             offset: float, max_sub: int, scale: float, lip_u: float
             ) -> tuple[bool, float, float, float, float, float]:
    """Growing steps ``x`` along ``d`` until the residual changes sign: (found, lo, g(lo),
    hi, g(hi), the step of smallest residual seen)."""
    lo = 0.0
    glo = g0
    best_x = 0.0
    best_g = abs(g0)
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
            return True, lo, glo, x, gx, best_x
        lo = x
        glo = gx
        x = x * 1.6 + 1e-12 * scale
        if x > 1e3 * scale:
            break
    return False, lo, glo, hi, ghi, best_x


@numba.njit(cache=True)
def _false_position(h: float, up: float, d: float, lo: float, glo: float, hi: float,
                    ghi: float, target: float, a_: float, b_: float, c_: float, n: float,
                    alpha: float, beta: float, offset: float, max_sub: int, scale: float,
                    lip_u: float) -> float:
    """Illinois false position inside a bracket ``[lo, hi]``: the end of smaller residual."""
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
    return hi if abs(ghi) < abs(glo) else lo


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
        found, lo, glo, hi, ghi, best_x = _bracket(
            h, up, d, g0, step, target, a_, b_, c_, n, alpha, beta, offset, max_sub, scale, lip_u)
        if found:
            x = _false_position(h, up, d, lo, glo, hi, ghi, target, a_, b_, c_, n, alpha, beta,
                                offset, max_sub, scale, lip_u)
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
