"""Candidates scored in forked workers: the same answer as in one process, in the same order."""

from __future__ import annotations

import multiprocessing as mp

import pytest

from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.parallel import map_ordered, resolve_workers
from hysteresis.discrepancy.workflow import WorkflowSettings, base_factory_for, run_workflow


class Refused(Exception):
    pass


def _square_or_refuse(x: int) -> int:
    if x == 3:
        raise Refused("three")
    return x * x


def test_results_come_back_in_order_with_expected_errors_in_place() -> None:
    out = list(map_ordered(_square_or_refuse, list(range(6)), workers=2, expected=(Refused,)))
    assert [o for i, o in enumerate(out) if i != 3] == [0, 1, 4, 16, 25]
    assert isinstance(out[3], Refused) and str(out[3]) == "three"


def test_an_unexpected_error_in_a_worker_is_raised_with_its_trace() -> None:
    with pytest.raises(DiscrepancyError, match="Refused: three"):
        list(map_ordered(_square_or_refuse, list(range(6)), workers=2))


def test_closures_and_their_results_cross_the_fork() -> None:
    factory = base_factory_for("gamma")  # a closure: plain pickle cannot send it back
    out = list(map_ordered(lambda k: (k, factory), [0, 1], workers=2))
    assert [k for k, _ in out] == [0, 1]
    assert all(type(f()) is type(factory()) for _, f in out)


def _in_daemon(q: mp.Queue) -> None:  # type: ignore[type-arg]
    q.put(list(map_ordered(_square_or_refuse, [1, 2], workers=2)))


def test_a_daemonic_process_scores_in_itself() -> None:
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_in_daemon, args=(q,), daemon=True)
    p.start()
    assert q.get(timeout=60) == [1, 4]
    p.join(timeout=60)


def test_workers_zero_means_every_available_core_and_negative_is_refused() -> None:
    assert resolve_workers(0) >= 1
    assert resolve_workers(3) == 3
    with pytest.raises(DiscrepancyError, match="workers must be >= 0"):
        resolve_workers(-1)


def test_the_workflow_answers_the_same_with_two_workers() -> None:
    runs = injected_runs("gamma", {"rate_dependence:viscous": 1.0})
    reps = [run_workflow(runs, base_factory_for("gamma"), base_name="gamma",
                         settings=WorkflowSettings(workers=w, max_effects=1)) for w in (1, 2)]
    one, two = reps
    assert [(e["name"], e["form"]) for e in one["effects"]] == \
        [(e["name"], e["form"]) for e in two["effects"]] == [("rate_dependence", "viscous")]
    assert [s["name"] for s in one["rankings"][0]] == [s["name"] for s in two["rankings"][0]]
    for key in ("heldout_rmse_before", "heldout_rmse_after", "rmse_after"):
        assert two["summary"][key] == pytest.approx(one["summary"][key], rel=1e-9)
