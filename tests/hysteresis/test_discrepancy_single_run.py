"""One run per configuration (how many labs record): its head identifies, its tail judges."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis.base import HysteresisError
from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.runs import split_single_runs
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow


def test_a_lone_run_is_split_in_time_and_the_note_says_so() -> None:
    (run,) = injected_runs("gamma", {}, kinds=("sine_decay",))
    out, notes = split_single_runs([run], heldout_fraction=0.25)
    head, tail = out
    assert (head.role, tail.role) == ("identification", "heldout")
    assert head.n + tail.n == run.n and head.n == int(round(0.75 * run.n))
    np.testing.assert_array_equal(np.concatenate([head.y, tail.y]), run.y)
    # time since the start keeps counting in the tail (a creep does not restart there)
    assert tail.ts[0] == pytest.approx(run.t[head.n] - run.t[0])
    assert head.run_id.endswith(":head") and tail.run_id.endswith(":tail")
    assert "judged on its last" in notes[run.config_key]


def test_configurations_with_several_runs_keep_their_roles() -> None:
    runs = injected_runs("gamma", {})
    out, notes = split_single_runs(runs)
    assert out == runs and notes == {}


def test_a_silly_fraction_is_refused() -> None:
    with pytest.raises(HysteresisError, match="heldout_fraction"):
        split_single_runs([], heldout_fraction=0.9)


def test_a_drift_in_a_lone_run_is_named_from_its_tail() -> None:
    (run,) = injected_runs("gamma", {"drift": 2.0}, kinds=("sine_decay",))
    runs, _ = split_single_runs([run.decimated(2)])
    report = run_workflow(runs, base_factory_for("gamma"), base_name="gamma")
    assert [e["name"] for e in report["effects"]][:1] == ["drift"]
    assert report["summary"]["heldout_reduction"] >= 0.5
