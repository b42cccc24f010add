"""A chosen base that does not fit the source is flagged, not trusted: on an independent
injector's clean Preisach plant, the thesis' sum-to-one Gamma base "finds" an asymmetry; the
stage's base check says the base fits many times worse than the best standard family."""

from __future__ import annotations

from typing import Any

import pytest

from hysteresis.discrepancy.analysis import analyse
from hysteresis.discrepancy.base_check import base_misfit, second_opinion
from hysteresis.discrepancy.headline import headline
from hysteresis.discrepancy.inject import SIZES, injected_runs
from hysteresis.discrepancy.ranking import ABSORBED_REACH, auto_base, choose_base, pick_base
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow


@pytest.fixture(scope="module")
def families(stage_auto_families: dict[str, Any]) -> dict[str, Any]:
    return stage_auto_families


def test_a_flagged_base_is_answered_for_by_the_best_family(families: dict[str, Any]) -> None:
    """On the clean Preisach plant the thesis' Gamma names an effect, which is its misfit: the
    stage's answer is the best family's, saying so; without the second opinion the check
    flags it."""
    runs = injected_runs("preisach", {})
    # the families that matter here (each plain fit costs time)
    families = {k: families[k] for k in ("gamma", "preisach", "bouc_wen")}
    rep, full = analyse(runs, base_family="gamma", auto_families=families)
    given = rep["given_base"]
    assert given["base"] == "gamma" and given["effects"], "a clean source got an effect"
    assert rep["verdict"] == "no_missing_effect" and rep["effects"] == []
    misfit = rep["base_misfit"]
    assert rep["base_family"] == misfit["best_family"] in ("preisach", "bouc_wen")
    assert misfit["ratio"] > 5.0 and misfit["ratio_with_terms"] > 2.0
    assert full["base_family"] == rep["base_family"]  # the plots show the answer's model
    assert "because the given base gamma fits this source" in rep["headline"]
    # base_misfit_fallback=false: the given base's answer, flagged after its terms
    own = {"base_family": "gamma", "summary": {"heldout_rmse_after": given["heldout_rmse_after"]}}
    flag = base_misfit(runs, own, families, factor=1.5)
    assert flag is not None and flag["ratio"] > 3.0  # with the "asymmetry" in: 4.6x
    kept = {**rep, "base_family": "gamma", "base_misfit": flag, "given_base": None}
    assert "caution: base gamma with its terms fits" in headline(kept)


def test_a_base_that_only_lacked_the_effect_is_not_flagged(families: dict[str, Any]) -> None:
    """A drift on the Gamma plant: plain, the thesis' Gamma (no offset) fits 1.9x worse than
    a Gamma with a free offset, which bends to the drift; with the drift term it predicts
    better than that family with its own terms, so its answer stands."""
    runs = injected_runs("gamma", {"drift": 2.0})
    families = {k: families[k] for k in ("gamma", "gamma_free")}
    rep, _ = analyse(runs, base_family="gamma", auto_families=families)
    _, _, plain = choose_base(runs, families)
    assert rep["summary"]["heldout_rmse_before"] > 1.5 * plain["gamma_free"]
    assert rep["base_misfit"] is None and rep["given_base"] is None
    assert [e["name"] for e in rep["effects"]][:1] == ["drift"]


def _answer(verdict: str, effects: list[str], before: float, after: float,
            over_noise: float) -> dict[str, Any]:
    return {"verdict": verdict, "effects": [{"name": n} for n in effects],
            "summary": {"heldout_rmse_before": before, "heldout_rmse_after": after},
            "residual": {"rmse_over_noise": over_noise}, "_models": {}}


def _stub_workflow(answer: dict[str, Any]) -> tuple[Any, list[str]]:
    """A workflow that answers ``answer`` on any base, and the bases it was asked about."""
    asked: list[str] = []

    def workflow(name: str, params: Any, *, reach_within: float | None = None
                 ) -> dict[str, Any]:
        asked.append(name)
        reaches.append(reach_within)
        return answer

    reaches: list[float | None] = []
    workflow.reaches = reaches  # type: ignore[attr-defined]

    return workflow, asked


@pytest.mark.parametrize("own_verdict, over_noise, own_after, best_after, answers", [
    # fits about as well plain, but leaves 12x the noise: auto is asked, and answers when its
    # model with its terms predicts clearly better (held-out RMSEs in the best plain's units)
    ("missing_effects_found", 12.0, 0.9, 0.4, "best"),
    ("missing_effects_found", 12.0, 0.9, 0.85, "given"),  # not 20 % better: the base stands
    # the given base's terms do not even reach the best family plain: they are its misfit
    ("missing_effects_found", 12.0, 1.1, 0.95, "best"),
    ("no_missing_effect", 3.0, 1.2, 0.4, "best"),  # "clean" at 3x the noise is asked too
    ("no_missing_effect", 1.2, 1.2, 0.4, "given"),  # clean to the noise: not asked
    ("missing_effects_found", 1.2, 0.9, 0.4, "given"),  # explained to the noise: not asked
])
def test_a_base_that_leaves_a_residual_gets_a_second_opinion(
        families: dict[str, Any], own_verdict: str, over_noise: float, own_after: float,
        best_after: float, answers: str) -> None:
    runs = injected_runs("gamma", {})
    _, _, plain = choose_base(runs, families)
    best = min(plain, key=plain.__getitem__)
    workflow, asked = _stub_workflow(_answer("missing_effects_found", ["rate_dependence"],
                                             plain[best], best_after * plain[best], 1.1))

    own = _answer(own_verdict, ["time_delay"] if own_verdict != "no_missing_effect" else [],
                  1.2 * plain[best], own_after * plain[best], over_noise)
    given = "coleman_hodgdon" if best != "coleman_hodgdon" else "bouc_wen"
    rep, full = second_opinion(runs, dict(own), own, workflow, families, base=given,
                               params={}, factor=1.5, retry_factor=1.5, min_gain=0.2)
    if answers == "best":
        assert [e["name"] for e in rep["effects"]] == ["rate_dependence"]
        assert rep["given_base"]["effects"] == [e["name"] for e in own["effects"]]
        assert full is not own
        assert rep["base_misfit"]["ratio_with_terms"] == pytest.approx(own_after / best_after)
        assert rep["base_misfit"]["best_family"] == best
    else:
        assert rep["effects"] == own["effects"] and full is own
        assert "given_base" not in rep
    # auto stops after the best plain family: its answer is explained to the noise
    assert len(asked) == (0 if over_noise < 1.5 else 1)


def test_the_second_opinion_reuses_the_given_base_and_lets_it_stand_when_auto_keeps_it(
        families: dict[str, Any]) -> None:
    """A given base that is auto's own best plain family, with an answer above the noise:
    auto runs on the next family only, and keeps the given base when that one does no
    better."""
    runs = injected_runs("gamma", {})
    _, _, plain = choose_base(runs, families)
    ranked = sorted(plain, key=plain.__getitem__)
    workflow, asked = _stub_workflow(
        _answer("unexplained", [], plain[ranked[1]], plain[ranked[1]], 4.0))

    spec = dict(families[ranked[0]])
    name = str(spec.pop("family", ranked[0]))
    own = _answer("missing_effects_found", ["drift"], plain[ranked[0]], 0.5 * plain[ranked[0]],
                  3.0)
    rep, full = second_opinion(runs, dict(own), own, workflow, families, base=name,
                               params=spec, factor=1.5, retry_factor=1.5, min_gain=0.2)
    assert full is own and rep["effects"] == own["effects"]
    assert len(asked) == 1  # the given base's own result stood for auto's first family


def test_a_base_that_fits_is_not_flagged(families: dict[str, Any]) -> None:
    runs = injected_runs("gamma", {"time_delay": 1.0})
    rep = run_workflow(runs, base_factory_for("gamma"), base_name="gamma")
    assert [e["name"] for e in rep["effects"]] == ["time_delay"]
    # every candidate tried reports its fitted parameters; the latency's is the injected one
    tried = {s["name"]: s["parameters"] for s in rep["rankings"][0]}
    assert len(tried) == 7 and all(tried.values())
    (delay,) = tried["time_delay"].values()
    assert delay["theta"] == pytest.approx(SIZES["time_delay"], rel=0.1)
    assert base_misfit(runs, rep, families, factor=1.5) is None
    assert "caution" not in headline({**rep, "base_misfit": None})


def _result(verdict: str, effects: list[str], after: float, over_noise: float = 3.0
            ) -> dict[str, Any]:
    return {"verdict": verdict, "effects": [{"name": n} for n in effects],
            "summary": {"heldout_rmse_after": after},
            "residual": {"rmse_over_noise": over_noise}}


def test_pick_base_keeps_the_best_plain_family_unless_another_explains_clearly_more() -> None:
    first = ("bouc_wen", _result("missing_effects_found", ["drift"], 0.10))
    # clearly better with its terms: taken
    assert pick_base([first, ("gamma_free", _result("missing_effects_found", ["drift"], 0.03))],
                     min_gain=0.2)[0] == "gamma_free"
    # a near tie keeps the best plain family
    assert pick_base([first, ("gamma_free", _result("missing_effects_found", ["drift"], 0.09))],
                     min_gain=0.2)[0] == "bouc_wen"
    # a later family that adds nothing while the first named an effect is not taken
    assert pick_base([first, ("preisach", _result("unexplained", [], 0.01))],
                     min_gain=0.2)[0] == "bouc_wen"
    # the best plain family found nothing to explain: a worse-fitting family's terms are its
    # own misfit ...
    clean = ("preisach", _result("no_missing_effect", [], 0.02, 2.3))
    asym = _result("missing_effects_found", ["asymmetry"], 0.01, 1.8)
    assert pick_base([clean, ("gamma", asym)], min_gain=0.2)[0] == "preisach"
    assert pick_base([clean, ("gamma", asym)], min_gain=0.2, clean_within=1.5)[0] == "preisach"
    # ... unless they explain the source to the noise where the first family stays above it
    asym["residual"]["rmse_over_noise"] = 1.1
    assert pick_base([clean, ("gamma", asym)], min_gain=0.2, clean_within=1.5)[0] == "gamma"


def test_auto_base_tries_the_next_family_when_the_first_leaves_the_effect_half_explained(
        families: dict[str, Any]) -> None:
    """Stretch injected into a Preisach plant: Bouc-Wen fits best plain, but Bouc-Wen plus
    the stretch term leaves the residual above the retry bar; Preisach plus the term halves
    the best plain error, so the stage keeps it and says which bases it tried."""
    runs = injected_runs("preisach", {"tendon_elongation": 1.0})
    pair = {k: families[k] for k in ("bouc_wen", "preisach")}
    rep, _ = analyse(runs, auto_families=pair, max_bases=2, base_retry_factor=1.5)
    assert [t["base"] for t in rep["bases_tried"]] == ["bouc_wen", "preisach"]
    assert rep["base_family"] == "preisach"
    assert [e["name"] for e in rep["effects"]][:1] == ["tendon_elongation"]
    assert rep["summary"]["heldout_reduction_vs_best_plain"] >= 0.5
    assert "base chosen with its terms (best plain family: bouc_wen" in rep["headline"]
    one, _ = analyse(runs, auto_families=pair, max_bases=1)
    assert one["base_family"] == "bouc_wen" and len(one["bases_tried"]) == 1


@pytest.mark.study
def test_an_effect_the_best_plain_family_absorbs_is_found_on_the_next(
        families: dict[str, Any]) -> None:
    """A pull/push gain difference on a Bouc-Wen plant: the Preisach plane fits best plain,
    takes most of the asymmetry into its density and finds nothing to add, still 2.3x above
    the noise. Auto tries Bouc-Wen next, which with the asymmetry reaches the noise, and keeps
    it; given Preisach, the stage's second opinion answers the same."""
    runs = injected_runs("bouc_wen", {"asymmetry:pull_push_gain": 1.0})
    pair = {k: families[k] for k in ("preisach", "bouc_wen")}
    rep, _ = analyse(runs, auto_families=pair, max_bases=2, base_retry_factor=1.5)
    first, second = rep["bases_tried"]
    assert first["base"] == "preisach" and first["effects"] == []
    assert first["rmse_over_noise"] > 1.5
    assert rep["base_family"] == "bouc_wen" and second["kept"]
    assert [(e["name"], e["form"]) for e in rep["effects"]][:1] == [
        ("asymmetry", "pull_push_gain")]
    assert rep["residual"]["rmse_over_noise"] < 1.5
    assert rep["summary"]["heldout_reduction_vs_best_plain"] >= 0.4
    assert second["stopped"] is None  # asked after a clean answer, and one term reached it
    params = {k: v for k, v in pair["preisach"].items() if k != "family"}
    given, _ = analyse(runs, base_family="preisach", base_params=params, auto_families=pair)
    assert given["given_base"]["base"] == "preisach" and given["given_base"]["effects"] == []
    assert [e["name"] for e in given["effects"]][:1] == ["asymmetry"]


def test_a_base_tried_after_a_clean_answer_is_asked_for_one_term_near_the_noise() -> None:
    """auto after a clean answer above the retry bar: the next base only matters if a term
    explains the source to the noise, so its workflow is told to stop after the first round
    unless one term alone comes within ABSORBED_REACH x the bar. After an answer with effects
    (or an unexplained one) the next base runs in full."""
    ranked = {"preisach": 1.0, "bouc_wen": 2.0}
    specs = {"preisach": ("preisach", {}), "bouc_wen": ("bouc_wen", {})}
    for first, reach in [(_answer("no_missing_effect", [], 1.0, 1.0, 2.3), 3.0),
                         (_answer("missing_effects_found", ["drift"], 1.0, 0.5, 2.3), None),
                         (_answer("unexplained", [], 1.0, 1.0, 8.0), None)]:
        workflow, asked = _stub_workflow(_answer("unexplained", [], 2.0, 2.0, 6.0))
        label, _, tried = auto_base(workflow, ranked, specs, max_bases=2, retry_factor=1.5,
                                    min_gain=0.2, known={"preisach": first})
        assert asked == ["bouc_wen"] and label == "preisach"
        assert workflow.reaches == [None if reach is None else ABSORBED_REACH * 1.5]
        assert [t["stopped"] for t in tried] == [None, None]


def test_the_workflow_stops_after_its_first_round_when_no_term_comes_near_the_noise() -> None:
    """``reach_within``: a latency on the Gamma plant is named as usual when its term reaches
    the bar, and with a bar no term reaches the workflow stops after scoring the first round:
    nothing named, the reason in the report."""
    runs = injected_runs("gamma", {"time_delay": 1.0})
    factory = base_factory_for("gamma")
    full = run_workflow(runs, factory, base_name="gamma", reach_within=1e6)
    assert [e["name"] for e in full["effects"]] == ["time_delay"] and full["stopped"] is None
    best = min(s["heldout_rmse_after"] for s in full["rankings"][0])
    floor = full["located"][0]["noise_floor"]
    bar = 0.5 * best / floor  # half of what the best term reaches
    cut = run_workflow(runs, factory, base_name="gamma", reach_within=bar)
    assert cut["effects"] == [] and len(cut["rankings"]) == 1
    assert cut["stopped"]["best"] == "time_delay"
    assert cut["stopped"]["best_over_noise"] == pytest.approx(2.0 * bar)
    assert cut["verdict"] == "unexplained"
    assert cut["rankings"][0] == full["rankings"][0]


def test_a_given_base_that_cannot_take_the_runs_is_one_clear_error() -> None:
    """A dead band around zero behind the injector's Bouc-Wen loop: no Preisach plane of
    positive density fits it (``auto`` passes over that family). Given by name, the stage says
    so in one line and names the way out, where it raised from inside the base's fit."""
    from hysteresis.discrepancy.errors import DiscrepancyError

    runs = injected_runs("bouc_wen_loop", {"dead_zone:dead_band": 1.0})
    with pytest.raises(DiscrepancyError,
                       match=r"base preisach cannot be fitted.*positive density.*base_family=auto"):
        analyse(runs, base_family="preisach", auto_families={})
