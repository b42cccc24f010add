"""A given base family checked against the best standard family: terms added to a base that
cannot take the loop's shape stand in for the base's misfit, and the answer would depend on
the base and not on the source. :func:`second_opinion` lets ``auto``'s answer stand in when
its model with its terms predicts clearly better; :func:`base_misfit` only flags. Pure: runs and
reports in, reports out."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.ranking import Workflow, auto_base, choose_base, rank_bases
from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import strip_private

log = logging.getLogger(__name__)


def asks_best_family(report: Mapping[str, Any], *, plain_ratio: float, factor: float,
                     retry_factor: float) -> bool:
    """Whether a given base's answer (``report``) is checked on ``auto``'s: the base fits
    ``factor`` x worse plain than the best family (``plain_ratio``), or its answer, clean or
    not, is not explained to within ``retry_factor`` x the noise floor (what makes ``auto``
    try a second base)."""
    return plain_ratio > factor or float(report["residual"]["rmse_over_noise"]) > retry_factor


def best_family_answers(own_after: float, best_after: float, *, min_gain: float,
                        own_named: bool = False, best_plain: float = float("inf")) -> bool:
    """Whether ``auto``'s model with its terms (held-out RMSE ``best_after``) answers for a
    given base's with its terms (``own_after``): it predicts the held-out runs ``min_gain``
    better; or it predicts better at all while the given base's terms (``own_named``) do not
    even take it to the best family's plain fit (``best_plain``), so what they name stands in
    for the base's misfit (on a Bouc-Wen plant the free Gamma sum plus an "asymmetry" left
    0.0229 mm where Bouc-Wen plain left 0.0185)."""
    if best_after < (1.0 - min_gain) * own_after:
        return True
    return own_named and own_after > best_plain and best_after < own_after


def second_opinion(runs: list[RunData], report: dict[str, Any], full: dict[str, Any],
                   workflow: Workflow, families: Mapping[str, Mapping[str, Any]], *,
                   base: str, params: Mapping[str, Any], factor: float, retry_factor: float,
                   min_gain: float, max_bases: int = 2) -> tuple[dict[str, Any], dict[str, Any]]:
    """A given base checked against ``auto`` on the same families (``base_misfit_fallback``).

    When the base fits ``factor`` x worse plain than the best family, or its answer is not
    explained to within ``retry_factor`` x the noise floor (what makes ``auto`` try a second
    base), ``auto`` runs too (:func:`.ranking.auto_base`: the best plain family, and the next
    while the answer stays above that floor; the given base's own result is reused where it
    is one of them). ``auto``'s answer stands in when its base is another family and
    :func:`best_family_answers`; ``given_base`` then keeps the given base's answer.
    Otherwise the given base's answer stands: a base that fits worse plain only because it
    lacked the effect predicts as well once the term is in."""
    try:
        _, _, scores, specs = rank_bases(runs, families)
    except DiscrepancyError:
        return report, full
    best_plain = min(scores, key=scores.__getitem__)
    own_plain = float(report["summary"]["heldout_rmse_before"])
    own_after = float(report["summary"]["heldout_rmse_after"])
    ratio = own_plain / scores[best_plain] if scores[best_plain] > 0 else float("inf")
    if not asks_best_family(report, plain_ratio=ratio, factor=factor,
                            retry_factor=retry_factor):
        return report, full
    known = {label: full for label, spec in specs.items() if spec == (base, dict(params))}
    label, best_full, _ = auto_base(workflow, scores, specs, max_bases=max_bases,
                                    retry_factor=retry_factor, min_gain=min_gain, known=known)
    best_after = float(best_full["summary"]["heldout_rmse_after"])
    if label in known or not best_family_answers(
            own_after, best_after, min_gain=min_gain, own_named=bool(report["effects"]),
            best_plain=scores[best_plain]):
        return report, full
    best, best_params = specs[label][0], dict(specs[label][1])
    given = {"base": base, "base_params": dict(params), "verdict": report["verdict"],
             "effects": [e["name"] for e in report["effects"]],
             "heldout_rmse_after": own_after,
             "rmse_over_noise": report["residual"]["rmse_over_noise"]}
    misfit = {"base": base, "heldout_rmse": own_plain, "best_family": label,
              "best_heldout_rmse": scores[label], "ratio": own_plain / scores[label]
              if scores[label] > 0 else float("inf"),
              "ratio_with_terms": own_after / best_after if best_after > 0 else float("inf"),
              "scores": scores}
    log.warning("base %s with its terms predicts this source %.1fx worse held out than %s with "
                "its own: %s answers", base, misfit["ratio_with_terms"], label, label)
    out = strip_private(best_full)
    out.update(base_family=best, base_params=best_params, base_selection=None,
               bases_tried=None, base_misfit=misfit, given_base=given)
    out["summary"]["heldout_rmse_best_plain"] = scores[best_plain]
    return out, best_full


def base_misfit(runs: list[RunData], report: Mapping[str, Any],
                families: Mapping[str, Mapping[str, Any]], *,
                factor: float) -> dict[str, Any] | None:
    """A chosen base that, *with the terms the workflow added*, still predicts the held-out
    runs ``factor`` x worse than the best standard family does plain: the base cannot take the
    loop's shape, and its terms may stand in for that misfit (a sum-to-one play sum on a
    Bouc-Wen-shaped loop gets an "asymmetry"). Judged after the terms, so a base that only
    lacked the effect (thesis Gamma on a drifting source, worse plain than a family that bends
    to the drift) is not flagged once the term is in. ``None`` if it fits. The check without
    a second workflow (``base_misfit_fallback=false``); :func:`second_opinion` is the one
    with."""
    try:
        _, _, scores = choose_base(runs, families)
    except DiscrepancyError:
        return None
    best = min(scores, key=scores.__getitem__)
    own = float(report["summary"]["heldout_rmse_after"])
    ratio = own / scores[best] if scores[best] > 0 else float("inf")
    if ratio <= factor:
        return None
    log.warning("base %s with its terms fits this source %.1fx worse held out than %s plain "
                "(%.4g vs %.4g): the effects named may stand in for the base's misfit",
                report["base_family"], ratio, best, own, scores[best])
    return {"base": report["base_family"], "heldout_rmse": own, "best_family": best,
            "best_heldout_rmse": scores[best], "ratio": ratio, "scores": scores}
