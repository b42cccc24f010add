"""Atomic writes: the target is either the old content or the new one, never half of it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rig_io.atomic import (
    OLD_TAG,
    TMP_TAG,
    atomic_path,
    clean_leftovers,
    contained,
    host_tag,
    is_temporary,
    pid_alive,
    write_text_atomic,
)
from rig_io.errors import RigIOError


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


# --------------------------------------------------------------------------------------
# containment, durability, recovery after a kill
# --------------------------------------------------------------------------------------


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    pid = int(proc.stdout)
    assert not pid_alive(pid)
    return pid


@pytest.mark.parametrize("part", ["../../escape", "/etc/passwd", "a/b", "..", ".", "", "a\\b",
                                  "x\x00y"])
def test_contained_refuses_anything_but_one_plain_name(tmp_path: Path, part: str) -> None:
    with pytest.raises(RigIOError, match="unsafe path component"):
        contained(tmp_path / "out", "samples", part)


def test_contained_refuses_a_symlink_out_of_the_root(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "models").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(RigIOError, match="outside its output folder"):
        contained(tmp_path / "out", "models", "m.json")
    assert contained(tmp_path / "out", "samples", "..run.parquet") == \
        tmp_path / "out" / "samples" / "..run.parquet"


def test_temporaries_carry_our_pattern_and_the_writers_pid(tmp_path: Path) -> None:
    target = tmp_path / "run"
    with atomic_path(target) as tmp:
        assert is_temporary(tmp.name) and f"-{os.getpid()}-" in tmp.name
        tmp.mkdir()
        (tmp / "a.csv").write_text("1")
        # a live writer's temporary is never cleaned by another stage starting
        assert clean_leftovers(tmp_path) == []
        assert tmp.is_dir()
    assert (target / "a.csv").read_text() == "1"


def test_leftovers_of_a_dead_writer_are_cleaned_and_nothing_else(tmp_path: Path) -> None:
    pid = _dead_pid()
    host = host_tag()
    sub = tmp_path / "samples"
    sub.mkdir()
    (sub / f".r1.parquet.{TMP_TAG}-{host}-{pid}-abcd1234.parquet.tmp").write_bytes(b"half")
    (tmp_path / f".run.{TMP_TAG}-{host}-{pid}-abcd1234.tmp").mkdir()
    (tmp_path / f".run.{TMP_TAG}-{host}-{pid}-abcd1234.tmp" / "x").write_text("x")
    (sub / "r0.parquet").write_bytes(b"good")
    (tmp_path / ".hidden_user_file.tmp").write_text("mine")  # not our pattern: kept
    (sub / f".r2.parquet.{TMP_TAG}-{host}-{os.getpid()}-abcd1234.tmp").write_text("live")
    done = clean_leftovers(tmp_path)
    assert len(done) == 2
    assert _siblings(sub) == {"r0.parquet", f".r2.parquet.{TMP_TAG}-{host}-{os.getpid()}"
                                            "-abcd1234.tmp"}
    assert _siblings(tmp_path) == {"samples", ".hidden_user_file.tmp"}


def test_a_folder_replace_killed_between_its_renames_is_undone(tmp_path: Path) -> None:
    pid = _dead_pid()
    # killed after moving the old folder aside, before moving the new one in
    old = tmp_path / f".run.{OLD_TAG}-{host_tag()}-{pid}"
    old.mkdir()
    (old / "encoder.csv").write_text("old complete")
    new = tmp_path / f".run.{TMP_TAG}-{host_tag()}-{pid}-abcd1234.tmp"
    new.mkdir()
    (new / "encoder.csv").write_text("new, maybe partial")
    clean_leftovers(tmp_path)
    assert _siblings(tmp_path) == {"run"}
    assert (tmp_path / "run" / "encoder.csv").read_text() == "old complete"
    # killed after moving the new one in, before removing the old one
    old.mkdir()
    (old / "encoder.csv").write_text("older")
    clean_leftovers(tmp_path)
    assert _siblings(tmp_path) == {"run"}
    assert (tmp_path / "run" / "encoder.csv").read_text() == "old complete"


def test_atomic_writes_fsync_the_file_before_the_rename_and_the_folder_after(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    events: list[str] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        events.append("dir" if os.path.isdir(f"/proc/self/fd/{fd}") else "file")
        real_fsync(fd)

    def replace(a: object, b: object) -> None:
        events.append("rename")
        real_replace(a, b)  # type: ignore[arg-type]

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    write_text_atomic(tmp_path / "a.json", "{}")
    assert events == ["file", "rename", "dir"]


# --------------------------------------------------------------------------------------
# what an output may replace, and a write that fails
# --------------------------------------------------------------------------------------


def test_a_symlink_at_the_target_is_refused_and_what_it_names_is_untouched(
        tmp_path: Path) -> None:
    precious = tmp_path / "elsewhere" / "precious.txt"
    precious.parent.mkdir()
    precious.write_bytes(b"keep me\n")
    link = tmp_path / "out" / "report.json"
    link.parent.mkdir()
    link.symlink_to(precious)
    with pytest.raises(RigIOError, match="symbolic link"):
        write_text_atomic(link, "new")
    assert precious.read_bytes() == b"keep me\n"
    assert link.is_symlink() and _siblings(link.parent) == {"report.json"}


def test_an_existing_folder_where_a_file_is_expected_is_refused_before_the_work(
        tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    (target / "inner").mkdir(parents=True)
    ran = []
    with pytest.raises(RigIOError, match="existing folder where a file is expected"):
        with atomic_path(target, folder=False) as tmp:
            ran.append(tmp)
    assert ran == [] and (target / "inner").is_dir()


def test_a_fifo_is_never_replaced(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(RigIOError, match="not a regular file"):
        write_text_atomic(fifo, "x")
    assert fifo.exists() and not fifo.is_file()


def test_a_target_turned_into_a_link_while_written_is_refused_at_the_rename(
        tmp_path: Path) -> None:
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    target = tmp_path / "out.txt"
    with pytest.raises(RigIOError, match="symbolic link"):
        with atomic_path(target) as tmp:
            tmp.write_text("new")
            target.symlink_to(precious)
    assert precious.read_text() == "keep" and target.is_symlink()
    assert _siblings(tmp_path) == {"precious.txt", "out.txt"}


def test_an_oserror_while_writing_is_a_write_error_naming_the_file_and_the_free_space(
        tmp_path: Path) -> None:
    import errno

    from rig_io.errors import WriteError

    target = tmp_path / "runs.json"
    write_text_atomic(target, "old")
    with pytest.raises(WriteError) as info:
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
    msg = str(info.value)
    assert "\n" not in msg and str(target) in msg and "No space left on device" in msg
    assert "ENOSPC" in msg and " free of " in msg, msg
    assert target.read_text() == "old" and _siblings(tmp_path) == {"runs.json"}
