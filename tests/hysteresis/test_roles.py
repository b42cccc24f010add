"""One rule for roles: fit/validate and the discrepancy workflow read a run's role, and cut a
lone run into head and tail, through :mod:`hysteresis.roles` alone."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hysteresis.base import HysteresisError
from hysteresis.discrepancy.runs import RunData, split_single_runs
from hysteresis.roles import (
    HELDOUT,
    IDENTIFICATION,
    manifest_role,
    normalise_role,
    run_role,
    tail_start,
)
from pipelines import discrepancy_data, stages
from pipelines.common import PipelineError


@pytest.mark.parametrize(("word", "role"), [
    ("identify", IDENTIFICATION), ("Train", IDENTIFICATION), ("fit", IDENTIFICATION),
    ("held_out", HELDOUT), ("TEST", HELDOUT), ("validation", HELDOUT), ("", None), (None, None)])
def test_every_accepted_word_means_one_role(word: str | None, role: str | None) -> None:
    assert normalise_role(word) == role


def test_a_misspelt_role_is_refused_with_the_words_that_work() -> None:
    # before, the stage ignored it (the run identified) and the discrepancy workflow made it
    # an identification run: a test run silently trained the model
    with pytest.raises(HysteresisError, match=r"run r7: excitation.role 'helduot' .*held_out"):
        manifest_role({"manifest": {"excitation": {"role": "helduot"}}}, run_id="r7")
    with pytest.raises(PipelineError, match="helduot"):
        stages.manifest_roles({"r7": {"manifest": {"excitation": {"role": "helduot"}}}})


def test_the_role_comes_from_the_manifest_else_from_the_kind() -> None:
    assert run_role(HELDOUT, "sine", {"sine"}) == HELDOUT
    assert run_role(None, "sine", {"sine"}) == IDENTIFICATION
    assert run_role(None, "triangle", {"sine"}) == HELDOUT


def _frame(n: int) -> pd.DataFrame:
    t = np.arange(n) * 0.01
    return pd.DataFrame({"run_id": "r1", "excitation": "sine", "rig": "tsm-bench",
                         "curve_angle_deg": 90.0, "radius_mm": 30.0, "t_s": t,
                         "input": np.sin(t), "output": 0.9 * np.sin(t)})


@pytest.mark.parametrize("n", [70, 137, 1000])
def test_fit_and_discrepancy_cut_a_lone_run_at_the_same_sample(n: int) -> None:
    frame = _frame(n)
    plan = stages.identification_plan(frame, fit_excitations=[], heldout=[],
                                      single_run_heldout_fraction=0.3)
    head_rows = int((plan.dataset["run_id"] == "r1").sum())
    run = RunData("r1", frame["t_s"].to_numpy(), frame["input"].to_numpy(),
                  frame["output"].to_numpy(), config={"rig": "tsm-bench"})
    (head, tail), _ = split_single_runs([run], heldout_fraction=0.3)
    assert head_rows == head.n == tail_start(n, 0.3)
    assert tail.role == HELDOUT
    notes = list(plan.notes.values())
    assert notes and notes[0].startswith("one run (r1): identifies on its first")


def test_a_run_too_short_to_split_stays_whole_everywhere() -> None:
    assert tail_start(39, 0.3) is None
    frame = _frame(39)
    plan = stages.identification_plan(frame, fit_excitations=[], heldout=[])
    assert set(plan.dataset["run_id"]) == {"r1"} and not plan.notes
    run = RunData("r1", frame["t_s"].to_numpy(), frame["input"].to_numpy(),
                  frame["output"].to_numpy())
    assert split_single_runs([run])[0] == [run]


def test_the_discrepancy_stage_reads_roles_with_the_same_rule() -> None:
    frame = pd.concat([_frame(60), _frame(60).assign(run_id="r2", excitation="triangle")])
    frame["tension_in_n"] = np.nan
    frame["tension_out_n"] = np.nan
    meta = {"r1": {"manifest": {"excitation": {"role": "test"}}}, "r2": {}}
    runs = discrepancy_data.runs_from_dataset(frame, meta, identify_excitations=["triangle"])
    assert {r.run_id: r.role for r in runs} == {"r1": HELDOUT, "r2": IDENTIFICATION}
    stage_roles = stages.manifest_roles(meta)
    assert stage_roles == {"r1": HELDOUT}
    bad = {"r1": {"manifest": {"excitation": {"role": "tst"}}}}
    with pytest.raises(discrepancy_data.DiscrepancyError, match="tst"):
        discrepancy_data.runs_from_dataset(frame, bad, identify_excitations=["triangle"])
