"""Two small base models used when no registered family is asked for.

``PlaySumModel``: a free-weight sum of play operators plus an offset (the Gamma operator of
seed 001 without the sum-to-one constraint), identified by bounded linear least squares.
``AffineModel``: gain and offset, the no-hysteresis baseline. Neither is registered as a
family: they exist so the discrepancy analysis can run (and be tested) on its own.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import nnls

from hysteresis.base import HysteresisError, HysteresisModel, as_1d, check_pair
from hysteresis.discrepancy._ops import FloatArray, play
from hysteresis.gamma import GammaModel


def pseudo_inverse(a: FloatArray) -> FloatArray:
    """The minimum-norm least-squares solver of ``a`` as a matrix (``x = P @ b``): singular
    values below ``numpy.linalg.lstsq``'s default cut-off (machine epsilon x the larger
    dimension x the largest) are dropped, so ``P @ b`` is its solution."""
    u, s, vt = np.linalg.svd(a, full_matrices=False)
    keep = s > np.finfo(np.float64).eps * max(a.shape) * (s[0] if s.size else 0.0)
    inv = np.zeros_like(s)
    inv[keep] = 1.0 / s[keep]
    return np.asarray((vt.T * inv) @ u.T, dtype=np.float64)


class PlaySumModel(HysteresisModel):
    """y = sum_i w_i play_{r_i}(u) + b, w_i >= 0 (any sign when ``signed``), each play's state
    starting at u[0] - start r_i (``start`` 0: at rest; 1: after a pull; -1: after a
    release)."""

    family = "play_sum"

    def __init__(self, *, thresholds: tuple[float, ...] | None = None, n: int = 11,
                 max_threshold: float | None = None, signed: bool = False,
                 start: float = 0.0) -> None:
        self.thresholds = thresholds
        self.n = n
        self.max_threshold = max_threshold
        self.signed = signed
        self.start = start

    def _r(self, u: FloatArray) -> FloatArray:
        if self.thresholds is not None:
            return np.asarray(self.thresholds, dtype=np.float64)
        top = self.max_threshold
        if top is None:
            # A third of the input range reaches every backlash the rig can show.
            top = max(float(np.ptp(u)) / 3.0, 1e-9)
        return np.linspace(0.0, top, self.n)

    def _design(self, u: FloatArray, r: FloatArray) -> FloatArray:
        cols = [play(u, float(ri), z0=float(u[0]) - self.start * float(ri)) for ri in r]
        cols.append(np.ones_like(u))
        return np.column_stack(cols)

    def fit(self, u: Any, y: Any, **fit_params: Any) -> PlaySumModel:
        if not -1.0 <= float(self.start) <= 1.0:
            raise HysteresisError(f"play_sum: start must lie in [-1, 1] (-1 after a release, 0 at "
                                  f"rest, 1 after a pull), got {self.start!r}")
        uu, yy = check_pair(u, y)
        r = self._r(uu)
        a = self._design(uu, r)
        self.thresholds_ = r
        self._solve(a, yy)
        self.u0_ = float(uu[0])
        self._design_for = (uu, a)
        return self

    def _solve(self, a: FloatArray, yy: FloatArray) -> None:
        n = self.thresholds_.size
        if self.signed:
            # The backfitting loop re-solves the same design for a new output thousands of
            # times per source (the screen's largest single cost, about a fifth of a slow
            # source's time): its pseudo-inverse is kept with the design it belongs to.
            cached: tuple[FloatArray, FloatArray] | None = getattr(self, "_pinv_for", None)
            if cached is None or cached[0] is not a:
                cached = (a, pseudo_inverse(a))
                self._pinv_for = cached
            w = cached[1] @ yy
            self.weights_ = np.asarray(w[:n], dtype=np.float64)
            self.offset_ = float(w[n])
            return
        # Non-negative weights (any gain: mm -> deg on a bending joint); the free offset is
        # split into a positive and a negative part so that NNLS can carry it.
        x, _ = nnls(np.column_stack([a, -a[:, -1]]), yy, maxiter=50 * a.shape[1])
        self.weights_ = np.asarray(x[:n], dtype=np.float64)
        self.offset_ = float(x[n] - x[n + 1])

    def refit_weights(self, u: Any, y: Any) -> PlaySumModel:
        """Re-solve the weights and offset for a new output over the same input (the
        thresholds kept; the play columns reused when ``u`` is the input of the last solve)."""
        self.check_fitted()
        uu, yy = check_pair(u, y)
        a = self._design_on(uu)
        self._solve(a, yy)
        self._design_for = (uu, a)
        return self

    def _design_on(self, uu: FloatArray) -> FloatArray:
        """The play columns on ``uu``: those of the last solve when ``uu`` is its input (a
        backfitting loop refits and predicts on one input thousands of times)."""
        cached: tuple[FloatArray, FloatArray] | None = getattr(self, "_design_for", None)
        if cached is not None and cached[0].shape == uu.shape and np.array_equal(cached[0], uu):
            return cached[1]
        return self._design(uu, self.thresholds_)

    def predict(self, u: Any, *, state: Any = None) -> FloatArray:
        self.check_fitted()
        a = self._design_on(as_1d(u, "u"))
        return np.asarray(a @ np.r_[self.weights_, self.offset_], dtype=np.float64)


class AffineModel(HysteresisModel):
    """y = a u + b (cannot represent any hysteresis, dead zone or backlash)."""

    family = "affine"

    def fit(self, u: Any, y: Any, **fit_params: Any) -> AffineModel:
        uu, yy = check_pair(u, y)
        a = np.column_stack([uu, np.ones_like(uu)])
        coef = np.linalg.solve(a.T @ a, a.T @ yy)
        self.gain_, self.offset_ = float(coef[0]), float(coef[1])
        return self

    def predict(self, u: Any, *, state: Any = None) -> FloatArray:
        self.check_fitted()
        uu = as_1d(u, "u")
        return np.asarray(self.gain_ * uu + self.offset_, dtype=np.float64)


class FrozenShapeModel(HysteresisModel):
    """y = a base(u) + b with ``fitted``, a base already fitted, kept as it is: its loop's
    shape (and start) frozen, only a gain and an offset refitted. A screen for an effect's
    parameters where no play sum draws the base's loop: one prediction of the fitted base per
    grid point instead of one iterative fit."""

    family = "frozen_shape"

    def __init__(self, fitted: HysteresisModel | None = None) -> None:
        self.fitted = fitted

    def _shape(self, u: FloatArray) -> FloatArray:
        if self.fitted is None:
            raise HysteresisError("frozen_shape: needs a fitted base")
        return np.asarray(self.fitted.predict(u), dtype=np.float64)

    def fit(self, u: Any, y: Any, **fit_params: Any) -> FrozenShapeModel:
        uu, yy = check_pair(u, y)
        a = np.column_stack([self._shape(uu), np.ones_like(uu)])
        (self.gain_, self.offset_), *_ = np.linalg.lstsq(a, yy, rcond=None)
        return self

    def predict(self, u: Any, *, state: Any = None) -> FloatArray:
        self.check_fitted()
        uu = as_1d(u, "u")
        return np.asarray(self.gain_ * self._shape(uu) + self.offset_, dtype=np.float64)


class TensionWidthGamma(GammaModel):
    """The Gamma play sum with every play's width in proportion to the output tension: the
    capstan law on each play. The friction a tendon meets along its sheath grows with its
    tension, and with it the input travel a reversal takes before the output follows; under a
    follower whose load grows with its travel (a return spring) the loop widens along the
    stroke, which plays of one width (or a Bouc-Wen loop) cannot draw.

    The widths follow ``T_out / T_ref`` (``T_ref``: the identification run's median output
    tension); the input tension is not used, as it jumps by the capstan ratio at every
    reversal where the friction along the sheath does not. Only a :class:`.effects.ComposedModel`
    reads the tension (it owns the run); this model's own ``fit(u, y)`` has no tension to read
    and fits the plain Gamma sum.
    """

    #: The run channel the widths follow (:class:`.runs.RunData` attribute).
    widths_follow = "tension_out"


LOCAL_BASES: dict[str, type[HysteresisModel]] = {
    "play_sum": PlaySumModel, "affine": AffineModel, "gamma_tension": TensionWidthGamma}


#: Where a record may start in a base's state space: at rest (the family's own start), after
#: a pull (the last motion rose to the first input: ``loaded``) or after a release.
STARTS = ("rest", "loaded", "unloaded")
#: Samples of the stroke that brings the base to a loaded or unloaded start.
_PREHISTORY_SAMPLES = 100


class FromRecordStart(HysteresisModel):
    """A base family whose own fit starts every record at rest, started instead where the
    record shows it starts: at rest, or at a band edge after a pull or a release.

    The state is reached the way the plant reached it: the base is driven through a stroke of
    the identification input's span that ends at the run's first input (from below for
    ``loaded``, from above for ``unloaded``), and the run is predicted from there. The start
    is chosen on the identification record (the one a plant starting loaded repeats on every
    run) and applied at every run's own first input; one of the edges must lower the squared
    error by :data:`hysteresis.gamma.START_GAIN` to be taken, as Gamma's fitted start position.
    """

    family = "from_record_start"

    def __init__(self, factory: Any = None) -> None:
        self.factory = factory

    def _prehistory(self, u0: float, start: str) -> FloatArray:
        if start == "rest":
            return np.zeros(0)
        s = np.sin(np.linspace(0.0, np.pi, _PREHISTORY_SAMPLES))[:-1]
        sign = -1.0 if start == "loaded" else 1.0
        return np.asarray(u0 + sign * self.span_ * s, dtype=np.float64)

    def _run(self, u: FloatArray, start: str) -> FloatArray:
        pre = self._prehistory(float(u[0]), start)
        out = self.base_.predict(np.r_[pre, u])
        return np.asarray(out[pre.size:], dtype=np.float64)

    def fit(self, u: Any, y: Any, **fit_params: Any) -> FromRecordStart:
        uu, yy = check_pair(u, y)
        self.base_ = self.factory().fit(uu, yy, **fit_params)
        self.span_ = float(np.ptp(uu))
        self._choose_start(uu, yy)
        return self

    def _choose_start(self, uu: FloatArray, yy: FloatArray) -> None:
        from hysteresis.gamma import START_GAIN

        sse = {s: float(np.sum((yy - self._run(uu, s)) ** 2)) for s in STARTS}
        best = min(sse, key=sse.__getitem__)
        self.start_ = best if sse[best] < (1.0 - START_GAIN) * sse["rest"] else "rest"

    @property
    def refit_warm(self) -> Callable[[Any, Any], FromRecordStart]:
        """The base's fit from its current shape (where it has one: a backfitting loop asks
        for it), the start chosen again."""
        warm = getattr(self.__dict__.get("base_"), "refit_warm", None)
        if warm is None:
            raise AttributeError("refit_warm")

        def refit(u: Any, y: Any) -> FromRecordStart:
            uu, yy = check_pair(u, y)
            warm(uu, yy)
            self._choose_start(uu, yy)
            return self

        return refit

    def predict(self, u: Any, *, state: Any = None) -> FloatArray:
        self.check_fitted()
        return self._run(as_1d(u, "u"), self.start_)
