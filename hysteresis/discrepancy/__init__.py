"""The discrepancy workflow: locate where a fitted model and the measurements disagree, name
the missing physical effect from a candidate library, add its term, refit, and show the gap
shrink on held-out runs. Pure arrays in, small dicts out (no files, no MLflow).
"""

from hysteresis.discrepancy.effects import CANDIDATES, EFFECT_NAMES, ComposedModel, Term, candidate
from hysteresis.discrepancy.locate import locate, noise_floor
from hysteresis.discrepancy.runs import RunData

__all__ = ["CANDIDATES", "EFFECT_NAMES", "ComposedModel", "RunData", "Term", "candidate",
           "locate", "noise_floor"]
