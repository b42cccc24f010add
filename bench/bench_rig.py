"""Virtual rig benchmark (`make bench`): the standard campaign's generation time and the rig's
per-step cost, with the numba kernel against the same kernel run as plain Python.

* ``campaign``: the 120 runs simulated and written as run folders into a temporary folder with
  the generate stage's defaults (2 workers): wall time, and the workers' CPU seconds (the
  machine is shared, so wall time depends on the load; CPU time much less).
* ``step``: cost of ``VirtualRig.step`` (one 10 ms control tick = 10 physics ticks, sensors
  included) and of one 1 ms physics tick inside ``run_ticks``.
* ``numba_vs_python``: the same physics on 2 s of the sine, once compiled and once with
  ``NUMBA_DISABLE_JIT=1`` (a subprocess), per physics tick.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from pipelines.core.generate import campaign_specs, run_generate
from rig_io.virtual import VirtualRig, make_excitation
from rig_io.virtual.rig import _Core

SINE = {"amplitudes_mm": [6.0, 4.5, 3.0, 1.5], "periods_per_amplitude": 5, "frequency_hz": 0.25}
REPO = Path(__file__).resolve().parents[1]

_PY_KERNEL = """
import json, sys, time
import numpy as np
from rig_io.virtual.rig import _Core
from rig_io.virtual import make_excitation
t, c = make_excitation("sine_decay", amplitudes_mm=[6.0], periods_per_amplitude=1,
                       frequency_hz=0.25)
core = _Core(rig="tsm-bench", curve_angle_deg=90, radius_mm=30, effects=None, seed=0,
             sensors=None, params=None)
n = int(sys.argv[1])
core.run(c[:2])
core.reset()
t0 = time.process_time()
rec = core.run(c[:n])
dt = time.process_time() - t0
print(json.dumps({"seconds": dt, "ticks": int(rec.shape[0]), "last": rec[-1].tolist()}))
"""


def _kernel_per_tick(n_ctrl: int, *, jit: bool) -> dict[str, Any]:
    env = dict(os.environ, NUMBA_DISABLE_JIT="0" if jit else "1")
    proc = subprocess.run([sys.executable, "-c", _PY_KERNEL, str(n_ctrl)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300, check=True)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["us_per_tick"] = out["seconds"] / out["ticks"] * 1e6
    return out


def run() -> dict[str, Any]:
    result: dict[str, Any] = {}
    # --- the campaign, as `make data` writes it ------------------------------------------
    specs = campaign_specs(seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        rep = run_generate(specs, Path(tmp) / "raw", n_jobs=2, progress=False)
        wall = time.perf_counter() - t0
        size = sum(f.stat().st_size for f in (Path(tmp) / "raw").rglob("*") if f.is_file())
    result["campaign"] = {
        "runs": len(specs), "wall_s": round(wall, 2), "n_jobs": 2,
        "simulate_s_sum": round(rep["simulate_s"], 2), "write_s_sum": round(rep["write_s"], 2),
        # CPU seconds of the workers (simulate + write): what the campaign costs on an idle
        # machine is about cpu_s / n_jobs plus the workers' start-up.
        "cpu_s_sum": round(rep["cpu_s"], 2),
        "idle_machine_estimate_s": round(rep["cpu_s"] / 2 + 3.0, 1),
        "megabytes": round(size / 1e6, 1),
        "target_s": 60.0,
    }
    # --- per-step cost ----------------------------------------------------------------------
    t, c = make_excitation("sine_decay", **SINE)
    rig = VirtualRig(curve_angle_deg=90, radius_mm=30)
    rig.reset()
    rig.step(0.0)
    n = 2000
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(n):
        rig.step(float(c[k]))
    step_us = (time.perf_counter() - t0) / n * 1e6
    step_cpu_us = (time.process_time() - c0) / n * 1e6
    core = _Core(rig="tsm-bench", curve_angle_deg=90, radius_mm=30, effects=None, seed=0,
                 sensors=None, params=None)
    core.run(c[:2])
    best = float("inf")
    for _ in range(3):
        core.reset()
        t0 = time.process_time()
        rec = core.run(c[:-1])
        best = min(best, time.process_time() - t0)
    result["step"] = {
        "virtualrig_step_us": round(step_us, 1),
        "virtualrig_step_cpu_us": round(step_cpu_us, 1),
        "physics_tick_cpu_us": round(best / rec.shape[0] * 1e6, 2),
        "physics_ticks_per_control_tick": core.n_sub,
        "sine_run_physics_cpu_s": round(best, 3),
    }
    # --- numba vs the same kernel as plain Python -----------------------------------------
    n_ctrl = 200  # 2 s of the sine = 2000 physics ticks
    fast = _kernel_per_tick(n_ctrl, jit=True)
    slow = _kernel_per_tick(n_ctrl, jit=False)
    agree = bool(np.allclose(fast["last"], slow["last"], rtol=0, atol=1e-9))
    result["numba_vs_python"] = {
        "numba_us_per_tick": round(fast["us_per_tick"], 2),
        "python_us_per_tick": round(slow["us_per_tick"], 1),
        "speedup": round(slow["us_per_tick"] / fast["us_per_tick"], 1),
        "same_result": agree,
    }
    return result


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
