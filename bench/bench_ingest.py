"""Ingest throughput on the 72-run standard campaign (issue 3: under 30 s).

The campaign comes from ``data/raw/virtual`` when ``make data`` has written it (72 runs);
otherwise 8 runs of the standard campaign are simulated and each is written 9 times under a
fresh run id (ingest cost does not depend on the physics, and simulating 72 runs would take
minutes). Reported against two references measured in the same run: the I/O floor (plain
``pandas.read_csv`` of every stream of every run, no checks) and the filterpy Kalman backend
(same ingest with ``kalman_backend=filterpy`` on the first 4 runs).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import pandas as pd

from pipelines.ingest import run_ingest
from rig_io.folder import write_run_folder
from rig_io.synchronise import SyncOptions

REPO = Path(__file__).resolve().parents[1]
N_RUNS = 72


def _campaign(work: Path) -> tuple[Path, str]:
    raw = REPO / "data" / "raw" / "virtual"
    if raw.is_dir() and sum((p / "manifest.json").exists() for p in raw.iterdir()) >= N_RUNS:
        return raw, "data/raw/virtual (make data)"
    from rig_io.run import RawRun
    from rig_io.virtual import simulate_run, standard_campaign

    specs = standard_campaign(0)
    picked = specs[:: len(specs) // 8][:8]
    src = work / "raw"
    for spec in picked:
        run = simulate_run(**spec)
        for k in range(N_RUNS // len(picked)):
            manifest = {**run.manifest, "run_id": f"{run.run_id}_copy{k}"}
            write_run_folder(RawRun(manifest=manifest, encoder=run.encoder,
                                    loadcell=run.loadcell, camera=run.camera,
                                    tracker=run.tracker, events=run.events), src)
    return src, "8 simulated standard-campaign runs x 9 run ids"


def _io_floor(src: Path) -> float:
    t0 = time.perf_counter()
    for folder in sorted(p for p in src.iterdir() if (p / "manifest.json").exists()):
        json.loads((folder / "manifest.json").read_text())
        for f in folder.glob("*.csv*"):
            pd.read_csv(f)
    return time.perf_counter() - t0


def run() -> dict[str, Any]:
    work = Path(tempfile.mkdtemp(prefix="bench_ingest_"))
    try:
        src, origin = _campaign(work)
        wall0, cpu0 = time.perf_counter(), time.process_time()
        report = run_ingest(src, work / "out", progress=False)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        t0 = time.perf_counter()
        again = run_ingest(src, work / "out", progress=False)
        noop = time.perf_counter() - t0
        floor = _io_floor(src)
        # filterpy reference on a subset of 4 runs (it is the slow part).
        sub = work / "sub"
        sub.mkdir()
        names = sorted(p.name for p in src.iterdir() if (p / "manifest.json").exists())[:4]
        for name in names:
            (sub / name).symlink_to(src / name)
        t0 = time.perf_counter()
        ref = run_ingest(sub, work / "out_fp", progress=False,
                         sync=SyncOptions(kalman_backend="filterpy"))
        fp = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_ingest(sub, work / "out_nb", progress=False)
        nb = time.perf_counter() - t0
        n = int(report["n_samples"])
        return {
            "campaign": origin,
            "runs": report["n_accepted"],
            "rejected": report["n_rejected"],
            "samples": n,
            "ingest_wall_s": round(wall, 3),
            "ingest_cpu_s": round(cpu, 3),
            "samples_per_s": round(n / wall, 1),
            "runs_per_s": round(report["n_accepted"] / wall, 2),
            "under_30_s": wall < 30.0,
            "incremental_noop_s": round(noop, 3),
            "incremental_processed": again["n_processed"],
            "io_floor_read_csv_s": round(floor, 3),
            "ratio_ingest_to_io_floor": round(wall / floor, 2) if floor > 0 else None,
            "subset_runs": ref["n_accepted"],
            "subset_filterpy_s": round(fp, 3),
            "subset_numba_s": round(nb, 3),
            "speedup_numba_vs_filterpy": round(fp / nb, 2) if nb > 0 else None,
        }
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
