"""The discrepancy workflow: locate where a fitted model and the measurements disagree, name
the missing physical effect from a candidate library, add its term, refit, and show the gap
shrink on held-out runs. Pure arrays in, small dicts out (no files, no MLflow).

Modules: :mod:`.runs` (the arrays of one run), :mod:`.locate` (residual analysis),
:mod:`.effects` (the candidate library and the composed model), :mod:`.workflow` (the loop),
:mod:`.bases` (two small local base models), :mod:`.analysis` (the discrepancy stage's
computation: :mod:`.ranking` chooses the base, :mod:`.base_check` checks a given one,
:mod:`.headline` says the answer).
"""

from hysteresis.discrepancy.effects import CANDIDATES, EFFECT_NAMES, ComposedModel, Term, candidate
from hysteresis.discrepancy.runs import RunData, concat_runs

__all__ = ["CANDIDATES", "EFFECT_NAMES", "ComposedModel", "RunData", "Term", "candidate",
           "concat_runs"]
