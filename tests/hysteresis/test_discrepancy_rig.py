"""The discrepancy workflow on virtual-rig runs with hidden effects.

Each case simulates a pair of configurations x the three excitations of seed 001 (sine_decay
identifies, triangle_decay and trapezoid_decay are held out; 3 periods per amplitude to keep the
file fast), ingests them with the ingest stage's pure functions, and hands the workflow only the
dataset rows: the effect is hidden from it. "Halved" is checked in *each* configuration of the
pair, not only pooled.

Strengths: 1 = the rig's nominal size (docs/virtual-rig.md has the physical meaning and the
range we take as realistic for each). These tests check the workflow's logic: the clean
verdict, the load cells' evidence, the ablations, the joint refit. Which effect is named first
and halved at which strength, and the two-effect combinations, are study-size figures:
``make discrepancy-study`` measures them on five configuration pairs
(docs/notes/discrepancy-measurements.md) and fails unless each case of its ``expect`` list (every
effect on the pairs used here), every clean case and every combination shows what it should.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
import pytest

from hysteresis.discrepancy.effects import CANDIDATES, fit_joint, fit_with_effect, retune
from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import (
    WorkflowSettings,
    base_factory_for,
    group_runs,
    run_workflow,
)
from pipelines.discrepancy_study import hidden_effect_runs
from rig_io.virtual.effects import EffectStrengths

# dozens of discrepancy workflows on simulated campaigns: `make test-fast` leaves these out
pytestmark = pytest.mark.slow

PAIRS = {
    "a": ((90.0, 30.0), (45.0, 60.0)),  # the pair the workflow was built on
    "e": ((90.0, 45.0), (90.0, 60.0)),  # one wrap, two radii
}


@cache
def runs(effects: tuple[tuple[str, float], ...], pair: str = "a") -> list[RunData]:
    return hidden_effect_runs(dict(effects), PAIRS[pair])


def report(effects: dict[str, float], base: str = "gamma", pair: str = "a",
           settings: WorkflowSettings | None = None, **params: Any) -> dict[str, Any]:
    return run_workflow(runs(tuple(sorted(effects.items())), pair),
                        base_factory_for(base, **params), base_name=base, settings=settings)


#: Where a test reads only the first effect and the first round's ranking: the search for a
#: second effect (and the pair search after it) changes neither, and is most of the time.
FIRST = WorkflowSettings(max_effects=1)


def first(rep: dict[str, Any]) -> dict[str, Any]:
    assert rep["verdict"] == "missing_effects_found", rep["rankings"]
    return rep["effects"][0]


def ranked(rep: dict[str, Any], name: str, round_: int = 0) -> dict[str, Any]:
    return next(s for s in rep["rankings"][round_] if s["name"] == name)


def test_workflow_sees_two_configurations_and_only_the_dataset():
    rs = runs(())
    assert {r.config_key for r in rs} == {"curve_angle_deg=90.0,radius_mm=30.0,rig=tsm-bench",
                                          "curve_angle_deg=45.0,radius_mm=60.0,rig=tsm-bench"}
    assert sorted(r.role for r in rs).count("identification") == 2


def test_clean_runs_have_no_missing_effect():
    rep = report({})
    assert rep["verdict"] == "no_missing_effect"
    assert rep["effects"] == []
    # every candidate was scored and none cleared the bar
    assert all(s["relative_gain"] < 0.2 for s in rep["rankings"][0])
    # and the load cells show none of the effects they can read
    assert rep["measured_within_reach"] == []


def test_load_cell_effects_are_corroborated_by_the_load_cells():
    rate = first(report({"rate_dependence": 1.0}, pair="e", settings=FIRST))
    ev = rate["evidence"]["load_cell_evidence"]
    assert ev["claim"] == "speed_ratio" and ev["corroborated"] is True
    assert all(x > 1.2 for x in ev["per_configuration"].values())
    asym = first(report({"asymmetry": 2.0}, settings=FIRST))
    assert asym["evidence"]["load_cell_evidence"]["corroborated"] is True
    # a latency makes the plays look wider at speed too, but the friction did not change:
    # the speed-scaled plays are ranked and rejected by the load cells
    delay = report({"time_delay": 1.0}, settings=FIRST)
    rate_on_delay = ranked(delay, "rate_dependence")
    assert rate_on_delay["relative_gain"] > 0.3  # 0.43
    assert rate_on_delay["load_cell_evidence"]["corroborated"] is False
    # the input load cell sees the carriage move 0.4 mm after each reversal before the
    # tendon's tension does (3.3 % of the 12 mm span)
    dz = first(report({"dead_zone": 1.0}, pair="e", settings=FIRST))
    ev = dz["evidence"]["load_cell_evidence"]
    assert ev["claim"] == "dead_travel" and ev["corroborated"] is True
    assert all(0.025 < x < 0.036 for x in ev["per_configuration"].values())


def test_a_dead_zone_the_asymmetry_term_reproduces_is_named_from_the_load_cells():
    # On a Gamma base, what a dead zone leaves beyond the plays' reach is a loop shift from
    # the first motion: the asymmetry term's own shape. Added first (the load cells show the
    # friction asymmetry and it clears the bar), the asymmetry term takes both shifts and
    # the dead zone's term removes nothing more; the output cannot name it. The input load
    # cell can: the report names it as measured and already reproduced, and does not add it.
    rep = report({"asymmetry": 2.0, "dead_zone": 1.0})
    names = [e["name"] for e in rep["effects"]]
    assert names[0] == "asymmetry" and "dead_zone" not in names
    (dz,) = [m for m in rep["measured_within_reach"] if m["name"] == "dead_zone"]
    assert dz["load_cell_evidence"]["corroborated"] is True
    assert abs(dz["relative_gain"]) < 0.05 and dz["delta_bic"] > 0
    assert "named but not added" in dz["note"] and "asymmetry" in dz["note"]
    # the clean level: what is left is what the Gamma base leaves on clean runs
    clean = report({})
    assert rep["summary"]["heldout_rmse_after"] < 1.1 * clean["summary"]["heldout_rmse_before"]


def test_without_physical_evidence_weak_friction_asymmetry_is_misnamed():
    # The ablation that motivates the evidence: judged on the output fit alone, a tension
    # shaped term (tendon_elongation: the input tension carries the direction-dependent
    # friction) edges out the direction-dependent friction the load cells show.
    fit_only = report({"asymmetry": 1.0},
                      settings=WorkflowSettings(physical_evidence=False, max_effects=1))
    assert first(fit_only)["name"] == "tendon_elongation"
    with_evidence = report({"asymmetry": 1.0}, settings=FIRST)
    assert first(with_evidence)["name"] == "asymmetry"
    assert first(with_evidence)["evidence"]["load_cell_evidence"]["corroborated"] is True
    # ... although the stretch fits the output better: the measured friction goes first
    assert (ranked(with_evidence, "tendon_elongation")["delta_bic"]
            < ranked(with_evidence, "asymmetry")["delta_bic"])


def test_dead_zone_is_within_reach_of_play_operators_with_an_offset():
    # Against Gamma with a free sum and an offset (play operators compose into wider ones),
    # the dead zone is not missing: it is not named and the base's held-out error stays near
    # its clean level. What may be named is the rig's own tendon stretch: with the dead
    # zone's tension swings its term removes 27 % of the held-out error (20 % when the
    # decimation averaged the input's reversals), and the model with it predicts below the
    # clean base's level.
    clean = report({}, "gamma", constraint="free", fit_offset=True)
    dz = report({"dead_zone": 2.0}, "gamma", constraint="free", fit_offset=True)
    assert "dead_zone" in clean["within_base_reach"]
    assert "dead_zone" in clean["within_base_reach_note"]
    assert {e["name"] for e in dz["effects"]} <= {"tendon_elongation"}
    assert dz["summary"]["heldout_rmse_before"] < 1.4 * clean["summary"]["heldout_rmse_before"]
    assert dz["summary"]["heldout_rmse_after"] < clean["summary"]["heldout_rmse_before"]


def test_interacting_effects_are_found_as_a_pair():
    # With a strong friction asymmetry, the sum-to-one Gamma bends to mimic part of it with
    # the latency's help: alone, the correct 50 ms delay makes the held-out error worse and
    # the asymmetry term removes 14 %. Greedy search finds nothing; the pair clears the bar.
    # (With the whole library the input-side stretch, driven by the direction-dependent
    # tension, clears the bar alone first and the three are named one by one; without it
    # the pair search is what finds the two.)
    library = tuple(n for n in CANDIDATES if n != "tendon_elongation")
    rep = report({"asymmetry": 2.0, "time_delay": 1.0},
                 settings=WorkflowSettings(candidates=library))
    assert [e["name"] for e in rep["effects"]][:2] == ["asymmetry", "time_delay"]
    assert rep["effects"][0]["evidence"]["added_jointly_with"] == "time_delay"
    pair = rep["effects"][1]["evidence"]["pair"]
    assert pair["relative_gain"] > 0.5 and pair["gain_over_better_member"] >= 0.2
    greedy = report({"asymmetry": 2.0, "time_delay": 1.0},
                    settings=WorkflowSettings(candidates=library, pair_search=False))
    # greedy alone names nothing, and a residual far above the noise is not called clean
    assert greedy["effects"] == [] and greedy["verdict"] == "unexplained"
    assert greedy["residual"]["rmse_over_noise"] > WorkflowSettings().clean_factor


# Two of the two-effect cases; `make discrepancy-study` runs all 21 combinations of the seven
# effects on pair a (the same runs and settings) and fails unless each names both effects.
# Several of them are regression cases, found only once the search changed:
# - dead_zone + drift, dead_zone + rate_dependence: the refit must be joint in the earlier
#   term's nonlinear parameter (delay, speed law, time constant);
# - asymmetry + tendon_elongation, dead_zone + tendon_elongation: one compliance coefficient
#   (two per-part coefficients took opposite signs next to a second effect);
# - dead_zone + time_delay: the candidate is also fitted first (kept below);
# - rate_dependence + time_delay: the speed law reads the speed the contact has been sliding
#   at (a centred difference left its misfit to the delay);
# - saturation + tendon_elongation, rate_dependence + tendon_elongation: the stretch acts on
#   the input side.
@pytest.mark.parametrize("effects", [
    {"time_delay": 1.0, "drift": 2.0},
    {"dead_zone": 1.0, "time_delay": 1.0},
], ids=lambda e: "+".join(e))
def test_two_hidden_effects_are_both_named(effects):
    rep = report(effects)
    names = [e["name"] for e in rep["effects"]]
    assert set(names[:2]) == set(effects), names
    # each added effect lowers the held-out error further
    h = [rep["effects"][0]["heldout_rmse_before"]]
    h += [e["heldout_rmse_after"] for e in rep["effects"]]
    assert all(b < a for a, b in zip(h, h[1:], strict=False))
    assert h[-1] < 0.6 * h[0]


@pytest.mark.study
def test_a_frozen_earlier_term_hides_the_second_effect():
    # The ablation for the joint refit, ranked on the output fit alone (which takes the drift
    # first): with the drift's time constant frozen where it was chosen (while the dead zone
    # was still unexplained), the dead zone removes too little to be named.
    fit_only = report({"dead_zone": 1.0, "drift": 2.0},
                      settings=WorkflowSettings(physical_evidence=False, joint_retune=False))
    assert [e["name"] for e in fit_only["effects"]] == ["drift"]
    joint = report({"dead_zone": 1.0, "drift": 2.0},
                   settings=WorkflowSettings(physical_evidence=False))
    assert [e["name"] for e in joint["effects"]] == ["drift", "dead_zone"]
    assert joint["summary"]["heldout_rmse_after"] < 0.8 * fit_only["summary"]["heldout_rmse_after"]
    # With the load cells the dead travel is read at the input and the dead zone goes in
    # first; with its width frozen where it was chosen, the drift then removes too little
    # alone (it came in as a pair with a passenger while pairs were searched after a first
    # effect): the joint refit is what names both.
    frozen = report({"dead_zone": 1.0, "drift": 2.0},
                    settings=WorkflowSettings(joint_retune=False, max_effects=2))
    assert [e["name"] for e in frozen["effects"]] == ["dead_zone"]
    drift = ranked(frozen, "drift", 1)
    assert 0.1 < drift["relative_gain"] < WorkflowSettings().min_relative_gain
    both = report({"dead_zone": 1.0, "drift": 2.0}, settings=WorkflowSettings(max_effects=2))
    assert [e["name"] for e in both["effects"]] == ["dead_zone", "drift"]


def test_fitting_the_candidate_first_recovers_a_latency_and_a_dead_zone():
    # Alone, the delay comes out too long (it holds the output back after each reversal in
    # the dead zone's place); re-searched with the dead zone on top, it stays in that basin.
    # Fitted the other way round, both come out at the rig's values.
    truth = EffectStrengths.from_mapping({"dead_zone": 1.0, "time_delay": 1.0})
    f = base_factory_for("gamma")
    for g in group_runs(runs((("dead_zone", 1.0), ("time_delay", 1.0)))):
        delay = fit_with_effect(f, [], CANDIDATES["time_delay"], g.ident)
        assert delay.terms[0].theta > 1.3 * truth.delay_s()
        on_top = retune(f, fit_with_effect(f, delay.terms, CANDIDATES["dead_zone"], g.ident),
                        g.ident)
        joint = fit_joint(f, delay.terms, CANDIDATES["dead_zone"], g.ident)
        assert [t.effect.name for t in joint.terms] == ["time_delay", "dead_zone"]
        assert joint.terms[0].theta == pytest.approx(truth.delay_s(), rel=0.05), g.key
        assert joint.terms[1].theta == pytest.approx(truth.dead_zone_mm(), rel=0.05), g.key
        sse = [float(np.sum((g.ident.y - m.predict(g.ident)) ** 2)) for m in (joint, on_top)]
        assert sse[0] < 0.85 * sse[1]


def test_the_speed_law_fits_a_rate_dependent_rig_nearly_as_well_as_a_clean_one():
    # The speed-scaled plays on a rig with friction up to doubling at speed leave a held-out
    # error close to what the same family leaves on the clean rig (the friction texture's
    # floor): 14-16 % more on this pair when the decimation averaged the input's reversals,
    # 23 % and 41 % more with the reversals kept (the clean base gains 4-5 % from them, the
    # rate model at 45/60 loses 14 %: not understood yet). The speed the law reads matters: a
    # centred difference (friction seeing the next sample) left 29 % more at 90 deg / 30 mm.
    f = base_factory_for("gamma")
    rate = group_runs(runs((("rate_dependence", 1.0),)))
    clean = group_runs(runs(()))
    for g, c in zip(rate, clean, strict=True):
        m = fit_with_effect(f, [], CANDIDATES["rate_dependence"], g.ident)
        base = f().fit(c.ident.u, c.ident.y)
        err = np.concatenate([r.y - m.predict(r) for r in g.heldout])
        err0 = np.concatenate([r.y - base.predict(r.u) for r in c.heldout])
        ratio = float(np.sqrt(np.mean(err**2) / np.mean(err0**2)))
        assert ratio < 1.5, (g.key, ratio)
