"""``make bench``: run every ``bench/bench_*.py`` module and collect one JSON.

    python -m bench.run --out bench/results.json
    python -m bench.run --only gamma,pipeline --out bench/results-partial.json

Each module exposes ``run() -> dict`` (JSON-able). Every module runs in its own Python process
(one crashing, hanging or leaking module cannot take the others down, and none inherits
another's warm caches); its dict, wall time and status are collected. A module that fails or
times out records its error instead of stopping the bench. The output holds machine
information (CPU, cores, memory, load average before each module - the machine is shared, so
read absolute times with it) and is written atomically.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

BENCH_DIR = Path(__file__).resolve().parent
REPO_ROOT = BENCH_DIR.parent
FORMAT = "tsm-bench-results/1"
#: Modules that need longer than ``--timeout`` (seconds): bench_scale runs the pipeline on
#: 24 and on 160 configurations, about 10 minutes alone and more on a loaded machine.
TIMEOUTS_S = {"bench_scale": 3600.0}


def discover() -> list[str]:
    """Module names ``bench_<topic>`` found beside this file, sorted."""
    return sorted(p.stem for p in BENCH_DIR.glob("bench_*.py"))


def _jsonable(obj: Any) -> Any:
    """Make a module's result strictly JSON-able (numpy scalars, NaN/inf -> None, tuples)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return _jsonable(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    return str(obj)


def machine_info() -> dict[str, Any]:
    info: dict[str, Any] = {
        "hostname": platform.node(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu_count": os.cpu_count(),
        "cpu_affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
        else None,
    }
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu_model"] = line.split(":", 1)[1].strip()
                break
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                info["mem_total_gb"] = round(int(line.split()[1]) / 1024**2, 2)
                break
    except OSError:
        pass
    from importlib.metadata import PackageNotFoundError, version

    versions: dict[str, str | None] = {}
    for pkg in ("numpy", "scipy", "pandas", "numba", "mlflow", "hydra-core", "joblib",
                "matplotlib", "pyarrow", "rosbags"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    info["versions"] = versions
    try:
        info["git_commit"] = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
            timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        info["git_commit"] = None
    return info


def _load() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def run_in_process(name: str) -> dict[str, Any]:
    """Import ``bench.<name>`` and call its ``run()``; never raises."""
    start = time.perf_counter()
    record: dict[str, Any] = {"module": name, "load_avg_before": _load()}
    try:
        module = importlib.import_module(f"bench.{name}")
        result = module.run()
        if not isinstance(result, dict):
            raise TypeError(f"run() returned {type(result).__name__}, expected dict")
        record.update(status="ok", result=_jsonable(result))
    except BaseException as exc:  # noqa: BLE001 - record any failure, keep benching
        if isinstance(exc, KeyboardInterrupt):
            raise
        record.update(status="error", error=f"{type(exc).__name__}: {exc}",
                      traceback=traceback.format_exc(limit=20))
    record["wall_s"] = round(time.perf_counter() - start, 3)
    return record


def run_isolated(name: str, *, timeout_s: float) -> dict[str, Any]:
    """Run one module in a child Python process; errors, crashes and timeouts are recorded."""
    start = time.perf_counter()
    load = _load()
    with tempfile.TemporaryDirectory(prefix="tsm-bench-") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, "-m", "bench.run", "--child", name, "--child-out", str(out)]
        env = {**os.environ, "MPLBACKEND": "Agg"}
        try:
            proc = subprocess.run(cmd, cwd=REPO_ROOT, env=env, capture_output=True, text=True,
                                  timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {"module": name, "status": "timeout", "load_avg_before": load,
                    "error": f"no result within {timeout_s:.0f} s",
                    "wall_s": round(time.perf_counter() - start, 3)}
        if out.is_file():
            record: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))
        else:
            record = {"module": name, "status": "error",
                      "error": f"child exited with code {proc.returncode} without a result",
                      "stderr_tail": proc.stderr[-4000:]}
        record["load_avg_before"] = load
        record["process_wall_s"] = round(time.perf_counter() - start, 3)
        return record


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    sys.path.insert(0, str(REPO_ROOT))
    from rig_io.atomic import write_text_atomic

    write_text_atomic(path, json.dumps(data, indent=1, allow_nan=False) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(BENCH_DIR / "results.json"))
    parser.add_argument("--only", default="", help="comma-separated topics or module names")
    parser.add_argument("--timeout", type=float, default=1200.0,
                        help="seconds per module before it is recorded as timed out")
    parser.add_argument("--in-process", action="store_true",
                        help="run the modules in this process (debugging)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--child-out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:  # inside the isolated process: one module, result to a file
        record = run_in_process(args.child)
        Path(args.child_out).write_text(json.dumps(record, allow_nan=False), encoding="utf-8")
        return 0

    names = discover()
    if args.only:
        wanted = {w if w.startswith("bench_") else f"bench_{w}"
                  for w in args.only.split(",") if w}
        unknown = sorted(wanted - set(names))
        if unknown:
            parser.error(f"unknown bench module(s) {unknown}; known: {names}")
        names = [n for n in names if n in wanted]
    started = dt.datetime.now(dt.UTC)
    t0 = time.perf_counter()
    results: dict[str, Any] = {}
    for name in names:
        print(f"bench: {name} ...", file=sys.stderr, flush=True)
        rec = (run_in_process(name) if args.in_process
               else run_isolated(name, timeout_s=max(args.timeout,
                                                     TIMEOUTS_S.get(name, 0.0))))
        results[name.removeprefix("bench_")] = rec
        print(f"bench: {name} {rec['status']} in {rec.get('wall_s', rec.get('process_wall_s'))}"
              " s", file=sys.stderr, flush=True)
    doc = {
        "format": FORMAT,
        "started_at": started.isoformat(timespec="seconds"),
        "total_wall_s": round(time.perf_counter() - t0, 3),
        "machine": machine_info(),
        "modules": results,
        "n_ok": sum(r["status"] == "ok" for r in results.values()),
        "n_failed": sum(r["status"] != "ok" for r in results.values()),
    }
    write_json_atomic(Path(args.out), doc)
    print(f"bench: {doc['n_ok']} ok, {doc['n_failed']} failed -> {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
