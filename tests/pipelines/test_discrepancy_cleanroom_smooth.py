"""The workflow with a slow base on the fourth clean-room generator
(``tests/cleanroom/smooth_plants.py``, written without our code): a Bouc-Wen plant of
exponent 2 whose reading relaxes (a Maxwell element's force, time constant 1 s), three 80 s
runs (decaying sine, triangle, trapezoid) ingested as the stage does. A Bouc-Wen base searches
an effect's parameters on a play sum (its screen) and is fitted with the forms found. The whole
set through the stage's command is in docs/notes/discrepancy-measurements.md."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hysteresis.discrepancy.analysis import analyse
from hysteresis.discrepancy.workflow import WorkflowSettings
from tests.cleanroom import load, stage_runs

# a clean-room set through the stage: `make test-study` and CI, not `make test`
pytestmark = pytest.mark.study

#: The generator's seed of this source in its own matrix (``write_all``).
SEED = 1002


@pytest.mark.slow
def test_a_relaxing_reading_on_a_bouc_wen_plant_is_named_with_its_form_and_time(
        tmp_path: Path) -> None:
    generator = load("smooth_plants")
    folder = Path(generator.write_source(tmp_path, "bouc_wen_hard", "rate_dependence",
                                         "relaxation", "rest", SEED))
    truth = json.loads((tmp_path / "smooth_plants_truth.json").read_text())
    params = truth["sources"][folder.name]["params"]
    runs = stage_runs(folder, tmp_path / "work")
    out, _ = analyse(runs, base_family="bouc_wen", auto_families={}, base_check=False,
                     settings=WorkflowSettings(max_effects=1))
    first = out["effects"][0]
    assert (first["name"], first["form"]) == ("rate_dependence", "relaxation"), json.dumps(
        out["rankings"][0], default=str)[:2000]
    assert out["summary"]["heldout_reduction"] >= 0.5
    (fit,) = first["evidence"]["parameters"].values()
    # a first-order lag of the reading (or of the speed's force): its time constant
    assert fit["theta"][0] in ("lag", "relaxation")
    assert float(fit["theta"][-1]) == pytest.approx(params["tau_s"], rel=0.3)
