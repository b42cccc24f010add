"""Ingest throughput on the 120-run standard campaign (under 30 s), and ingest of big and
hostile inputs (peak memory under 1 GB, raw files unchanged).

The campaign comes from ``data/raw/virtual`` when ``make data`` has written it (120 runs);
otherwise 8 runs of the standard campaign are simulated and each is written 15 times under a
fresh run id (ingest cost does not depend on the physics, and simulating 120 runs would take
minutes). Reported against two references measured in the same run: the I/O floor (plain
``pandas.read_csv`` of every stream of every run, no checks) and the filterpy Kalman backend
(same ingest with ``kalman_backend=filterpy`` on the first 4 runs).

``big_inputs``: each case is one run folder built in a temporary folder at bench time (never
committed) and ingested in a fresh Python process, whose peak resident memory
(``ru_maxrss``) is reported against a baseline process that ingests the small committed
sample: a 1 GiB sparse ``encoder.csv`` (NUL bytes: the "header" once ended up whole in the
report), a 1 GiB generated, well-formed ``encoder.csv``, a gzip bomb (1 GiB of text in a
~1 MB ``encoder.csv.gz``), and the largest well-formed ``encoder.csv`` the default limits
accept (streamed and processed). Each case checks the raw files' sha256 before and after.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipelines.ingest import run_ingest
from rig_io.folder import write_run_folder
from rig_io.synchronise import SyncOptions

REPO = Path(__file__).resolve().parents[1]
N_RUNS = 120


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
    return src, f"8 simulated standard-campaign runs x {N_RUNS // len(picked)} run ids"


def _io_floor(src: Path) -> float:
    t0 = time.perf_counter()
    for folder in sorted(p for p in src.iterdir() if (p / "manifest.json").exists()):
        json.loads((folder / "manifest.json").read_text())
        for f in folder.glob("*.csv*"):
            pd.read_csv(f)
    return time.perf_counter() - t0


GIB = 1 << 30
MB = 1 << 20
#: Peak memory allowed for ingesting any one input.
MAX_PEAK_MB = 1000.0

_CHILD = """
import json, resource, sys, time
from pathlib import Path
from pipelines.ingest import run_ingest
src, out = Path(sys.argv[1]), Path(sys.argv[2])
t0 = time.perf_counter()
report = run_ingest(src, out, progress=False)
wall = time.perf_counter() - t0
peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"wall_s": wall, "peak_mb": peak_mb, "accepted": report["n_accepted"],
                  "rejected": report["n_rejected"],
                  "reason": report["rejected"][0]["reason"] if report["rejected"] else None,
                  "report_bytes": (out / "ingest_report.json").stat().st_size}))
"""


def _sha256(folder: Path) -> str:
    h = hashlib.sha256()
    for f in sorted(folder.rglob("*")):
        if f.is_file():
            h.update(f.name.encode())
            with f.open("rb") as fh:
                for block in iter(lambda: fh.read(4 * MB), b""):
                    h.update(block)
    return h.hexdigest()


def _manifest(run_id: str) -> dict[str, Any]:
    from rig_io.synthetic import make_manifest

    m = make_manifest(run_id)
    for ch in ("loadcell", "camera", "tracker"):
        m["channels"].pop(ch)
    return m


def _encoder_rows(start: int, n: int) -> bytes:
    """Well-formed encoder rows (100 Hz, a 0.05 Hz sine of 3 mm at 10000 counts/mm)."""
    k = np.arange(start, start + n, dtype=np.int64)
    counts = np.round(30000.0 * np.sin(2 * np.pi * 0.05 * k / 100.0)).astype(np.int64)
    frame = pd.DataFrame({"t_ns": k * 10_000_000, "input_counts": counts,
                          "output_counts": -(counts * 4) // 5})
    text: str = frame.to_csv(index=False, header=False, lineterminator="\n")
    return text.encode()


def _write_encoder(path: Path, size: int, *, gz: bool = False) -> int:
    """A well-formed encoder.csv of about ``size`` bytes (text); returns the rows written."""
    header = b"t_ns,input_counts,output_counts\n"
    opener: Any = gzip.open(path, "wb", compresslevel=1) if gz else path.open("wb")
    rows, written = 0, len(header)
    with opener as fh:
        fh.write(header)
        while True:
            block = _encoder_rows(rows, 50_000)
            if written + len(block) > size:
                break
            fh.write(block)
            rows += 50_000
            written += len(block)
    return rows


def _case(work: Path, name: str, build: Any) -> dict[str, Any]:
    src = work / name / "src"
    folder = src / f"{name}_0001"
    folder.mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps(_manifest(f"{name}_0001")))
    t0 = time.perf_counter()
    info = build(folder) or {}
    build_s = time.perf_counter() - t0
    on_disk = sum(f.stat().st_blocks * 512 for f in folder.iterdir())
    apparent = sum(f.stat().st_size for f in folder.iterdir())
    before = _sha256(folder)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(work / name / "out")],
                          capture_output=True, text=True, timeout=1800, check=False)
    if proc.returncode != 0:
        return {"error": proc.stderr[-500:], "build_s": round(build_s, 1)}
    res: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    res.update(info, input_mb=round(apparent / MB, 1), on_disk_mb=round(on_disk / MB, 1),
               build_s=round(build_s, 1), raw_unchanged=_sha256(folder) == before)
    shutil.rmtree(work / name, ignore_errors=True)
    return res


def big_inputs() -> dict[str, Any]:
    """Peak memory and outcome of ingesting big and hostile single runs (module docstring)."""
    from rig_io.limits import DEFAULT_LIMITS

    work = Path(tempfile.mkdtemp(prefix="bench_ingest_big_"))
    sample = REPO / "data" / "samples" / "folder"
    accept_mb = 0.95 * min(DEFAULT_LIMITS.max_file_mb, DEFAULT_LIMITS.max_decompressed_mb)

    def sparse(folder: Path) -> None:
        with (folder / "encoder.csv").open("wb") as fh:
            fh.truncate(GIB)

    def dense(folder: Path) -> dict[str, Any]:
        return {"rows": _write_encoder(folder / "encoder.csv", GIB)}

    def bomb(folder: Path) -> None:
        with gzip.open(folder / "encoder.csv.gz", "wb", compresslevel=9) as fh:
            fh.write(b"t_ns,input_counts,output_counts\n")
            zeros = b"0" * (16 * MB)
            for _ in range(GIB // len(zeros)):
                fh.write(zeros)

    def largest(folder: Path) -> dict[str, Any]:
        return {"rows": _write_encoder(folder / "encoder.csv", int(accept_mb * MB))}

    try:
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(sample), str(work / "base")],
                              capture_output=True, text=True, timeout=600, check=False)
        base = json.loads(proc.stdout.strip().splitlines()[-1]) if proc.returncode == 0 else {
            "error": proc.stderr[-500:]}
        out: dict[str, Any] = {"baseline_sample_run": base,
                               "limits_mb": {"max_file_mb": DEFAULT_LIMITS.max_file_mb,
                                             "max_decompressed_mb":
                                                 DEFAULT_LIMITS.max_decompressed_mb}}
        for name, build in (("sparse_1gib", sparse), ("dense_1gib", dense),
                            ("gzip_bomb_1gib", bomb), ("largest_accepted", largest)):
            res = _case(work, name, build)
            res["under_1gb"] = bool(res.get("peak_mb", 1e9) < MAX_PEAK_MB)
            out[name] = res
        out["all_under_1gb"] = all(v.get("under_1gb", False) for k, v in out.items()
                                   if isinstance(v, dict) and k not in ("baseline_sample_run",
                                                                        "limits_mb"))
        out["all_raw_unchanged"] = all(v.get("raw_unchanged", False) for k, v in out.items()
                                       if isinstance(v, dict) and "raw_unchanged" in v)
        return out
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run() -> dict[str, Any]:
    return {**campaign(), "big_inputs": big_inputs()}


def campaign() -> dict[str, Any]:
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
    print(json.dumps(big_inputs() if "--big" in sys.argv else run(), indent=1))
