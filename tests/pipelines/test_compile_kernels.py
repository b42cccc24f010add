"""The kernel warm-up that make runs after installing the environment reaches every kernel."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

from pipelines.compile_kernels import HALVES, KERNEL_MODULES, dispatchers

REPO = Path(__file__).resolve().parents[2]


def test_every_module_with_a_kernel_is_listed() -> None:
    defining = set()
    for pkg in ("hysteresis", "rig_io", "pipelines"):
        for path in (REPO / pkg).rglob("*.py"):
            if re.search(r"^@(numba\.)?n?jit\b", path.read_text(), re.M):
                defining.add(".".join(path.relative_to(REPO).with_suffix("").parts))
    assert defining == set(KERNEL_MODULES)


def test_the_warm_up_reaches_every_kernel() -> None:
    for job in HALVES:
        job()
    # called from Python here, or from a kernel that was (a kernel's callees are compiled
    # and cached with it, and get no signature of their own when it comes from the cache)
    uncalled = []
    for name in KERNEL_MODULES:
        kernels = dispatchers(importlib.import_module(name))
        reached = {k for k, d in kernels.items() if d.signatures}
        grew = True
        while grew:
            callees = {c for k in reached for c in kernels[k].py_func.__code__.co_names
                       if c in kernels}
            grew = not callees <= reached
            reached |= callees
        uncalled += [f"{name}.{k}" for k in sorted(set(kernels) - reached)]
    assert uncalled == []
