"""Property-based fuzzing of the committed rosbag1 sample (copied; raw samples are never
modified): truncations at any byte and bit flips anywhere, including the message data.

Every outcome must be either an accepted run with sound values (a flipped low mantissa bit
is a legal, small change) or a :class:`RigIOError` naming the bag file, never another
exception and never a hang.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rig_io.errors import RigIOError
from tests.rig_io.hardening_util import (
    SAMPLE_BAG,
    assert_names_where,
    assert_sound,
    bag_source,
    ingest_one,
)

FUZZ = settings(max_examples=120, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])
DATA = SAMPLE_BAG.read_bytes()


def _check(mutated: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / SAMPLE_BAG.name
        bag.write_bytes(mutated)
        try:
            frame = ingest_one(bag_source(bag))
        except RigIOError as err:
            assert err.file is not None and err.file.startswith(str(bag)), str(err)
            assert_names_where(err)
            event(f"rejected: {err.reason[:30]}")
            return
    event("accepted")
    assert_sound(frame)


@settings(FUZZ, max_examples=50)
@given(cut=st.integers(min_value=0, max_value=len(DATA) - 1))
def test_bag_truncations(cut: int) -> None:
    _check(DATA[:cut])


@FUZZ
@given(flips=st.lists(st.tuples(st.integers(0, len(DATA) - 1), st.integers(0, 7)),
                      min_size=1, max_size=4))
def test_bag_bit_flips(flips: list[tuple[int, int]]) -> None:
    data = bytearray(DATA)
    for pos, bit in flips:
        data[pos] ^= 1 << bit
    _check(bytes(data))
