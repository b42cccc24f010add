"""The science: hysteresis model families behind one estimator face, their identification
and inverses, the papers' error statistics, and the discrepancy analysis.

Free of files and MLflow: arrays in, arrays and small result objects out.
"""

import importlib

from hysteresis.base import (
    HysteresisError,
    HysteresisModel,
    NotFittedError,
    family_class,
    family_names,
    make_family,
    register_family,
)
from hysteresis.metrics import METRIC_NAMES, error_statistics

# One module per family; each registers itself on import. Modules still being written are
# skipped only if absent (never on a real import error inside them).
for _module in ("linear", "gamma", "preisach", "bouc_wen", "coleman_hodgdon"):
    try:
        importlib.import_module(f"hysteresis.{_module}")
    except ModuleNotFoundError as exc:  # pragma: no cover - only while a family is missing
        if exc.name != f"hysteresis.{_module}":
            raise

__all__ = [
    "METRIC_NAMES", "HysteresisError", "HysteresisModel", "NotFittedError", "error_statistics",
    "family_class", "family_names", "make_family", "register_family",
]
