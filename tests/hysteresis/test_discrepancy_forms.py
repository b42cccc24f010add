"""Each effect as a family of physical forms: the workflow names the effect and the form, takes
every run's start from the data, and answers with a class where the output cannot decide."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysteresis.discrepancy.effects import CANDIDATES, ComposedModel, Term
from hysteresis.discrepancy.identifiability import statement
from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow


def _answer(runs: list, base: str = "gamma") -> dict:
    return run_workflow(runs, base_factory_for(base), base_name=base)


@pytest.mark.parametrize(("plant", "base"), [("gamma", "gamma"), ("bouc_wen_loop", "bouc_wen")])
def test_a_plant_that_starts_loaded_is_clean(plant: str, base: str) -> None:
    # every play (or the Bouc-Wen state) starts at a band edge on every run; a base started at
    # zero or at rest left a transient for a term to explain (4x the noise floor on Gamma)
    rep = _answer(injected_runs(plant, start="loaded"), base)
    assert rep["verdict"] == "no_missing_effect"
    assert rep["residual"]["rmse_over_noise"] < 2.0


@pytest.mark.parametrize(("hidden", "named"), [
    ("rate_dependence:viscous", ("rate_dependence", "viscous")),
    ("rate_dependence:power", ("rate_dependence", "power")),
    ("rate_dependence:stribeck", ("rate_dependence", "stribeck")),
    ("asymmetry:pull_push_gain", ("asymmetry", "pull_push_gain")),
    ("time_delay:long", ("time_delay", "latency")),
])
def test_the_form_is_named_with_the_effect(hidden: str, named: tuple[str, str]) -> None:
    rep = _answer(injected_runs("gamma", {hidden: 1.0}))
    first = rep["effects"][0]
    assert (first["name"], first["form"]) == named
    assert rep["summary"]["heldout_reduction"] >= 0.5
    params = first["evidence"]["parameters"]["plant=gamma"]
    assert params["form"] == named[1]


def test_a_long_latency_is_recovered() -> None:
    rep = _answer(injected_runs("gamma", {"time_delay:long": 2.0}))  # 0.9 s
    tau = rep["effects"][0]["evidence"]["parameters"]["plant=gamma"]["theta"]
    assert tau == pytest.approx(0.9, abs=0.02)


def test_linear_creep_term_recovers_a_known_creep_exactly() -> None:
    run = injected_runs("gamma")[0]
    drift = CANDIDATES["drift"]
    ctx = tuple(sorted(drift.context(run).items()))
    base = ComposedModel(base_factory_for("gamma")).fit(run)
    y = base.predict(run) + 0.3 * run.ts / run.ts.max()
    m = ComposedModel(base_factory_for("gamma"), [Term(drift, ("linear", 0.0), ctx)])
    m.fit(replace(run, y=y))
    assert m.coef_[0] == pytest.approx(0.3, rel=1e-3)
    # the exponential form cannot: its coefficient is not the creep's size
    e = ComposedModel(base_factory_for("gamma"), [Term(drift, 5.0, ctx)]).fit(replace(run, y=y))
    assert abs(float(e.coef_[0]) - 0.3) > 0.05


def test_stribeck_term_recovers_a_known_friction_law() -> None:
    # a Coulomb level and a static excess fading over v_S: the two coefficients are the law's
    run = injected_runs("gamma")[0]
    rate = CANDIDATES["rate_dependence"]
    ctx = tuple(sorted(rate.context(run).items()))
    v = run.v / dict(ctx)["v_top"]
    slide = np.tanh(v / 0.02)
    base = ComposedModel(base_factory_for("gamma")).fit(run)
    y = base.predict(run) - slide * (0.03 + 0.08 * np.exp(-(np.abs(v) / 0.12) ** 2))
    m = ComposedModel(base_factory_for("gamma"), [Term(rate, ("stribeck", 0.12), ctx)])
    m.fit(replace(run, y=y))
    assert m.coef_[-2:] == pytest.approx([-0.03, -0.08], rel=0.02)


def test_a_one_way_backlash_is_answered_with_its_class_unless_the_load_cell_splits_it() -> None:
    entry = {"name": "asymmetry", "form": "one_way_backlash",
             "evidence": {"load_cell_evidence": {"claim": None, "corroborated": None}}}
    ident = statement(entry, channels=set())
    assert ident is not None and set(ident["class"]) == {"dead_zone", "asymmetry"}
    assert ident["statement"] == ("dead_zone or asymmetry: not separable without the input "
                                  "tension")
    # a backlash the input load cell shows (a dead travel at every reversal) is named
    shown = {"name": "dead_zone", "form": "backlash", "evidence": {"load_cell_evidence": {
        "claim": "dead_travel", "corroborated": True}}}
    assert statement(shown, channels={"tension"}) is None
    assert statement({**shown, "evidence": {}}, channels={"tension"}) is not None
    # effects outside a class stand alone
    assert statement({"name": "drift", "form": "linear"}, channels=set()) is None


def test_a_one_way_backlash_on_a_play_base_is_absorbed_not_misnamed() -> None:
    # a one-way backlash is a wider play plus a shift from the first motion, which a play base
    # with its start taken from the record reproduces: clean, never another effect's name
    rep = _answer(injected_runs("gamma", {"asymmetry": 2.0}))
    assert [e["name"] for e in rep["effects"]] in ([], ["asymmetry"], ["dead_zone"])
    if rep["effects"]:
        assert rep["identifiability"] is not None


def test_a_named_drift_is_not_a_class() -> None:
    rep = _answer(injected_runs("gamma", {"drift": 1.0}))
    assert rep["effects"][0]["name"] == "drift"
    assert rep["identifiability"] is None
    assert np.isfinite(rep["summary"]["heldout_rmse_after"])
