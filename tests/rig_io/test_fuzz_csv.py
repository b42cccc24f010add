"""Property-based fuzzing of the CSV streams of the committed sample run (copied as plain CSV):
hostile cells, deleted, repeated or swapped lines, truncations and stray bytes.

Every outcome must be either an accepted run with sound values or a :class:`RigIOError` that
names the file and the column or row; an encoder count outside the declared counter, a
non-number in a number column and a decimal comma must never be accepted.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rig_io.errors import RigIOError
from tests.rig_io.hardening_util import (
    SAMPLE_FOLDER,
    assert_names_where,
    assert_sound,
    folder_source,
    ingest_one,
    plain_copy,
)

FUZZ = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])
STREAMS = ("encoder", "loadcell", "camera", "events")
COUNTS = ("input_counts", "output_counts")
BITS = 32

CELLS = st.one_of(
    st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "1e30", "-1e30", str(2**63),
                     str(2**63 - 1), str(-(2**63) - 1), str(2**64), str(2**32), str(2**31),
                     "1,5", '"1,5"', '"a, b"', "abc", "0x10", "1e-300", "-0", "0.5", "1.5",
                     "\u0661", "True", "estop", "note", "start", "1_000", "+3", "  7  ",
                     "\x00", '"', "1e308", "9" * 40]),
    st.integers(min_value=-(2**66), max_value=2**66).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet=st.characters(codec="utf-8"), max_size=6),
)


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield plain_copy(tmp_path_factory.mktemp("fuzz_csv"))


@st.composite
def mutation(draw: st.DrawFn) -> tuple[str, str, int, int, str]:
    stream = draw(st.sampled_from(STREAMS))
    kind = draw(st.sampled_from(["cell", "cell", "cell", "cell", "delete", "repeat", "swap",
                                 "truncate", "insert"]))
    row = draw(st.integers(0, 10_000))
    col = draw(st.integers(0, 3))
    value = draw(CELLS) if kind in ("cell", "insert") else ""
    return stream, kind, row, col, value


def _apply(text: str, kind: str, row: int, col: int, value: str) -> tuple[str, str | None]:
    """The mutated text and, for a cell mutation, the column it hit."""
    lines = text.split("\n")[:-1]
    header = lines[0].split(",")
    i = 1 + row % (len(lines) - 1)  # a data line
    if kind == "cell":
        fields = lines[i].split(",")
        j = col % len(fields)
        fields[j] = value
        lines[i] = ",".join(fields)
        return "\n".join(lines) + "\n", header[j] if j < len(header) else None
    if kind == "delete":
        del lines[i]
    elif kind == "repeat":
        lines.insert(i, lines[i])
    elif kind == "swap":
        k = 1 + (row // 7) % (len(lines) - 1)
        lines[i], lines[k] = lines[k], lines[i]
    elif kind == "insert":
        lines.insert(i, value)
    elif kind == "truncate":
        full = "\n".join(lines) + "\n"
        return full[: row % len(full)], None
    return "\n".join(lines) + "\n", None


def _must_reject(stream: str, kind: str, column: str | None, value: str) -> bool:
    if kind != "cell" or column is None:
        return False
    if "," in value and not value.startswith('"'):
        return stream != "events" or column != "detail"
    if stream == "encoder" and column in COUNTS:
        try:
            count = int(value.strip())
        except ValueError:
            return value.strip() != "" or column == "input_counts"
        return not -(2 ** (BITS - 1)) <= count < 2**BITS
    if stream in ("encoder", "loadcell") or column in ("t_ns", "frame", "confidence"):
        try:
            number = float(value)
        except ValueError:
            return True
        return number != number or abs(number) == float("inf")
    return False


@FUZZ
@given(m=mutation())
def test_csv_mutations(base: Path, m: tuple[str, str, int, int, str]) -> None:
    stream, kind, row, col, value = m
    text = (base / f"{stream}.csv").read_text()
    mutated, column = _apply(text, kind, row, col, value)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / base.name
        shutil.copytree(base, folder)
        (folder / f"{stream}.csv").write_bytes(mutated.encode("utf-8"))
        try:
            frame = ingest_one(folder_source(folder))
        except RigIOError as err:
            assert_names_where(err)
            event(f"rejected {stream}: {err.reason[:28]}")
            return
    event(f"accepted {stream} {kind}")
    assert not _must_reject(stream, kind, column, value), (
        f"accepted {value!r} in {stream}.{column}")
    assert_sound(frame)


GZ = (SAMPLE_FOLDER / "encoder.csv.gz").read_bytes()


@settings(FUZZ, max_examples=60)
@given(cut=st.integers(0, len(GZ)), flips=st.lists(
    st.tuples(st.integers(0, len(GZ) - 1), st.integers(0, 7)), max_size=3))
def test_gzip_stream_damage(base: Path, cut: int, flips: list[tuple[int, int]]) -> None:
    data = bytearray(GZ[:cut] if cut < len(GZ) else GZ)
    for pos, bit in flips:
        if pos < len(data):
            data[pos] ^= 1 << bit
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / base.name
        shutil.copytree(base, folder)
        (folder / "encoder.csv").unlink()
        (folder / "encoder.csv.gz").write_bytes(bytes(data))
        try:
            frame = ingest_one(folder_source(folder))
        except RigIOError as err:
            assert_names_where(err)
            event(f"rejected: {err.reason[:30]}")
            return
    event("accepted")
    assert_sound(frame)
