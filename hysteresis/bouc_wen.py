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
:mod:`hysteresis._bw_raw` and are reachable through ``method``; the paper's comparison of
them is :mod:`hysteresis.optimisers`.

Inverses: ``"feedforward"`` is eq. 4 (``u_c = (y_d - beta h)/alpha`` with h driven by y_d);
``"exact"`` solves ``alpha u + beta h(u) + offset = y_d`` per step for u with the state carried.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize

from hysteresis._blas import single_thread_blas
from hysteresis._bw_kernels import (
    PAPER_PENALTY,
    _advance,
    _canon_sens,
    _invert_exact,
    _invert_feedforward,
    _lip_ultimate,
    _simulate,
    bw_simulate,
    canonical_params,
    paper_mse,
)
from hysteresis._numerics import decimation_indices
from hysteresis.base import (
    FloatArray,
    HysteresisError,
    Records,
    StatefulModel,
    as_1d,
    check_records,
    records_sse,
    register_family,
    state_from,
)

__all__ = ["PAPER_PENALTY", "BoucWenModel", "BoucWenState", "bw_simulate", "canonical_params",
           "paper_mse"]


@dataclass(frozen=True)
class BoucWenState:
    """Memory of the Bouc-Wen model: the last input ``u`` and the hysteretic state ``h``
    (eq. 3). Frozen: a step returns a new state and never changes the one it was given."""

    u: float
    h: float


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
class BoucWenModel(StatefulModel):
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
        recs = check_records(u, y, min_samples=10)
        if self.method not in ("varpro", *_RAW_METHODS):
            raise HysteresisError(
                f"unknown Bouc-Wen method {self.method!r}; use 'varpro' or one of {_RAW_METHODS}"
            )
        return self._fit(recs, x0=fit_params.get("x0"))

    def refit_warm(self, u: Any, y: Any) -> BoucWenModel:
        """Fit again on a new output ``y`` from the current loop shape: one local search, no
        grid of starts (varpro only). A backfitting loop refits one input many times against
        outputs that differ by a small term, and the shape moves little between its rounds."""
        self.check_fitted()
        if self.method != "varpro":
            return self.fit(u, y)
        return self._fit(check_records(u, y, min_samples=10),
                         warm=(float(self.A_), float(self.B_), float(self.n_)))

    def _fit(self, recs: Records, *, x0: Any = None,
             warm: tuple[float, float, float] | None = None) -> BoucWenModel:
        thin = recs.thin(decimation_indices(recs, int(self.fit_max_samples)))
        ud, yd = thin.u, thin.y
        if self.method == "varpro":
            with single_thread_blas():
                params, offset = self._fit_varpro(ud, yd, thin.slices(), warm=warm)
        else:
            from hysteresis._bw_raw import fit_raw

            if thin.n_records > 1:
                raise HysteresisError(f"method {self.method!r} fits one record; use 'varpro' "
                                      f"for {thin.n_records} records")
            if self.fit_offset:
                raise HysteresisError(
                    f"method {self.method!r} fits the paper's exact form; set fit_offset=False"
                )
            res = fit_raw(ud, yd, method=self.method, x0=x0,
                          seed=self.seed, max_substeps=self.max_substeps)
            params, offset = res.x, 0.0
        a_, b_, c_, n, alpha, beta = (float(v) for v in params)
        self.A_, self.B_, self.C_, self.n_ = a_, b_, c_, n
        self.alpha_, self.beta_, self.offset_ = alpha, beta, float(offset)
        # the one training error of every family: squared errors summed over the records
        self.sse_ = records_sse(self, recs)
        self.n_samples_ = int(recs.u.size)
        return self

    def _fit_varpro(self, u: FloatArray, y: FloatArray, pieces: list[slice], *,
                    warm: tuple[float, float, float] | None = None
                    ) -> tuple[FloatArray, float]:
        """Canonical shape search with the linear stage projected out; ``pieces`` are the
        records (each simulated from h = 0 at its own first input). ``warm``: (A, B, n) of a
        previous fit on the same input, the one start of the local search."""
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
            ok = all(_canon_sens(un[sl], float(z[0]), float(z[1]), float(z[2]), max_sub,
                                 h[sl], s[sl]) for sl in pieces)
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
        if warm is None:
            scored = sorted(grid, key=lambda z: objective(z)[0])
        else:
            a_w, b_w, n_w = warm
            z_w = np.array([math.log(1.0 / (a_w * us)), 2.0 * b_w / a_w - 1.0, n_w])
            lo, hi = np.array(bounds).T
            scored = [np.clip(z_w, lo, hi)]
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
    def initial_state(self, u0: float = 0.0) -> BoucWenState:
        """Rest state (h = 0) at input u0."""
        return BoucWenState(float(u0), 0.0)

    def _state(self, state: Any, u0: float) -> tuple[float, float]:
        """(h, u) of ``state``: a :class:`BoucWenState`, or a mapping with keys ``u`` and
        ``h`` (a state written by hand); None is the rest state at ``u0``."""
        if state is None:
            return 0.0, u0
        state = state_from(state, BoucWenState, "Bouc-Wen")
        return state.h, state.u

    def simulate(self, u: Any, state: Any = None) -> tuple[FloatArray, BoucWenState]:
        """``predict`` that also returns the final state (to continue a simulation)."""
        uu = as_1d(u, "u")
        a_, b_, c_, n, alpha, beta, off = self._p()
        h0, u0 = self._state(state, float(uu[0]))
        out = np.empty_like(uu)
        h = _simulate(uu, a_, b_, c_, n, alpha, beta, off, h0, u0, int(self.max_substeps), out)
        return out, BoucWenState(float(uu[-1]), float(h))

    def predict(self, u: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """Output of eq. 2 along u, from rest (h = 0 at u[0]) or from ``state``; with
        ``return_state`` also the end state (the same face as every family)."""
        y, end = self.simulate(u, state=state)
        return (y, end) if return_state else y

    def step(self, u_k: float, state: Any = None) -> tuple[float, BoucWenState]:
        """One sample: returns (y, new state). ``state=None`` starts at rest at this input."""
        a_, b_, c_, n, alpha, beta, off = self._p()
        u = float(u_k)
        h0, u0 = self._state(state, u)
        h = float(_advance(h0, u - u0, a_, b_, c_, n, int(self.max_substeps),
                           _lip_ultimate(a_, b_, c_, n)))
        return alpha * u + beta * h + off, BoucWenState(u, h)

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
    ) -> tuple[FloatArray, BoucWenState]:
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
        return out, BoucWenState(float(up), float(h))

    def invert_step(
        self, y_desired: float, state: Any = None, *, method: str | None = None
    ) -> tuple[float, BoucWenState]:
        """One sample of the inverse: returns (u, new state) with the state of the *model*."""
        u, st = self.simulate_inverse(np.array([float(y_desired)]), state=state, method=method)
        return float(u[0]), st
