"""Which base family answers: every standard family scored by its plain held-out RMSE
(:func:`rank_bases`), and of the workflow's answers on several bases the one whose model with
its terms predicts the held-out runs best (:func:`pick_base`). Pure: runs in, scores out."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from hysteresis.discrepancy.effects import ComposedModel
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import base_factory_for, evaluate, group_runs

log = logging.getLogger(__name__)

#: A family as the ranking keeps it: (registered or local family name, its parameters).
Spec = tuple[str, dict[str, Any]]

#: A base that reads a channel beyond the input (plays whose widths follow the output tension,
#: :class:`.bases.TensionWidthGamma`) ranks only where it predicts the held-out runs this
#: fraction better than every base of fixed shape: under a follower of constant load its
#: widths hardly change, it is the free Gamma sum again, and as the second base tried it would
#: repeat the first instead of giving another family's answer. (On a clean-room capstan loop
#: under a return spring it left 0.010-0.024 mm where the best fixed base left 0.094.)
CHANNEL_BASE_GAIN = 0.2


def reads_channel(name: str) -> str:
    """The run channel a local base family reads beyond the input ('' for none)."""
    from hysteresis.discrepancy.bases import LOCAL_BASES

    return str(getattr(LOCAL_BASES.get(name), "widths_follow", "") or "")


def runs_lacking(runs: list[RunData], name: str) -> tuple[str, list[str]]:
    """The channel base family ``name`` reads beyond the input, and the ids of the runs that
    do not carry it (``("", [])`` for a family that reads none)."""
    channel = reads_channel(name)
    return channel, [r.run_id for r in runs if channel and getattr(r, channel) is None]


def rank_bases(runs: list[RunData], families: Mapping[str, Mapping[str, Any]]
               ) -> tuple[str, dict[str, Any], dict[str, float], dict[str, Spec]]:
    """Every family of ``families`` scored by its plain held-out RMSE: (best family, its
    parameters, scores by label, (family, parameters) by label)."""
    groups = group_runs(runs)
    scores: dict[str, float] = {}
    specs: dict[str, Spec] = {}
    reading: list[str] = []
    for label, spec in families.items():
        params = dict(spec or {})
        name = str(params.pop("family", label))
        channel, lacking = runs_lacking(runs, name)
        if channel:
            if lacking:
                log.info("base family %s not ranked: the runs do not all carry %s", label,
                         channel)
                continue
            reading.append(label)
        try:
            factory = base_factory_for(name, **params)
            models = {g.key: ComposedModel(factory).fit(g.ident) for g in groups}
            _, e_h = evaluate(models, groups).errors(groups)
            score = float(np.sqrt(np.mean(e_h**2)))
        except Exception as err:  # a family that cannot fit this data is simply not chosen
            log.warning("base family %s skipped: %s", label, err)
            continue
        if math.isfinite(score):
            scores[label] = score
            specs[label] = (name, params)
    fixed = [v for k, v in scores.items() if k not in reading]
    for label in [k for k in reading if k in scores]:
        if fixed and scores[label] > (1.0 - CHANNEL_BASE_GAIN) * min(fixed):
            log.info("base family %s not ranked: %.4g held out, not %g better than the best "
                     "base of fixed shape (%.4g)", label, scores[label], CHANNEL_BASE_GAIN,
                     min(fixed))
            del scores[label], specs[label]
    if not scores:
        raise DiscrepancyError("no base family could be fitted to this source")
    best = min(scores, key=scores.__getitem__)
    return specs[best][0], specs[best][1], scores, specs


def choose_base(runs: list[RunData], families: Mapping[str, Mapping[str, Any]]
                ) -> tuple[str, dict[str, Any], dict[str, float]]:
    """The family of ``families`` with the lowest held-out RMSE (the best standard family)."""
    name, params, scores, _ = rank_bases(runs, families)
    return name, params, scores


def pick_base(results: Sequence[tuple[str, dict[str, Any]]], *, min_gain: float
              ) -> tuple[str, dict[str, Any]]:
    """Of the workflow's results on several bases (best plain base first), the one whose final
    model predicts the held-out runs best. A later base must beat the first by ``min_gain``
    (the bar a term must clear) so a near tie keeps the best plain family, and one that adds
    terms where the first found nothing to add is not taken: a family that fits the source
    worse may name its own misfit."""
    first_label, first = results[0]
    best_label, best = first_label, first
    for label, res in results[1:]:
        if not res["effects"] and first["effects"]:
            continue
        if first["verdict"] == "no_missing_effect":
            break
        after = float(res["summary"]["heldout_rmse_after"])
        if after < (1.0 - min_gain) * float(best["summary"]["heldout_rmse_after"]):
            best_label, best = label, res
    return best_label, best
