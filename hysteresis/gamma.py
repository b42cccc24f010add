"""Complex hysteresis operator Gamma_n of seed 001 (eq. 4.7-4.10): weighted discrete play operators.

``y(k) = offset + sum_i q_i gamma_i[v(k), w_i(k-1), p_i]`` with preassigned thresholds
``P = (p_1..p_n)``. The output is linear in ``Q``, so identification (eq. 4.10) is an exact
least-squares problem.

Defaults are derived from the identification record, never from a unit: the thresholds span
a fraction of the input's peak-to-peak range (the one of :data:`THRESHOLD_FRACTIONS` with the
least squared error; 1/6 is the thesis' 0..2 mm on its +-6 mm record); the weights are
non-negative, or free where a held-out part of the record says the loop bends the other way
(``constraint="auto"``), with a free output offset (a sum-to-one constraint only makes sense
when input and output share a unit and a unit gain; free weights are only kept where they
predict unseen data better, since they can also fit a lag or a sign flip as a "loop" that no
inverse can use); and every play starts at the first input, at
the place in its band (just came down, at rest in the middle, just came up, or between) that
fits the identification record best: a record that starts mid-stroke is not read as a jump from
zero, and a rig that always starts its records the same way is predicted from that start.
The thesis' exact setting is ``max_threshold=2.0, constraint="sum_to_one", fit_offset=False,
start_state="zero"``.

* ``constraint="auto"`` (default): the loop's orientation and curvature decided by the record:
  ``nonneg`` or ``free``, whichever fitted on the head of the identification record(s)
  predicts their last 30 % better (free weights must win by 10 %); ``constraint_`` says which.
  A non-negative sum bends its branches one way only (steeper after a reversal, as behind a
  backlash); a softening loop (Bouc-Wen, piezo stacks) or a mixed-sign play sum needs free
  weights.
* ``constraint="nonneg"``: ``Q >= 0`` (bounded-variable least squares).
* ``constraint="sum_to_one"``: minimise ``||A Q - y||^2`` subject to ``sum(Q) = 1``.
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

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from hysteresis._blas import single_thread_blas
from hysteresis.base import (
    FloatArray,
    HysteresisError,
    HysteresisModel,
    Records,
    StatefulModel,
    as_1d,
    check_inverse_reach,
    check_records,
    choose_form,
    register_family,
)
from hysteresis.play import (
    gamma_at,
    gamma_invert_exact,
    gamma_invert_sequence,
    gamma_simulate,
    play_matrix,
)

CONSTRAINTS = ("nonneg", "free", "sum_to_one")
#: ``constraint="auto"``: the loop's orientation and curvature decided by the record.
AUTO = "auto"
#: The forms ``auto`` chooses between, the physical one first (see ``constraint``).
AUTO_FORMS = ("nonneg", "free")
INVERSE_METHODS = ("exact", "bounded")
START_STATES = ("fit", "rest", "zero")
#: Where in its band every play starts with ``start_state="fit"``: ``w = u0 - position p``
#: (0: the input just came down to ``u0``; 1/2: at rest in the middle; 1: it just came up).
START_POSITIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: Relative drop in squared error a start position other than 0 must bring to be chosen.
START_GAIN = 0.05
#: Candidate widest thresholds, as fractions of the identification input's peak-to-peak range.
#: Up to the whole range: a lag of a good fraction of a period reads as a wide loop.
THRESHOLD_FRACTIONS = (1.0 / 12.0, 1.0 / 6.0, 1.0 / 3.0, 1.0 / 2.0, 3.0 / 4.0, 1.0)


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
        ``max_threshold=None``: derived from the identification input (module docstring).
    threshold_fraction:
        With ``max_threshold=None``: the widest threshold as this fraction of the
        identification input's peak-to-peak range, instead of the best of
        :data:`THRESHOLD_FRACTIONS` (1/6 is the thesis' proportion).
    thresholds:
        Explicit thresholds (overrides the two above); non-negative, distinct.
    constraint:
        ``"auto"`` (default): ``"nonneg"`` or ``"free"``, whichever fitted on the head of the
        identification record(s) predicts their last 30 % better (``constraint_`` records
        it; free weights must win by 10 %); ``"nonneg"`` (``Q >= 0``: branches that steepen
        after a reversal, as behind a backlash), ``"free"`` (any sign: also branches that
        flatten after a reversal, a softening loop, and mixed-sign play sums) or
        ``"sum_to_one"`` (seed 001 eq. 4.10 as the text means it).
    fit_offset:
        Also fit a constant output offset (not in the thesis).
    record_offsets:
        With ``fit_offset`` and several identification records: each record gets its own
        offset (a run-to-run zero: a tracker re-zeroed per run, a catheter that settles a few
        degrees elsewhere from one run to the next), so that their spread does not bend the
        weights; ``offset_`` (used from rest) is their plain mean, one vote per run, and
        ``record_offsets_`` keeps them. One record: the same fit as without.
    start_state:
        ``"fit"``: every play at ``w = u0 - position p`` at the first input ``u0``, the
        position (:data:`START_POSITIONS`) fitted on the identification record
        (``start_position_``) and used for every prediction from rest; ``"rest"``: position
        1/2 (centred); ``"zero"``: the thesis' ``W(0) = 0`` whatever the first input.
    inverse_method:
        ``"exact"`` (breakpoint walk) or ``"bounded"`` (the thesis' bounded scalar search).
    search_radius:
        Half-width of the bounded search interval around the previous input, in input units
        (``None``: ``max(P)`` plus twice the output step divided by ``sum(Q)``).
    xatol:
        Input tolerance of the bounded search (``None``: 1e-10 of the identification input's
        range, so it means the same in any unit).
    """

    def __init__(
        self,
        *,
        n_operators: int = 11,
        max_threshold: float | None = None,
        threshold_fraction: float | None = None,
        thresholds: list[float] | None = None,
        constraint: str = "auto",
        fit_offset: bool = True,
        record_offsets: bool = True,
        start_state: str = "fit",
        inverse_method: str = "exact",
        search_radius: float | None = None,
        xatol: float | None = None,
    ) -> None:
        self.n_operators = n_operators
        self.max_threshold = max_threshold
        self.threshold_fraction = threshold_fraction
        self.thresholds = thresholds
        self.constraint = constraint
        self.fit_offset = fit_offset
        self.record_offsets = record_offsets
        self.start_state = start_state
        self.inverse_method = inverse_method
        self.search_radius = search_radius
        self.xatol = xatol

    @classmethod
    def from_params(cls, thresholds: Any, weights: Any, offset: float = 0.0, *,
                    start_position: float = 0.0) -> GammaModel:
        """A model with known parameters (the thesis' Table 4.1, a plant's), fitted to nothing.

        Every play starts at ``w = u0 - start_position p`` (``start_state="fit"``): with the
        default 0 an initial state is every play at the first input.
        """
        p = _check_thresholds(np.array(thresholds, dtype=np.float64))
        q = np.array(weights, dtype=np.float64)
        if q.shape != p.shape or not np.all(np.isfinite(q)):
            raise HysteresisError(
                f"weights must be {p.size} finite values (one per threshold), got {q.tolist()}")
        if not (np.isfinite(offset) and np.isfinite(start_position)):
            raise HysteresisError(
                f"offset and start_position must be finite, got {offset}, {start_position}")
        model = cls(thresholds=p.tolist())
        model.thresholds_, model.weights_ = p, q
        model.offset_, model.start_position_ = float(offset), float(start_position)
        # NaN multiplier: no sum-to-one constraint was solved (as a fit without one reports)
        model.lagrange_multiplier_, model.sse_, model.n_samples_ = float("nan"), 0.0, 0
        # no identification record: the widest play stands for its span (bounded search tolerance)
        model.input_span_ = float(p.max()) or 1.0
        return model

    @classmethod
    def structure_candidates(cls, models: Sequence[HysteresisModel]) -> list[dict[str, Any]]:
        """Each distinct threshold grid of ``models`` when their fits chose different ones:
        weights of plays of different widths do not compare, so a regression over shapes
        needs every model refitted on one grid."""
        grids: list[FloatArray] = []
        for m in cast("Sequence[GammaModel]", models):
            g = np.asarray(m.thresholds_, dtype=np.float64)
            if not any(g.shape == h.shape and np.array_equal(g, h) for h in grids):
                grids.append(g)
        return [] if len(grids) < 2 else [{"thresholds": g.tolist()} for g in grids]

    # -- hyper-parameters -------------------------------------------------------------
    def _threshold_candidates(self, uu: FloatArray) -> list[FloatArray]:
        """The threshold vectors to try: the given ones, or one per derived span."""
        if self.thresholds is not None:
            p = np.asarray(list(self.thresholds), dtype=np.float64)
            return [_check_thresholds(p)]
        if int(self.n_operators) < 1:
            raise HysteresisError(f"n_operators must be >= 1, got {self.n_operators}")
        if self.max_threshold is not None:
            if not self.max_threshold >= 0:
                raise HysteresisError(f"max_threshold must be >= 0, got {self.max_threshold}")
            tops = [float(self.max_threshold)]
        else:
            span = float(np.ptp(uu))
            if not span > 0:
                raise HysteresisError("the identification input is constant: no threshold "
                                      "can be derived from it; give max_threshold")
            fractions = THRESHOLD_FRACTIONS if self.threshold_fraction is None \
                else (float(self.threshold_fraction),)
            if not all(0 < f < np.inf for f in fractions):
                raise HysteresisError(
                    f"threshold_fraction must be > 0, got {self.threshold_fraction}")
            tops = [f * span for f in fractions]
        # copies: a fitted model owns its thresholds
        return [g.copy() for g in _play_grids(tuple(tops), int(self.n_operators))]

    def play_setup(self, u: Any, y: Any = None) -> tuple[FloatArray, float]:
        """(thresholds, start position) a fit on ``(u, y)`` uses: the fitted ones; else the
        candidate pair with the least squared error. Without ``y``: the widest play at 1/6 of
        the input's range (the thesis' proportion) and the first start position."""
        if hasattr(self, "thresholds_"):
            return self.thresholds_, float(getattr(self, "start_position_", 0.5))
        if y is None:
            cands = self._threshold_candidates(as_1d(u, "u"))
            p = cands[THRESHOLD_FRACTIONS.index(1.0 / 6.0)] if len(cands) > 1 else cands[0]
            return p, self._positions()[0]
        return self._choose_setup(check_records(u, y))

    def start_outputs(self, u0: float, p: Any, position: float | None = None) -> FloatArray:
        """Every play's output before the first sample ``u0`` (see ``start_state``)."""
        return self._start(float(u0), np.asarray(p, dtype=np.float64), position)

    def _positions(self) -> tuple[float, ...]:
        """The start positions a fit tries (one unless ``start_state="fit"``)."""
        if self.start_state not in START_STATES:
            raise HysteresisError(
                f"start_state must be one of {START_STATES}, got {self.start_state!r}")
        if self.start_state == "fit":
            return START_POSITIONS
        return (0.5,)

    def _start(self, u0: float, p: FloatArray, position: float | None = None) -> FloatArray:
        """Every play's output before the first sample ``u0`` (see ``start_state``)."""
        if self.start_state == "zero":
            return np.zeros(p.size)
        if position is None:
            position = float(getattr(self, "start_position_", self._positions()[0]))
            if self.start_state == "rest":
                position = 0.5
        return u0 - position * p

    # -- identification ---------------------------------------------------------------
    def design_matrix(self, u: Any, y: Any = None) -> FloatArray:
        """Play-operator outputs (one column per threshold) over ``u`` from the initial state:
        the fitted thresholds and start, else :meth:`play_setup` ``(u, y)``."""
        uu = as_1d(u, "u")
        p, pos = self.play_setup(uu, y)
        a, _ = play_matrix(uu, p, self._start(float(uu[0]), p, pos))
        return np.asarray(a)

    def fit(self, u: Any, y: Any, **fit_params: Any) -> GammaModel:
        """Identify ``Q`` (and the offset) by exact (constrained) least squares, zero state."""
        if fit_params:
            raise HysteresisError(f"GammaModel.fit takes no extra arguments: {sorted(fit_params)}")
        if self.constraint not in (AUTO, *CONSTRAINTS):
            raise HysteresisError(
                f"constraint must be {AUTO!r} or one of {CONSTRAINTS}, got {self.constraint!r}"
            )
        recs = check_records(u, y)
        constraint = str(self.constraint)
        if constraint == AUTO:
            params = self.get_params()
            constraint, _ = choose_form(
                lambda form: type(self)(**{**params, "constraint": form}), AUTO_FORMS, recs)
        sse, p, x, lam, pos = self._best_fit(recs, constraint)
        self.start_position_ = pos
        self.thresholds_ = p
        self._take_solution(recs, x, lam, sse, constraint)
        return self

    def refit_weights(self, u: Any, y: Any) -> GammaModel:
        """Re-solve the weights (and offsets) for a new output ``y`` over the same input, the
        fitted thresholds, start position and constraint kept: one least squares, no screening
        of the setup. A backfitting loop refits one input many times against outputs that
        differ by a small term; :meth:`fit` once more at its end re-chooses the setup."""
        self.check_fitted()
        recs = check_records(u, y)
        p, pos = self.thresholds_, float(self.start_position_)
        plays, a, q, r = self._refit_design(recs, p, pos)
        if a.shape[0] < a.shape[1]:
            raise HysteresisError(f"need at least {a.shape[1]} samples to fit, got {a.shape[0]}")
        # the same minimiser on the QR-reduced k x k problem (the design is factored once)
        x, lam = solve_play_weights(r, q.T @ recs.y, n_weights=p.size,
                                    constraint=str(self.constraint_))
        n = p.size
        if x.size > n + 1:
            resid = plays @ x[:n] + float(np.mean(x[n:])) - recs.y
        else:
            resid = a @ x - recs.y
        self._take_solution(recs, x, lam, float(resid @ resid), str(self.constraint_))
        return self

    def _refit_design(self, recs: Records, p: FloatArray, pos: float
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(plays, design, Q, R) over the records' input: the last ones when the input,
        thresholds and start are those of the previous :meth:`refit_weights`."""
        key = (recs.u.tobytes(), p.tobytes(), pos, recs.bounds)
        cached = getattr(self, "_refit_cache", None)
        if cached is not None and cached[0] == key:
            return cast("tuple[FloatArray, FloatArray, FloatArray, FloatArray]", cached[1])
        plays = np.asarray(self._plays(recs, p, pos), dtype=np.float64)
        a = np.asarray(self._design(plays, recs), dtype=np.float64)
        with single_thread_blas():
            q, r = np.linalg.qr(a)
        self._refit_cache = (key, (plays, a, q, r))
        return plays, a, q, r

    def _take_solution(self, recs: Records, x: FloatArray, lam: float, sse: float,
                       constraint: str) -> None:
        """Set the fitted weights, offsets and statistics from a solution ``x`` (in the order
        a saved model lists them)."""
        n = self.thresholds_.size
        self.weights_ = np.ascontiguousarray(x[:n])
        offsets = np.asarray(x[n:], dtype=np.float64)
        self.offset_ = float(np.mean(offsets)) if offsets.size else 0.0
        self.__dict__.pop("record_offsets_", None)
        if offsets.size > 1:
            self.record_offsets_ = offsets
        self.lagrange_multiplier_ = lam
        self.constraint_ = constraint
        self.sse_ = sse
        self.n_samples_ = int(recs.u.size)
        self.input_span_ = float(np.ptp(recs.u))

    def _best_fit(self, recs: Records, constraint: str
                  ) -> tuple[float, FloatArray, FloatArray, float, float]:
        """(SSE, thresholds, solution, multiplier, start position) of the best candidate.

        Width and start position are chosen together: a wide loop screened with every play
        at the wrong start misfits the first stroke and loses to a narrower one that should
        not win. At each width, a start position other than the first must lower the
        squared error by :data:`START_GAIN`: a clean record that starts where the thesis
        assumes keeps it, so the fits of a campaign's shapes stay comparable (the shape-aware
        model regresses their weights), while a record that clearly starts elsewhere gets its
        own start. Candidates are compared on the QR-reduced problem (a k x k least squares
        with the same minimiser); the chosen one is solved on the full record.
        """
        p, pos = self._choose_setup(recs, constraint)
        plays = self._plays(recs, p, pos)
        x, lam = self._solve(plays, recs.y, constraint, recs)
        n = p.size
        if x.size > n + 1:  # the error as the model predicts: with the mean record offset
            resid = np.asarray(plays) @ x[:n] + float(np.mean(x[n:])) - recs.y
        else:
            resid = self._design(plays) @ x - recs.y
        return float(resid @ resid), p, x, lam, pos

    def _plays(self, recs: Records, p: FloatArray, pos: float) -> FloatArray:
        """Play outputs over every record, each record's plays started at its own first
        input (stacked: one least squares over all records, no seam between them)."""
        mats = [np.asarray(play_matrix(uu, p, self._start(float(uu[0]), p, pos))[0])
                for uu, _ in recs.pairs()]
        return mats[0] if len(mats) == 1 else np.vstack(mats)

    def _choose_setup(self, recs: Records,
                      constraint: str | None = None) -> tuple[FloatArray, float]:
        """(thresholds, start position) of the best candidate, screened on the QR-reduced
        problem (see :meth:`_best_fit`); no solve on the full record."""
        constraint = constraint or self.weight_constraint
        spans = self._threshold_candidates(recs.u)
        positions = self._positions()
        if len(spans) == 1 and len(positions) == 1:
            return spans[0], positions[0]
        screened: list[tuple[float, int, float]] = []
        for i, c in enumerate(spans):
            scores = [self._screen(recs, c, pos, constraint) for pos in positions]
            k = int(np.argmin(scores))
            if scores[k] > (1.0 - START_GAIN) * scores[0]:
                k = 0
            screened.append((scores[k], i, positions[k]))
        _, i, pos = min(screened)
        return spans[i], pos

    def check_reach(self, *, identified_range: tuple[float, float] | None = None,
                    desired: Any = None) -> None:
        """Refuse an inverse that cannot reach the ``desired`` outputs, from the weights and
        thresholds alone (O(n_operators)): :class:`HysteresisError` naming the range when

        * the total weight ``sum(Q)`` is <= 0: the outer slope of ``v -> Gamma(v)`` then
          points the wrong way (or nowhere), so outputs beyond the loop are unreachable and
          the nearest reachable one drives the plant away from the target;
        * a threshold reaches the span of the identification input ``identified_range``: that
          play never reversed inside the record (from rest it does not even move), so its
          weight is not identified (it only trades against the offset and the other weights)
          and the inverse relies on it beyond the data.
        """
        q = np.asarray(self.weights_, dtype=np.float64).ravel()
        p = np.asarray(self.thresholds_, dtype=np.float64).ravel()
        name = type(self).__name__
        where = ""
        lo = hi = 0.0
        if identified_range is not None:
            lo, hi = (float(v) for v in identified_range)
            where = f" (identified on inputs {lo:.4g}..{hi:.4g})"
        total = float(q.sum())
        wide = bool(identified_range is not None and p.size
                    and float(p.max()) >= (hi - lo) * (1 - 1e-9))
        if total > 0 and not wide:
            return
        asked = ""  # only built for the message
        if desired is not None:
            yd = np.asarray(desired, dtype=np.float64)
            if yd.size:
                asked = f"; demanded outputs {float(np.min(yd)):.4g}..{float(np.max(yd)):.4g}"
        if not total > 0:
            chose = (" (constraint='auto' chose free weights for this loop's shape)"
                     if self.constraint == AUTO else "")
            raise HysteresisError(
                f"{name} cannot reach the demanded outputs{where}: its total weight sum(Q) = "
                f"{total:.4g} <= 0, so its output does not rise with the input beyond the "
                f"loop{chose}{asked}; refit with constraint='nonneg' or 'sum_to_one' for an "
                f"invertible model, or with thresholds inside the identification range")
        raise HysteresisError(
            f"{name} cannot be trusted to reach the demanded outputs{where}: thresholds up to "
            f"{float(p.max()):.4g} reach the identification range's span {hi - lo:.4g}, so "
            f"the widest plays never reversed inside it and their weights are not identified"
            f"{asked}; refit with max_threshold < {hi - lo:.4g}")

    @property
    def weight_constraint(self) -> str:
        """The constraint in force: the fitted one, else the setting (``auto`` screens as
        its physical form until a fit decides)."""
        fitted = getattr(self, "constraint_", None)
        if fitted is not None:
            return str(fitted)
        return AUTO_FORMS[0] if self.constraint == AUTO else str(self.constraint)

    def _screen(self, recs: Records, p: FloatArray, pos: float, constraint: str) -> float:
        """Squared error of the candidate (thresholds ``p``, start ``pos``), through the QR
        reduction: ``||A x - y||^2 = ||R x - Q^T y||^2 + ||y||^2 - ||Q^T y||^2``."""
        yy = recs.y
        a = self._design(self._plays(recs, p, pos), recs)
        with single_thread_blas():
            gram, aty = a.T @ a, a.T @ yy
            try:  # R^T R = A^T A: R is Q^T A's triangle (up to signs), for a fraction of a QR
                r = np.linalg.cholesky(gram).T
                qty = np.linalg.solve(r.T, aty)
            except np.linalg.LinAlgError:  # rank-deficient candidate: the QR itself
                q, r = np.linalg.qr(a)
                qty = q.T @ yy
        x, _ = solve_play_weights(np.asarray(r, dtype=np.float64),
                                  np.asarray(qty, dtype=np.float64), n_weights=p.size,
                                  constraint=constraint)
        rest = float(yy @ yy - qty @ qty)
        e = r @ x - qty
        return float(e @ e) + max(rest, 0.0)

    def _design(self, plays: Any, recs: Records | None = None) -> FloatArray:
        """Plays, then the offset column(s): one, or one per record (``record_offsets``)."""
        a = np.asarray(plays)
        if not self.fit_offset:
            return a
        if recs is None or recs.n_records == 1 or not self.record_offsets:
            return np.column_stack([a, np.ones(a.shape[0])])
        ones = np.zeros((a.shape[0], recs.n_records))
        for j, part in enumerate(recs.slices()):
            ones[part, j] = 1.0
        return np.column_stack([a, ones])

    def _solve(self, plays: Any, yy: FloatArray, constraint: str,
               recs: Records | None = None) -> tuple[FloatArray, float]:
        """Exact (constrained) least squares for ``Q`` (and the offsets) on one play matrix."""
        a = self._design(plays, recs)
        if a.shape[0] < a.shape[1]:
            raise HysteresisError(f"need at least {a.shape[1]} samples to fit, got {a.shape[0]}")
        return solve_play_weights(a, yy, n_weights=np.asarray(plays).shape[1],
                                  constraint=constraint)

    # -- simulation -------------------------------------------------------------------
    def initial_state(self, u0: float = 0.0) -> GammaState:
        """The identification state at the input ``u0``: every play at rest centred on ``u0``,
        or (``start_state="zero"``) seed 001's ``W = 0`` after ``u0`` is applied once."""
        self.check_fitted()
        v = float(u0)
        w = np.minimum(v, np.maximum(v - self.thresholds_, self._start(v, self.thresholds_)))
        return GammaState(w, v)

    def _state(self, state: Any, u0: float = 0.0) -> GammaState:
        if state is None:
            return self.initial_state(u0)
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
        """Simulate from the rest state at ``u[0]`` (or ``state``); ``return_state``: also the
        end state."""
        self.check_fitted()
        uu = as_1d(u, "u")
        st = self._state(state, float(uu[0]))
        y, w = gamma_simulate(uu, self.thresholds_, self.weights_, self.offset_, st.w)
        if return_state:
            return y, GammaState(w, float(uu[-1]))
        return y

    def step(self, u_k: float, state: Any = None) -> tuple[float, GammaState]:
        """One forward step: ``(y_k, state_k)`` from ``u_k`` and ``state_{k-1}`` (not modified)."""
        self.check_fitted()
        st = self._state(state, float(u_k))
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
        if state is None and self.start_state != "zero":
            # from the start state the output is affine in the input: start where it is y_k
            v = self._rest_input(float(y_k))
            return v, self.initial_state(v)
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
            options={"xatol": self._xatol()},
        )
        return float(res.x)

    def _rest_input(self, y0: float) -> float:
        """The input whose start output is ``y0`` (where an inverse from rest starts)."""
        total = float(self.weights_.sum())
        if abs(total) < 1e-12:
            return 0.0
        start_at_zero = self.offset_ + float(self.weights_ @ self._start(0.0, self.thresholds_))
        return (y0 - start_at_zero) / total

    def _xatol(self) -> float:
        if self.xatol is not None:
            return float(self.xatol)
        span = float(getattr(self, "input_span_", 0.0)) or float(self.thresholds_.max()) or 1.0
        return 1e-10 * span

    def invert(
        self, y_desired: Any, *, state: Any = None, method: str | None = None,
        return_state: bool = False,
    ) -> Any:
        """Inverse input sequence (state carried); ``return_state``: also the end state."""
        self.check_fitted()
        yd = as_1d(y_desired, "y_desired")
        check_inverse_reach(self, desired=yd)
        meth = method or self.inverse_method
        if meth not in INVERSE_METHODS:
            raise HysteresisError(f"inverse method must be one of {INVERSE_METHODS}, got {meth!r}")
        head: list[float] = []
        if state is None and self.start_state != "zero":
            u0, st = self.invert_step(float(yd[0]))
            head, yd = [u0], yd[1:]
        else:
            st = self._state(state)
        if yd.size == 0:
            u, end = np.empty(0), st
        elif meth == "exact":
            u, w, v = gamma_invert_sequence(
                yd, self.thresholds_, self.weights_, self.offset_, st.w, st.u
            )
            end = GammaState(w, float(v))
        else:
            u = np.empty(yd.size)
            for k in range(yd.size):
                u[k], st = self.invert_step(float(yd[k]), st, method="bounded")
            end = st
        u = np.concatenate([np.asarray(head, dtype=np.float64), u])
        return (u, end) if return_state else u


def solve_play_weights(a: FloatArray, y: FloatArray, *, n_weights: int,
                       constraint: str) -> tuple[FloatArray, float]:
    """Least squares ``a x ~ y`` where the first ``n_weights`` columns are play operators:
    their weights constrained as ``constraint`` says (the other columns are free). Returns the
    solution and the sum-to-one Lagrange multiplier (NaN for the other constraints)."""
    if constraint not in CONSTRAINTS:
        raise HysteresisError(f"constraint must be one of {CONSTRAINTS}, got {constraint!r}")
    # tiny dense problem: BLAS threads only add contention (fits run in parallel)
    with single_thread_blas():
        if constraint == "free":
            x, *_ = np.linalg.lstsq(a, y, rcond=None)
            return np.asarray(x, dtype=np.float64), float("nan")
        if constraint == "nonneg":
            lower = np.full(a.shape[1], -np.inf)
            lower[:n_weights] = 0.0
            if a.shape[0] > 2 * a.shape[1]:
                # same minimiser on the k x k QR-reduced problem, and BVLS is cheap there
                q, r = np.linalg.qr(a)
                a, y = r, q.T @ y
            res = lsq_linear(a, y, bounds=(lower, np.inf), method="bvls")
            # BVLS may leave an active bound a rounding error outside (-3.5e-18 with one
            # OpenBLAS kernel, 0.0 with another): the weights must satisfy Q >= 0 exactly.
            sol = np.asarray(res.x, dtype=np.float64).copy()
            sol[:n_weights] = np.maximum(sol[:n_weights], 0.0)
            return np.asarray(sol, dtype=np.float64), float("nan")
        c = np.zeros(a.shape[1])
        c[:n_weights] = 1.0  # the sum of the weights (other columns unconstrained)
        return constrained_lstsq(a, y, c, 1.0)


@functools.lru_cache(maxsize=256)
def _play_grids(tops: tuple[float, ...], n: int) -> tuple[FloatArray, ...]:
    """Evenly spaced thresholds from 0 to each top, checked: a discrepancy search fits
    thousands of times on the same few records, so the same spans recur."""
    return tuple(_check_thresholds(np.linspace(0.0, top, n)) for top in tops)


def _check_thresholds(p: FloatArray) -> FloatArray:
    # plain Python on the handful of values: a fit checks them thousands of times in a search
    values = p.tolist() if p.ndim == 1 else []
    if not values or not all(math.isfinite(v) and v >= 0 for v in values):
        raise HysteresisError(f"thresholds must be finite and >= 0, got {p.tolist()}")
    if len(set(values)) != len(values):
        raise HysteresisError(f"thresholds must be distinct, got {p.tolist()}")
    return p


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
    z_basis = _null_space_basis(np.ascontiguousarray(c, dtype=np.float64).tobytes())
    z, *_ = np.linalg.lstsq(a @ z_basis, y - a @ x0, rcond=None)
    x = x0 + z_basis @ z
    grad = a.T @ (a @ x - y)
    lam = -float(c @ grad) / cc
    return x, lam


@functools.lru_cache(maxsize=64)
def _null_space_basis(c_bytes: bytes) -> FloatArray:
    """An orthonormal basis of the constraint vector's null space: the trailing columns of
    the Householder QR of ``c``. Cached: a discrepancy search solves thousands of problems
    with the same few constraint vectors, and the QR call costs as much as the solve."""
    c = np.frombuffer(c_bytes, dtype=np.float64)
    qmat, _ = np.linalg.qr(c.reshape(-1, 1), mode="complete")
    z_basis = np.ascontiguousarray(qmat[:, 1:])
    z_basis.setflags(write=False)
    return z_basis


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
