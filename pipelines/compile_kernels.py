"""Compile every numba kernel of the package into the on-disk cache, once.

A kernel compiles on its first call in each process until its cache file exists. On a fresh
checkout, the parallel workers of a stage (and of the test suite) each compile the same
kernels side by side: the virtual rig's physics alone takes about seven seconds a process.
``make`` runs this module once after it installs the virtual environment, so every later
process loads the kernels from ``NUMBA_CACHE_DIR`` instead.

The kernels are reached through the public functions, on short signals of the array type the
stages hand them (C-contiguous float64, see :func:`hysteresis.base.as_1d`), so what is cached
is what the stages call. Two processes compile two halves side by side.

    python -m pipelines.compile_kernels
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from types import ModuleType
from typing import Any

import numpy as np

#: The modules that define numba kernels (a kernel added elsewhere is missed: the test of
#: this module lists every dispatcher of the package and fails on one left uncompiled).
KERNEL_MODULES = ("hysteresis.play", "hysteresis._bw_kernels", "hysteresis.coleman_hodgdon",
                  "hysteresis.discrepancy._ops", "rig_io.synchronise", "rig_io.virtual.physics")


def _signal(n: int = 240) -> tuple[Any, Any]:
    t = np.linspace(0.0, 12.0, n)
    u = 3.0 * np.sin(2 * np.pi * 0.25 * t) * np.minimum(1.0, t / 4.0)
    y = np.clip(u, -2.5, 2.5) * 0.8
    return u, y


def compile_rig() -> None:
    """The rig's physics with every effect on, and the ingest (calibration, the clock
    synchroniser's Kalman smoother) of its raw run."""
    import rig_io.virtual as rig
    from pipelines.discrepancy_data import rows_from_raw
    from rig_io.virtual.effects import EFFECT_NAMES

    raw = rig.simulate_run(curve_angle_deg=90.0, radius_mm=30.0, seed=0,
                           excitation={"kind": "sine_decay", "amplitudes_mm": [2.0],
                                       "periods_per_amplitude": 1, "frequency_hz": 1.0},
                           effects=dict.fromkeys(EFFECT_NAMES, 0.5))
    rows_from_raw([raw])


def compile_models() -> None:
    """Every family's fit, prediction, step and inverse, and the discrepancy terms' plays."""
    from hysteresis._bw_kernels import paper_mse
    from hysteresis.base import family_class, family_names, make_family
    from hysteresis.discrepancy import _ops

    u, y = _signal()
    variants: dict[str, list[dict[str, Any]]] = {"coleman_hodgdon": [{}, {"method": "varpro"}]}
    inverses: dict[str, list[dict[str, Any]]] = {"bouc_wen": [{}, {"method": "feedforward"}]}
    for name in family_names():
        if not family_class(name).__module__.startswith("hysteresis."):
            continue  # a family registered from outside the package runs no kernel of ours
        for params in variants.get(name, [{}]):
            model: Any = make_family(name, **params).fit(u, y)  # every family's face
            out, state = model.simulate(u)
            model.step(float(u[-1]), state)
            for how in inverses.get(name, [{}]):
                model.invert(0.5 * out, **how)
    paper_mse(u, y, [1.0, 0.5, -0.2, 1.0, 0.5, 0.5])
    half = np.full(u.size, 0.2)
    _ops.play(u, 0.3)
    _ops.scaled_play(u, half, z0=0.0)
    _ops.scaled_play_bank(u, np.ones(u.size), np.array([0.0, 0.3]), np.zeros(2))
    _ops.direction(np.gradient(u), eps=0.1)


HALVES: tuple[Callable[[], None], ...] = (compile_rig, compile_models)


def _run(job: Callable[[], None]) -> float:
    t0 = time.perf_counter()
    job()
    return time.perf_counter() - t0


def dispatchers(module: ModuleType) -> dict[str, Any]:
    """The numba dispatchers ``module`` defines (name -> dispatcher), without those inlined
    into their callers (``inline="always"``), which are compiled as part of them."""
    from numba.core.registry import CPUDispatcher

    return {k: v for k, v in vars(module).items()
            if isinstance(v, CPUDispatcher) and v.py_func.__module__ == module.__name__
            and v.targetoptions.get("inline") != "always"}


def main() -> int:
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=len(HALVES)) as pool:
        seconds = list(pool.map(_run, HALVES))
    print(f"numba kernels compiled into the cache in {time.perf_counter() - t0:.1f} s "
          f"({', '.join(f'{j.__name__} {s:.1f} s' for j, s in zip(HALVES, seconds, strict=True))})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
