"""Atomic, durable, contained writes.

* :func:`atomic_path` yields a temporary name beside the target; on success the content is
  fsynced, renamed onto the target and the folder fsynced, so a crash (even a power cut)
  never leaves a half-written file or folder under the target's name.
* A folder cannot be replaced in one step: the old folder is renamed aside, the new one
  renamed in, then the old one removed. If the process dies in between, the target is either
  the old complete folder, the new complete folder, or absent with the old one aside;
  :func:`clean_leftovers` (called by each stage on its output roots when it starts) puts the
  old one back in the last case and removes temporaries of dead writers.
* :func:`contained` builds an output path from data (run ids, rig names ...) and refuses any
  that would land outside its output root.
* An output is never written through a symbolic link and never replaces anything but a
  regular file (or, for a folder output, a real folder): :func:`check_output` refuses the
  rest, before the writer starts and again just before the rename.
* An ``OSError`` while writing (a full disk, no permission) becomes a
  :class:`~rig_io.errors.WriteError` naming the target and the free space left: a failure of
  the stage, which must not be mistaken for a bad input.

Temporary names carry the writer's host and process id, ``.<name>.tsmtmp-<host>-<pid>-<random>
<suffix>.tmp`` and ``.<name>.tsmold-<host>-<pid>``, so a cleaner removes only leftovers of
processes that are gone, never a parallel job's file in flight, and never anything else.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import socket
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

from rig_io.errors import RigIOError, WriteError

TMP_TAG = "tsmtmp"
OLD_TAG = "tsmold"
_TMP_RE = re.compile(rf"^\.(?P<name>.+)\.{TMP_TAG}-(?P<host>[0-9a-f]{{8}})-(?P<pid>\d+)-.*\.tmp$")
_OLD_RE = re.compile(rf"^\.(?P<name>.+)\.{OLD_TAG}-(?P<host>[0-9a-f]{{8}})-(?P<pid>\d+)$")


def host_tag() -> str:
    """Short, file-name-safe tag of this host (temporary names, MLflow run tags)."""
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def _owner() -> str:
    return f"{host_tag()}-{os.getpid()}"


def pid_alive(pid: int) -> bool:
    """True when a process with this id exists on this host (signal 0 probes, sends nothing)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def owner_gone(host: str, pid: int) -> bool:
    """True only when the writer ran on this host and its process no longer exists."""
    return host == host_tag() and pid != os.getpid() and not pid_alive(pid)


# --------------------------------------------------------------------------------------
# containment
# --------------------------------------------------------------------------------------


def safe_part(part: object, *, what: str = "path component") -> str:
    """``part`` as a single file-name component, or :class:`RigIOError` if it is not one."""
    text = str(part)
    bad = (not text or text in (".", "..") or "/" in text or "\\" in text or "\x00" in text
           or (os.altsep is not None and os.altsep in text) or Path(text).is_absolute())
    if bad:
        raise RigIOError(f"unsafe {what} {text!r}: an output name must be one plain file name "
                         "(no '/', '\\', '..', absolute path or empty name)")
    return text


def contained(root: str | os.PathLike[str], *parts: object) -> Path:
    """``root / part / ...`` after checking that each part is one plain name and that the
    resolved result (symlinks followed) lies under the resolved ``root``."""
    names = [safe_part(p) for p in parts]
    path = Path(root).joinpath(*names)
    base = Path(root).resolve()
    real = path.resolve()
    if real != base and base not in real.parents:
        raise RigIOError(f"resolves outside its output folder {str(base)!r} (to {str(real)!r})",
                         file=str(path))
    return path


# --------------------------------------------------------------------------------------
# durability
# --------------------------------------------------------------------------------------


def _fsync_fd_of(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(folder: Path) -> None:
    """Make a rename or a new entry in ``folder`` durable (no-op where unsupported)."""
    with contextlib.suppress(OSError):
        _fsync_fd_of(folder)


def fsync_tree(path: Path) -> None:
    """fsync a file, or every file and folder under a folder (symlinks skipped)."""
    if path.is_symlink():
        return
    if path.is_file():
        _fsync_fd_of(path)
        return
    if path.is_dir():
        for dirpath, _dirs, files in os.walk(path):
            for f in files:
                p = Path(dirpath) / f
                if not p.is_symlink():
                    _fsync_fd_of(p)
            fsync_dir(Path(dirpath))


# --------------------------------------------------------------------------------------
# what may be replaced
# --------------------------------------------------------------------------------------


def check_output(target: str | os.PathLike[str], *, folder: bool | None = False) -> Path:
    """``target`` as an output path, or :class:`RigIOError` when writing it would follow a
    symbolic link or replace something that is not ours to replace.

    Refused: a symbolic link (a rename would drop the link, and a writer that resolved it
    would overwrite the file it points to), a device, FIFO or socket, an existing folder where
    a file is expected (``folder=False``) and an existing file where a folder is expected
    (``folder=True``). ``folder=None`` accepts either. Folders above ``target`` may be links
    (a data folder on another disk); only the output's own name is checked.
    """
    path = Path(target)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return path
    except OSError as err:
        raise RigIOError(f"output path cannot be checked: {err.strerror or err}",
                         file=str(path)) from None
    if stat.S_ISLNK(mode):
        raise RigIOError("output path is a symbolic link: outputs are never written through a "
                         "link (it would replace what it points to); remove the link or give "
                         "another path", file=str(path))
    if stat.S_ISDIR(mode):
        if folder is False:
            raise RigIOError("output path is an existing folder where a file is expected; "
                             "remove it or give another path", file=str(path))
        return path
    if not stat.S_ISREG(mode):
        raise RigIOError("output path exists and is not a regular file (a device, FIFO or "
                         "socket); it is never replaced", file=str(path))
    if folder is True:
        raise RigIOError("output path is an existing file where a folder is expected; remove "
                         "it or give another path", file=str(path))
    return path


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"


def free_space(path: str | os.PathLike[str]) -> str:
    """Free space on the file system holding ``path`` (its nearest existing folder), as text."""
    here = Path(path)
    while not here.exists() and here != here.parent:
        here = here.parent
    try:
        usage = shutil.disk_usage(here)
    except OSError:
        return "free space unknown"
    return f"{_size(usage.free)} free of {_size(usage.total)}"


def write_error(target: str | os.PathLike[str], err: OSError) -> WriteError:
    """The one-line :class:`WriteError` for an ``OSError`` met while writing ``target``."""
    name = errno.errorcode.get(err.errno or 0, "") if err.errno else ""
    reason = err.strerror or str(err) or type(err).__name__
    return WriteError(f"cannot write: {reason}{f' ({name})' if name else ''}; "
                      f"{free_space(Path(target).parent)} on its file system; the stage "
                      "stopped and removed nothing", file=str(target))


# --------------------------------------------------------------------------------------
# atomic replace
# --------------------------------------------------------------------------------------


def _replace(src: Path, target: Path) -> None:
    """Move the complete, synced ``src`` onto ``target``, durably."""
    if target.is_dir() and not target.is_symlink() and src.is_dir():
        old = target.with_name(f".{target.name}.{OLD_TAG}-{_owner()}")
        if old.exists():
            shutil.rmtree(old)
        os.replace(target, old)
        os.replace(src, target)
        fsync_dir(target.parent)
        shutil.rmtree(old)
    else:
        os.replace(src, target)
        fsync_dir(target.parent)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], *, suffix: str = "",
                keep_name: bool = False, folder: bool | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; sync and rename it onto ``target`` on success.

    Works for files and for folders (the caller creates what it needs at the yielded path;
    ``folder`` says which when known, so a wrong kind of existing ``target`` is refused
    before any work, see :func:`check_output`). With ``keep_name`` the yielded path has
    ``target``'s own name, inside a hidden temporary folder: for writers that name inner
    files after their folder (rosbag2 storage files). On error the temporary is removed and
    ``target`` is left as it was; an ``OSError`` (disk full ...) is raised as
    :class:`~rig_io.errors.WriteError`.
    """
    target = Path(target)
    check_output(target, folder=folder)
    prefix = f".{target.name}.{TMP_TAG}-{_owner()}-"
    holder: Path | None = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        if keep_name:
            holder = Path(tempfile.mkdtemp(prefix=prefix, suffix=f"{suffix}.tmp",
                                           dir=target.parent))
            tmp = holder / target.name
        else:
            fd, tmp_name = tempfile.mkstemp(prefix=prefix, suffix=f"{suffix}.tmp",
                                            dir=target.parent)
            os.close(fd)
            tmp = Path(tmp_name)
            tmp.unlink()  # the caller decides whether this becomes a file or a folder
    except OSError as err:
        raise write_error(target, err) from err
    try:
        try:
            yield tmp
            fsync_tree(tmp)
            # again at the end: the target may have changed while the content was made
            check_output(target, folder=tmp.is_dir() and not tmp.is_symlink())
            _replace(tmp, target)
        except OSError as err:
            raise write_error(target, err) from err
    finally:
        for leftover in (tmp, holder):
            if leftover is None:
                continue
            with contextlib.suppress(OSError):  # a cleanup must not hide the first error
                if leftover.is_dir() and not leftover.is_symlink():
                    shutil.rmtree(leftover, ignore_errors=True)
                elif leftover.exists() or leftover.is_symlink():
                    leftover.unlink()


def write_text_atomic(target: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``target`` atomically (UTF-8)."""
    with atomic_path(target, folder=False) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)


def write_bytes_atomic(target: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically."""
    with atomic_path(target, folder=False) as tmp:
        tmp.write_bytes(data)
    return Path(target)


# --------------------------------------------------------------------------------------
# recovery
# --------------------------------------------------------------------------------------


def is_temporary(name: str) -> bool:
    """True for a name :func:`atomic_path` uses for its temporaries (any writer)."""
    return bool(_TMP_RE.match(name) or _OLD_RE.match(name))


def clean_leftovers(root: str | os.PathLike[str], *, recursive: bool = True) -> list[Path]:
    """Finish or undo what writers killed mid-way left under ``root``; return what was done.

    Only names of our own temporary pattern whose writer is gone (same host, dead pid) are
    touched: a temporary is removed; a folder set aside by an interrupted folder replace is
    put back when the target is missing (the old complete state), else removed. Live
    writers' temporaries and every other file are left alone.
    """
    base = Path(root)
    if not base.is_dir():
        return []
    touched: list[Path] = []
    for dirpath, dirs, files in os.walk(base):
        here = Path(dirpath)
        for name in sorted([*dirs, *files]):
            m_tmp, m_old = _TMP_RE.match(name), _OLD_RE.match(name)
            m = m_tmp or m_old
            if m is None or not owner_gone(m["host"], int(m["pid"])):
                continue
            path = here / name
            if m_old is not None:
                target = here / m["name"]
                if not target.exists() and not target.is_symlink():
                    os.replace(path, target)
                    fsync_dir(here)
                    touched.append(target)
                    continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
            touched.append(path)
        # temporaries were handled whole above; do not walk into them
        dirs[:] = [d for d in dirs if not is_temporary(d) and (here / d).is_dir()] \
            if recursive else []
    return touched


def owned_prefix(tag: str) -> str:
    """Prefix for a temporary folder in the system temp dir that names its owner
    (``<tag>-<host>-<pid>-``), so :func:`clean_owned_temp` can tell a leak from a live one."""
    return f"{tag}-{host_tag()}-{os.getpid()}-"


def clean_owned_temp(tag: str, folder: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove ``<tag>-<host>-<pid>-*`` folders (default: the system temp dir) whose process
    is gone; return them."""
    pattern = re.compile(rf"^{re.escape(tag)}-(?P<host>[0-9a-f]{{8}})-(?P<pid>\d+)-")
    base = Path(folder if folder is not None else tempfile.gettempdir())
    removed = []
    with contextlib.suppress(OSError):
        for p in base.iterdir():
            m = pattern.match(p.name)
            if m and p.is_dir() and not p.is_symlink() and owner_gone(m["host"], int(m["pid"])):
                shutil.rmtree(p, ignore_errors=True)
                removed.append(p)
    return removed
