"""The discrepancy bench's scoring of one answer against its truth (pure: a report in, a dict
out): a form counts when it is named or among the forms the report cannot tell apart."""

from __future__ import annotations

from typing import Any

from bench.bench_discrepancy import excess_halved, score_answer, summarise


def _report(named: list[tuple[str, str, list[str]]], cut: float) -> dict[str, Any]:
    return {"effects": [{"name": n, "form": f, "forms_not_separable": ties}
                        for n, f, ties in named],
            "identifiability": None, "verdict": "missing_effects_found" if named else "clean",
            "summary": {"heldout_reduction": cut, "heldout_reduction_vs_best_plain": cut}}


def test_a_form_among_the_inseparable_ones_counts_but_not_as_a_single_form() -> None:
    tie = _report([("drift", "linear", ["linear", "exponential"])], 0.8)
    got = score_answer(tie, ("drift", "exponential"), True)
    assert got == {"hit": True, "name_hit": True, "form_hit": True, "single_form_hit": False}
    alone = _report([("drift", "exponential", [])], 0.8)
    assert score_answer(alone, ("drift", "exponential"), True)["single_form_hit"] is True
    wrong = _report([("drift", "linear", [])], 0.8)
    assert score_answer(wrong, ("drift", "exponential"), True)["hit"] is False
    short = _report([("drift", "exponential", [])], 0.4)  # not halved
    got = score_answer(short, ("drift", "exponential"), True)
    assert got["hit"] is False and got["form_hit"] is True


def test_only_sources_with_room_to_halve_count_as_halvable() -> None:
    def row(over: float, cut: float, hit: bool) -> dict[str, Any]:
        return {"hidden": ["drift", "linear"], "identifiable": True, "named": [],
                "hit": hit, "name_hit": hit, "seconds": 1.0, "cpu_seconds": 1.0,
                "rmse_over_noise": over, "heldout_reduction_vs_best_plain": cut}
    # plain 3x the noise (1.5 after a 50 % cut) has room; plain 1.6x does not
    out = summarise({"a": row(1.5, 0.5, True), "b": row(1.6, 0.0, False)})
    assert out["identifiable"] == 2 and out["identifiable_halvable"] == 1
    assert out["identifiable_halvable_named_first_and_halved"] == 1


def test_room_to_halve_is_also_read_against_the_plants_clean_floor() -> None:
    def row(plant: str, over: float, cut: float, hit: bool, *, clean: bool = False
            ) -> dict[str, Any]:
        return {"plant": plant, "start": "rest", "hidden": None if clean else ["drift", "linear"],
                "identifiable": not clean, "named": [], "hit": hit, "name_hit": hit,
                "seconds": 1.0, "cpu_seconds": 1.0, "rmse_over_noise": over,
                "heldout_reduction_vs_best_plain": cut}
    # the plant's base leaves 1.5x the noise on its clean source: a plain fit at 2.5x has
    # room over the noise but not over that floor; one at 4x has room over both
    out = summarise({"p:clean": row("p", 1.5, 0.0, True, clean=True),
                     "p:a": row("p", 2.5, 0.0, False), "p:b": row("p", 2.0, 0.5, True)})
    assert out["identifiable_halvable"] == 2
    assert out["identifiable_halvable_over_clean_floor"] == 1
    assert out["identifiable_halvable_over_clean_floor_named_first_and_halved"] == 1


def test_the_effects_share_is_read_over_the_plants_clean_floor() -> None:
    def row(plant: str, over: float, cut: float, form: bool, *, clean: bool = False
            ) -> dict[str, Any]:
        return {"plant": plant, "start": "rest", "hidden": None if clean else ["drift", "linear"],
                "identifiable": not clean, "named": [], "hit": form and cut >= 0.5,
                "name_hit": form, "form_hit": form, "seconds": 1.0, "cpu_seconds": 1.0,
                "rmse_over_noise": over, "heldout_reduction_vs_best_plain": cut}
    # floor 1.0x the noise; plain 1.9x (the effect adds sqrt(1.9^2 - 1) = 1.62x): a term
    # that leaves 1.0x removed it all though the whole error fell by 47 %, one that leaves
    # 1.5x kept 1.12x of it (69 %)
    at_floor, short = row("p", 1.0, 1 - 1.0 / 1.9, True), row("p", 1.5, 1 - 1.5 / 1.9, True)
    assert excess_halved(at_floor, 1.0) and not excess_halved(short, 1.0)
    # the least clean floor is the one read (1.0, not 1.4); a wrong form never counts
    out = summarise({"p:clean": row("p", 1.0, 0.0, False, clean=True),
                     "p:clean#1": row("p", 1.4, 0.0, False, clean=True),
                     "p:a": at_floor, "p:b": short,
                     "p:c": row("p", 1.0, 1 - 1.0 / 1.9, False)})
    assert out["identifiable_named_first_and_halved"] == 0
    assert out["identifiable_with_clean_floor"] == 3
    assert out["identifiable_named_first_and_excess_halved"] == 1


def test_rows_without_a_start_are_summarised_on_one_floor_per_plant() -> None:
    def row(over: float, hidden: list[str] | None) -> dict[str, Any]:
        return {"plant": "p", "hidden": hidden, "identifiable": True, "named": [],
                "hit": hidden is None, "name_hit": hidden is None, "seconds": 1.0,
                "cpu_seconds": 1.0, "rmse_over_noise": over,
                "heldout_reduction_vs_best_plain": 0.0}
    out = summarise({"a": row(1.0, None), "b": row(3.0, ["drift", "linear"])})
    assert out["identifiable_with_clean_floor"] == 1
    assert out["identifiable_halvable_over_clean_floor"] == 1
