"""Numerics shared by several families (no model code)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from hysteresis.base import FloatArray


def decimation_index(u: FloatArray, max_samples: int) -> npt.NDArray[np.intp]:
    """Indices of a rate-independent decimation: every k-th sample plus the input's turning
    points (so the decimated record sees the same reversals), at most about ``max_samples``
    (turning points are dropped first if a noisy input has too many of them)."""
    n = u.size
    stride = max(1, math.ceil(n / max(10, int(max_samples))))
    idx = np.arange(0, n, stride)
    if stride == 1:
        return idx
    du = np.diff(u)
    tol = 1e-6 * float(np.ptp(u))
    nz = np.flatnonzero(np.abs(du) > tol)
    if nz.size > 1:
        sgn = np.sign(du[nz])
        turns = nz[1:][sgn[1:] != sgn[:-1]]  # first sample of each new direction
        if turns.size <= max_samples // 2:
            idx = np.union1d(idx, np.concatenate([turns, np.array([n - 1])]))
    return idx


def decimation_indices(records: Any, max_samples: int) -> list[npt.NDArray[np.intp]]:
    """:func:`decimation_index` of each record of ``records`` (a :class:`hysteresis.base.
    Records`), the budget ``max_samples`` shared in proportion to the records' lengths."""
    total = max(1, int(records.u.size))
    return [decimation_index(uu, max(10, int(round(max_samples * uu.size / total))))
            for uu, _ in records.pairs()]
