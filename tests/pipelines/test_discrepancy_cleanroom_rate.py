"""The workflow on the second clean-room generator (``tests/cleanroom/rate_forms.py``, written
without our code): a rate effect hidden in a Bouc-Wen or play-sum plant, three 80 s runs
(decaying sine, a stepped-frequency probe, decaying triangle) ingested as the stage does.
The whole set through the stage's command is in docs/notes/discrepancy-measurements.md."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from hysteresis.discrepancy.analysis import analyse
from hysteresis.discrepancy.workflow import WorkflowSettings
from tests.cleanroom import load, stage_runs

# a clean-room set through the stage: `make test-study` and CI, not `make test`
pytestmark = pytest.mark.study

#: The base (as ``auto_families.gamma_free``): free play weights with an offset, start fitted.
BASE = {"constraint": "free", "fit_offset": True}


@pytest.fixture(scope="module")
def generator() -> Any:
    return load("rate_forms")


@pytest.mark.slow
@pytest.mark.parametrize(("case", "form"), [("viscous", "viscous"),
                                             ("nonlinear_damping", "power")])
def test_a_rate_form_of_a_foreign_generator_is_named_and_halved(
        generator: Any, tmp_path: Path, case: str, form: str) -> None:
    truth = generator.write_source(tmp_path / "src", "play_sum", case)
    assert len(truth["runs"]) == 3
    runs = stage_runs(tmp_path / "src", tmp_path / "work")
    out, _ = analyse(runs, base_family="gamma", base_params=BASE, auto_families={},
                     base_check=False, settings=WorkflowSettings(max_effects=1))
    first = out["effects"][0]
    assert (first["name"], first["form"]) == ("rate_dependence", form)
    assert out["summary"]["heldout_reduction"] >= 0.5


@pytest.mark.slow
def test_runs_recorded_one_after_another_are_judged_from_the_state_they_were_left_in(
        generator: Any, tmp_path: Path) -> None:
    # the generator runs its three excitations back to back without resetting the plant, and
    # the relative encoder zeroes each run where the last one left it: judged from the base's
    # own start, the clean plant's held-out runs sit 0.1-0.25 mm off (15-35x the noise) and a
    # term that reads the tension was named to explain it
    generator.write_source(tmp_path / "src", "play_sum", "clean")
    runs = stage_runs(tmp_path / "src", tmp_path / "work")
    out, _ = analyse(runs, base_family="gamma", base_params=BASE, auto_families={},
                     base_check=False, settings=WorkflowSettings(max_effects=1))
    hist = out["run_history"]
    assert hist["chained"] is True and hist["joined_in_round"] == 0
    (check,) = hist["checks"]
    assert check["heldout_rmse_joined"] < 0.2 * check["heldout_rmse_separate"]
    assert sorted(len(v) for v in hist["recorded_before"].values()) == [1, 2]
    assert out["verdict"] == "no_missing_effect"
    assert out["residual"]["rmse_over_noise"] < 3.0
    separate, _ = analyse(runs, base_family="gamma", base_params=BASE, auto_families={},
                          base_check=False, settings=WorkflowSettings(max_effects=1),
                          history="separate")
    assert separate["run_history"]["chained"] is False
    assert separate["verdict"] != "no_missing_effect"
