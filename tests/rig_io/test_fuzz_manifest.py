"""Property-based fuzzing of the manifest of the committed sample run (copied; raw samples are
never modified): set, delete or add keys with hostile values, or damage the JSON text.

Every outcome must be either an accepted run with sound values or a :class:`RigIOError`
that names the file and the key or row; corrupt calibration values and unsafe identifiers
must never be accepted.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rig_io.errors import RigIOError
from rig_io.manifest import is_safe_identifier
from tests.rig_io.hardening_util import (
    assert_names_where,
    assert_sound,
    folder_source,
    ingest_one,
    plain_copy,
)

FUZZ = settings(max_examples=160, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])

#: Keys whose value must be a finite number (calibration and the sheath shape).
NUMERIC = {"channels.encoder.counts_per_unit", "channels.encoder.counter_bits",
           "channels.encoder.input_sign", "channels.encoder.output_sign",
           *(f"channels.loadcell.{s}.{k}" for s in ("input", "output")
             for k in ("newton_per_mv_per_v", "zero_mv_per_v", "range_n"))}
#: Identifiers that become file names.
IDENTIFIERS = {"run_id", "rig"}


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield plain_copy(tmp_path_factory.mktemp("fuzz_manifest"))


def _paths(value: Any, prefix: str = "") -> list[str]:
    out = []
    if isinstance(value, dict):
        for k, v in value.items():
            p = f"{prefix}.{k}" if prefix else k
            out.append(p)
            out.extend(_paths(v, p))
    return out


NASTY_STRINGS = ["", " ", "../../escape", "/abs/path", "sub/dir", "..", ".", "a\x00b", "x" * 300,
                 "NaN", "1e-300", "tsm-bench", "bending-joint", "mm", "deg", "rad", "sine",
                 "zigzag", "output_mm", "tip_angle_deg", "camera", "tracker", "32", "-1",
                 "C:\\win", "~", "é", "\n"]
VALUES = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, -1, 2, 8, 16, 31, 32, 63, 64, 2**63, -(2**63), 10**9]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e-300, 1e300, -0.0, 5e-324, 0.5]),
    st.sampled_from(NASTY_STRINGS), st.text(max_size=12),
    st.lists(st.integers(-3, 3), max_size=3), st.just({}), st.just([]),
)


@st.composite
def mutations(draw: st.DrawFn, manifest: dict[str, Any]) -> tuple[str, str, Any]:
    kind = draw(st.sampled_from(["set", "set", "set", "delete", "add", "text"]))
    paths = _paths(manifest)
    if kind == "text":
        text = json.dumps(manifest)
        pos = draw(st.integers(0, len(text)))
        return kind, str(pos), draw(st.sampled_from(["", "}", "{", ",", '"', "\\", "NaN",
                                                     "Infinity", "\x00", "[" * 3]))
    path = draw(st.sampled_from(paths))
    if kind == "add":
        return kind, path, draw(st.sampled_from(["extra", "kind", "unit", "range_n"]))
    return kind, path, draw(VALUES) if kind == "set" else None


def _apply(manifest: dict[str, Any], mutation: tuple[str, str, Any]) -> str:
    kind, path, value = mutation
    if kind == "text":
        text = json.dumps(manifest)
        pos = int(path)
        return text[:pos] + str(value) + text[pos + 1:]
    keys = path.split(".")
    d: Any = manifest
    for k in keys[:-1]:
        d = d[k]
    if kind == "set":
        d[keys[-1]] = value
    elif kind == "delete":
        del d[keys[-1]]
    else:
        target = d[keys[-1]]
        if isinstance(target, dict):
            target[str(value)] = 1.0
        else:
            d[keys[-1]] = {str(value): target}
    return json.dumps(manifest)


def _must_reject(mutation: tuple[str, str, Any]) -> bool:
    kind, path, value = mutation
    if kind == "delete" and (path in NUMERIC or path in IDENTIFIERS or path == "format"):
        return True
    if kind != "set":
        return False
    if path in IDENTIFIERS:
        return not is_safe_identifier(value)
    if path in NUMERIC or path.startswith("configuration."):
        if path.startswith("configuration.") and value is None:
            return False
        return (not isinstance(value, int | float) or isinstance(value, bool)
                or not math.isfinite(value))
    return path == "format" and value != "tsm-rig-log/1"


@FUZZ
@given(data=st.data())
def test_manifest_mutations(base: Path, data: st.DataObject) -> None:
    manifest = json.loads((base / "manifest.json").read_text())
    mutation = data.draw(mutations(manifest))
    text = _apply(manifest, mutation)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / base.name
        shutil.copytree(base, folder)
        (folder / "manifest.json").write_text(text)
        try:
            frame = ingest_one(folder_source(folder))
        except RigIOError as err:
            assert_names_where(err)
            event(f"rejected: {err.key or err.reason[:30]}")
            return
    event("accepted")
    assert not _must_reject(mutation), f"accepted a corrupt manifest: {mutation}"
    assert_sound(frame)
