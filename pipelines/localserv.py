"""Throwaway local services for checks: started on 127.0.0.1, stopped by process group.

Every service is started in its own session (``start_new_session``), so its process id is
also its process-group id: :func:`stop` ends exactly that group (the server and whatever
workers it forked), never anything found by name. :func:`group_alive` tells whether any
process of a group is left, which the checks assert after tearing down.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

LOOPBACK = "127.0.0.1"


class ServiceError(Exception):
    """A service that would not start, answer or stop."""


def free_port(*, start: int = 41000, stop: int = 48000) -> int:
    """A TCP port nobody listens on at 127.0.0.1, from an uncommon range."""
    import random

    ports = list(range(start, stop))
    random.shuffle(ports)
    for port in ports[:200]:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((LOOPBACK, port))
            except OSError:
                continue
            return port
    raise ServiceError(f"no free port in {start}-{stop}")


def start(cmd: Sequence[str], *, log: Path, cwd: Path | None = None,
          env: Mapping[str, str] | None = None) -> subprocess.Popen[bytes]:
    """Start ``cmd`` in a new session (its pid = its process group), output to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("ab") as fh:
        return subprocess.Popen(list(cmd), stdout=fh, stderr=subprocess.STDOUT, cwd=cwd,
                                env=dict(env) if env is not None else None,
                                start_new_session=True)


def wait_http(url: str, *, timeout: float = 60.0, proc: subprocess.Popen[bytes] | None = None,
              log: Path | None = None) -> None:
    """Until ``url`` answers (any HTTP status below 500)."""
    deadline = time.monotonic() + timeout
    last = ""
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise ServiceError(f"{url}: server exited with {proc.returncode}" + _tail(log))
        try:
            with urllib.request.urlopen(url, timeout=5) as resp:
                if resp.status < 500:
                    return
        except urllib.error.HTTPError as exc:
            if exc.code < 500:
                return
            last = str(exc)
        except (OSError, urllib.error.URLError) as exc:
            last = str(exc)
        time.sleep(0.3)
    raise ServiceError(f"{url} did not answer in {timeout:.0f} s ({last})" + _tail(log))


def _tail(log: Path | None, n: int = 3000) -> str:
    if log is None or not log.exists():
        return ""
    return "\n--- " + str(log) + " ---\n" + log.read_text(errors="replace")[-n:]


def group_alive(pgid: int) -> list[int]:
    """Process ids still in process group ``pgid`` (zombies excluded)."""
    alive = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # pid (comm) state ppid pgrp ...: comm may contain spaces, split after the last ')'
        fields = stat[stat.rfind(")") + 2:].split()
        if len(fields) >= 3 and int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(entry.name))
    return alive


def stop(proc: subprocess.Popen[bytes], *, timeout: float = 20.0) -> None:
    """SIGTERM the service's process group, SIGKILL what is left after ``timeout``."""
    pgid = proc.pid
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pgid, signal.SIGTERM)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        proc.poll()
        if not group_alive(pgid):
            break
        time.sleep(0.2)
    else:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(pgid, signal.SIGKILL)
        time.sleep(0.5)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=5)


@contextlib.contextmanager
def running(cmd: Sequence[str], *, log: Path, url: str | None = None, timeout: float = 60.0,
            cwd: Path | None = None, env: Mapping[str, str] | None = None
            ) -> Iterator[subprocess.Popen[bytes]]:
    """A service for the block; always stopped (its whole process group) afterwards."""
    proc = start(cmd, log=log, cwd=cwd, env=env)
    try:
        if url is not None:
            wait_http(url, timeout=timeout, proc=proc, log=log)
        yield proc
    finally:
        stop(proc)


def mlflow_ui_command(python: str, store_uri: str, port: int) -> list[str]:
    """What ``make ui`` runs, on a given store and port (always loopback)."""
    return [python, "-m", "mlflow", "ui", "--backend-store-uri", store_uri,
            "--host", LOOPBACK, "--port", str(port), "--workers", "1"]


#: The environment variable ``mlflow server`` reads its ``--backend-store-uri`` from (click's
#: ``envvar`` of that option in mlflow/cli).
BACKEND_STORE_ENV = "MLFLOW_BACKEND_STORE_URI"


def mlflow_server_launch(python: str, store_uri: str, *, artifacts_uri: str, port: int,
                         workers: int = 2, env: Mapping[str, str] | None = None
                         ) -> tuple[list[str], dict[str, str]]:
    """The command and environment of an ``mlflow server`` on loopback.

    The backend store URI (a database URI with its password) goes in the environment, never
    on the command line: every local user can read a process's arguments (``ps``), while its
    environment is readable by its owner only.
    """
    cmd = [python, "-m", "mlflow", "server", "--artifacts-destination", artifacts_uri,
           "--host", LOOPBACK, "--port", str(port), "--workers", str(workers)]
    return cmd, {**(os.environ if env is None else env), BACKEND_STORE_ENV: store_uri}
