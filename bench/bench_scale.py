"""Does every stage stay linear in the number of runs? The same campaign at two sizes.

The standard campaign (24 configurations, 120 runs) and the dense shape map
(``conf/campaign/dense.yaml``: 16 curve angles x 10 radii = 160 configurations, 800 runs) run
back to back, each as a cold ``python -m pipelines.run_all`` in its own temporary folder, so
both sizes see the same machine load. Per stage (the pipeline's own timer,
``pipeline_timing.json``): seconds, seconds per configuration, and the ratio of the large
map's seconds per configuration to the standard one's (1.0 = linear); peak memory of the
pipeline's process tree (resident memory of the process and its workers, summed, sampled
every 0.2 s) and its ratio. Targets: every stage's ratio <= 1.2, memory ratio <= 2.
Takes about 10 minutes on 2 cores. ``python -m bench.bench_scale`` prints the JSON;
``TSM_BENCH_KEEP=1`` keeps both folders.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
#: (label, campaign in conf/campaign/, configurations it holds)
SIZES = (("standard", "standard", 24), ("dense", "dense", 160))
STAGE_RATIO_TARGET = 1.2
MEMORY_RATIO_TARGET = 2.0
#: stages whose time grows with the work (``tracking_init`` is a fixed cost; ``tracking`` is
#: what MLflow adds after the report it overlaps, seconds either way)
STAGES = ("generate", "ingest", "read_dataset", "fit", "validate", "unseen_shape", "report",
          "tracking_overlapped", "registry", "total")
_PAGE = os.sysconf("SC_PAGE_SIZE")


def _tree_rss(root_pid: int) -> int:
    """Resident bytes of ``root_pid`` and all its descendants (from /proc)."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(entry.path, "stat").read_text()
            statm = Path(entry.path, "statm").read_text().split()
        except OSError:  # gone meanwhile
            continue
        ppid = int(stat[stat.rindex(")") + 2:].split()[1])
        pid = int(entry.name)
        children.setdefault(ppid, []).append(pid)
        rss[pid] = int(statm[1]) * _PAGE
    total, todo = 0, [root_pid]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        todo.extend(children.get(pid, []))
    return total


class _PeakSampler(threading.Thread):
    def __init__(self, pid: int, every_s: float = 0.2) -> None:
        super().__init__(daemon=True)
        self.pid, self.every_s, self.peak = pid, every_s, 0
        self._stop_event = threading.Event()

    def run(self) -> None:
        while not self._stop_event.is_set():
            self.peak = max(self.peak, _tree_rss(self.pid))
            self._stop_event.wait(self.every_s)

    def stop(self) -> int:
        self._stop_event.set()
        self.join()
        return self.peak


def measure(root: Path, campaign: str, extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """A cold ``run_all`` of ``campaign`` into ``root``: stage seconds, CPU, peak memory."""
    env = {**os.environ, "MPLBACKEND": "Agg", "HYDRA_FULL_ERROR": "1",
           "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR",
                                             str(REPO_ROOT / ".venv" / "numba-cache"))}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    cmd = [sys.executable, "-m", "pipelines.run_all", f"paths.root={root}", "progress=false",
           f"hydra.run.dir={root / 'outputs' / 'run_all'}",
           f"overrides.generate=['campaign={campaign}']", *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    sampler = _PeakSampler(proc.pid)
    sampler.start()
    _, stderr = proc.communicate()
    peak = sampler.stop()
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"pipeline ({campaign}) failed ({proc.returncode}): {stderr[-3000:]}")
    stages = json.loads((root / "data" / "reports" / "pipeline_timing.json").read_text())
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
                       2),
        "stage_s": {k: round(float(v), 2) for k, v in stages.items()},
        "peak_tree_rss_gb": round(peak / 1024**3, 3),
        # the largest single process (Linux reports KiB)
        "peak_process_rss_gb": round(after.ru_maxrss / 1024**2, 3),
    }


def compare(small: dict[str, Any], n_small: int, large: dict[str, Any],
            n_large: int) -> dict[str, Any]:
    """Per stage: seconds per configuration at each size and their ratio (1.0 = linear)."""
    rows: dict[str, Any] = {}
    for stage in STAGES:
        a, b = small["stage_s"].get(stage), large["stage_s"].get(stage)
        if a is None or b is None:
            continue
        per_a, per_b = a / n_small, b / n_large
        rows[stage] = {f"s_{n_small}": a, f"s_{n_large}": b,
                       f"s_per_config_{n_small}": round(per_a, 4),
                       f"s_per_config_{n_large}": round(per_b, 4),
                       "per_config_ratio": round(per_b / per_a, 3) if per_a > 0 else None}
    ratios = [r["per_config_ratio"] for k, r in rows.items()
              if k != "total" and r["per_config_ratio"] is not None]
    mem_ratio = large["peak_tree_rss_gb"] / small["peak_tree_rss_gb"]
    return {
        "stages": rows,
        "worst_stage": max((k for k in rows if k != "total"),
                           key=lambda k: rows[k]["per_config_ratio"] or 0.0, default=None),
        "max_stage_ratio": max(ratios, default=None),
        "stage_ratio_target": STAGE_RATIO_TARGET,
        "stages_within_target": all(r <= STAGE_RATIO_TARGET for r in ratios),
        "peak_memory_gb": {str(n_small): small["peak_tree_rss_gb"],
                           str(n_large): large["peak_tree_rss_gb"]},
        "peak_memory_ratio": round(mem_ratio, 3),
        "memory_ratio_target": MEMORY_RATIO_TARGET,
        "memory_within_target": mem_ratio <= MEMORY_RATIO_TARGET,
    }


def run() -> dict[str, Any]:
    keep = os.environ.get("TSM_BENCH_KEEP") == "1"
    runs: dict[str, Any] = {}
    roots: dict[str, str] = {}
    load_before = [round(x, 2) for x in os.getloadavg()]
    for label, campaign, _ in SIZES:
        root = Path(tempfile.mkdtemp(prefix=f"tsm-bench-scale-{label}-"))
        try:
            runs[label] = measure(root, campaign)
            runs[label]["load_avg_after"] = [round(x, 2) for x in os.getloadavg()]
        finally:
            if keep:
                roots[label] = str(root)
            else:
                shutil.rmtree(root, ignore_errors=True)
    (small_label, _, n_small), (large_label, _, n_large) = SIZES
    return {
        "configurations": {small_label: n_small, large_label: n_large},
        **compare(runs[small_label], n_small, runs[large_label], n_large),
        "runs": runs,
        "load_avg_before": load_before,
        "cpu_count": os.cpu_count(),
        "roots": roots or None,
    }


if __name__ == "__main__":
    print(json.dumps(run(), indent=1))
