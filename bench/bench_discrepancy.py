"""Benchmark of the discrepancy workflow.

``injector``: what ``make discrepancy`` answers (automatic base) on every case type of the
independent injector, with seconds per source. The rest: one virtual-rig configuration
(90 deg / 30 mm) with a hidden time delay and drift, seed 001 excitations with 3 periods per
amplitude, analysed at 20 Hz with the Gamma base. Reports the wall time of the whole
locate -> name -> add loop, and the ratio against the reference joint refit by backfitting
(the generic path every non-Gamma family takes) measured in the same run.
"""

from __future__ import annotations

import time
from typing import Any
from unittest import mock


def _runs() -> list[Any]:
    from pipelines.discrepancy_study import hidden_effect_runs

    return hidden_effect_runs({"time_delay": 1.0, "drift": 2.0}, [(90.0, 30.0)])


def _time(fn: Any, repeat: int = 2) -> tuple[float, Any]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run() -> dict[str, Any]:
    from hysteresis.discrepancy import effects
    from hysteresis.discrepancy.workflow import base_factory_for, run_workflow

    runs = _runs()
    factory = base_factory_for("gamma")

    def workflow() -> dict[str, Any]:
        return run_workflow(runs, factory, base_name="gamma")

    workflow()  # warm numba caches
    t_exact, rep = _time(workflow)
    with mock.patch.object(effects, "_joint_linear", lambda *a, **k: None):
        t_backfit, rep_bf = _time(workflow)
    n_samples = sum(r.n for r in runs)
    injector = injector_sources()
    return {
        "injector": injector,
        "blas_limit": blas_limit(),
        "samples_analysed": n_samples,
        "effects_found": [e["name"] for e in rep["effects"]],
        "heldout_rmse_before": rep["summary"]["heldout_rmse_before"],
        "heldout_rmse_after": rep["summary"]["heldout_rmse_after"],
        "workflow_s_exact_joint": t_exact,
        "workflow_s_backfitting_reference": t_backfit,
        "speedup_exact_vs_backfitting": t_backfit / t_exact,
        "effects_found_backfitting": [e["name"] for e in rep_bf["effects"]],
        "heldout_rmse_after_backfitting": rep_bf["summary"]["heldout_rmse_after"],
    }


#: One source per case type and plant: clean, each effect at its reference size, a pair.
CASES: dict[str, dict[str, float]] = {
    "clean": {}, **{name: {name: 1.0} for name in (
        "time_delay", "dead_zone", "rate_dependence", "tendon_elongation", "drift",
        "asymmetry", "saturation")},
    "time_delay+drift": {"time_delay": 1.0, "drift": 1.0},
}


def injector_sources() -> dict[str, dict[str, Any]]:
    """What ``make discrepancy`` does (automatic base, then the workflow) on three 80 s runs
    from the independent injector (plain Gamma, Preisach and Bouc-Wen plants): seconds, the
    base chosen, the verdict and what was named, per case type and plant.

    About 6 min for the 27 sources on 2 cores (``python -m bench.bench_discrepancy
    --injector`` runs it alone); ``run()`` includes it under ``injector``."""
    from hydra import compose, initialize_config_dir

    from hysteresis.discrepancy.inject import injected_runs
    from hysteresis.discrepancy.workflow import base_factory_for, run_workflow
    from pipelines.common import CONF_DIR, to_container
    from pipelines.discrepancy import choose_base

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        families = dict(to_container(compose("discrepancy"))["auto_families"])
    out: dict[str, dict[str, Any]] = {}
    for plant in ("gamma", "preisach", "bouc_wen"):
        for case, effects in CASES.items():
            runs = injected_runs(plant, effects)
            t0 = time.perf_counter()
            base, params, _ = choose_base(runs, families)
            rep = run_workflow(runs, base_factory_for(base, **params), base_name=base)
            out[f"{plant}:{case}"] = {
                "seconds": round(time.perf_counter() - t0, 2), "base": base,
                "verdict": rep["verdict"], "named": [e["name"] for e in rep["effects"]],
                "heldout_reduction": round(rep["summary"]["heldout_reduction"], 3)}
    secs = [v["seconds"] for v in out.values()]
    out["_summary"] = {"sources": len(secs), "max_seconds": max(secs),
                       "over_60_s": sum(x > 60 for x in secs)}
    return out


def blas_limit(calls: int = 300) -> dict[str, float]:
    """The one-BLAS-thread limit as identification enters it (thousands of times a
    workflow): the cached controller against ``threadpool_limits``, which rescans the loaded
    libraries on every call."""
    from threadpoolctl import threadpool_limits

    from hysteresis._blas import single_thread_blas

    def ours() -> None:
        for _ in range(calls):
            with single_thread_blas():
                pass

    def reference() -> None:
        for _ in range(calls):
            with threadpool_limits(limits=1, user_api="blas"):
                pass

    ours()
    t_ours, _ = _time(ours)
    t_ref, _ = _time(reference)
    return {"us_per_call_ours": 1e6 * t_ours / calls, "us_per_call_reference": 1e6 * t_ref / calls,
            "speedup": t_ref / t_ours}


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(injector_sources() if "--injector" in sys.argv else run(), indent=1))
