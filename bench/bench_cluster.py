"""100 fit jobs through Hydra's Ray launcher vs the joblib launcher, both logging to a
PostgreSQL-backed MLflow server: wall times, their ratio, and runs lost.

The jobs: 5 families x 5 curve angles x 4 radii = 100 ``pipelines.fit`` multirun jobs on the
standard virtual campaign, ``cache=false`` (every job fits), ``tracking=server``. Both sweeps
run against the same throwaway services (``pipelines.cluster_check.team_services``: PostgreSQL,
``mlflow server``, a 2-CPU Ray head, all on 127.0.0.1) and the same data; the joblib launcher
uses its 2 loky processes, the Ray launcher one CPU per job on the 2-CPU head. A job is lost
when its (family, configuration) has no FINISHED model run under its sweep's parent.

Needs the team extras (ray, hydra-ray-launcher, psycopg2): ``make bench-cluster`` runs it in
``.venv-team`` and writes ``bench/results_cluster.json``. Under ``make bench`` (base venv) it
runs itself with ``.venv-team``'s interpreter when that venv exists, and otherwise reports
what is missing.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
TEAM_PY = REPO_ROOT / ".venv-team" / "bin" / "python"
FAMILIES = ("linear", "gamma", "preisach", "bouc_wen", "coleman_hodgdon")
ANGLES = (15, 30, 45, 60, 75)
RADII = (30, 45, 60, 75)


def _bench(work: Path) -> dict[str, Any]:
    from pipelines import cluster_check as cc

    expected = len(FAMILIES) * len(ANGLES) * len(RADII)
    overrides = cc.grid_overrides(families=FAMILIES, angles=ANGLES, radii=RADII)
    root = work / "root"
    (work / "logs").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cc.prepare_data(root, log_file=work / "logs" / "prepare.log")
    out: dict[str, Any] = {"jobs": expected, "prepare_s": round(time.perf_counter() - t0, 1)}
    with cc.team_services(work, num_cpus=2) as services:
        for launcher in ("joblib", "ray"):
            sweep_dir = work / "multirun" / launcher
            cmd = cc.sweep_command(root=root, sweep_dir=sweep_dir, launcher=launcher,
                                   tracking_uri=services.tracking_uri,
                                   ray_address=services.ray_address, overrides=overrides)
            load = [round(x, 2) for x in os.getloadavg()]  # shared machine: read with it
            code, wall = cc.run_sweep(cmd, log_file=work / "logs" / f"sweep_{launcher}.log")
            counted = cc.count_runs(services.tracking_uri, sweep_dir)
            out[launcher] = {"exit": code, "wall_s": round(wall, 1),
                             "s_per_job": round(wall / expected, 2), "load_avg_before": load,
                             "runs": counted["runs"], "finished": counted["finished"],
                             "with_dataset": counted["with_dataset"],
                             "lost": expected - len(counted["keys"])}
    out["left_behind"] = services.left_behind
    out["ratio_ray_over_joblib"] = round(out["ray"]["wall_s"] / out["joblib"]["wall_s"], 3)
    out["lost_total"] = out["ray"]["lost"] + out["joblib"]["lost"]
    return out


def run() -> dict[str, Any]:
    """``make bench`` entry: in this interpreter if it has the extras, else in .venv-team."""
    if importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is not None \
            and importlib.util.find_spec("psycopg2") is not None:
        with tempfile.TemporaryDirectory(prefix="tsm-bench-cluster-") as tmp:
            return _bench(Path(tmp))
    if not TEAM_PY.exists():
        return {"skipped": "needs the team extras: `make bench-cluster` (builds .venv-team)"}
    with tempfile.TemporaryDirectory(prefix="tsm-bench-cluster-") as tmp:
        out = Path(tmp) / "out.json"
        subprocess.run([str(TEAM_PY), "-m", "bench.bench_cluster", "--out", str(out)],
                       check=True, cwd=REPO_ROOT, timeout=3600)
        result: dict[str, Any] = json.loads(out.read_text())
        return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Ray vs joblib launcher, 100 fit jobs")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--keep", type=Path, default=None, help="keep the work folder here")
    args = parser.parse_args(argv)
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        result = _bench(args.keep)
    else:
        with tempfile.TemporaryDirectory(prefix="tsm-bench-cluster-") as tmp:
            result = _bench(Path(tmp))
    text = json.dumps(result, indent=1)
    print(text)
    if args.out is not None:
        from rig_io.atomic import write_text_atomic

        write_text_atomic(args.out, text + "\n")
    ok = result["lost_total"] == 0 and not result["left_behind"] \
        and result["ray"]["exit"] == 0 and result["joblib"]["exit"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
