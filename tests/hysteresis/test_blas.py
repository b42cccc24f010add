"""The shared one-BLAS-thread limit: it limits inside the block and restores after."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from hysteresis._blas import single_thread_blas


@pytest.fixture(autouse=True)
def two_blas_threads() -> Iterator[None]:
    """Start from two BLAS threads (the test session runs with one), so that a limit that
    did nothing, or a restore that did not happen, shows."""
    with threadpool_limits(limits=2, user_api="blas"):
        assert set(_blas_threads()) == {2}
        yield


def _blas_threads() -> list[int]:
    return [int(lib["num_threads"]) for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_limits_blas_to_one_thread_and_restores_the_previous_count() -> None:
    before = _blas_threads()
    assert before, "numpy's BLAS is not visible to threadpoolctl"
    with single_thread_blas():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_nested_limits_restore_in_order() -> None:
    before = _blas_threads()
    with single_thread_blas():
        with single_thread_blas():
            assert _blas_threads() == [1] * len(before)
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_an_error_inside_nested_limits_still_restores_the_count() -> None:
    before = _blas_threads()
    try:
        with single_thread_blas():
            with single_thread_blas():
                raise RuntimeError("inside")
    except RuntimeError:
        pass
    assert _blas_threads() == before
    with single_thread_blas():  # and the next block limits again
        assert _blas_threads() == [1] * len(before)
