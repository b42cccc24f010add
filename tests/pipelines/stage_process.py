"""Stage processes for the tests that kill or time whole stages.

A stage started as ``python -m pipelines.<stage>`` spends about four seconds importing
numpy, scipy, pandas, Hydra and MLflow before it does anything. The tests that start dozens
of stages take them from a fork server instead (``multiprocessing``'s ``forkserver``), which
has imported the stage modules once: each stage is still its own operating-system process,
with its own pid, working directory, environment and output files, started with the same
arguments, running the module's ``__main__`` the way ``python -m`` does, and killed with a
real SIGKILL. Only the imports are shared, and they are done before any stage starts.

For single-process stages only: a stage that starts a process pool of its own (a multirun
sweep, ``n_jobs`` > 1) is left to ``python -m``, because a forked child leaves by ``os._exit``
and a pool's workers would lose the semaphores they were handed.
"""

from __future__ import annotations

import atexit
import importlib.util
import multiprocessing
import os
import runpy
import sys
import threading
from collections.abc import Mapping, Sequence
from multiprocessing.context import ForkServerContext
from multiprocessing.process import BaseProcess
from pathlib import Path

#: What the fork server imports once: every stage entry point and the MLflow store code
#: the stages open.
PRELOAD = ("pipelines.generate", "pipelines.ingest", "pipelines.fit", "pipelines.validate",
           "pipelines.report", "pipelines.unseen_shape", "pipelines.discrepancy",
           "pipelines.compensate", "pipelines.run_all", "pipelines.registry", "mlflow",
           "mlflow.store.tracking.sqlalchemy_store", "matplotlib.pyplot")

_context: ForkServerContext | None = None


def _server() -> ForkServerContext:
    global _context
    if _context is None:
        # matplotlib picks its backend when imported, which the server does before any stage
        os.environ.setdefault("MPLBACKEND", "Agg")
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(PRELOAD))
        _context = ctx
    return _context


def _main(module: str, args: Sequence[str], cwd: str, env: Mapping[str, str], log: str) -> None:
    """The child: ``python -m module *args`` in ``cwd`` with ``env``, output to ``log``."""
    os.chdir(cwd)
    os.environ.clear()
    os.environ.update(env)
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    spec = importlib.util.find_spec(module)
    sys.argv = [spec.origin if spec and spec.origin else module, *args]
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    finally:
        # what the interpreter does on the way out of `python -m`, which a forked child
        # (it leaves by os._exit) would skip: the threading exit hooks first (they tell idle
        # thread-pool workers, e.g. MLflow's artifact downloads, to stop), then wait for
        # non-daemon threads, then run atexit hooks
        for hook in list(getattr(threading, "_threading_atexits", [])):
            hook()
        for thread in threading.enumerate():
            if thread is not threading.main_thread() and not thread.daemon:
                thread.join()
        atexit._run_exitfuncs()


def start(module: str, args: Sequence[str], *, cwd: Path, env: Mapping[str, str],
          log: Path) -> BaseProcess:
    """Start ``python -m module *args`` as a forked stage process; its output goes to ``log``."""
    if "-m" in args or "--multirun" in args:
        raise ValueError("a multirun sweep starts a process pool: run it with python -m")
    proc = _server().Process(target=_main, args=(module, list(args), str(cwd), dict(env),
                                                 str(log)))
    proc.start()
    return proc


def run(module: str, args: Sequence[str], *, cwd: Path, env: Mapping[str, str], log: Path,
        timeout: float) -> int:
    """Run a stage process to its end; its exit status (negative: killed by that signal)."""
    proc = start(module, args, cwd=cwd, env=env, log=log)
    proc.join(timeout)
    if proc.exitcode is None:
        proc.kill()
        proc.join()
        raise TimeoutError(f"{module} {' '.join(args)} ran over {timeout} s")
    return proc.exitcode
