"""The papers' error statistics, all from the error ``e = measured - model``.

* seed 001 Table 4.1: SSE = sum e^2 (at the rig's 100 Hz);
* seed 001 Table 4.2: sample standard deviation S_{n-1}, mean error, max-min error range, RMSE;
* seed 000 eq. 27-28: mean |error| and the (population, 1/N) variance of the error.
"""

from __future__ import annotations

from typing import Any

import numpy as np

METRIC_NAMES = (
    "n", "sse", "mse", "rmse", "std_error", "mean_error", "error_range",
    "mean_abs_error", "var_error",
)


def error_statistics(measured: Any, model: Any) -> dict[str, float]:
    """All statistics of ``measured - model`` as a flat dict (keys :data:`METRIC_NAMES`).

    Samples where either signal is NaN are dropped (a camera frame that was not measured).
    """
    y = np.asarray(measured, dtype=np.float64)
    yhat = np.asarray(model, dtype=np.float64)
    if y.shape != yhat.shape:
        raise ValueError(f"measured and model differ in shape: {y.shape} vs {yhat.shape}")
    e = (y - yhat)[np.isfinite(y) & np.isfinite(yhat)]
    n = int(e.size)
    if n == 0:
        raise ValueError("no finite samples to compare")
    sse = float(np.sum(e**2))
    mean = float(np.mean(e))
    return {
        "n": float(n),
        "sse": sse,
        "mse": sse / n,
        "rmse": float(np.sqrt(sse / n)),
        "std_error": float(np.std(e, ddof=1)) if n > 1 else float("nan"),
        "mean_error": mean,
        "error_range": float(np.max(e) - np.min(e)),
        "mean_abs_error": float(np.mean(np.abs(e))),
        "var_error": float(np.mean((e - mean) ** 2)),
    }
