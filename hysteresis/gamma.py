"""Complex hysteresis operator Gamma_n of seed 001 (eq. 4.7-4.10): weighted discrete play operators.

``y(k) = offset + sum_i q_i gamma_i[v(k), w_i(k-1), p_i]`` with preassigned thresholds
``P = (p_1..p_n)`` (default 0, 0.2, ..., 2.0 input units) and zero initial state. The output is
linear in ``Q``, so identification (eq. 4.10) is an exact least-squares problem:

* ``constraint="sum_to_one"`` (default): minimise ``||A Q - y||^2`` subject to ``sum(Q) = 1``.
  Eq. 4.10 writes the constraint as ``Q Q^T = 1``, but the text says it is the *sum* of the
  weights; we follow the text. The KKT system is solved exactly through the null space of the
  constraint (no iterative optimiser, so no early stop: Table 4.1's vectors sum to
  0.967-0.982 because the thesis' interior-point run stopped early).
* ``constraint="free"``: ordinary least squares.

The inverse is the recursive per-step inverse of Fig. 4.22-4.33: the state (every operator's
last output) is carried from step to step and the search is warm-started at the previous
input. ``inverse_method="exact"`` walks the breakpoints of the piecewise-linear map
``v -> Gamma(v | state)`` (numba, microseconds); ``inverse_method="bounded"`` is the thesis'
reference, a bounded scalar search (``scipy.optimize.minimize_scalar(method="bounded")``,
Brent's golden-section/parabolic method like Matlab's FMINBND).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from hysteresis._blas import single_thread_blas
from hysteresis.base import (
    FloatArray,
    HysteresisError,
    StatefulModel,
    as_1d,
    check_inverse_reach,
    check_pair,
    register_family,
)
from hysteresis.play import (
    gamma_at,
    gamma_invert_exact,
    gamma_invert_sequence,
    gamma_simulate,
    play_matrix,
)

CONSTRAINTS = ("sum_to_one", "free")
INVERSE_METHODS = ("exact", "bounded")


@dataclass
class GammaState:
    """Memory of Gamma_n: every play operator's last output ``w`` and the last input ``u``."""

    w: FloatArray
    u: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def copy(self) -> GammaState:
        return GammaState(self.w.copy(), float(self.u), dict(self.extra))


@register_family("gamma")
class GammaModel(StatefulModel):
    """Weighted sum of discrete play operators (Prandtl-Ishlinskii type, seed 001 Gamma_n).

    Parameters
    ----------
    n_operators, max_threshold:
        Thresholds ``P = linspace(0, max_threshold, n_operators)`` (seed 001: 11 and 2.0 mm).
    thresholds:
        Explicit thresholds (overrides the two above); non-negative, distinct.
    constraint:
        ``"sum_to_one"`` (seed 001 eq. 4.10 as the text means it) or ``"free"``.
    fit_offset:
        Also fit a constant output offset (not in the thesis; off by default).
    inverse_method:
        ``"exact"`` (breakpoint walk) or ``"bounded"`` (the thesis' bounded scalar search).
    search_radius:
        Half-width of the bounded search interval around the previous input, in input units
        (``None``: ``max(P)`` plus twice the output step divided by ``sum(Q)``).
    xatol:
        Absolute input tolerance of the bounded search.
    """

    def __init__(
        self,
        *,
        n_operators: int = 11,
        max_threshold: float = 2.0,
        thresholds: list[float] | None = None,
        constraint: str = "sum_to_one",
        fit_offset: bool = False,
        inverse_method: str = "exact",
        search_radius: float | None = None,
        xatol: float = 1e-9,
    ) -> None:
        self.n_operators = n_operators
        self.max_threshold = max_threshold
        self.thresholds = thresholds
        self.constraint = constraint
        self.fit_offset = fit_offset
        self.inverse_method = inverse_method
        self.search_radius = search_radius
        self.xatol = xatol

    # -- hyper-parameters -------------------------------------------------------------
    def _thresholds(self) -> FloatArray:
        if self.thresholds is not None:
            p = np.asarray(list(self.thresholds), dtype=np.float64)
        else:
            if int(self.n_operators) < 1:
                raise HysteresisError(f"n_operators must be >= 1, got {self.n_operators}")
            if not self.max_threshold >= 0:
                raise HysteresisError(f"max_threshold must be >= 0, got {self.max_threshold}")
            p = np.linspace(0.0, float(self.max_threshold), int(self.n_operators))
        if p.ndim != 1 or p.size == 0 or not np.all(np.isfinite(p)) or np.any(p < 0):
            raise HysteresisError(f"thresholds must be finite and >= 0, got {p.tolist()}")
        if np.unique(p).size != p.size:
            raise HysteresisError(f"thresholds must be distinct, got {p.tolist()}")
        return p

    # -- identification ---------------------------------------------------------------
    def design_matrix(self, u: Any) -> FloatArray:
        """Play-operator outputs (one column per threshold) over ``u`` from the zero state."""
        uu = as_1d(u, "u")
        p = self.thresholds_ if hasattr(self, "thresholds_") else self._thresholds()
        a, _ = play_matrix(uu, p, np.zeros(p.size))
        return np.asarray(a)

    def fit(self, u: Any, y: Any, **fit_params: Any) -> GammaModel:
        """Identify ``Q`` (and the offset) by exact (constrained) least squares, zero state."""
        if fit_params:
            raise HysteresisError(f"GammaModel.fit takes no extra arguments: {sorted(fit_params)}")
        if self.constraint not in CONSTRAINTS:
            raise HysteresisError(
                f"constraint must be one of {CONSTRAINTS}, got {self.constraint!r}"
            )
        uu, yy = check_pair(u, y)
        p = self._thresholds()
        a, _ = play_matrix(uu, p, np.zeros(p.size))
        n = p.size
        if self.fit_offset:
            a = np.column_stack([a, np.ones(uu.size)])
        c = np.zeros(a.shape[1])
        c[:n] = 1.0  # constraint row: sum of the weights (the offset is not constrained)
        if a.shape[0] < a.shape[1]:
            raise HysteresisError(f"need at least {a.shape[1]} samples to fit, got {a.shape[0]}")
        # tiny dense problem: BLAS threads only add contention (fits run in parallel)
        with single_thread_blas():
            if self.constraint == "free":
                x, *_ = np.linalg.lstsq(a, yy, rcond=None)
                lam = float("nan")
            else:
                x, lam = constrained_lstsq(a, yy, c, 1.0)
        resid = a @ x - yy
        self.thresholds_ = p
        self.weights_ = np.ascontiguousarray(x[:n])
        self.offset_ = float(x[n]) if self.fit_offset else 0.0
        self.lagrange_multiplier_ = lam
        self.sse_ = float(resid @ resid)
        self.n_samples_ = int(uu.size)
        return self

    # -- simulation -------------------------------------------------------------------
    def initial_state(self, u0: float = 0.0) -> GammaState:
        """The identification state, every operator at zero (seed 001 ``W_{k-1}(1) = 0``),
        after the input ``u0`` is applied once (for ``u0 = 0`` the zero state itself)."""
        self.check_fitted()
        v = float(u0)
        w = np.minimum(v, np.maximum(v - self.thresholds_, 0.0))
        return GammaState(w, v)

    def _state(self, state: Any) -> GammaState:
        if state is None:
            return self.initial_state()
        if isinstance(state, GammaState):
            st = state.copy()
        else:
            st = GammaState(np.asarray(state, dtype=np.float64).copy(), 0.0)
        if st.w.shape != self.thresholds_.shape:
            raise HysteresisError(
                f"state has {st.w.size} operator outputs, model has {self.thresholds_.size}"
            )
        return st

    def predict(
        self, u: Any, *, state: Any = None, return_state: bool = False
    ) -> Any:
        """Simulate from the zero state (or ``state``); with ``return_state`` also the end state."""
        self.check_fitted()
        uu = as_1d(u, "u")
        st = self._state(state)
        y, w = gamma_simulate(uu, self.thresholds_, self.weights_, self.offset_, st.w)
        if return_state:
            return y, GammaState(w, float(uu[-1]))
        return y

    def step(self, u_k: float, state: Any = None) -> tuple[float, GammaState]:
        """One forward step: ``(y_k, state_k)`` from ``u_k`` and ``state_{k-1}`` (not modified)."""
        self.check_fitted()
        st = self._state(state)
        v = float(u_k)
        w = np.minimum(v, np.maximum(v - self.thresholds_, st.w))
        return self.offset_ + float(self.weights_ @ w), GammaState(w, v)

    # -- inverse ----------------------------------------------------------------------
    def invert_step(
        self, y_k: float, state: Any = None, *, method: str | None = None
    ) -> tuple[float, GammaState]:
        """One step of the recursive inverse: ``(u_k, state_k)`` from ``y_k`` and ``state_{k-1}``.

        Warm-started at ``state.u`` (the previous input). The returned state is new; the
        given one is not modified.
        """
        self.check_fitted()
        st = self._state(state)
        meth = method or self.inverse_method
        p, q, off = self.thresholds_, self.weights_, self.offset_
        if meth == "exact":
            v = float(gamma_invert_exact(float(y_k), st.w, p, q, off, st.u))
        elif meth == "bounded":
            v = self._bounded_step(float(y_k), st)
        else:
            raise HysteresisError(f"inverse method must be one of {INVERSE_METHODS}, got {meth!r}")
        w = np.minimum(v, np.maximum(v - p, st.w))
        return v, GammaState(w, v)

    def _bounded_step(self, y_k: float, st: GammaState) -> float:
        """The thesis' LSQ_Opt step: bounded scalar search on (Gamma(v) - y_k)^2 near v_{k-1}."""
        p, q, off, w = self.thresholds_, self.weights_, self.offset_, st.w

        def err2(v: float) -> float:
            wi = np.minimum(v, np.maximum(v - p, w))
            e = off + float(q @ wi) - y_k
            return e * e

        if self.search_radius is not None:
            rad = float(self.search_radius)
        else:
            gap = abs(float(gamma_at(st.u, w, p, q, off)) - y_k)
            rad = float(p.max()) + 2.0 * gap / max(abs(float(q.sum())), 1e-3) + 1e-6
        res = minimize_scalar(
            err2, bounds=(st.u - rad, st.u + rad), method="bounded",
            options={"xatol": float(self.xatol)},
        )
        return float(res.x)

    def invert(
        self, y_desired: Any, *, state: Any = None, method: str | None = None,
        return_state: bool = False,
    ) -> Any:
        """Inverse input sequence (state carried); ``return_state``: also the end state."""
        self.check_fitted()
        yd = as_1d(y_desired, "y_desired")
        check_inverse_reach(self, desired=yd)
        st = self._state(state)
        meth = method or self.inverse_method
        if meth == "exact":
            u, w, v = gamma_invert_sequence(
                yd, self.thresholds_, self.weights_, self.offset_, st.w, st.u
            )
            end = GammaState(w, float(v))
        elif meth == "bounded":
            u = np.empty(yd.size)
            for k in range(yd.size):
                u[k], st = self.invert_step(float(yd[k]), st, method="bounded")
            end = st
        else:
            raise HysteresisError(f"inverse method must be one of {INVERSE_METHODS}, got {meth!r}")
        return (u, end) if return_state else u


def constrained_lstsq(
    a: FloatArray, y: FloatArray, c: FloatArray, d: float
) -> tuple[FloatArray, float]:
    """Exact solution of ``min ||a x - y||^2  s.t.  c . x = d`` and its Lagrange multiplier.

    Null-space method (numerically better than forming the KKT matrix with ``a^T a``):
    ``x = x0 + Z z`` with ``x0 = d c / (c.c)`` and ``Z`` an orthonormal basis of ``c``'s null
    space; ``z`` by ordinary least squares. The multiplier ``lam`` satisfies the stationarity
    condition ``a^T (a x - y) + lam c = 0`` (objective ``||a x - y||^2 / 2``).
    """
    cc = float(c @ c)
    if cc == 0:
        raise HysteresisError("constraint vector is zero")
    x0 = d * c / cc
    # Householder QR of c: the trailing columns of Q span its orthogonal complement.
    qmat, _ = np.linalg.qr(c.reshape(-1, 1), mode="complete")
    z_basis = qmat[:, 1:]
    z, *_ = np.linalg.lstsq(a @ z_basis, y - a @ x0, rcond=None)
    x = x0 + z_basis @ z
    grad = a.T @ (a @ x - y)
    lam = -float(c @ grad) / cc
    return x, lam


def seed001_table41() -> list[dict[str, Any]]:
    """Seed 001 Table 4.1 rows: ``curve_angle_deg``, ``radius_mm``, ``weights``, ``sse``."""
    import json
    from importlib import resources

    text = resources.files("hysteresis").joinpath("data/seed001_table41.json").read_text("utf-8")
    rows: list[dict[str, Any]] = json.loads(text)["rows"]
    return rows


def sine_decay(
    *, amplitudes: tuple[float, ...] = (6.0, 4.5, 3.0, 1.5), periods_per_amplitude: int = 5,
    frequency_hz: float = 0.25, rate_hz: float = 100.0,
) -> FloatArray:
    """Seed 001's identification input (Fig. 4.8): decaying sinusoid from rest, 80 s at 100 Hz."""
    per_amp = int(round(periods_per_amplitude * rate_hz / frequency_hz))
    t = np.arange(per_amp) / rate_hz
    s = np.sin(2.0 * np.pi * frequency_hz * t)
    return np.concatenate([a * s for a in amplitudes])


def triangle_decay(
    *, amplitudes: tuple[float, ...] = (6.0, 4.5, 3.0, 1.5), periods_per_amplitude: int = 3,
    slope: float = 6.0, rate_hz: float = 100.0,
) -> FloatArray:
    """Seed 001's triangular validation input (Fig. 4.9a) from rest: constant ``slope`` per s."""
    parts = [np.zeros(1)]
    for a in amplitudes:
        quarter = np.minimum(np.arange(1, int(round(a / slope * rate_hz)) + 1) * slope / rate_hz, a)
        period = np.concatenate([quarter, a - quarter, -quarter, quarter - a])
        parts.append(np.tile(period, periods_per_amplitude))
    return np.concatenate(parts)
