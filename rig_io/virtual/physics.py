"""Quasi-static lumped-element physics of a tendon-sheath mechanism (the tsm-bench of seed 001).

The tendon is a chain of ``M`` segments (the two free ends outside the sheath plus the sheath's
lead-in straight, arc and lead-out straight, >= 50 elements in all) joined by friction nodes.

* Segment ``i`` carries tension ``T[i]`` (N). Its elongation relative to the reference tension
  is ``coef[i,0] (T - T_ref) + coef[i,1] (e(T) - e(T_ref)) + coef[i,2] (T^2 - T_ref^2)
  + coef[i,3] T_s (log(1 + T/T_s) - log(1 + T_ref/T_s))``: the tendon's axial compliance
  (EA), the clearance lost motion (``e(T) = T / (T + T_c)`` is how far the tendon has moved
  across the radial clearance towards the inner wall of a turn; ``coef[i,1]`` = clearance x
  turning angle, so it only exists where the path turns and grows with the wrap angle), the
  optional extra load-dependent compliance (``tendon_elongation``) and the compression of the
  flat-wire coil sheath, soft at low load and stiffening as its turn gaps close (compliance
  ``coef[i,3] / (1 + T/T_s)``).
* Friction node ``j`` (between segments ``j-1`` and ``j``) holds ``|T[j-1] - T[j]| <= mu N_j`` with
  the normal force ``N_j = theta[j] (T[j-1] + T[j]) / 2 + cont[j]``: the capstan term (tension x
  local turning angle) plus a contact term that grows as the radius shrinks.
* The output node is the follower: a spring ``F(u) = F0 + k_f u`` (constant-force spring on the
  bench, the elastic backbone of a bending section) with guide friction ``f_F`` and an optional
  end-of-stroke stop.

Each physics tick (1 ms) moves the input end to its new position and solves stick/slip node by
node: a slip front runs from the input; node ``j`` slips when the force jump across it exceeds
its friction capacity, and then takes the limiting tension; the first node that holds stops the
front (everything beyond keeps its stuck tension). The input tension is found by a bracketed
root search so that the tendon's input end lands on the commanded position; if the front
reaches the follower and overcomes its spring and friction, the whole tendon slides and the
follower moves. This is Coulomb friction on a discretised elastic tendon, not a hysteresis
operator: loops, their width and their shape come out of the mechanics.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]

# Indices into the scalar parameter vector ``p`` of the kernels (numba wants flat arrays).
P_MU = 0  # friction coefficient (before asymmetry / rate dependence)
P_F0 = 1  # follower spring force at u=0 (pretension), N
P_KF = 2  # follower spring rate, N/mm
P_FF = 3  # follower guide friction, N
P_TREF = 4  # reference tension of the stretch (the pretension), N
P_TC = 5  # tension scale of the clearance lost motion, N
P_STOP = 6  # follower stop on the pull side (end of stroke), mm (inf = none)
P_ASYM = 7  # asymmetry: mu_pull = mu (1 + a), mu_release = mu (1 - a)
P_RATE = 8  # rate dependence gain: mu (texture + g tanh(|v_f| / v0))
P_V0 = 9  # rate dependence velocity scale, mm/s
P_PLAY = 10  # actuator-side backlash (full width), mm
P_TAU = 11  # servo time constant, s
P_VMAX = 12  # servo velocity limit, mm/s
P_DT = 13  # physics tick, s
P_FS = 14  # follower guide breakaway (static) friction, N
P_TS = 15  # tension scale of the coil sheath's stiffening (gaps closing), N
P_STOP_LO = 16  # follower stop on the release side, mm (-inf = none)
P_TF = 17  # frictional memory: time constant of the speed the rate dependence follows, s
N_P = 18

_EPS_T = 1e-12  # N: tolerance of the stick/slip comparisons
_TOL_X = 1e-8  # mm: tolerance of the position solve (encoder: 1e-4 mm)


@njit(cache=True)
def _stretch(t: float, coef: FloatArray, i: int, tref: float, tc: float, ts: float) -> float:
    """Elongation of segment ``i`` at tension ``t`` relative to the reference tension."""
    if t < 0.0:
        t = 0.0
    s: float = (coef[i, 0] * (t - tref)
                + coef[i, 1] * (t / (t + tc) - tref / (tref + tc))
                + coef[i, 2] * (t * t - tref * tref)
                + coef[i, 3] * ts * (math.log1p(t / ts) - math.log1p(tref / ts)))
    return s


@njit(cache=True)
def _front(t0: float, sgn: float, mu: float, tens: FloatArray, sv: FloatArray, out: FloatArray,
           wsv: FloatArray, theta: FloatArray, cont: FloatArray, coef: FloatArray, tref: float,
           tc: float, ts: float) -> float:
    """Run the slip front from input tension ``t0`` into ``out``; return the stretch change.

    ``sgn`` = +1 pulling (nodes slip towards the input, tension falls along the tendon),
    -1 releasing. ``tens``/``sv`` are the stuck profile and its stretches before the tick;
    ``out``/``wsv`` receive the new ones.
    """
    m = tens.shape[0]
    if t0 < 0.0:
        t0 = 0.0
    out[0] = t0
    wsv[0] = _stretch(t0, coef, 0, tref, tc, ts)
    d: float = wsv[0] - sv[0]
    j = 1
    while j < m:
        prev = out[j - 1]
        cap = mu * (theta[j] * 0.5 * (prev + tens[j]) + cont[j])
        if sgn * (prev - tens[j]) > cap + _EPS_T:
            h = 0.5 * mu * theta[j]
            if sgn > 0.0:
                tj = (prev * (1.0 - h) - mu * cont[j]) / (1.0 + h)
            else:
                tj = (prev * (1.0 + h) + mu * cont[j]) / (1.0 - h)
            if tj < 0.0:
                tj = 0.0
            out[j] = tj
            wsv[j] = _stretch(tj, coef, j, tref, tc, ts)
            d += wsv[j] - sv[j]
            j += 1
        else:
            break
    while j < m:
        out[j] = tens[j]
        wsv[j] = sv[j]
        j += 1
    return d


@njit(cache=True)
def _backward(t_last: float, sgn: float, mu: float, out: FloatArray, theta: FloatArray,
              cont: FloatArray) -> None:
    """Fully slipping profile ending in tension ``t_last`` at the follower."""
    m = out.shape[0]
    if t_last < 0.0:
        t_last = 0.0
    out[m - 1] = t_last
    for j in range(m - 1, 0, -1):
        h = 0.5 * mu * theta[j]
        if sgn > 0.0:
            t = (out[j] * (1.0 + h) + mu * cont[j]) / (1.0 - h)
        else:
            t = (out[j] * (1.0 - h) - mu * cont[j]) / (1.0 + h)
        if t < 0.0:
            t = 0.0
        out[j - 1] = t


@njit(cache=True)
def _fill(tens: FloatArray, sv: FloatArray, coef: FloatArray, tref: float, tc: float,
          ts: float) -> float:
    """Stretch of every segment into ``sv``; return the sum."""
    s = 0.0
    for i in range(tens.shape[0]):
        sv[i] = _stretch(tens[i], coef, i, tref, tc, ts)
        s += sv[i]
    return s


@njit(cache=True)
def _solve_t0(target: float, lo: float, hi: float, sgn: float, mu: float, tens: FloatArray,
              sv: FloatArray, out: FloatArray, wsv: FloatArray, theta: FloatArray,
              cont: FloatArray, coef: FloatArray, tref: float, tc: float, ts: float) -> None:
    """Find the input tension whose slip front stretches the tendon by ``target`` (Illinois).

    The stretch change is monotone in the input tension; ``[lo, hi]`` brackets the root.
    Leaves the solution profile in ``out``/``wsv``.
    """
    flo = _front(lo, sgn, mu, tens, sv, out, wsv, theta, cont, coef, tref, tc, ts) - target
    fhi = _front(hi, sgn, mu, tens, sv, out, wsv, theta, cont, coef, tref, tc, ts) - target
    if sgn * fhi <= 0.0:  # cannot reach (e.g. slack tendon): stay at the bracket end
        return
    if sgn * flo >= 0.0:
        _front(lo, sgn, mu, tens, sv, out, wsv, theta, cont, coef, tref, tc, ts)
        return
    side = 0
    x = lo
    for _ in range(100):
        x = (lo * fhi - hi * flo) / (fhi - flo)
        fx = _front(x, sgn, mu, tens, sv, out, wsv, theta, cont, coef, tref, tc, ts) - target
        if abs(fx) < _TOL_X or abs(hi - lo) < 1e-13:
            return
        if (fx > 0.0) == (fhi > 0.0):
            hi = x
            fhi = fx
            if side == 1:
                flo *= 0.5
            side = 1
        else:
            lo = x
            flo = fx
            if side == -1:
                fhi *= 0.5
            side = -1
    _front(x, sgn, mu, tens, sv, out, wsv, theta, cont, coef, tref, tc, ts)


@njit(cache=True)
def _accept(tens: FloatArray, sv: FloatArray, work: FloatArray, wsv: FloatArray) -> None:
    for i in range(tens.shape[0]):
        tens[i] = work[i]
        sv[i] = wsv[i]


@njit(cache=True)
def advance(x_in: float, u_out: float, mu_pull: float, mu_rel: float, tens: FloatArray,
            sv: FloatArray, work: FloatArray, wsv: FloatArray, theta: FloatArray,
            cont: FloatArray, coef: FloatArray, p: FloatArray, slide: FloatArray) -> float:
    """Quasi-static update for a new input-end position ``x_in`` (mm, pull positive).

    ``tens`` (segment tensions) and ``sv`` (their stretches) are updated in place; returns the
    new follower position. The input end sits at ``u_out + sum(sv)``. ``slide[0]`` is the
    follower's sliding direction of the last tick (0 = stuck): a stuck follower needs the
    breakaway friction ``P_FS`` to start, a sliding one only the kinetic ``P_FF`` (the
    stick-slip of the guide).
    """
    tref = p[P_TREF]
    tc = p[P_TC]
    ts = p[P_TS]
    f0 = p[P_F0]
    kf = p[P_KF]
    ff = p[P_FF]
    stop_hi = p[P_STOP]
    stop_lo = p[P_STOP_LO]
    s_old = 0.0
    for i in range(sv.shape[0]):
        s_old += sv[i]
    dx = x_in - (u_out + s_old)
    if abs(dx) <= _TOL_X:
        slide[0] = 0.0
        return u_out
    sgn = 1.0 if dx > 0.0 else -1.0
    mu = mu_pull if sgn > 0.0 else mu_rel
    at_stop = (sgn > 0.0 and u_out >= stop_hi) or (sgn < 0.0 and u_out <= stop_lo)
    if slide[0] == sgn and kf == 0.0 and not at_stop:
        # Still sliding the same way: the whole tendon slips (fast path of the sine's bulk).
        _backward(f0 + sgn * ff, sgn, mu, work, theta, cont)
        s_full = _fill(work, wsv, coef, tref, tc, ts)
        u_new = x_in - s_full
        if sgn * (u_new - u_out) >= 0.0 and stop_lo <= u_new <= stop_hi:
            _accept(tens, sv, work, wsv)
            return u_new
    f_hold = ff if slide[0] == sgn else max(ff, p[P_FS])
    slide[0] = 0.0
    if not at_stop:
        # Largest input tension (pulling; smallest releasing) with the follower still held.
        _backward(f0 + kf * u_out + sgn * f_hold, sgn, mu, work, theta, cont)
        t_full = work[0]
        d_full = _front(t_full, sgn, mu, tens, sv, work, wsv, theta, cont, coef, tref, tc, ts)
        if sgn * (dx - d_full) <= 0.0:
            _solve_t0(dx, tens[0], t_full, sgn, mu, tens, sv, work, wsv, theta, cont, coef,
                      tref, tc, ts)
            _accept(tens, sv, work, wsv)
            return u_out
        # The follower slides: find its new position (spring rate makes the tension move).
        u_new = _sliding_follower(x_in, u_out, dx - d_full, sgn, mu, f_hold, work, wsv, theta,
                                  cont, coef, p)
        if stop_lo <= u_new <= stop_hi:
            _accept(tens, sv, work, wsv)
            slide[0] = sgn
            return u_new
        # Hit an end-of-stroke stop: the follower becomes a wall.
        u_out = stop_hi if sgn > 0.0 else stop_lo
        _backward(f0 + kf * u_out + sgn * ff, sgn, mu, work, theta, cont)
        s_old = _fill(work, wsv, coef, tref, tc, ts)
        _accept(tens, sv, work, wsv)
        dx = x_in - (u_out + s_old)
        if sgn * dx <= 0.0:
            return u_out
    _against_stop(dx, sgn, mu, tens, sv, work, wsv, theta, cont, coef, tref, tc, ts)
    return u_out


@njit(cache=True)
def _sliding_follower(x_in: float, u_out: float, overshoot: float, sgn: float, mu: float,
                      f_hold: float, work: FloatArray, wsv: FloatArray, theta: FloatArray,
                      cont: FloatArray, coef: FloatArray, p: FloatArray) -> float:
    """The follower's new position once it slides (the spring rate makes the tension move);
    ``work``/``wsv`` hold the tensions and stretches there. ``overshoot``: the input's move
    left after the held tendon took its stretch."""
    f0, kf, ff = p[P_F0], p[P_KF], p[P_FF]
    lo = u_out
    hi = u_out + overshoot  # stretch only grows when pulling: this overshoots
    if kf > 0.0:
        hi += sgn * (f_hold - ff) / kf
    for _ in range(100):
        mid = hi if kf == 0.0 else 0.5 * (lo + hi)
        _backward(f0 + kf * mid + sgn * ff, sgn, mu, work, theta, cont)
        s_new = _fill(work, wsv, coef, p[P_TREF], p[P_TC], p[P_TS])
        if kf == 0.0:
            hi = x_in - s_new
            break
        if sgn * (mid + s_new - x_in) > 0.0:
            hi = mid
        else:
            lo = mid
        if abs(hi - lo) < _TOL_X:
            break
    u_new = hi
    if kf != 0.0:
        _backward(f0 + kf * u_new + sgn * ff, sgn, mu, work, theta, cont)
        _fill(work, wsv, coef, p[P_TREF], p[P_TC], p[P_TS])
    return u_new


@njit(cache=True)
def _against_stop(dx: float, sgn: float, mu: float, tens: FloatArray, sv: FloatArray,
                  work: FloatArray, wsv: FloatArray, theta: FloatArray, cont: FloatArray,
                  coef: FloatArray, tref: float, tc: float, ts: float) -> None:
    """Follower held by the stop: raise (lower) the input tension until the input end
    arrives; the tensions and stretches are accepted in place."""
    lo_t = tens[0]
    hi_t = lo_t
    if sgn > 0.0:
        step = 1.0
        for _ in range(60):
            hi_t = hi_t + step
            if _front(hi_t, sgn, mu, tens, sv, work, wsv, theta, cont, coef, tref, tc,
                      ts) >= dx:
                break
            step *= 2.0
    else:
        hi_t = 0.0
    _solve_t0(dx, lo_t, hi_t, sgn, mu, tens, sv, work, wsv, theta, cont, coef, tref, tc, ts)
    _accept(tens, sv, work, wsv)


@njit(cache=True)
def run_ticks(commands: FloatArray, n_sub: int, state: FloatArray, tens: FloatArray,
              sv: FloatArray, work: FloatArray, wsv: FloatArray, theta: FloatArray,
              cont: FloatArray, coef: FloatArray, p: FloatArray, texture: FloatArray,
              rec: FloatArray) -> None:
    """Advance the rig through ``len(commands)`` control ticks of ``n_sub`` physics ticks.

    ``state`` = [carriage position, carriage velocity, tendon-end position, follower position,
    follower sliding direction, remembered sliding speed] (mm, mm/s, mm, mm, -1/0/+1, mm/s).
    ``rec`` has shape ``(len(commands) * n_sub, 4)`` and receives, after every physics tick:
    carriage position, follower position, input tension, output tension.
    The command of a tick is the servo set-point held during it (the 10 ms loop).
    ``texture`` rows ``(amplitude, wavenumber rad/mm, phase)`` modulate the friction with the
    sliding distance (strand lay and coil pitch): ``mu (1 + sum a sin(k x + psi))``.
    The rate dependence adds a velocity-strengthening part ``mu g tanh(|v_f| / v0)`` (Coulomb
    plus a viscous-like term, as Stribeck-type laws add them; the texture of the contact does
    not modulate the lubricant's shear). ``v_f`` is the tendon's sliding speed seen through the
    contact's frictional memory, a first-order lag ``P_TF``: friction does not follow the
    speed's swings inside one servo tick (a 10 ms set-point step makes the carriage lurch from
    ~2x to ~0.4x its mean speed), it follows the speed the contact has been sliding at.
    """
    dt = p[P_DT]
    alpha = 1.0 - math.exp(-dt / p[P_TAU]) if p[P_TAU] > 0.0 else 1.0
    vmax = p[P_VMAX]
    half_play = 0.5 * p[P_PLAY]
    mu0 = p[P_MU]
    asym = p[P_ASYM]
    gain = p[P_RATE]
    v0 = p[P_V0]
    beta = 1.0 - math.exp(-dt / p[P_TF]) if p[P_TF] > 0.0 else 1.0
    m = tens.shape[0]
    k = 0
    for c in range(commands.shape[0]):
        cmd = commands[c]
        for _ in range(n_sub):
            xm = state[0]
            step = alpha * (cmd - xm)
            lim = vmax * dt
            if step > lim:
                step = lim
            elif step < -lim:
                step = -lim
            xm_new = xm + step
            v = step / dt
            state[0] = xm_new
            state[1] = v
            # Actuator-side backlash between the carriage (and its encoder) and the tendon.
            xt = state[2]
            if xm_new - xt > half_play:
                xt = xm_new - half_play
            elif xt - xm_new > half_play:
                xt = xm_new + half_play
            v_slide = abs(xt - state[2]) / dt
            state[2] = xt
            state[5] += beta * (v_slide - state[5])
            scale = 1.0
            for q in range(texture.shape[0]):
                scale += texture[q, 0] * math.sin(texture[q, 1] * xt + texture[q, 2])
            if gain != 0.0:
                scale += gain * math.tanh(state[5] / v0)
            mu_p = mu0 * (1.0 + asym) * scale
            mu_r = mu0 * (1.0 - asym) * scale
            state[3] = advance(xt, state[3], mu_p, mu_r, tens, sv, work, wsv, theta, cont, coef,
                               p, state[4:5])
            rec[k, 0] = xm_new
            rec[k, 1] = state[3]
            rec[k, 2] = tens[0]
            rec[k, 3] = tens[m - 1]
            k += 1
