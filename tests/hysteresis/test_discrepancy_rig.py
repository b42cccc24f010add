"""The discrepancy workflow on virtual-rig runs with hidden effects (issue 7, "done when").

Each case simulates two configurations (curve 90 deg / radius 30 mm and 45 deg / 60 mm) x the
three excitations of seed 001 (sine_decay identifies, triangle_decay and trapezoid_decay are
held out; 3 periods per amplitude to keep the file fast), ingests them with the ingest stage's
pure functions, and hands the workflow only the dataset rows: the effect is hidden from it.

Strengths: 1 = the rig's nominal size (docs/virtual-rig.md). Where the nominal size is smaller
than the base family's own structural error on clean runs (the rig's friction texture leaves
~0.063 mm RMSE that no family removes), a larger strength is used so that halving the held-out
RMSE is possible at all: 2 for drift, asymmetry and dead_zone, 8 for tendon_elongation (a
polymer tendon), 1.5 for rate_dependence (+81 % friction at 6 mm/s; at strength 1 it is named
first but stays near -35 %: the friction texture is multiplied by the same speed factor, which
raises the floor of those runs, see docs/discrepancy.md).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import pytest

from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow
from pipelines.discrepancy import rows_from_raw, runs_from_dataset

rig = pytest.importorskip("rig_io.virtual")

CONFIGS = ((90.0, 30.0), (45.0, 60.0))
EXCITATIONS: dict[str, dict[str, Any]] = {
    "sine_decay": {"kind": "sine_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                   "periods_per_amplitude": 3, "frequency_hz": 0.25},
    "triangle_decay": {"kind": "triangle_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                       "periods_per_amplitude": 3, "slope_mm_s": 6.0},
    "trapezoid_decay": {"kind": "trapezoid_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                        "periods_per_amplitude": 3, "slope_mm_s": 6.0, "dwell_s": 1.0},
}


@cache
def runs(effects: tuple[tuple[str, float], ...]) -> list[RunData]:
    raws = [rig.simulate_run(curve_angle_deg=phi, radius_mm=r, excitation=exc,
                             effects=dict(effects) or None, seed=3)
            for phi, r in CONFIGS for exc in EXCITATIONS.values()]
    rows, meta = rows_from_raw(raws)
    return runs_from_dataset(rows, meta, identify_excitations=["sine_decay"], rate_hz=20.0)


def report(effects: dict[str, float], base: str = "gamma", **params: Any) -> dict[str, Any]:
    return run_workflow(runs(tuple(sorted(effects.items()))), base_factory_for(base, **params),
                        base_name=base)


def first(rep: dict[str, Any]) -> dict[str, Any]:
    assert rep["verdict"] == "missing_effects_found", rep["rankings"]
    return rep["effects"][0]


def reduction(effect: dict[str, Any]) -> float:
    return 1.0 - effect["heldout_rmse_after"] / effect["heldout_rmse_before"]


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


@pytest.mark.parametrize(("effect", "strength"), [
    ("time_delay", 1.0),
    ("saturation", 1.0),
    ("drift", 2.0),
    ("asymmetry", 2.0),
    ("dead_zone", 2.0),
    # 8 = a polymer tendon (extra strain 5e-6 x 8 x T^2: 0.4 % at 10 N); a steel or tungsten
    # cable's stretch is inside the base family's reach and the rig's error floor.
    ("tendon_elongation", 8.0),
])
def test_hidden_effect_is_named_first_and_halves_the_heldout_error(effect, strength):
    rep = report({effect: strength})
    e = first(rep)
    assert e["name"] == effect
    assert reduction(e) >= 0.5, (effect, reduction(e))
    assert e["rmse_after"] < e["rmse_before"]
    # every held-out run of both configurations improves
    assert e["evidence"]["runs_improved"] == 1.0


def test_rate_dependence_is_named_first_and_halves_the_heldout_error():
    # Strength 1.5 = friction x (1 + 1.5 tanh(|v| / 10 mm/s)): +81 % at the held-out runs'
    # 6 mm/s. The term scales the Gamma base's play widths by the speed law; it is named ahead
    # of time_delay (a latency also looks like a wider loop at one speed) and removes half.
    rep = report({"rate_dependence": 1.5})
    e = first(rep)
    assert e["name"] == "rate_dependence"
    assert e["evidence"]["runner_up"]["name"] == "time_delay"
    assert reduction(e) >= 0.5, reduction(e)
    assert e["evidence"]["runs_improved"] == 1.0
    # the speed law fitted per configuration is physical: a gain inside its range, and the
    # same speed scale in both configurations (one sheath material)
    thetas = [p["theta"] for p in e["evidence"]["parameters"].values()]
    assert all(0.2 < g < 1.0 for _, _, g in thetas)
    assert thetas[0][1] == pytest.approx(thetas[1][1], rel=0.01)


def test_nominal_rate_dependence_is_named_first_down_to_the_rigs_error_floor():
    # At strength 1 (+54 % at 6 mm/s) the term is named first but removes about a third: the
    # rig multiplies its friction texture by the same speed factor, which raises the floor of
    # these runs above the clean 0.063 mm (docs/discrepancy.md).
    rep = report({"rate_dependence": 1.0})
    e = first(rep)
    assert e["name"] == "rate_dependence"
    assert e["evidence"]["runner_up"]["name"] == "tendon_elongation"
    assert reduction(e) >= 0.33, reduction(e)
    assert e["heldout_rmse_after"] < 0.085


def test_dead_zone_is_within_reach_of_play_operators_with_an_offset():
    # Against Gamma with a free sum and an offset (play operators compose into wider ones),
    # the dead zone is not missing: no effect is added and the base's held-out error stays
    # near its clean level.
    clean = report({}, "gamma", constraint="free", fit_offset=True)
    dz = report({"dead_zone": 2.0}, "gamma", constraint="free", fit_offset=True)
    assert "dead_zone" in clean["within_base_reach"]
    assert "dead_zone" in clean["within_base_reach_note"]
    assert dz["verdict"] == "no_missing_effect"
    assert dz["summary"]["heldout_rmse_before"] < 1.4 * clean["summary"]["heldout_rmse_before"]


@pytest.mark.parametrize("effects", [
    {"time_delay": 1.0, "drift": 2.0},
    # the tension-profile term and a latency: one shapes the loop, the other shifts it in time
    {"tendon_elongation": 8.0, "time_delay": 1.0},
])
def test_two_hidden_effects_are_both_named(effects):
    rep = report(effects)
    names = [e["name"] for e in rep["effects"]]
    assert set(names[:2]) == set(effects), names
    # each added effect lowers the held-out error further
    h = [rep["effects"][0]["heldout_rmse_before"]]
    h += [e["heldout_rmse_after"] for e in rep["effects"]]
    assert all(b < a for a, b in zip(h, h[1:], strict=False))
    assert h[-1] < 0.5 * h[0]
