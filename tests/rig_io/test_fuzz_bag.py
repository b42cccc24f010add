"""Property-based fuzzing of the committed rosbag1 sample (copied; raw samples are never
modified): truncations at any byte and bit flips anywhere, including the message data.

Every outcome must be either an accepted run with sound values (a flipped low mantissa bit
is a legal, small change) or a :class:`RigIOError` naming the bag file, never another
exception and never a hang.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rig_io.bag import write_bag
from rig_io.errors import RigIOError
from rig_io.folder import read_run_folder
from rig_io.sources import Source
from tests.rig_io.hardening_util import (
    SAMPLE_BAG,
    SAMPLE_FOLDER,
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


@pytest.fixture(scope="module")
def bags2(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Path]]:
    """The sample run written as rosbag2 folders (mcap and sqlite3 storage)."""
    root = tmp_path_factory.mktemp("bags2")
    run = read_run_folder(SAMPLE_FOLDER)
    yield {s: write_bag(run, root / f"sample_{s}", storage=s)  # type: ignore[arg-type]
           for s in ("mcap", "sqlite3")}


@settings(FUZZ, max_examples=40)
@given(storage=st.sampled_from(["mcap", "sqlite3"]), where=st.floats(0.0, 1.0),
       flip=st.booleans(), bit=st.integers(0, 7))
def test_rosbag2_damage(bags2: dict[str, Path], storage: str, where: float, flip: bool,
                        bit: int) -> None:
    src = bags2[storage]
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / src.name
        shutil.copytree(src, bag)
        data_file = next(f for f in bag.iterdir() if f.suffix in (".mcap", ".db3"))
        data = bytearray(data_file.read_bytes())
        pos = min(int(where * len(data)), len(data) - 1)
        if flip:
            data[pos] ^= 1 << bit
        else:
            del data[pos:]
        data_file.write_bytes(bytes(data))
        try:
            frame = ingest_one(Source("rosbag2", bag, tuple(sorted(bag.iterdir()))))
        except RigIOError as err:
            assert err.file is not None and err.file.startswith(str(bag)), str(err)
            assert_names_where(err)
            event(f"rejected {storage}: {err.reason[:30]}")
            return
    event(f"accepted {storage}")
    assert_sound(frame)
