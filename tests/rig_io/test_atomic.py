"""Atomic writes: the target is either the old content or the new one, never half of it."""

from __future__ import annotations

from pathlib import Path

import pytest

from rig_io.atomic import atomic_path, write_text_atomic


def _siblings(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def test_file_is_replaced_and_no_temporary_is_left(tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    write_text_atomic(target, "old")
    write_text_atomic(target, "new")
    assert target.read_text() == "new"
    assert _siblings(tmp_path) == {"report.json"}


def test_folder_is_replaced_whole(tmp_path: Path) -> None:
    target = tmp_path / "run"
    target.mkdir()
    (target / "stale.csv").write_text("x")
    with atomic_path(target) as tmp:
        tmp.mkdir()
        (tmp / "encoder.csv").write_text("t_ns\n0\n")
    assert _siblings(target) == {"encoder.csv"}
    assert _siblings(tmp_path) == {"run"}


def test_keep_name_yields_the_targets_own_name(tmp_path: Path) -> None:
    target = tmp_path / "bag_folder"
    with atomic_path(target, keep_name=True) as tmp:
        assert tmp.name == "bag_folder" and tmp.parent != tmp_path
        tmp.mkdir()
        (tmp / f"{tmp.name}.db3").write_text("storage")
    assert (target / "bag_folder.db3").read_text() == "storage"
    assert _siblings(tmp_path) == {"bag_folder"}


@pytest.mark.parametrize("keep_name", [False, True])
def test_a_crash_leaves_the_old_target_and_no_temporary(tmp_path: Path, keep_name: bool) -> None:
    target = tmp_path / "metrics.csv"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="crash"):
        with atomic_path(target, keep_name=keep_name) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash")
    assert target.read_text() == "old"
    assert _siblings(tmp_path) == {"metrics.csv"}
