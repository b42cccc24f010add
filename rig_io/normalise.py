"""Normalisation (seed 001 section 3.2): offsets removed at the start, and ``*_norm`` columns
divided by the run's maximum input amplitude."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def start_offset(x: FloatArray) -> float:
    """The first finite value (the rig's rest position at the start of the run)."""
    finite = np.flatnonzero(np.isfinite(x))
    return float(x[finite[0]]) if finite.size else float("nan")


def remove_offset(x: FloatArray) -> tuple[FloatArray, float]:
    """``x`` minus its start offset, and that offset."""
    off = start_offset(x)
    return x - off, off


def max_amplitude(x: FloatArray) -> float:
    """The largest |x| of an offset-free signal (nan-safe)."""
    return float(np.nanmax(np.abs(x))) if np.isfinite(x).any() else float("nan")


def normalise(input_: FloatArray, output: FloatArray, *,
              rezero_output: bool = True) -> dict[str, FloatArray | float]:
    """Offsets removed; ``input_norm``/``output_norm`` = value / max input amplitude.

    ``rezero_output=False`` keeps an absolute output (a tracker's or a camera's angle) as
    measured: a run that starts loaded then keeps its level, where re-zeroing at its first
    sample would shift it against every other run of the same plant by its start state."""
    u, u0 = remove_offset(input_)
    y, y0 = remove_offset(output) if rezero_output else (np.array(output, dtype=np.float64),
                                                         0.0)
    amp = max_amplitude(u)
    if not amp > 0:  # a still input: callers reject the run; avoid 0/0 warnings here
        amp = float("nan")
    return {"input": u, "output": y, "input_norm": u / amp, "output_norm": y / amp,
            "input_offset": u0, "output_offset": y0, "input_amplitude": amp}
