"""Excitations the log format does not list travel as ``free`` runs with a ``name``."""

from __future__ import annotations

import pytest

from rig_io.errors import RigIOError
from rig_io.manifest import check_manifest, excitation_name
from rig_io.synthetic import make_manifest
from rig_io.virtual.excitations import manifest_excitation


def test_a_rig_only_excitation_is_written_as_a_named_free_run() -> None:
    block = manifest_excitation("band_random", {"amplitude_mm": 5.0, "seed": 3})
    assert block["kind"] == "free" and block["name"] == "band_random"
    assert excitation_name(block) == "band_random"
    listed = manifest_excitation("mixed_sine", {"terms": []})
    assert listed["kind"] == "mixed_sine" and "name" not in listed


def test_the_name_only_renames_free_runs() -> None:
    assert excitation_name({"kind": "sine", "name": "other"}) == "sine"
    assert excitation_name({"kind": "free"}) == "free"


@pytest.mark.parametrize("name", ["../x", "a/b", "", ".hidden"])
def test_an_unsafe_name_is_rejected(name: str) -> None:
    manifest = make_manifest("r1")
    manifest["excitation"] = {"kind": "free", "name": name}
    with pytest.raises(RigIOError, match="excitation.name"):
        check_manifest(manifest, file="manifest.json", streams=["encoder"])


def test_a_safe_name_passes_the_manifest_schema() -> None:
    manifest = make_manifest("r1")
    manifest["excitation"] = {"kind": "free", "name": "band_random", "seed": 4}
    assert check_manifest(manifest, file="manifest.json", streams=["encoder"]) == "r1"
