"""The workflow on the sixth clean-room generator (``tests/cleanroom/form_pairs.py``, written
without our code): sources whose hidden effect another form of the same effect reproduces
within the noise ("near") or not ("far"), with the generator's own oracle as the truth. The
whole set through the stage's command is in docs/notes/discrepancy-measurements.md."""

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
def test_a_cubic_softening_the_record_cannot_tell_from_a_tanh_stop_is_named_with_it(
        tmp_path: Path, stage_auto_families: dict) -> None:
    generator = load("form_pairs")
    name, truth = generator.write_source(tmp_path, "bouc_wen", "saturation", "cubic_softening",
                                         {"k_rel": 0.08})
    # the oracle: a tanh stop reproduces it within half the noise, a hard clip does not
    verdicts = {f: v["verdict"] for f, v in truth["alternatives"].items()}
    assert verdicts["soft_tanh"] == "indistinguishable"
    assert verdicts["hard_clip"] != "indistinguishable"
    runs = stage_runs(tmp_path / name, tmp_path / "work")
    out, _ = analyse(runs, auto_families=stage_auto_families,
                     settings=WorkflowSettings(max_effects=1))
    first = out["effects"][0]
    assert first["name"] == "saturation", json.dumps(out["rankings"][0], default=str)[:2000]
    assert out["summary"]["heldout_reduction"] >= 0.5
    assert {"cubic", "soft"} <= set(first["forms_not_separable"])
    assert "hard_stop" not in first["forms_not_separable"]
