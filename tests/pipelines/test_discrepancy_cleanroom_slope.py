"""The workflow on the fifth clean-room generator (``tests/cleanroom/slope_backlash.py``,
written without our code): a play-sum plant whose follower is a backlash with different
loading and unloading slopes (Tao and Kokotovic's form: branches 1 + g and 1 - g crossing
above the pulled end, the output held between them), three 80 s runs ingested as the stage
does. The whole set through the stage's command is in docs/notes/discrepancy-measurements.md."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hysteresis.discrepancy.analysis import analyse
from hysteresis.discrepancy.workflow import WorkflowSettings
from tests.cleanroom import load, stage_runs

# a clean-room set through the stage: `make test-study` and CI, not `make test`
pytestmark = pytest.mark.study


@pytest.mark.slow
def test_a_backlash_with_different_slopes_is_named_a_loading_gain_with_its_slopes(
        tmp_path: Path, stage_auto_families: dict) -> None:
    generator = load("slope_backlash")
    folder = Path(generator.write_source(tmp_path, "play_sum", "slope_backlash", "weak"))
    truth = json.loads((tmp_path / "slope_backlash_truth.json").read_text())
    g = truth[folder.name]["parameters"]["effect"]["g"]
    runs = stage_runs(folder, tmp_path / "work")
    # the stage's defaults: the base chosen among the plain families
    out, _ = analyse(runs, auto_families=stage_auto_families,
                     settings=WorkflowSettings(max_effects=1))
    first = out["effects"][0]
    assert (first["name"], first["form"]) == ("asymmetry", "loading_gain"), json.dumps(
        out["rankings"][0], default=str)[:2000]
    assert out["summary"]["heldout_reduction"] >= 0.5
    (fit,) = first["evidence"]["parameters"].values()
    # the held form, pivot at the pulled end, its slope difference times its coefficient
    assert fit["theta"][:2] == ["held_gain", 1.0]
    assert float(fit["theta"][-1]) * fit["coefficients"][0] == pytest.approx(g, rel=0.2)
