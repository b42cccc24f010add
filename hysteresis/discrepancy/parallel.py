"""Candidates scored on several cores.

Each candidate's score is a refit of every configuration's model with its term added: seconds
of independent work, tens of times per round. Forked workers inherit the runs and the model as
they stand (nothing is sent to them but an index) and send back the score, models included
(``cloudpickle``: the base factories are closures). The results come back in the input's order,
so the answer does not depend on the number of workers.

Forking is used only where it is safe and pays: on a platform with ``fork``, outside a daemonic
process (a pool worker cannot have children), with more than one task and worker.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import traceback
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import cloudpickle

from hysteresis.discrepancy.errors import DiscrepancyError

T = TypeVar("T")
R = TypeVar("R")

#: What a forked worker runs: set in the parent just before the fork, read by the children.
_TASK: tuple[Callable[[Any], Any], Sequence[Any], tuple[type[BaseException], ...]] | None = None


def available_cores() -> int:
    """Cores this process may run on (its affinity, not the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - platforms without affinity
        return max(1, os.cpu_count() or 1)


def resolve_workers(workers: int) -> int:
    """``workers`` as a count: 0 means every available core; negative is refused."""
    if workers < 0:
        raise DiscrepancyError(f"workers must be >= 0 (0: every available core), got {workers}")
    return available_cores() if workers == 0 else workers


def _can_fork() -> bool:
    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def _run(i: int) -> bytes:
    assert _TASK is not None
    fn, items, expected = _TASK
    out: tuple[str, Any]
    try:
        out = ("ok", fn(items[i]))
    except expected as err:
        out = ("expected", err)
    except BaseException:  # noqa: BLE001 - sent to the parent, raised there with its trace
        out = ("error", traceback.format_exc())
    blob: bytes = cloudpickle.dumps(out)
    return blob


def map_ordered(fn: Callable[[T], R], items: Sequence[T], *, workers: int = 1,
                expected: tuple[type[BaseException], ...] = ()) -> Iterator[R | BaseException]:
    """``fn`` on every item, results yielded in the items' order as they complete in order.

    An exception of an ``expected`` type is yielded in place of that item's result (the caller
    decides what it means); any other exception in a worker is raised here with the worker's
    traceback. ``workers`` <= 1, or a process that cannot fork: in this process, in order.
    """
    n = min(resolve_workers(workers), len(items))
    if n <= 1 or not _can_fork():
        for item in items:
            try:
                yield fn(item)
            except expected as err:
                yield err
        return
    global _TASK
    _TASK = (fn, items, expected)
    try:
        with mp.get_context("fork").Pool(n) as pool:
            for blob in pool.imap(_run, range(len(items))):
                status, value = cloudpickle.loads(blob)
                if status == "error":
                    raise DiscrepancyError(f"a worker failed:\n{value}")
                yield value
    finally:
        _TASK = None
