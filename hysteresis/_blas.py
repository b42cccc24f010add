"""One BLAS thread for the many tiny dense solves of identification.

``threadpoolctl.threadpool_limits`` rescans the process's loaded libraries on every call
(``/proc/self/maps`` on Linux, milliseconds each); identification calls it thousands of times
per workflow, where the scan cost more than the algebra it guarded. One controller, built on
first use, makes entering the limit a pair of cheap getter/setter calls.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from functools import lru_cache
from typing import Any

import numpy as np  # noqa: F401  (BLAS must be loaded before the controller scans)
from threadpoolctl import ThreadpoolController


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def single_thread_blas() -> AbstractContextManager[Any]:
    """Limit BLAS to one thread inside a ``with`` block: the problems are small enough that
    threads only add contention, and the pipeline already runs fits in parallel."""
    limiter: AbstractContextManager[Any] = _controller().limit(limits=1, user_api="blas")
    return limiter
