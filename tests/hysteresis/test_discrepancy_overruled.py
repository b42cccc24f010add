"""A term the load cells contradict: named only when it alone explains the output to the
noise, and then with a note that the load cells did not show it."""

from __future__ import annotations

from typing import Any

from hysteresis.discrepancy.workflow import WorkflowSettings, _winners

FLOOR = 0.01


def _score(name: str, after: float, corroborated: bool | None, gain: float = 0.9
           ) -> dict[str, Any]:
    return {"name": name, "relative_gain": gain, "delta_bic": -500.0, "runs_improved": 1.0,
            "heldout_rmse_after": after,
            "load_cell_evidence": {"claim": "dead_travel", "per_configuration": {},
                                   "corroborated": corroborated}}


def _no_pairs() -> list[dict[str, Any]]:
    return []


def test_a_contradicted_term_that_leaves_the_noise_is_named_with_a_note() -> None:
    st = WorkflowSettings()
    won = _winners([_score("dead_zone", 1.1 * FLOOR, False)], st, 0, 10.0, _no_pairs,
                   noise_floor=FLOOR)
    assert [s["name"] for s in won] == ["dead_zone"]
    note = won[0]["load_cell_evidence"]["note"]
    assert "do not show its dead_travel" in note and "1.1x the noise floor" in note


def test_a_contradicted_term_short_of_the_noise_is_not_named() -> None:
    st = WorkflowSettings()
    assert _winners([_score("dead_zone", 2.5 * FLOOR, False)], st, 0, 10.0, _no_pairs,
                    noise_floor=FLOOR) == []
    # judged on the output alone, the reading does not count
    off = WorkflowSettings(physical_evidence=False)
    won = _winners([_score("dead_zone", 2.5 * FLOOR, False)], off, 0, 10.0, _no_pairs,
                   noise_floor=FLOOR)
    assert [s["name"] for s in won] == ["dead_zone"]
    assert "note" not in won[0]["load_cell_evidence"]


def _ranked(scores: list[dict[str, Any]]) -> list[str]:
    scores = sorted(scores, key=lambda s: s["delta_bic"])
    return [s["name"] for s in _winners(scores, WorkflowSettings(), 0, 10.0, _no_pairs,
                                        noise_floor=FLOOR)]


def test_a_contradicted_term_that_settles_the_output_ranks_by_its_delta_bic() -> None:
    settles = {**_score("dead_zone", 1.0 * FLOOR, False), "delta_bic": -900.0}
    held_gain = {**_score("asymmetry", 11.0 * FLOOR, None, 0.3), "delta_bic": -400.0}
    assert _ranked([settles, held_gain]) == ["dead_zone"]
    # an acceptable term with the better delta BIC still goes first
    assert _ranked([{**settles, "delta_bic": -300.0}, held_gain]) == ["asymmetry"]
    # and a term the load cells show goes ahead of both
    shown = {**_score("drift", 3.0 * FLOOR, True, 0.5), "delta_bic": -100.0}
    assert _ranked([settles, held_gain, shown]) == ["drift"]


def test_the_score_offered_is_not_changed_by_the_check() -> None:
    s = _score("dead_zone", 1.0 * FLOOR, False)
    won = _winners([s], WorkflowSettings(), 0, 10.0, _no_pairs, noise_floor=FLOOR)
    assert "note" in won[0]["load_cell_evidence"] and "note" not in s["load_cell_evidence"]
