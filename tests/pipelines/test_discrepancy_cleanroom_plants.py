"""The workflow on the third clean-room generator (``tests/cleanroom/other_plants.py``, written
without our code): a generalised Maxwell-slip plant with a loading/unloading gain whose state
turns over along 0.5 mm of input (a play of half-width 0.25 mm), three 80 s runs (decaying
sine, triangle, trapezoid) ingested as the stage does. The whole set through the stage's
command is in docs/notes/discrepancy-measurements.md."""

from __future__ import annotations

import json
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
    return load("other_plants")


@pytest.mark.slow
def test_a_loading_gain_that_turns_over_along_a_travel_is_named_with_its_width(
        generator: Any, tmp_path: Path) -> None:
    truth = generator.write_source(tmp_path, "maxwell_slip", "asymmetry",
                                   "loading_unloading_gain")
    src = tmp_path / truth["source"]
    runs = stage_runs(src, tmp_path / "work")
    out, _ = analyse(runs, base_family="gamma", base_params=BASE, auto_families={},
                     base_check=False, settings=WorkflowSettings(max_effects=1))
    first = out["effects"][0]
    assert (first["name"], first["form"]) == ("asymmetry", "loading_gain"), json.dumps(
        out["rankings"][0], default=str)[:2000]
    assert out["summary"]["heldout_reduction"] >= 0.5
    (fit,) = first["evidence"]["parameters"].values()
    width = float(fit["theta"][-1]) * fit["context"]["input_half"]
    effect = truth["params"]["effect"]
    assert width == pytest.approx(effect["turnover_half_width_mm"], rel=0.3)
    # the branches' gains 1 +- eps about the pivot
    assert abs(float(fit["coefficients"][0])) == pytest.approx(effect["eps"], rel=0.3)
