"""The discrepancy-study stage: config, bad input, the tables, and one real case end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pipelines import discrepancy_study as study
from pipelines.common import CONF_DIR, to_container
from pipelines.schemas import StudyExpectation
from tests.pipelines.pipeline_data import mlflow_store

# the detection study end to end: `make test-fast` leaves these out
pytestmark = pytest.mark.slow


def _cfg(tmp_path: Path, tracking: str = "off", **over: object) -> dict[str, object]:
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = to_container(compose(config_name="discrepancy_study",
                                   overrides=[f"paths.root={tmp_path}", f"tracking={tracking}",
                                              "progress=false", "n_jobs=1"]))
    cfg.update(over)
    return cfg


def test_config_composes_with_every_effect_and_five_pairs(tmp_path: Path) -> None:
    from rig_io.virtual.effects import EFFECT_NAMES

    cfg = _cfg(tmp_path)
    assert set(cfg["strengths"]) == set(EFFECT_NAMES)
    assert cfg["pairs_selected"] == ["a", "b", "c", "d", "e"]
    assert all(len(cfg["pairs"][p]) == 2 for p in cfg["pairs_selected"])
    assert cfg["out"] == f"{tmp_path}/data/reports/discrepancy_study"
    assert set(cfg["combinations"]["strengths"]) == set(EFFECT_NAMES)


@pytest.mark.parametrize(("over", "message"), [
    ({"strengths": {"friction_creep": [1.0]}}, "unknown effect"),
    ({"pairs_selected": ["zz"]}, "unknown pair"),
    ({"effects_selected": ["drift", "creep"]}, "have no strengths"),
    ({"workflow": {"min_gain": 0.1}}, "unknown workflow setting"),
    ({"effects_selected": [], "combinations": {"strengths": {"creep": 1.0},
                                               "pairs_selected": ["a"]}}, "unknown effect"),
    ({"effects_selected": [], "combinations": {"strengths": {"drift": 1.0},
                                               "pairs_selected": ["q"]}}, "unknown pair"),
    ({"out": ""}, "out=<path stem> is required"),
    ({"expect": [{"effect": "drift", "strength": 1.0, "pair": "a", "outcome": "found",
                  "min_reduction": 0.0}]}, r"expect\[0\]: unknown outcome 'found'"),
    # a misspelt effect or pair would never match a case: refused, not skipped
    ({"expect": [{"effect": "drift", "strength": 1.0, "pair": "a", "outcome": "clean",
                  "min_reduction": 0.0},
                 {"effect": "dirft", "strength": 1.0, "pair": "a", "outcome": "halved",
                  "min_reduction": 0.0}]}, r"expect\[1\]: unknown effect 'dirft'"),
    ({"expect": [{"effect": "drift", "strength": 1.0, "pair": "z", "outcome": "halved",
                  "min_reduction": 0.0}]}, r"expect\[0\]: unknown pair 'z'"),
])
def test_bad_configuration_is_named(tmp_path: Path, over: dict[str, object],
                                    message: str) -> None:
    with pytest.raises(study.StudyError, match=message):
        study.run(_cfg(tmp_path, **over))


def _case(effect: str, strength: float, pair: str, named: list[str], per: dict[str, float],
          ) -> dict[str, object]:
    correct = named[:1] == [effect] if effect != "clean" else not named
    return {"effect": effect, "strength": strength, "pair": pair, "named": named,
            "first_named": named[0] if named else None, "correct": correct,
            "heldout_rmse_before": 0.1, "reduction": min(per.values()) if per else 0.0,
            "reduction_per_configuration": per,
            "halved": bool(correct and effect != "clean" and per and min(per.values()) >= 0.5)}


def test_detection_limits_take_the_smallest_strength_and_list_misnamings() -> None:
    cases = [
        {**_case("clean", 0.0, "a", [], {}), "verdict": "no_missing_effect"},
        {**_case("clean", 0.0, "b", [], {}), "verdict": "unexplained"},
        {**_case("drift", 0.5, "a", ["tendon_elongation"], {"x": 0.2, "y": 0.2}),
         "measured": ["drift"]},
        _case("drift", 1.0, "a", ["drift"], {"x": 0.6, "y": 0.4}),
        _case("drift", 2.0, "a", ["drift"], {"x": 0.7, "y": 0.6}),
        _case("drift", 4.0, "a", ["drift"], {"x": 0.8, "y": 0.7}),
    ]
    lim = study.detection_limits(cases)
    assert lim == {"drift": {"a": {"named_from": 1.0, "halved_from": 2.0,
                                   "mistaken_for": ["tendon_elongation at 0.5"]}}}
    md = study.markdown(cases)
    assert "| drift | a | 1 | 2 | tendon_elongation at 0.5 |" in md
    assert "| a | drift | 1 | 0.100 | drift | - | 40 % | 40 % | no |" in md
    # an effect the load cells show but the model already reproduces has its own column
    assert "| a | drift | 0.5 | 0.100 | tendon_elongation | drift | 20 % | 20 % | no |" in md
    # a clean source whose residual stays far above the noise is reported as unexplained
    assert "Clean runs: a no_missing_effect, b unexplained" in md


def test_shortfalls_name_each_expectation_the_study_missed() -> None:
    cases = [
        {**_case("clean", 0.0, "a", [], {}), "verdict": "no_missing_effect"},
        {**_case("clean", 0.0, "b", ["drift"], {"x": 0.1}), "verdict": "missing_effects_found"},
        _case("drift", 1.0, "a", ["drift"], {"x": 0.6, "y": 0.4}),  # named, not halved
        _case("drift", 2.0, "a", ["drift"], {"x": 0.7, "y": 0.6}),
        _case("time_delay", 1.0, "a", ["drift"], {"x": 0.6, "y": 0.6}),  # misnamed
        _case("saturation", 0.5, "a", [], {}),
    ]
    combos = [
        {"label": "drift 2 + time_delay 1", "pair": "a", "named": ["drift", "time_delay"],
         "measured": [], "all_named": True, "reduction": 0.7},
        {"label": "dead_zone 1 + drift 2", "pair": "a", "named": ["drift"], "measured": [],
         "all_named": False, "reduction": 0.6},
        {"label": "asymmetry 2 + drift 2", "pair": "a", "named": ["drift", "asymmetry"],
         "measured": [], "all_named": True, "reduction": 0.3},
    ]
    rows = [{"effect": "drift", "strength": 1.0, "pair": "a", "outcome": "halved"},
            {"effect": "drift", "strength": 2.0, "pair": "a", "outcome": "halved"},
            {"effect": "drift", "strength": 1.0, "pair": "a", "outcome": "named",
             "min_reduction": 0.45},
            {"effect": "time_delay", "strength": 1.0, "pair": "a", "outcome": "halved"},
            {"effect": "saturation", "strength": 0.5, "pair": "a", "outcome": "clean"},
            {"effect": "drift", "strength": 4.0, "pair": "a", "outcome": "halved"}]  # not run
    expect = [StudyExpectation(**e) for e in rows]
    missed = study.shortfalls(cases, combos, expect, combination_reduction=0.4)
    assert missed == [
        "clean on pair b: named ['drift']",
        "dead_zone 1 + drift 2 on pair a: named ['drift'], measured []",
        "asymmetry 2 + drift 2 on pair a: terms remove 30 % < 40 %",
        "drift 1 on pair a: not halved in every configuration (60 %, 40 %)",
        "drift 1 on pair a: removes 40 % < 45 %",
        "time_delay 1 on pair a: named first 'drift'",
    ]
    assert study.shortfalls(cases[:1] + cases[3:4], combos[:1], expect,
                            combination_reduction=0.4) == []


@pytest.mark.study
def test_one_hidden_effect_end_to_end_logged_and_checked(tmp_path: Path) -> None:
    import mlflow

    mlflow_store(tmp_path)  # an initialised store: the migrations are not what is tested
    # one effect, one combination, and an expectation the effect's case cannot meet: the
    # stage writes and logs its tables, then fails naming the case
    cfg = _cfg(tmp_path, tracking="local", effects_selected=["time_delay"],
               pairs_selected=["a"],
               combinations={"strengths": {"time_delay": 1.0, "drift": 2.0},
                             "pairs_selected": ["a"]},
               expect=[{"effect": "time_delay", "strength": 1.0, "pair": "a",
                        "outcome": "clean"}])
    cfg["strengths"]["time_delay"] = [1.0]
    with pytest.raises(study.StudyError, match=r"fell short of 1 expectation.*\n  time_delay 1 "
                       r"on pair a: expected no effect, named \['time_delay'"):
        study.stage(cfg)
    out = tmp_path / "data" / "reports"
    doc = json.loads((out / "discrepancy_study.json").read_text())
    cases = doc["cases"]
    assert [(c["effect"], c["strength"]) for c in cases] == [("clean", 0.0), ("time_delay", 1.0)]
    clean, delay = cases
    assert clean["correct"] and clean["named"] == []
    assert delay["first_named"] == "time_delay" and delay["halved"]
    assert set(delay["reduction_per_configuration"]) == {
        "curve_angle_deg=90.0,radius_mm=30.0,rig=tsm-bench",
        "curve_angle_deg=45.0,radius_mm=60.0,rig=tsm-bench"}
    assert doc["detection_limits"]["time_delay"]["a"]["halved_from"] == 1.0
    md = (out / "discrepancy_study.md").read_text()
    assert "| time_delay | a | 1 | 1 | - |" in md
    assert not list(out.glob("*.tmp*"))
    # the two-effect part: one combination, both named, in the JSON and the table
    (combo,) = doc["combinations"]
    assert combo["effects"] == {"drift": 2.0, "time_delay": 1.0}
    assert combo["all_named"] and combo["all_added"] and not combo["extra"]
    assert combo["reduction"] > 0.5
    assert "| a | drift 2 + time_delay 1 | time_delay, drift | - | yes |" in md
    # and one MLflow run with the cases' figures
    mlflow.set_tracking_uri(f"sqlite:///{tmp_path}/mlflow.db")
    runs = mlflow.search_runs(search_all_experiments=True)
    child = runs[runs["metrics.cases"].notna()]
    assert len(child) == 1 and child["metrics.cases"].iloc[0] == 2.0
    assert child["metrics.a.time_delay.1.reduction"].iloc[0] > 0.5
    assert set(runs["status"]) == {"FINISHED"}
