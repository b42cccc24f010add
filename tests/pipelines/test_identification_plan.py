"""Which run identifies and which judges: the documented rule, decided visibly, never a silent
alphabetical pick (manifest role, else the fit excitations, else a single run split in time)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hysteresis import make_family
from pipelines import stages
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from pipelines.stages import PipelineError, identification_plan
from tests.pipelines.pipeline_data import make_dataset, stage_cfg, write_dataset


def _one_sine_per_shape() -> pd.DataFrame:
    """Two shapes recorded as another lab does: one run each, of a kind we do not fit on."""
    data = make_dataset(angles=(15, 90), radii=(30,), kinds=("sine_decay",), dt=0.1)
    data["excitation"] = "sine"
    return data


def test_a_single_run_configuration_is_split_in_time_and_the_note_says_so() -> None:
    data = _one_sine_per_shape()
    plan = identification_plan(data, fit_excitations=["sine_decay"], heldout=["triangle_decay"])
    assert plan.fit_excitations == ("sine_decay", "sine")
    assert plan.heldout == ("triangle_decay", "sine.tail")
    for run_id, rows in data.groupby("run_id"):
        head = plan.dataset[plan.dataset["run_id"] == run_id]
        tail = plan.dataset[plan.dataset["run_id"] == f"{run_id}.tail"]
        assert len(head) + len(tail) == len(rows)
        assert len(tail) == pytest.approx(0.3 * len(rows), abs=1)
        assert set(tail["excitation"]) == {"sine.tail"} and set(head["excitation"]) == {"sine"}
        # the tail follows the head in time: nothing is judged on what identified
        assert tail["t_s"].min() > head["t_s"].max()
    assert len(plan.notes) == 2
    assert all("identifies on its first" in n and "sine.tail" in n for n in plan.notes.values())


def test_a_manifest_role_decides_before_the_excitation_kind() -> None:
    data = make_dataset(angles=(15,), radii=(30,), dt=0.2)
    tri = str(data.loc[data["excitation"] == "triangle_decay", "run_id"].iloc[0])
    plan = identification_plan(data, fit_excitations=["sine_decay"], heldout=[],
                               roles={tri: "identify"})
    assert tri in plan.chosen and "triangle_decay" in plan.fit_excitations
    spec = fit_stage.family_specs({"families": ["linear"]})
    tasks = stages.plan_fits(plan.dataset, spec, stages.configurations(plan.dataset),
                             fit_excitations=plan.fit_excitations, fit_runs=plan.chosen,
                             marked=plan.marked)
    assert [t.runs[0].run_id for t in tasks] == [tri]


def test_a_run_marked_held_out_is_never_split_into_identification() -> None:
    data = _one_sine_per_shape()
    run = str(data["run_id"].iloc[0])
    plan = identification_plan(data, fit_excitations=["sine_decay"], heldout=[],
                               roles={run: "validation"})
    assert f"{run}.tail" not in set(plan.dataset["run_id"])
    assert len(plan.notes) == 1  # only the other shape was split


def test_the_fraction_is_bounded() -> None:
    with pytest.raises(PipelineError, match="single_run_heldout_fraction"):
        identification_plan(_one_sine_per_shape(), fit_excitations=[], heldout=[],
                            single_run_heldout_fraction=0.9)


def test_fit_and_validate_judge_one_run_per_shape_on_its_held_out_tail(tmp_path: Path) -> None:
    write_dataset(_one_sine_per_shape(), tmp_path)
    cfg = stage_cfg(tmp_path, families=["linear", "gamma"])
    fits = fit_stage.run(cfg)
    assert len(fits) == 4 and fits["error"].isna().all()
    assert set(fits["fit_excitation"]) == {"sine"}
    assert all(not r.endswith(".tail") for r in fits["fit_run_ids"])
    metrics, errors = validate_stage.run({**cfg, "heldout": []})
    assert not errors
    held = metrics[metrics["split"] == "heldout"]
    assert set(held["eval_excitation"]) == {"sine.tail"} and len(held) == 4
    assert held["rmse"].notna().all()


def test_the_plan_reads_roles_from_ingests_run_index(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), dt=0.2)
    processed = write_dataset(data, tmp_path)
    tri = str(data.loc[data["excitation"] == "triangle_decay", "run_id"].iloc[0])
    (processed / "runs.json").write_text(json.dumps(
        {"runs": {tri: {"manifest": {"excitation": {"kind": "triangle_decay",
                                                     "role": "identify"}}}}}))
    fits = fit_stage.run(stage_cfg(tmp_path, families=["linear"]))
    assert list(fits["fit_run_ids"]) == [tri]


def test_a_held_out_tail_is_predicted_from_the_state_its_head_left() -> None:
    # the tail starts mid-motion: predicting it from rest would judge the model on a state it
    # cannot know; run through the head's input first, it is exactly the whole record's
    # prediction (no output of the tail is used)
    data = _one_sine_per_shape()
    plan = identification_plan(data, fit_excitations=[], heldout=[],
                               single_run_heldout_fraction=0.37)  # a cut mid-swing
    config = stages.configurations(plan.dataset)[0]
    signals = stages.run_signals(stages.config_rows(plan.dataset, config))
    (tail,), (head,) = signals["sine.tail"], signals["sine"]
    assert tail.lead_in is not None and tail.lead_in.size == head.u.size
    model = make_family("gamma").fit(head.u, head.y)
    whole = model.predict(np.concatenate([head.u, tail.u]))
    np.testing.assert_array_equal(tail.predict(model), whole[head.u.size:])
    from_rest = model.predict(tail.u)
    assert np.max(np.abs(from_rest - whole[head.u.size:])) > 1e-3
