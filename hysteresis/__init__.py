"""The science: hysteresis model families behind one estimator face, their identification
and inverses, the papers' error statistics, and the discrepancy analysis.

Free of files and MLflow: arrays in, arrays and small result objects out.
"""

import importlib

from hysteresis.base import (
    FAMILY_MODULES,
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
for _module in FAMILY_MODULES:
    importlib.import_module(f"hysteresis.{_module}")

__all__ = [
    "METRIC_NAMES", "HysteresisError", "HysteresisModel", "NotFittedError", "error_statistics",
    "family_class", "family_names", "make_family", "register_family",
]
