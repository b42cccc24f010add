"""Two bases that predict the held-out runs about as well but name different first effects:
the name is the base's, so no effect is named (:func:`analysis.base_dependence`)."""

from __future__ import annotations

from typing import Any

from hysteresis.discrepancy.analysis import (
    BASE_AGREEMENT_FACTOR,
    BASE_DEPENDENT_BELOW,
    base_dependence,
)
from hysteresis.discrepancy.headline import headline


def _report(kept: list[str], rival: list[str], ratio: float) -> dict[str, Any]:
    effects = [{"name": n, "form": None, "heldout_rmse_before": 0.03,
                "heldout_rmse_after": 0.02} for n in kept]
    return {
        "base_family": "bouc_wen", "verdict": "missing_effects_found", "effects": effects,
        "identifiability": None, "base_selection": {"bouc_wen": 0.025, "preisach": 0.07},
        "bases_tried": [
            {"base": "bouc_wen", "effects": kept, "heldout_rmse_after": 0.02, "kept": True,
             "verdict": "missing_effects_found", "rmse_over_noise": 11.0},
            {"base": "preisach", "effects": rival, "heldout_rmse_after": 0.02 * ratio,
             "kept": False, "verdict": "missing_effects_found", "rmse_over_noise": 14.0}],
        "summary": {"heldout_rmse_before": 0.025, "heldout_reduction_vs_best_plain": 0.2},
        "residual": {"rmse_over_noise": 11.0}}


def test_bases_that_name_different_first_effects_about_as_well_name_nothing() -> None:
    rep = _report(["drift", "asymmetry"], ["tendon_elongation", "asymmetry"], 1.7)
    dep = base_dependence(rep)
    assert dep is not None and dep["answers"] == {"bouc_wen": ["drift", "asymmetry"],
                                                  "preisach": ["tendon_elongation", "asymmetry"]}
    assert rep["verdict"] == "unexplained" and rep["effects"] == []
    assert [e["name"] for e in rep["effects_base_dependent"]] == ["drift", "asymmetry"]
    rep["base_dependence"] = dep
    text = headline(rep)
    assert text.startswith("unexplained: the first effect named depends on the base")
    assert "preisach names tendon_elongation" in text


def test_agreeing_bases_or_a_clearly_worse_rival_keep_the_name() -> None:
    same = _report(["drift"], ["drift", "saturation"], 1.2)
    assert base_dependence(same) is None and same["effects"]
    worse = _report(["time_delay"], ["rate_dependence"], BASE_AGREEMENT_FACTOR + 1.0)
    assert base_dependence(worse) is None and worse["verdict"] == "missing_effects_found"
    silent = _report(["asymmetry"], [], 1.1)  # a rival that names nothing does not veto
    assert base_dependence(silent) is None
    # the kept base's terms halve the error: the better base's name stands
    strong = _report(["drift"], ["tendon_elongation"], 1.1)
    strong["summary"]["heldout_reduction_vs_best_plain"] = BASE_DEPENDENT_BELOW
    assert base_dependence(strong) is None
    alone = _report(["drift"], ["tendon_elongation"], 1.1)
    alone["bases_tried"] = alone["bases_tried"][:1]
    assert base_dependence(alone) is None
