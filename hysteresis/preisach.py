"""Classical Preisach model of seed 001 (eq. 4.1-4.6) on a discretised Preisach plane.

``y(k) = offset + sum_c mu(alpha_c, beta_c) dA_c r_c(k)`` over the cells ``alpha >= beta`` of a
uniform ``n_levels`` grid spanning the identification input range (plus a margin). Each cell
holds one relay hysteron ``r in [-1, 1]`` (eq. 4.1-4.2); by default (``smooth=True``) the relay
switches along a linear ramp one grid step wide (a Krasnosel'skii-Pokrovskii kernel) so that the
output is continuous in the input - the ideal relay is ``smooth=False``. See
:mod:`hysteresis.play` for the kernel.

Densities (``density=``), with ``a = alpha - centre``, ``b = beta - centre``:

* ``"lorentzian"`` (eq. 4.4): ``N / ([1 + ((a - H0)/(s H0))^2] [1 + ((b + H0)/(s H0))^2])``;
* ``"gauss_gauss"`` (eq. 4.5):
  ``N exp(-((a-b)/2 - H0)^2 / (2 s^2 H0^2)) exp(-kappa ((a+b)/2)^2 / (2 s^2 H0^2))``;
* ``"lognormal_gauss"`` (eq. 4.6):
  ``N (2/(a-b)) exp(-ln((a-b)/(2 H0))^2 / (2 s^2)) exp(-kappa (a+b)^2 / (8 s^2 H0^2))``
  (the printed eq. 4.6 lost the square on the logarithm; the lognormal needs it);
* ``"nonparametric"``: one non-negative weight per cell, by non-negative least squares.

``kappa = 1`` is the paper's density; with ``free_spread`` it is fitted in ``[0, 100]``
(``kappa = 0``: uniform along ``alpha + beta``, the plane of a play-operator model).
``reversible`` adds ``gain * u``. Parametric densities are identified by nonlinear least squares
(``scipy.optimize.least_squares``) over the shape ``(H0, s, centre[, kappa])`` with the linear
part (``N >= 0``, offset, ``gain >= 0``) projected out exactly at every evaluation, from the
best start of a small grid. The relay states depend only
on the input, so they are computed once per fit (numba); ``fit_every`` keeps every n-th row of
them for the least squares (the plane itself is advanced on every sample).

Initial state: demagnetised about the first input ``u0`` (cells with ``(alpha+beta)/2 < u0`` up,
the others down), the usual rest state of a mechanism that settled at ``u0``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from scipy.linalg import qr as scipy_qr
from scipy.optimize import least_squares, nnls

from hysteresis._blas import single_thread_blas
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
)
from hysteresis.play import (
    relay_invert_sequence,
    relay_invert_step,
    relay_simulate,
    relay_states,
    relay_update,
)

DENSITIES = ("gauss_gauss", "lorentzian", "lognormal_gauss", "nonparametric")
DENSITY_SIGNS = ("auto", "positive", "negative")
PARAM_NAMES = ("N", "H0", "sigma", "centre")


@dataclass
class PreisachState:
    """Every hysteron's state ``r`` (cells in the order of ``alpha_``/``beta_``) and last input."""

    r: FloatArray
    u: float = 0.0

    def copy(self) -> PreisachState:
        return PreisachState(self.r.copy(), float(self.u))


def density_shape(
    kind: str, alpha: FloatArray, beta: FloatArray, h0: float, sigma: float, centre: float,
    *, min_width: float, kappa: float = 1.0,
) -> FloatArray:
    """Unscaled density ``mu / N`` at the cells; ``alpha - beta`` floored at ``min_width``.

    ``kappa`` scales the precision (inverse variance) of the Gaussian factor along
    ``alpha + beta`` (the interaction axis) only: ``kappa = 1`` is the paper's density,
    ``kappa = 0`` a density uniform along that axis (a Prandtl-Ishlinskii-like plane).
    The factorised Lorentzian has no such factor and ignores it.
    """
    a = alpha - centre
    b = beta - centre
    s = sigma * h0
    if kind == "lorentzian":
        return 1.0 / ((1.0 + ((a - h0) / s) ** 2) * (1.0 + ((b + h0) / s) ** 2))
    if kind == "gauss_gauss":
        return np.exp(-(((a - b) / 2.0 - h0) ** 2) / (2.0 * s * s)) * np.exp(
            -kappa * ((a + b) / 2.0) ** 2 / (2.0 * s * s)
        )
    if kind == "lognormal_gauss":
        width = np.maximum(a - b, min_width)
        return (2.0 / width) * np.exp(-(np.log(width / (2.0 * h0)) ** 2) / (2.0 * sigma**2)) * (
            np.exp(-kappa * (a + b) ** 2 / (8.0 * s * s))
        )
    raise HysteresisError(f"density must be one of {DENSITIES}, got {kind!r}")


@register_family("preisach")
class PreisachModel(StatefulModel):
    """Relay hysterons on a discretised Preisach plane with a parametric or free density.

    Parameters
    ----------
    density:
        ``"gauss_gauss"`` (default), ``"lorentzian"``, ``"lognormal_gauss"`` or ``"nonparametric"``.
    n_levels:
        Grid levels per axis; the plane has ``n_levels (n_levels + 1) / 2`` cells.
    margin:
        Fraction of the identification input span added on both sides of the plane.
    smooth:
        Relays switch along a one-cell ramp (continuous output) instead of a jump.
    fit_every:
        Keep every n-th sample for the least squares (speed; the plane sees every sample).
    max_nfev:
        Function-evaluation budget of the nonlinear least squares.
    inverse_xtol:
        Input tolerance of the per-step inverse search, in input units.
    free_spread:
        Fit the precision of the density along ``alpha + beta`` separately (``kappa``); with
        ``False`` the density is exactly the paper's (one width ``sigma H0`` for both axes).
    reversible:
        Add a reversible linear term ``gain * u`` (``gain >= 0``) to the relay sum.
    density_sign:
        ``"positive"``: ``mu >= 0``, the classical plane, whose branches steepen after a
        reversal (a backlash-like loop); ``"negative"``: ``mu <= 0`` below the reversible
        gain, branches that flatten after a reversal (a softening, Bouc-Wen-like loop);
        ``"auto"`` (default): the one whose fit on the head of the identification record(s)
        predicts their last 30 % better (``density_sign_`` records it).
    """

    def __init__(
        self,
        *,
        density: str = "gauss_gauss",
        n_levels: int = 24,
        margin: float = 0.05,
        smooth: bool = True,
        fit_every: int = 4,
        max_nfev: int = 200,
        inverse_xtol: float = 1e-10,
        free_spread: bool = True,
        reversible: bool = True,
        density_sign: str = "auto",
    ) -> None:
        self.density = density
        self.n_levels = n_levels
        self.margin = margin
        self.smooth = smooth
        self.fit_every = fit_every
        self.max_nfev = max_nfev
        self.inverse_xtol = inverse_xtol
        self.free_spread = free_spread
        self.reversible = reversible
        self.density_sign = density_sign

    # -- the plane --------------------------------------------------------------------
    def _check_hyper(self) -> None:
        if self.density not in DENSITIES:
            raise HysteresisError(f"density must be one of {DENSITIES}, got {self.density!r}")
        if int(self.n_levels) < 2:
            raise HysteresisError(f"n_levels must be >= 2, got {self.n_levels}")
        if not self.margin >= 0:
            raise HysteresisError(f"margin must be >= 0, got {self.margin}")
        if int(self.fit_every) < 1:
            raise HysteresisError(f"fit_every must be >= 1, got {self.fit_every}")
        if self.density_sign not in DENSITY_SIGNS:
            raise HysteresisError(
                f"density_sign must be one of {DENSITY_SIGNS}, got {self.density_sign!r}")

    def _set_plane(self, u: FloatArray) -> None:
        lo, hi = float(u.min()), float(u.max())
        span = hi - lo
        if span <= 0:
            raise HysteresisError("the input is constant; a Preisach plane needs an input range")
        lo, hi = lo - self.margin * span, hi + self.margin * span
        n = int(self.n_levels)
        levels = np.linspace(lo, hi, n)
        step = float(levels[1] - levels[0])
        ii, jj = np.tril_indices(n)  # i >= j: alpha = levels[i] >= beta = levels[j]
        self.levels_ = levels
        self.alpha_ = np.ascontiguousarray(levels[ii])
        self.beta_ = np.ascontiguousarray(levels[jj])
        self.cell_area_ = np.where(ii == jj, 0.5 * step * step, step * step)
        self.ramp_width_ = step if self.smooth else 0.0

    def _shape(self, theta: FloatArray) -> FloatArray:
        """Cell weights per unit ``N`` for ``theta = (N, H0, sigma, centre, kappa)``."""
        step = float(self.levels_[1] - self.levels_[0])
        return density_shape(
            self.density, self.alpha_, self.beta_, float(theta[1]), float(theta[2]),
            float(theta[3]), min_width=step / 3.0, kappa=float(theta[4]),
        ) * self.cell_area_

    def initial_state(self, u0: float = 0.0) -> PreisachState:
        """Demagnetised about ``u0`` (see the module docstring)."""
        self.check_fitted()
        mid = 0.5 * (self.alpha_ + self.beta_)
        r = np.where(mid < u0, 1.0, -1.0)
        relay_update(float(u0), r, self.alpha_, self.beta_, float(self.ramp_width_))
        return PreisachState(r, float(u0))

    def _state(self, state: Any, u0: float) -> PreisachState:
        if state is None:
            return self.initial_state(u0)
        st = state.copy() if isinstance(state, PreisachState) else PreisachState(
            np.asarray(state, dtype=np.float64).copy(), u0
        )
        if st.r.shape != self.alpha_.shape:
            raise HysteresisError(
                f"state has {st.r.size} hysterons, the plane has {self.alpha_.size}"
            )
        return st

    # -- identification ---------------------------------------------------------------
    def fit(self, u: Any, y: Any, **fit_params: Any) -> PreisachModel:
        """Identify the density (and offset) from one record or several, each from the
        demagnetised state at its own first input."""
        if fit_params:
            raise HysteresisError(f"PreisachModel.fit takes no extra args: {sorted(fit_params)}")
        self._check_hyper()
        recs = check_records(u, y)
        sign = self.density_sign
        if sign == "auto":
            params = self.get_params()
            sign, _ = choose_form(
                lambda form: type(self)(**{**params, "density_sign": form}),
                ("positive", "negative"), recs)
        self._fit_signed(recs, str(sign))
        return self

    def refit_warm(self, u: Any, y: Any) -> PreisachModel:
        """Fit again on a new output ``y`` from the current density's shape (its sign kept):
        one local search, no grid of starts. A backfitting loop refits one input many times
        against outputs that differ by a small term, and the shape moves little between its
        rounds. A free (nonparametric) density has no shape to start from: fitted in full."""
        self.check_fitted()
        recs = check_records(u, y)
        warm = None if self.density == "nonparametric" else np.array(self.density_params_)
        self._fit_signed(recs, str(self.density_sign_), warm=warm)
        return self

    def _fit_signed(self, recs: Records, sign: str, *, warm: FloatArray | None = None) -> None:
        """Identify the plane on ``recs`` with the density's sign fixed (``warm``: the local
        search's start, else the best of a grid)."""
        self._set_plane(recs.u)
        every = int(self.fit_every)
        rows = self._relay_rows(recs, cache=warm is not None)
        target = np.concatenate([yy[::every] for _, yy in recs.pairs()])
        u_rows = np.concatenate([uu[::every] for uu, _ in recs.pairs()])
        sgn = 1.0 if sign == "positive" else -1.0
        # Small dense algebra: BLAS threads only add contention (the pipeline already fits
        # configurations in parallel), so identification runs single-threaded.
        with single_thread_blas():
            if self.density == "nonparametric":
                self._fit_nonparametric(rows, target, u_rows, sgn)
            else:
                self._fit_parametric(rows, target, recs.u, u_rows, sgn, warm=warm)
        self.density_sign_ = sign
        if sgn < 0 and not self._rises(recs):
            # a negative plane below a small reversible gain fits an output that falls with
            # the input: a sign flip, not a loop; only the positive form may say so
            raise HysteresisError("no negative density with a rising outer slope fits the "
                                  "data (is the output decreasing in the input?)")
        self.sse_ = records_sse(self, recs)
        self.n_samples_ = int(recs.u.size)

    def _relay_rows(self, recs: Records, *, cache: bool) -> FloatArray:
        """Every ``fit_every``-th relay state of each record from its own demagnetised start.
        With ``cache`` the last rows are kept and reused while the input and the plane are
        the same: a backfitting loop refits one input many times, only the output changes."""
        every = int(self.fit_every)
        key = (recs.u.tobytes(), recs.bounds, self.alpha_.tobytes(), self.beta_.tobytes(),
               float(self.ramp_width_), every)
        cached = getattr(self, "_relay_cache", None)
        if cache and cached is not None and cached[0] == key:
            return cast("FloatArray", cached[1])
        blocks = []
        for uu, _ in recs.pairs():
            r0 = self.initial_state(float(uu[0])).r
            blocks.append(relay_states(uu, self.alpha_, self.beta_, float(self.ramp_width_),
                                       r0, every)[0])
        rows = blocks[0] if len(blocks) == 1 else np.vstack(blocks)
        if cache:
            self._relay_cache = (key, rows)
        return rows

    def _fit_nonparametric(self, rows: FloatArray, target: FloatArray, u_rows: FloatArray,
                           sgn: float = 1.0) -> None:
        ones = np.ones((rows.shape[0], 1))
        # the offset may have either sign: two non-negative columns +1 and -1
        cols = [sgn * rows, ones, -ones]
        if self.reversible:
            cols.append(u_rows.reshape(-1, 1))
        x, _ = nnls(np.hstack(cols), target, maxiter=50 * rows.shape[1])
        k = rows.shape[1]
        # nnls keeps the magnitudes >= 0; the clip makes that hold whatever a BLAS kernel
        # rounds, and the sign is the form's
        self.cell_weights_ = np.ascontiguousarray(sgn * np.maximum(x[:k], 0.0))
        self.offset_ = float(x[k] - x[k + 1])
        self.reversible_gain_ = float(x[k + 2]) if self.reversible else 0.0
        self.density_params_ = np.zeros(0)

    def _fit_parametric(self, rows: FloatArray, target: FloatArray, u: FloatArray,
                        u_rows: FloatArray, sgn: float, *,
                        warm: FloatArray | None = None) -> None:
        # x = (N, H0, sigma, centre, kappa, offset, gain); N, offset, gain enter linearly.
        half = 0.5 * float(u.max() - u.min())
        centre0 = 0.5 * float(u.max() + u.min())
        k = rows.shape[1]
        # The residual is linear in (cell weights, offset, gain): one QR of [rows, 1, u] turns
        # the n_rows-long least squares into an equivalent (K + 2)-long one (same minimiser).
        # QR of the augmented matrix [rows, 1, u, target] (R only, no Q formed): its last column
        # holds Q^T target; robust to rank deficiency (cells the record never switches).
        aug = np.column_stack([rows, np.ones(rows.shape[0]), u_rows, target])
        raug = scipy_qr(aug, mode="r", overwrite_a=True, check_finite=False)[0]
        rmat, qt = raug[: k + 2, : k + 2], raug[: k + 2, k + 2]
        r_cells, r_off, r_gain = rmat[:, :k], rmat[:, k], rmat[:, k + 1]
        spread_free = self.free_spread and self.density != "lorentzian"
        rev = bool(self.reversible)

        def linear_part(x: FloatArray) -> tuple[FloatArray, FloatArray]:
            """Variable projection: best (N >= 0, offset, gain >= 0) for the shape in ``x``."""
            cols = [sgn * (r_cells @ self._shape(x)), r_off, -r_off]  # offset of either sign
            if rev:
                cols.append(r_gain)
            a = np.column_stack(cols)
            c, _ = nnls(a, qt)
            coef = np.array([c[0], c[1] - c[2], c[3] if rev else 0.0])
            res_: FloatArray = a @ c - qt
            return coef, res_

        best = (_grid_start(linear_part, half, centre0, spread_free) if warm is None
                else (0.0, np.array(warm, dtype=np.float64)))
        # Nonlinear least squares over the shape only (H0, sigma, centre[, kappa]); the
        # linear part is projected out at every evaluation (far fewer iterations than
        # optimising N and the offset jointly with the shape).
        free = [1, 2, 3, 4] if spread_free else [1, 2, 3]
        full0 = best[1]

        def unpack(z: FloatArray) -> FloatArray:
            x = full0.copy()
            x[free] = z
            return x

        def resid(z: FloatArray) -> FloatArray:
            return linear_part(unpack(z))[1]

        span = 2.0 * half
        lo_all = np.array([0.0, 1e-3 * half, 0.02, centre0 - span, 0.0])
        hi_all = np.array([np.inf, 2.0 * span, 20.0, centre0 + span, 100.0])
        lo, hi = lo_all[free], hi_all[free]
        z0 = np.clip(full0[free], lo + 1e-9, hi - 1e-9)
        res = least_squares(
            resid, z0, jac="2-point", bounds=(lo, hi), x_scale="jac",
            max_nfev=int(self.max_nfev), method="trf",
        )
        x = unpack(res.x)
        coef, _ = linear_part(x)
        x[0] = sgn * coef[0]
        if spread_free and x[4] == 0.0:
            x[3] = centre0  # uniform along alpha + beta: the centre has no effect; report the mid

        self.density_params_ = np.ascontiguousarray(x[:5])
        self.cell_weights_ = np.ascontiguousarray(x[0] * self._shape(x))
        self.offset_ = float(coef[1])
        self.reversible_gain_ = float(coef[2])
        self.n_fev_ = int(res.nfev)

    def _rises(self, recs: Records) -> bool:
        """Whether the fitted plane's output rises with the input over the records."""
        pred = np.concatenate([self.predict(uu) for uu, _ in recs.pairs()])
        return bool(np.isfinite(pred).all() and np.ptp(recs.u) > 0
                    and np.corrcoef(recs.u, pred)[0, 1] > 0)

    # -- simulation -------------------------------------------------------------------
    def predict(self, u: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """Simulate from the demagnetised state at ``u[0]`` (or ``state``)."""
        self.check_fitted()
        uu = as_1d(u, "u")
        st = self._state(state, float(uu[0]))
        y, r = relay_simulate(
            uu, self.alpha_, self.beta_, float(self.ramp_width_), self.cell_weights_,
            self.offset_, self.reversible_gain_, st.r,
        )
        if return_state:
            return y, PreisachState(r, float(uu[-1]))
        return y

    # -- inverse ----------------------------------------------------------------------
    def _input_bounds(self) -> tuple[float, float]:
        step = float(self.levels_[1] - self.levels_[0])
        return float(self.levels_[0] - step), float(self.levels_[-1] + step)

    def _default_u0(self) -> float:
        lo, hi = self._input_bounds()
        return 0.0 if lo < 0.0 < hi else 0.5 * (lo + hi)

    def invert_step(self, y_k: float, state: Any = None) -> tuple[float, PreisachState]:
        """One step of the per-step inverse search: ``(u_k, state_k)``."""
        self.check_fitted()
        st = self._state(state, self._default_u0())
        lo, hi = self._input_bounds()
        v = float(relay_invert_step(
            float(y_k), st.r, self.alpha_, self.beta_, float(self.ramp_width_),
            self.cell_weights_, self.offset_, self.reversible_gain_, st.u, lo, hi,
            float(self.inverse_xtol),
        ))
        relay_update(v, st.r, self.alpha_, self.beta_, float(self.ramp_width_))
        return v, PreisachState(st.r, v)

    def invert(
        self, y_desired: Any, *, state: Any = None, return_state: bool = False,
        u0: float | None = None,
    ) -> Any:
        """Per-step inverse with the plane state carried (warm start at the previous input).

        Without a state the plane starts demagnetised about ``u0`` (default: the middle of
        the identification range, or 0 if that lies inside it).
        """
        self.check_fitted()
        yd = as_1d(y_desired, "y_desired")
        lo, hi = self._input_bounds()
        st = self._state(state, self._default_u0() if u0 is None else float(u0))
        u, r, v = relay_invert_sequence(
            yd, self.alpha_, self.beta_, float(self.ramp_width_), self.cell_weights_,
            self.offset_, self.reversible_gain_, st.r, st.u, lo, hi, float(self.inverse_xtol),
        )
        return (u, PreisachState(r, float(v))) if return_state else u


def _grid_start(linear_part: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
                half: float, centre0: float, spread_free: bool) -> tuple[float, FloatArray]:
    """The parametric fit's start: the best (sse, shape) of a coarse grid over
    (H0, sigma[, kappa]) with a positive density."""
    best: tuple[float, FloatArray] | None = None
    kappas = (1.0, 1.0 / 16.0, 1.0 / 256.0, 0.0) if spread_free else (1.0,)
    for h0 in half * np.array([0.03, 0.08, 0.15, 0.3, 0.5]):
        for sigma in (0.3, 0.6, 1.2):
            for kappa in kappas:
                theta = np.array([1.0, h0, sigma, centre0, kappa])
                coef, res_ = linear_part(theta)
                if coef[0] <= 0:
                    continue
                sse = float(res_ @ res_)
                if best is None or sse < best[0]:
                    best = (sse, theta)
    if best is None:
        raise HysteresisError(
            "no positive density fits the data (is the output decreasing in the input?)"
        )
    return best
