"""One BLAS thread for the many tiny dense solves of identification.

``threadpoolctl.threadpool_limits`` rescans the process's loaded libraries on every call
(``/proc/self/maps`` on Linux, milliseconds each); identification calls it thousands of times
per workflow, where the scan cost more than the algebra it guarded. One controller, built on
first use, makes entering the limit a pair of cheap getter/setter calls.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from functools import lru_cache
from typing import Any

import numpy as np  # noqa: F401  (BLAS must be loaded before the controller scans)
from threadpoolctl import ThreadpoolController


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


_held = threading.local()


@contextmanager
def single_thread_blas() -> Iterator[None]:
    """Limit BLAS to one thread inside a ``with`` block: the problems are small enough that
    threads only add contention, and the pipeline already runs fits in parallel. Inside an
    outer block (a whole workflow) the inner ones cost nothing: the limit is already held."""
    if getattr(_held, "depth", 0):
        _held.depth += 1
        try:
            yield
        finally:
            _held.depth -= 1
        return
    limiter: AbstractContextManager[Any] = _controller().limit(limits=1, user_api="blas")
    with limiter:
        _held.depth = 1
        try:
            yield
        finally:
            _held.depth = 0
