"""Identification for compensation: a fitted model whose inverse can reach what it will be
asked for."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from hysteresis.base import HysteresisError, check_inverse_reach, make_family

log = logging.getLogger(__name__)
#: The widest play's reach, as fractions of the identification span, tried in turn when a fit's
#: inverse is refused.
NARROWER = (0.75, 0.5, 0.25)


def fit_family(name: str, u: np.ndarray, y: np.ndarray, params: Mapping[str, Any]) -> Any:
    return make_family(name, **dict(params)).fit(u, y)


def fit_reachable(name: str, u: np.ndarray, y: np.ndarray, params: Mapping[str, Any], *,
                  label: str) -> tuple[Any, str]:
    """Fit ``name`` and check that its inverse can reach what it will be asked for.

    A weighted-play fit whose thresholds reach the identification input's span (or whose total
    weight is <= 0) is refused by :func:`hysteresis.base.check_inverse_reach`; unless its
    thresholds were given explicitly, it is then refitted with ``max_threshold`` at 3/4, 1/2,
    1/4 of that span (the widest play must reverse inside the record; the default widths may
    reach the whole span, which predicts a lagging output well but leaves the widest play
    unidentified for an inverse) until one passes; if none does, the last refusal is raised and
    nothing is driven with it. Returns ``(model, note)``; ``note`` says what was refused and
    what was changed ("" when the first fit passed). ``params`` is the family's parameter
    mapping (its keys are the family's own).
    """
    span = (float(np.min(u)), float(np.max(u)))
    model = fit_family(name, u, y, params)
    try:
        check_inverse_reach(model, identified_range=span)
        return model, ""
    except HysteresisError as exc:
        if params.get("thresholds") is not None:
            raise
        note = f"{label}: {exc}"
    log.warning("%s; refitting with narrower plays", note)
    model, top = _refit_narrower(name, u, y, params, span)
    return model, f"{note} -> refitted with max_threshold={top:.4g}"


def _refit_narrower(name: str, u: np.ndarray, y: np.ndarray, params: Mapping[str, Any],
                    span: tuple[float, float]) -> tuple[Any, float]:
    """The first of the :data:`NARROWER` refits whose inverse passes (never wider than a given
    ``max_threshold``); the last one's refusal is raised."""
    width = span[1] - span[0]
    given = params.get("max_threshold")

    def refit(frac: float) -> tuple[Any, float]:
        top = frac * width if given is None else min(float(given), frac * width)
        return fit_family(name, u, y, {**dict(params), "max_threshold": top}), top

    *wider, last = NARROWER
    for frac in wider:
        model, top = refit(frac)
        try:
            check_inverse_reach(model, identified_range=span)
        except HysteresisError:
            continue
        return model, top
    model, top = refit(last)
    check_inverse_reach(model, identified_range=span)  # the last refusal is the error raised
    return model, top
