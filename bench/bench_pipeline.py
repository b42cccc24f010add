"""``make pipeline`` cold and warm, in a temporary folder: wall time and per-stage times.

The cold run is exactly what a fresh clone does (the 120-run virtual campaign, ingest, 5
families x 24 configurations, validation, report, a new MLflow SQLite store); the warm run
repeats it with nothing changed. Both run as ``python -m pipelines.run_all`` processes, so
interpreter start-up and imports are counted. Target: cold < 90 s on 2 cores,
warm a few seconds. ``python -m bench.bench_pipeline`` prints the JSON.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
COLD_TARGET_S = 90.0


def _pipeline(root: Path, extra: list[str]) -> tuple[float, dict[str, float]]:
    env = {**os.environ, "MPLBACKEND": "Agg", "HYDRA_FULL_ERROR": "1",
           "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR",
                                             str(REPO_ROOT / ".venv" / "numba-cache"))}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    cmd = [sys.executable, "-m", "pipelines.run_all", f"paths.root={root}", "progress=false",
           f"hydra.run.dir={root / 'outputs' / 'run_all'}", *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                          check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"pipeline failed ({proc.returncode}): {proc.stderr[-3000:]}")
    stages = json.loads((root / "data" / "reports" / "pipeline_timing.json").read_text())
    # CPU seconds of the pipeline and the worker processes it waited for: unlike the wall
    # time, hardly affected by other people's jobs on the shared machine.
    stages["cpu_s"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, {k: float(v) for k, v in stages.items()}


def run() -> dict[str, Any]:
    import pandas as pd

    root = Path(tempfile.mkdtemp(prefix="tsm-bench-pipeline-"))
    try:
        load_before = list(os.getloadavg())
        cold_wall, cold = _pipeline(root, [])
        warm_wall, warm = _pipeline(root, [])
        metrics = pd.read_parquet(root / "data" / "reports" / "metrics.parquet")
        fit_s: dict[str, list[float]] = {}
        models = root / "data" / "interim" / "models"
        for f in models.glob("*/*.json"):
            rec = json.loads(f.read_text())
            fit_s.setdefault(rec["family"], []).append(float(rec.get("fit_seconds") or 0.0))
        from mlflow import MlflowClient

        client = MlflowClient(f"sqlite:///{root / 'mlflow.db'}")
        exp = client.get_experiment_by_name("tsm-hysteresis")
        n_runs = len(client.search_runs([exp.experiment_id], max_results=5000)) if exp else 0
        return {
            "cold_wall_s": round(cold_wall, 2),
            "cold_cpu_s": round(cold["cpu_s"], 2),
            "warm_cpu_s": round(warm["cpu_s"], 2),
            "cold_stage_s": cold,
            "cold_under_target": cold_wall < COLD_TARGET_S,
            "cold_target_s": COLD_TARGET_S,
            "warm_wall_s": round(warm_wall, 2),
            "warm_stage_s": warm,
            "warm_over_cold": round(warm_wall / cold_wall, 4),
            "metric_rows": int(len(metrics)),
            "families": sorted(metrics["family"].unique().tolist()),
            "configurations": int(metrics.groupby(["rig", "curve_angle_deg",
                                                  "radius_mm"]).ngroups),
            "fit_seconds_per_model_by_family": {
                k: {"mean": round(sum(v) / len(v), 3), "max": round(max(v), 3), "n": len(v)}
                for k, v in sorted(fit_s.items())},
            "mlflow_runs": n_runs,
            "load_avg_before": [round(x, 2) for x in load_before],
            "cpu_count": os.cpu_count(),
            "root": str(root) if os.environ.get("TSM_BENCH_KEEP") == "1" else None,
        }
    finally:
        # TSM_BENCH_KEEP=1 keeps the cold run's folder (its reports) for a look afterwards.
        if os.environ.get("TSM_BENCH_KEEP") != "1":
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
