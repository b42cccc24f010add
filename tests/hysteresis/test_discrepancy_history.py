"""Held-out runs judged from the state the runs recorded before them left (chain_records)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hysteresis.discrepancy.analysis import run_history
from hysteresis.discrepancy.effects import ComposedModel
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.runs import RunData, chain_records
from hysteresis.discrepancy.workflow import base_factory_for


def _run(run_id: str, role: str, started: float | None, amp: float = 3.0,
         tension: bool = True) -> RunData:
    t = np.arange(0.0, 20.0, 0.04)
    u = amp * np.sin(2 * np.pi * 0.25 * t)
    return RunData(run_id=run_id, t=t, u=u, y=0.9 * u, role=role, started_at=started,
                   tension=(5.0 + 0.1 * u) if tension else None)


def test_a_heldout_run_is_joined_to_the_runs_recorded_before_it() -> None:
    runs = [_run("c", "heldout", 300.0), _run("a", "identification", 0.0),
            _run("b", "heldout", 100.0, amp=2.0), _run("d", "heldout", None)]
    out, before = chain_records(runs)
    assert before == {"b": ["a"], "c": ["a", "b"]}
    by = {r.run_id: r for r in out}
    assert by["a"] is runs[1] and by["d"] is runs[3]  # the first run, a run without a time
    c = by["c"]
    assert c.rezeroed and c.offset == 2 * 500 and c.whole is not None and c.whole.n == 1500
    assert np.all(np.diff(c.whole.t) > 0)
    # the run's own input, moved to start where the run before it stopped
    assert np.allclose(np.diff(c.whole.u[-500:]), np.diff(c.u))
    assert c.whole.u[1000] == pytest.approx(c.whole.u[999])
    assert np.array_equal(c.y, runs[0].y)


def test_a_session_missing_a_channel_the_run_carries_is_not_joined() -> None:
    runs = [_run("a", "identification", 0.0, tension=False), _run("b", "heldout", 100.0)]
    out, before = chain_records(runs)
    assert before == {} and out[1] is runs[1]


def test_the_prediction_of_a_joined_run_is_the_change_from_its_first_sample() -> None:
    a, b = _run("a", "identification", 0.0), _run("b", "heldout", 100.0)
    b = replace(b, y=b.y + 0.25)  # the run's zero sits elsewhere: only the change is predicted
    (_, joined), _ = chain_records([a, b])
    model = ComposedModel(base_factory_for("linear")).fit(a)
    pred = model.predict(joined)
    assert pred[0] == pytest.approx(joined.y[0])
    assert np.sqrt(np.mean((joined.y - pred) ** 2)) < 1e-6


def test_history_modes() -> None:
    runs = [_run("a", "identification", 0.0), _run("b", "heldout", 100.0)]
    kept, session, rep = run_history(runs, "separate")
    assert kept is runs and session is None and rep is not None and rep["mode"] == "separate"
    kept, session, rep = run_history(runs, "chained")
    assert session is None and kept[1].whole is not None
    # auto: the workflow is handed the joined runs and decides round by round
    kept, session, rep = run_history(runs, "auto")
    assert kept is runs and session is not None and session[1].whole is not None
    untimed = [replace(r, started_at=None) for r in runs]
    assert run_history(untimed, "auto") == (untimed, None, None)  # nothing to decide
    with pytest.raises(DiscrepancyError, match="history='later'"):
        run_history(runs, "later")
