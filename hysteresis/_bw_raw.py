"""The paper's raw-parameter optimisers for Bouc-Wen (seed 002 IV-A): BFGS, GA, PSO, ... on
eq. 5 over ``[A, B, C, n, alpha, beta]``. The estimator (:mod:`hysteresis.bouc_wen`) reaches
them through ``method``; the paper-comparison harness (:mod:`hysteresis.optimisers`) times them.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution, minimize

from hysteresis._blas import single_thread_blas
from hysteresis._bw_kernels import PAPER_PENALTY, paper_mse
from hysteresis.base import FloatArray, HysteresisError, check_pair

PAPER_METHODS = ("ga", "pso", "nelder-mead", "powell", "cg", "bfgs", "tnc", "cobyla", "slsqp")
# Box of arbitrary initial guesses [A, B, C, n, alpha, beta] (and GA/PSO search space), after
# the authors' GA bounds [-0.1..1, -0.1..0.4, 0..0.1, 0..20, 0..5, 0..40] with beta -> -beta and
# n >= 0.5 (|h|^(n-1) is singular at h = 0 for n < 1).
INIT_BOX = (
    np.array([-0.1, -0.1, 0.0, 0.5, 0.0, -40.0]),
    np.array([1.0, 0.4, 0.1, 20.0, 5.0, 0.0]),
)
_SCIPY_NAMES = {
    "nelder-mead": "Nelder-Mead", "powell": "Powell", "cg": "CG", "bfgs": "BFGS",
    "tnc": "TNC", "cobyla": "COBYLA", "slsqp": "SLSQP",
}


@dataclass(frozen=True)
class RawFitResult:
    method: str
    x: FloatArray
    mse: float
    time_s: float
    nfev: int
    extra: dict[str, Any] = field(default_factory=dict)


def pso(
    fun: Callable[[FloatArray], float], bounds: tuple[FloatArray, FloatArray], *,
    n_particles: int = 30, iters: int = 100, seed: int = 0, inertia: float = 0.729,
    c_personal: float = 1.49445, c_global: float = 1.49445,
) -> tuple[FloatArray, float, int]:
    """Global-best particle swarm (Clerc-Kennedy constriction weights) in a box.

    Returns (best x, best f, number of evaluations).
    """
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    rng = np.random.default_rng(seed)
    dim = lo.size
    x = lo + (hi - lo) * rng.random((n_particles, dim))
    vmax = 0.2 * (hi - lo)
    v = (rng.random((n_particles, dim)) - 0.5) * vmax
    f = np.array([fun(xi) for xi in x])
    pbest, pf = x.copy(), f.copy()
    g = int(np.argmin(pf))
    gbest, gf = pbest[g].copy(), float(pf[g])
    nfev = n_particles
    for _ in range(iters):
        r1 = rng.random((n_particles, dim))
        r2 = rng.random((n_particles, dim))
        v = inertia * v + c_personal * r1 * (pbest - x) + c_global * r2 * (gbest - x)
        v = np.clip(v, -vmax, vmax)
        x = np.clip(x + v, lo, hi)
        f = np.array([fun(xi) for xi in x])
        nfev += n_particles
        better = f < pf
        pbest[better], pf[better] = x[better], f[better]
        g = int(np.argmin(pf))
        if pf[g] < gf:
            gbest, gf = pbest[g].copy(), float(pf[g])
    return gbest, gf, nfev


def fit_raw(
    u: Any, y: Any, *, method: str, x0: Any = None,
    bounds: tuple[FloatArray, FloatArray] = INIT_BOX, seed: int = 0, max_substeps: int = 1,
    maxiter: int = 1000, ga_popsize: int = 10, ga_maxiter: int = 100, pso_particles: int = 30,
    pso_iters: int = 100,
) -> RawFitResult:
    """Minimise eq. 5 over the raw six parameters with one of the paper's optimisers."""
    uu, yy = check_pair(u, y)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    start = 0.5 * (lo + hi) if x0 is None else np.asarray(x0, dtype=np.float64)
    if start.shape != (6,):
        raise HysteresisError(f"x0 must be [A, B, C, n, alpha, beta], got shape {start.shape}")

    def fun(p: FloatArray) -> float:
        return paper_mse(uu, yy, p, max_substeps=max_substeps)

    with single_thread_blas():
        return _fit_raw(fun, start, lo, hi, method, seed, maxiter, ga_popsize, ga_maxiter,
                        pso_particles, pso_iters)


def _fit_raw(
    fun: Callable[[FloatArray], float], start: FloatArray, lo: FloatArray, hi: FloatArray,
    method: str, seed: int, maxiter: int, ga_popsize: int, ga_maxiter: int,
    pso_particles: int, pso_iters: int,
) -> RawFitResult:
    t0 = time.perf_counter()
    if method == "ga":
        res = differential_evolution(
            fun, list(zip(lo, hi, strict=True)), seed=seed, popsize=ga_popsize,
            maxiter=ga_maxiter, polish=False, tol=1e-8,
        )
        x, nfev = np.asarray(res.x, dtype=np.float64), int(res.nfev)
    elif method == "pso":
        x, _, nfev = pso(fun, (lo, hi), n_particles=pso_particles, iters=pso_iters, seed=seed)
    elif method in _SCIPY_NAMES:
        opts: dict[str, Any] = {"maxfun": maxiter} if method == "tnc" else {"maxiter": maxiter}
        with warnings.catch_warnings():
            # The paper's raw problem overflows and divides by zero in places; that is the
            # behaviour being measured, not a bug to be reported on the console.
            warnings.simplefilter("ignore")
            res = minimize(fun, start, method=_SCIPY_NAMES[method], options=opts)
        x, nfev = np.asarray(res.x, dtype=np.float64), int(res.nfev)
    else:
        raise HysteresisError(
            f"unknown raw optimiser {method!r}; use one of {PAPER_METHODS}"
        )
    elapsed = time.perf_counter() - t0
    mse = fun(x) if np.all(np.isfinite(x)) else PAPER_PENALTY
    return RawFitResult(method=method, x=x, mse=float(mse), time_s=elapsed, nfev=nfev)
