"""Which base family answers: every standard family scored by its plain held-out RMSE
(:func:`rank_bases`), and of the workflow's answers on several bases the one whose model with
its terms predicts the held-out runs best (:func:`pick_base`, :func:`auto_base`). Pure: runs
and a workflow in, scores and answers out."""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from hysteresis.discrepancy.effects import ComposedModel
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import base_factory_for, evaluate, group_runs

log = logging.getLogger(__name__)

#: A family as the ranking keeps it: (registered or local family name, its parameters).
Spec = tuple[str, dict[str, Any]]


class Workflow(Protocol):
    """The workflow on one base: (family name, its parameters) -> the workflow's full result;
    ``reach_within`` as :func:`.workflow.run_workflow`'s."""

    def __call__(self, name: str, params: Mapping[str, Any], *,
                 reach_within: float | None = None) -> dict[str, Any]: ...


#: A base that reads a channel beyond the input (plays whose widths follow the output tension,
#: :class:`.bases.TensionWidthGamma`) ranks only where it predicts the held-out runs this
#: fraction better than every base of fixed shape: under a follower of constant load its
#: widths hardly change, it is the free Gamma sum again, and as the second base tried it would
#: repeat the first instead of giving another family's answer. (On a clean-room capstan loop
#: under a return spring it left 0.010-0.024 mm where the best fixed base left 0.094.)
CHANNEL_BASE_GAIN = 0.2

#: After a clean answer above the retry bar, a later base is asked one thing: whether its
#: model with a term explains the source to within ``retry_factor`` x the noise floor
#: (:func:`pick_base`'s ``clean_within``). Its workflow goes past the first round only where
#: one term alone already comes within this multiple of that bar (the slack leaves room for a
#: second term). On the clean-room Bouc-Wen source ``fp-4dec26`` the free Gamma sum's three
#: rounds took 35 of the source's 68 s and ended at 3.1x the noise, not taken; every later
#: base that was taken got there with its first term (1.0-1.2x the noise).
ABSORBED_REACH = 2.0


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


def pick_base(results: Sequence[tuple[str, dict[str, Any]]], *, min_gain: float,
              clean_within: float | None = None) -> tuple[str, dict[str, Any]]:
    """Of the workflow's results on several bases (best plain base first), the one whose final
    model predicts the held-out runs best. A later base must beat the first by ``min_gain``
    (the bar a term must clear) so a near tie keeps the best plain family, and one that adds
    nothing where the first named an effect is not taken.

    Where the first found nothing to add, a later base's terms are taken only when they also
    explain the source to within ``clean_within`` x the noise floor (never, if ``None``): a
    family that fits the source worse may name its own misfit, but one whose model with a term
    predicts the held-out runs to the noise, where the best plain family stays above it, has
    found what that family's shape absorbs (a Preisach plane takes up a pull/push gain
    difference of a Bouc-Wen loop and stays at 2.3x the noise; Bouc-Wen plus the asymmetry
    reaches 1.1x)."""
    first_label, first = results[0]
    best_label, best = first_label, first
    for label, res in results[1:]:
        if not res["effects"] and first["effects"]:
            continue
        if first["verdict"] == "no_missing_effect" and (
                not res["effects"] or clean_within is None
                or float(res["residual"]["rmse_over_noise"]) > clean_within):
            continue
        after = float(res["summary"]["heldout_rmse_after"])
        if after < (1.0 - min_gain) * float(best["summary"]["heldout_rmse_after"]):
            best_label, best = label, res
    return best_label, best


def auto_base(workflow: Workflow, ranked: Mapping[str, float], specs: Mapping[str, Spec], *,
              max_bases: int, retry_factor: float, min_gain: float,
              known: Mapping[str, dict[str, Any]] | None = None
              ) -> tuple[str, dict[str, Any], list[dict[str, Any]]]:
    """``base_family=auto`` on a ranking (plain held-out RMSE by label, :func:`rank_bases`):
    the workflow on the best plain families in turn, up to ``max_bases``, while the answer is
    not explained to within ``retry_factor`` x the noise floor; a clean verdict above that
    floor is retried too, since a family's shape can absorb the effect; a base tried after
    such an answer stops after its first round unless one term comes within
    :data:`ABSORBED_REACH` x ``retry_factor`` of the noise floor. Returns (the kept label, its
    full result, what each base tried answered). ``known``: results already had, by label (a
    given base's), not run again."""
    results: list[tuple[str, dict[str, Any]]] = []
    tried: list[dict[str, Any]] = []
    for label in sorted(ranked, key=ranked.__getitem__)[:max(1, max_bases)]:
        after_clean = bool(results) and results[0][1]["verdict"] == "no_missing_effect"
        res = (known or {}).get(label) or workflow(
            *specs[label], reach_within=ABSORBED_REACH * retry_factor if after_clean else None)
        results.append((label, res))
        tried.append({"base": label, "verdict": res["verdict"],
                      "effects": [e["name"] for e in res["effects"]],
                      "heldout_rmse_after": res["summary"]["heldout_rmse_after"],
                      "rmse_over_noise": res["residual"]["rmse_over_noise"],
                      "stopped": (res.get("stopped") or {}).get("note")})
        if res["residual"]["rmse_over_noise"] <= retry_factor:
            break
    label, full = pick_base(results, min_gain=min_gain, clean_within=retry_factor)
    for t in tried:
        t["kept"] = t["base"] == label
    return label, full, tried
