"""Numba kernels shared by the Gamma (play-operator) and Preisach (relay-plane) families.

Play operator (seed 001 eq. 4.8, the discrete form the thesis actually uses)::

    w(k) = v(k)          if w(k-1) > v(k)
         = w(k-1)        if w(k-1) <= v(k) <= w(k-1) + p
         = v(k) - p      if v(k) > w(k-1) + p

i.e. ``w(k) = min(v(k), max(v(k) - p, w(k-1)))``: the output lags a rising input by ``p`` and
follows a falling one at once (eq. 4.7 writes the mirror image, ``max(v, min(v + p, w))``;
Fig. 4.22 and eq. 4.8 agree with the form used here).

Relay hysteron (seed 001 eq. 4.1-4.2) on a grid of the Preisach plane, optionally with a
linear switching ramp of width ``h`` (one grid step; ``h = 0`` is the ideal relay)::

    up(v) = clip(2 (v - alpha) / h, -1, 1)      (ideal: +1 if v >= alpha else -1)
    dn(v) = clip(2 (v - beta) / h, -1, 1)       (ideal: -1 if v <= beta else +1)
    r(k)  = min(dn(v(k)), max(up(v(k)), r(k-1)))

With ``alpha >= beta`` we have ``up <= dn`` so ``r`` is clipped into ``[up, dn]``; the ramp
(a Krasnosel'skii-Pokrovskii kernel) keeps the model output continuous in the input, which is
what makes an exact per-step inverse possible, and tends to the ideal relay as ``h -> 0``.
Both kernels are monotone in the state and path-independent on monotone input segments, so
both families are rate independent and wipe out minor loops.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hysteresis.base import FloatArray

# --------------------------------------------------------------------------------------
# play operators / Gamma
# --------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def play_matrix(u: FloatArray, p: FloatArray, w0: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Outputs of every play operator (columns) over ``u`` from state ``w0``; and final state."""
    n_s, n_p = u.size, p.size
    out = np.empty((n_s, n_p))
    w = w0.copy()
    for k in range(n_s):
        v = u[k]
        for i in range(n_p):
            wi = max(v - p[i], w[i])
            if wi > v:
                wi = v
            w[i] = wi
            out[k, i] = wi
    return out, w


@njit(cache=True, nogil=True)
def gamma_simulate(
    u: FloatArray, p: FloatArray, q: FloatArray, offset: float, w0: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Gamma_n output ``offset + sum_i q_i w_i(k)`` over ``u`` from state ``w0``; final state."""
    n_s, n_p = u.size, p.size
    y = np.empty(n_s)
    w = w0.copy()
    for k in range(n_s):
        v = u[k]
        s = offset
        for i in range(n_p):
            wi = max(v - p[i], w[i])
            if wi > v:
                wi = v
            w[i] = wi
            s += q[i] * wi
        y[k] = s
    return y, w


@njit(cache=True, nogil=True)
def gamma_at(v: float, w: FloatArray, p: FloatArray, q: FloatArray, offset: float) -> float:
    """Output the Gamma operator would give for input ``v`` from state ``w`` (state untouched)."""
    s = offset
    for i in range(p.size):
        wi = max(v - p[i], w[i])
        if wi > v:
            wi = v
        s += q[i] * wi
    return s


@njit(cache=True, nogil=True)
def gamma_invert_exact(
    y_d: float, w: FloatArray, p: FloatArray, q: FloatArray, offset: float, v_prev: float
) -> float:
    """Exact per-step inverse: the input closest to ``v_prev`` that gives output ``y_d``.

    Given the state, ``v -> Gamma(v)`` is continuous and piecewise linear with breakpoints at
    ``w_i`` and ``w_i + p_i`` (slope 1 outside ``[w_i, w_i + p_i]`` per operator, 0 inside) and
    slope ``sum q`` beyond all of them. Walk the breakpoints outwards from ``v_prev`` on both
    sides, interpolate linearly inside the first bracketing segment, and keep the nearer root.
    This also handles weights of mixed sign (Table 4.1), where the map need not be monotone.
    When no root exists (``sum q <= 0`` and ``y_d`` out of reach) the input with the smallest
    output error among the breakpoints is returned.
    """
    bps = _sorted_breakpoints(w, p)
    sq = 0.0
    for i in range(p.size):
        sq += q[i]
    f0 = gamma_at(v_prev, w, p, q, offset) - y_d
    if f0 == 0.0:
        return v_prev
    right = _root_right(y_d, w, p, q, offset, v_prev, f0, bps, sq)
    left = _root_left(y_d, w, p, q, offset, v_prev, f0, bps, sq)
    if right < np.inf or left > -np.inf:
        return right if (right - v_prev) <= (v_prev - left) else left
    # unreachable: least-error breakpoint
    best_v, best_e = v_prev, abs(f0)
    for j in range(bps.size):
        e = abs(gamma_at(bps[j], w, p, q, offset) - y_d)
        if e < best_e:
            best_v, best_e = bps[j], e
    return best_v


@njit(cache=True, nogil=True)
def _sorted_breakpoints(w: FloatArray, p: FloatArray) -> FloatArray:
    """The ``2n`` breakpoints ``w_i`` and ``w_i + p_i`` in ascending order."""
    n = p.size
    bps = np.empty(2 * n)
    for i in range(n):
        bps[2 * i] = w[i]
        bps[2 * i + 1] = w[i] + p[i]
    # insertion sort: 2n ~ 22 values, and np.sort costs seconds of numba compile time
    for i in range(1, 2 * n):
        x = bps[i]
        j = i - 1
        while j >= 0 and bps[j] > x:
            bps[j + 1] = bps[j]
            j -= 1
        bps[j + 1] = x
    return bps


@njit(cache=True, nogil=True)
def _root_right(y_d: float, w: FloatArray, p: FloatArray, q: FloatArray, offset: float,
                v_prev: float, f0: float, bps: FloatArray, sq: float) -> float:
    """The nearest root above ``v_prev`` (``inf`` when there is none)."""
    right = np.inf
    a, fa = v_prev, f0
    for j in range(bps.size):
        b = bps[j]
        if b <= v_prev:
            continue
        fb = gamma_at(b, w, p, q, offset) - y_d
        # signs, not the product: the product of two tiny values underflows to 0
        if (fa <= 0.0 <= fb) or (fb <= 0.0 <= fa):
            den = fa - fb
            return a if den == 0.0 else a + (b - a) * fa / den
        a, fa = b, fb
    if sq != 0.0:
        t = -fa / sq  # beyond the last breakpoint the slope is sum(q)
        if t >= 0.0:
            right = a + t
    return right


@njit(cache=True, nogil=True)
def _root_left(y_d: float, w: FloatArray, p: FloatArray, q: FloatArray, offset: float,
               v_prev: float, f0: float, bps: FloatArray, sq: float) -> float:
    """The nearest root below ``v_prev`` (``-inf`` when there is none)."""
    left = -np.inf
    a, fa = v_prev, f0
    for j in range(bps.size - 1, -1, -1):
        b = bps[j]
        if b >= v_prev:
            continue
        fb = gamma_at(b, w, p, q, offset) - y_d
        if (fa <= 0.0 <= fb) or (fb <= 0.0 <= fa):
            den = fa - fb
            return a if den == 0.0 else a + (b - a) * fa / den
        a, fa = b, fb
    if sq != 0.0:
        t = fa / sq  # going left the output falls at rate sum(q)
        if t >= 0.0:
            left = a - t
    return left


@njit(cache=True, nogil=True)
def _play_update(v: float, w: FloatArray, p: FloatArray) -> None:
    for i in range(p.size):
        wi = max(v - p[i], w[i])
        if wi > v:
            wi = v
        w[i] = wi


@njit(cache=True, nogil=True)
def gamma_invert_sequence(
    y_d: FloatArray, p: FloatArray, q: FloatArray, offset: float, w0: FloatArray, v0: float
) -> tuple[FloatArray, FloatArray, float]:
    """Recursive inverse (Fig. 4.33) with the exact step: inputs, final state, last input."""
    w = w0.copy()
    u = np.empty(y_d.size)
    v = v0
    for k in range(y_d.size):
        v = gamma_invert_exact(y_d[k], w, p, q, offset, v)
        _play_update(v, w, p)
        u[k] = v
    return u, w, v


# --------------------------------------------------------------------------------------
# relay plane / Preisach
# --------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def _relay_bounds(v: float, a: float, b: float, inv_h: float) -> tuple[float, float]:
    if inv_h > 0.0:
        up = 2.0 * (v - a) * inv_h
        up = min(1.0, max(-1.0, up))
        dn = 2.0 * (v - b) * inv_h
        dn = min(1.0, max(-1.0, dn))
    else:
        up = 1.0 if v >= a else -1.0
        dn = -1.0 if v <= b else 1.0
    return up, dn


@njit(cache=True, nogil=True)
def relay_update(v: float, r: FloatArray, alpha: FloatArray, beta: FloatArray, h: float) -> None:
    """Advance every hysteron of the plane by one input sample, in place."""
    inv_h = 1.0 / h if h > 0.0 else 0.0
    for c in range(r.size):
        up, dn = _relay_bounds(v, alpha[c], beta[c], inv_h)
        rc = max(up, r[c])
        if rc > dn:
            rc = dn
        r[c] = rc


@njit(cache=True, nogil=True)
def relay_states(
    u: FloatArray, alpha: FloatArray, beta: FloatArray, h: float, r0: FloatArray, every: int
) -> tuple[FloatArray, FloatArray]:
    """Hysteron states at samples ``0, every, 2*every, ...`` (rows) over ``u``; final state.

    The plane is advanced on every sample (memory needs every extremum); only the rows kept
    for least squares are stored.
    """
    n_rows = (u.size + every - 1) // every
    n_c = r0.size
    out = np.empty((n_rows, n_c))
    r = r0.copy()
    inv_h = 1.0 / h if h > 0.0 else 0.0
    row = 0
    countdown = 0
    for k in range(u.size):
        v = u[k]
        for c in range(n_c):
            up, dn = _relay_bounds(v, alpha[c], beta[c], inv_h)
            rc = max(up, r[c])
            if rc > dn:
                rc = dn
            r[c] = rc
        if countdown == 0:
            for c in range(n_c):
                out[row, c] = r[c]
            row += 1
            countdown = every
        countdown -= 1
    return out, r


@njit(cache=True, nogil=True)
def relay_simulate(
    u: FloatArray, alpha: FloatArray, beta: FloatArray, h: float, wts: FloatArray,
    offset: float, lin: float, r0: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Output ``offset + lin u(k) + sum_c wts_c r_c(k)`` over ``u`` from ``r0``; final state."""
    y = np.empty(u.size)
    r = r0.copy()
    inv_h = 1.0 / h if h > 0.0 else 0.0
    for k in range(u.size):
        v = u[k]
        s = offset + lin * v
        for c in range(r.size):
            up, dn = _relay_bounds(v, alpha[c], beta[c], inv_h)
            rc = max(up, r[c])
            if rc > dn:
                rc = dn
            r[c] = rc
            s += wts[c] * rc
        y[k] = s
    return y, r


@njit(cache=True, nogil=True)
def relay_at(
    v: float, r: FloatArray, alpha: FloatArray, beta: FloatArray, h: float, wts: FloatArray,
    offset: float, lin: float,
) -> float:
    """Output for input ``v`` from plane state ``r`` (state untouched)."""
    inv_h = 1.0 / h if h > 0.0 else 0.0
    s = offset + lin * v
    for c in range(r.size):
        up, dn = _relay_bounds(v, alpha[c], beta[c], inv_h)
        rc = max(up, r[c])
        if rc > dn:
            rc = dn
        s += wts[c] * rc
    return s


@njit(cache=True, nogil=True)
def relay_invert_step(
    y_d: float, r: FloatArray, alpha: FloatArray, beta: FloatArray, h: float, wts: FloatArray,
    offset: float, lin: float, v_prev: float, v_lo: float, v_hi: float, xtol: float,
) -> float:
    """Per-step inverse by bisection (non-negative weights and ``lin``: output monotone in v).

    Searches from ``v_prev`` towards ``y_d`` and returns the nearest input that reaches it
    (the output is flat where no hysteron switches, so the solution set is an interval);
    clamps to ``[v_lo, v_hi]`` (the saturated ends of the plane) when ``y_d`` is out of reach.
    """
    f0 = relay_at(v_prev, r, alpha, beta, h, wts, offset, lin) - y_d
    if f0 == 0.0:
        return v_prev
    if f0 < 0.0:  # need more output: nearest v >= v_prev with f(v) >= 0
        lo, hi = v_prev, max(v_hi, v_prev)
        fh = relay_at(hi, r, alpha, beta, h, wts, offset, lin) - y_d
        if fh < 0.0 and lin > 0.0:  # beyond the plane only the linear part moves
            hi = hi - fh / lin
            fh = relay_at(hi, r, alpha, beta, h, wts, offset, lin) - y_d
        if fh < 0.0:
            return hi
        while hi - lo > xtol:
            mid = 0.5 * (lo + hi)
            if relay_at(mid, r, alpha, beta, h, wts, offset, lin) - y_d >= 0.0:
                hi = mid
            else:
                lo = mid
        fl = relay_at(lo, r, alpha, beta, h, wts, offset, lin) - y_d
        fh = relay_at(hi, r, alpha, beta, h, wts, offset, lin) - y_d
        return lo if abs(fl) < abs(fh) else hi
    lo, hi = min(v_lo, v_prev), v_prev  # need less output: nearest v <= v_prev, f(v) <= 0
    fl = relay_at(lo, r, alpha, beta, h, wts, offset, lin) - y_d
    if fl > 0.0 and lin > 0.0:
        lo = lo - fl / lin
        fl = relay_at(lo, r, alpha, beta, h, wts, offset, lin) - y_d
    if fl > 0.0:
        return lo
    while hi - lo > xtol:
        mid = 0.5 * (lo + hi)
        if relay_at(mid, r, alpha, beta, h, wts, offset, lin) - y_d <= 0.0:
            lo = mid
        else:
            hi = mid
    fl = relay_at(lo, r, alpha, beta, h, wts, offset, lin) - y_d
    fh = relay_at(hi, r, alpha, beta, h, wts, offset, lin) - y_d
    return lo if abs(fl) < abs(fh) else hi


@njit(cache=True, nogil=True)
def relay_invert_sequence(
    y_d: FloatArray, alpha: FloatArray, beta: FloatArray, h: float, wts: FloatArray,
    offset: float, lin: float, r0: FloatArray, v0: float, v_lo: float, v_hi: float,
    xtol: float,
) -> tuple[FloatArray, FloatArray, float]:
    """Recursive per-step inverse with the plane state carried: inputs, final state, last input."""
    r = r0.copy()
    u = np.empty(y_d.size)
    v = v0
    for k in range(y_d.size):
        v = relay_invert_step(y_d[k], r, alpha, beta, h, wts, offset, lin, v, v_lo, v_hi, xtol)
        relay_update(v, r, alpha, beta, h)
        u[k] = v
    return u, r, v
