"""The no-hysteresis baseline: ``y(k) = gain * u(k - delay) + offset``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hysteresis.base import (
    FloatArray,
    HysteresisError,
    StatefulModel,
    as_1d,
    check_records,
    choose_form,
    records_sse,
    register_family,
)
from hysteresis.lag import delay_search_max


@dataclass
class LinearState:
    """The last ``delay`` inputs (oldest first); empty without delay."""

    history: FloatArray

    def copy(self) -> LinearState:
        return LinearState(self.history.copy())


@register_family("linear")
class LinearModel(StatefulModel):
    """Gain, offset and a pure delay in samples.

    Parameters
    ----------
    delay:
        Fixed delay in samples; ``None``: searched (see ``max_delay``).
    max_delay:
        With ``delay=None``, ``fit`` picks the delay in ``0..max_delay`` with the smallest mean
        squared error among those that keep the gain's sign without delay (half a period of
        lag with the gain reversed also fits a softening loop's phase), and keeps it only where
        it predicts the last 30 % of the record better than no delay; ``None``: up to twice
        the lag at which the output's velocity correlates best with the input's, at most a
        quarter of the record (:func:`hysteresis.lag.delay_search_max`) and a quarter of the
        input's period (on a periodic record a longer lag cannot be told from a loop's
        phase): a lag of seconds on a compliant drive is found without knowing the sample
        rate, and a record with no lag keeps ``delay_ = 0``.
    """

    def __init__(self, *, delay: int | None = None, max_delay: int | None = None) -> None:
        self.delay = delay
        self.max_delay = max_delay

    def fit(self, u: Any, y: Any, **fit_params: Any) -> LinearModel:
        """Least-squares gain and offset (and delay, if searched)."""
        if fit_params:
            raise HysteresisError(f"LinearModel.fit takes no extra arguments: {sorted(fit_params)}")
        recs = check_records(u, y)
        for name in ("delay", "max_delay"):
            value = getattr(self, name)
            if value is not None and int(value) < 0:
                raise HysteresisError(f"{name} must be >= 0 or None, got {value}")
        pairs = recs.pairs()
        delays: range | list[int]
        if self.delay is not None:
            delays = [int(self.delay)]
        else:
            top = self.max_delay
            if top is None:
                top = min(min(int(np.floor(delay_search_max(uu, yy, 1.0))),
                              _quarter_period(uu)) for uu, yy in pairs)
            delays = range(int(top) + 1)
        _, d, gain, off = _best_delay(pairs, delays, recs.u.size, self.delay)
        if self.delay is None and d > 0:
            # the searched delay is kept only where it predicts a held-out part of the record
            # better than none (a loop's phase also reads as a lag, and extrapolates badly)
            kept, _ = choose_form(lambda k: type(self)(delay=k), (d, 0), recs)
            if kept == 0:
                _, d, gain, off = _best_delay(pairs, [0], recs.u.size, 0)
        self.gain_ = gain
        self.offset_ = off
        self.delay_ = int(d)
        self.sse_ = records_sse(self, recs)
        self.n_samples_ = int(recs.u.size)
        return self

    def initial_state(self, u0: float = 0.0) -> LinearState:
        """Rest state: the input has been ``u0`` for ``delay_`` samples."""
        self.check_fitted()
        return LinearState(np.full(self.delay_, float(u0)))

    def _state(self, state: Any, u0: float) -> LinearState:
        if state is None:
            return self.initial_state(u0)
        st = state.copy() if isinstance(state, LinearState) else LinearState(
            np.asarray(state, dtype=np.float64).reshape(-1).copy()
        )
        if st.history.size != self.delay_:
            raise HysteresisError(
                f"state holds {st.history.size} past inputs, the delay is {self.delay_}"
            )
        return st

    def predict(self, u: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """Simulate; without a state the input is taken to have rested at ``u[0]``."""
        self.check_fitted()
        uu = as_1d(u, "u")
        st = self._state(state, float(uu[0]))
        full = np.concatenate([st.history, uu])
        y = self.gain_ * full[: uu.size] + self.offset_
        if return_state:
            return y, LinearState(full[full.size - self.delay_ :].copy())
        return y

    def invert(self, y_desired: Any, *, state: Any = None, return_state: bool = False) -> Any:
        """``u(k) = (y(k + delay) - offset) / gain``; the last ``delay`` inputs hold the last value.

        With a delay the first ``delay`` outputs depend only on the past (unreachable); with a
        state given the returned state is the one :meth:`predict` would reach on ``u``.
        """
        self.check_fitted()
        yd = as_1d(y_desired, "y_desired")
        if self.gain_ == 0:
            raise HysteresisError("linear model with zero gain has no inverse")
        d = self.delay_
        shifted = np.concatenate([yd[d:], np.full(min(d, yd.size), yd[-1])])[: yd.size]
        u = (shifted - self.offset_) / self.gain_
        if return_state:
            _, st = self.predict(u, state=state, return_state=True)
            return u, st
        return u

    def invert_step(self, y_k: float, state: Any = None) -> tuple[float, LinearState]:
        """Causal static inverse ``(y_k - offset) / gain`` (a delay cannot be undone causally)."""
        self.check_fitted()
        if self.gain_ == 0:
            raise HysteresisError("linear model with zero gain has no inverse")
        v = (float(y_k) - self.offset_) / self.gain_
        st = self._state(state, v)
        hist = np.concatenate([st.history, [v]])[1:] if self.delay_ else st.history
        return v, LinearState(hist)


def _best_delay(pairs: list[tuple[FloatArray, FloatArray]], delays: range | list[int],
                n: int, asked: int | None) -> tuple[float, int, float, float]:
    """(MSE, delay, gain, offset) of the delay in ``delays`` with the smallest mean squared
    error over the samples it explains, every record delayed on its own."""
    best: tuple[float, int, float, float] | None = None
    sign0 = 0.0  # the gain's sign without delay: a delay may not flip it
    for d in delays:
        # every record delayed on its own: no sample of one explains another's
        usable = [(uu[: uu.size - d], yy[d:]) for uu, yy in pairs if uu.size - d >= 1]
        if sum(x.size for x, _ in usable) < 2 or len(usable) < len(pairs):
            break
        x = np.concatenate([x for x, _ in usable])
        t = np.concatenate([t for _, t in usable])
        a = np.column_stack([x, np.ones(x.size)])
        coef, *_ = np.linalg.lstsq(a, t, rcond=None)
        mse = float(np.mean((a @ coef - t) ** 2))
        if best is None:
            sign0 = float(np.sign(coef[0]))
        elif float(np.sign(coef[0])) * sign0 < 0:
            # half a period of lag with the gain reversed also fits a loop in the MSE, but
            # predicts nothing the record did not show
            continue
        if best is None or mse < best[0]:
            best = (mse, d, float(coef[0]), float(coef[1]))
    if best is None:
        raise HysteresisError(f"too few samples ({n}) for delay {asked}")
    return best


def _quarter_period(u: FloatArray) -> int:
    """A quarter of the input's typical period, in samples: half the median spacing of its
    reversals (no cap when the input reverses fewer than three times)."""
    du = np.diff(u)
    moving = np.flatnonzero(du != 0)
    if moving.size < 2:
        return u.size
    sign = np.sign(du[moving])
    turns = moving[1:][sign[1:] != sign[:-1]]
    if turns.size < 3:
        return u.size
    return max(1, int(np.median(np.diff(turns)) // 2))
