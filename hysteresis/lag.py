"""How late the output can be: the range a delay search must cover, read from the data.

A fixed cap (half a second) misses the lags of long, compliant drives (seconds on a bending
joint with a long sheath). The output's velocity correlates best with the input's at the
lag where the output follows; a hysteresis loop adds its own phase lag, so that estimate is
an upper-leaning one, which is what a search range needs.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

#: The search never stops short of this (s): the latencies of cameras and controllers.
MIN_SEARCH_S = 0.5
#: ... and never reaches past this fraction of the record (a lag longer than that leaves too
#: little overlap to be told from the record itself).
MAX_RECORD_FRACTION = 0.25


def xcorr_lag(u: npt.ArrayLike, y: npt.ArrayLike, dt: float, *,
              max_lag_s: float | None = None) -> float:
    """The lag (s, >= 0) at which the output's velocity correlates best with the input's.

    Velocities (first differences) are used so that offsets and slow drift do not pull the
    peak; ``max_lag_s`` bounds the search (default: :data:`MAX_RECORD_FRACTION` of the
    record). 0.0 when either signal is still.
    """
    du = np.diff(np.asarray(u, dtype=np.float64))
    dy = np.diff(np.asarray(y, dtype=np.float64))
    ok = np.isfinite(du) & np.isfinite(dy)
    du, dy = np.where(ok, du, 0.0), np.where(ok, dy, 0.0)
    n = du.size
    if n < 4 or not (np.any(du) and np.any(dy)):
        return 0.0
    limit = MAX_RECORD_FRACTION * n * dt if max_lag_s is None else max_lag_s
    max_k = int(min(n - 2, max(1, np.floor(limit / dt))))
    size = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(dy, size) * np.conj(np.fft.rfft(du, size))
    corr = np.fft.irfft(spec, size)[: max_k + 1]  # corr[k] = sum du[i] dy[i + k]
    # normalise by the overlap so that long lags are not penalised for their shorter sum
    corr = corr / (n - np.arange(max_k + 1))
    # the first peak that comes close to the best: a periodic excitation correlates as well
    # one period later, and that is not a latency
    best = float(np.max(corr))
    if best <= 0.0:
        return 0.0
    left = np.concatenate([[-np.inf], corr[:-1]])
    right = np.concatenate([corr[1:], [-np.inf]])
    peaks = np.flatnonzero((corr >= left) & (corr >= right) & (corr >= 0.9 * best))
    return float(peaks[0]) * dt


def delay_search_max(u: npt.ArrayLike, y: npt.ArrayLike, dt: float) -> float:
    """The largest delay (s) a latency search should try on this record: twice the
    cross-correlation lag, at least :data:`MIN_SEARCH_S`, at most
    :data:`MAX_RECORD_FRACTION` of the record."""
    record = (np.asarray(u).size - 1) * dt
    cap = MAX_RECORD_FRACTION * record
    return float(min(max(MIN_SEARCH_S, 2.0 * xcorr_lag(u, y, dt)), max(cap, dt)))


def delay_grid(u: npt.ArrayLike, y: npt.ArrayLike, dt: float) -> list[float]:
    """Delays to try: whole samples, roughly geometric (1, 2, 3, 5, 8, 12, 18, 27, 40, then
    about 1.5x each step) up to :func:`delay_search_max`; a refinement between grid points
    finds the value."""
    top = delay_search_max(u, y, dt)
    steps = [1, 2, 3, 5, 8, 12, 18, 27, 40]
    while steps[-1] * dt <= top:
        steps.append(int(round(steps[-1] * 1.5)))
    return [k * dt for k in steps if k * dt <= top + 1e-12] or [dt]
