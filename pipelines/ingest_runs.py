"""Ingest every raw run of a source into a processed folder: the ingest stage's work, shared
with the stages that ingest a source of their own (the discrepancy stage, into a temporary
folder) so no stage imports another.

Every run is read, checked, calibrated, synchronised and normalised by the pure functions of
``rig_io``; a bad run is rejected with its reason while the others go through, and a run whose
source files, ingest version and options are unchanged is not processed again (what the
command does around it: ``pipelines/ingest.py``).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tqdm import tqdm

from rig_io.atomic import clean_leftovers, write_text_atomic
from rig_io.bag import sidecar_manifest
from rig_io.dataset import REPORT, SAMPLES, read_runs, run_file, write_run_rows, write_runs
from rig_io.errors import RigIOError, WriteError
from rig_io.importer import IMPORTER_VERSION, load_mapping, matches
from rig_io.limits import ReadLimits
from rig_io.process import INGEST_VERSION, process_run
from rig_io.sources import Source, _looks_like_run_folder, discover, hash_files, load
from rig_io.synchronise import SyncOptions


def options_hash(sync: SyncOptions, mapping: dict[str, Any] | None) -> str:
    """Hash of everything besides the source files that changes a run's rows."""
    doc = {"sync": asdict(sync), "mapping": mapping, "importer": IMPORTER_VERSION}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def run_ingest(source: str | Path, out: str | Path, *,
               mapping: Mapping[str, Any] | None = None,
               sync: SyncOptions | None = None, force: bool = False, prune: bool = True,
               progress: bool = True, limits: ReadLimits | None = None) -> dict[str, Any]:
    """Ingest every run under ``source`` into ``out``; return the report (also written)."""
    started = time.perf_counter()
    # the output is not resolved (a link at an output name is refused, not followed); the
    # source check below compares real paths
    given, dst = Path(source).resolve(), Path(os.path.abspath(out))
    if not given.exists():
        raise RigIOError("source does not exist (nothing ingested, nothing removed)",
                         file=str(given))
    sync = sync or SyncOptions()
    plain = load_mapping(mapping) if mapping is not None else None
    opts = options_hash(sync, plain)
    single = single_run_source(given, mapping=plain)
    # keys (the cache) are relative to the folder holding the runs, as when it is the source
    src = given.parent if single is not None else given
    real_dst = dst.resolve()
    if real_dst == src or src in real_dst.parents:
        raise RigIOError("the output folder must not be inside the source folder "
                         "(raw runs are never written)", file=str(dst))
    if single is not None:
        sources = [single]
        prune = False  # one run given: the other processed runs are not "gone"
    else:
        sources = discover(src, mapping=plain)
    if not sources:
        raise RigIOError("no raw run found in the source (run folders, .bag files, rosbag2 "
                         "folders); nothing ingested, nothing removed", file=str(given))
    clean_leftovers(dst)
    try:
        old = read_runs(dst)
    except RigIOError:
        if not force:
            raise
        old = {}  # force reprocesses every run anyway: the index is written anew below
    by_key = {str(m.get("source_key")): (rid, m) for rid, m in old.items()}
    runs: dict[str, dict[str, Any]] = {}
    accepted: list[dict[str, Any]] = []
    rejected: list[dict[str, Any]] = []
    bar = tqdm(sources, desc="ingest", unit="run", disable=not progress, file=sys.stderr)
    for s in bar:
        key = s.key(src)
        bar.set_postfix_str(key[-40:])
        try:
            digest, hashes = hash_files(s.files, root=src)
        except OSError as err:
            rejected.append(_rejection(s, key, RigIOError(f"unreadable: {err}",
                                                          file=str(s.path))))
            continue
        cached = by_key.get(key)
        if (not force and cached is not None and cached[1].get("source_hash") == digest
                and cached[1].get("ingest_version") == INGEST_VERSION
                and cached[1].get("options_hash") == opts
                and cached[0] not in runs
                and _output_intact(dst, cached[0], cached[1].get("output_sha256"))):
            runs[cached[0]] = cached[1]
            accepted.append({"run_id": cached[0], "source": key, "status": "unchanged",
                             "n_samples": cached[1].get("n_samples")})
            continue
        try:
            phys = load(s, mapping=plain, limits=limits or ReadLimits())
            if phys.run_id in runs:
                raise RigIOError(f"duplicate run_id: already ingested from "
                                 f"{runs[phys.run_id]['source_key']!r}", run=phys.run_id,
                                 file=str(s.path))
            frame, info = process_run(phys, sync=sync)
            meta = {**info, "source_key": key, "source_kind": s.kind, "source_path": str(s.path),
                    "source_hash": digest, "source_files": hashes, "manifest": phys.manifest,
                    "options_hash": opts, "sync_options": asdict(sync),
                    "ingested_at": datetime.now(UTC).isoformat(timespec="seconds")}
            written = write_run_rows(dst, frame, meta)
            meta["output_sha256"] = file_sha256(written)
        except WriteError:
            # the run was fine, its output could not be stored (disk full ...): the stage
            # stops here, before any prune, and removes nothing
            raise
        except RigIOError as err:
            rejected.append(_rejection(s, key, err))
            continue
        except Exception as err:  # one broken run must not stop the batch
            rejected.append(_rejection(s, key, RigIOError(
                f"{type(err).__name__} while processing: {err}", run=s.path.name,
                file=str(s.path))))
            continue
        runs[phys.run_id] = meta
        accepted.append({"run_id": phys.run_id, "source": key, "status": "processed",
                         "n_samples": meta["n_samples"]})
    refused = None
    if not accepted:  # a wrong source must not look like "every run was removed"
        refused = (f"all {len(rejected)} run(s) of the source were rejected: nothing "
                   "ingested, no processed run removed")
        removed: list[str] = []
    elif prune:
        removed = _prune(dst, runs)
    else:  # keep the index of the processed runs this ingest did not touch
        removed = []
        for rid, m in old.items():
            if rid not in runs and run_file(dst, rid).is_file():
                runs[rid] = m
    if refused is None:
        write_runs(dst, runs)
    report = {
        "source": str(src), "out": str(dst), "ingest_version": INGEST_VERSION,
        "options_hash": opts, "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "elapsed_s": round(time.perf_counter() - started, 3),
        "n_sources": len(sources), "n_accepted": len(accepted), "n_rejected": len(rejected),
        "n_processed": sum(a["status"] == "processed" for a in accepted),
        "n_samples": int(sum(int(runs[a["run_id"]]["n_samples"]) for a in accepted)),
        "accepted": accepted, "rejected": rejected, "removed": removed, "refused": refused,
    }
    write_text_atomic(dst / REPORT, json.dumps(report, indent=1, default=str) + "\n")
    return report


def single_run_source(path: Path, *, mapping: dict[str, Any] | None = None) -> Source | None:
    """``path`` as one raw run (run folder, ``.bag``, rosbag2 folder, importable log), or
    None when it is a folder of runs."""
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            files = sorted(f for f in path.iterdir() if f.is_file())
            side = sidecar_manifest(path)
            return Source("rosbag2", path, tuple(files + ([side] if side.exists() else [])))
        if _looks_like_run_folder(path):
            return Source("folder", path, tuple(sorted(
                f for f in path.iterdir() if f.is_file() and not f.name.startswith("."))))
        return None
    if path.suffix == ".bag":
        side = sidecar_manifest(path)
        return Source("rosbag1", path, (path, side) if side.exists() else (path,))
    if mapping is not None and matches(mapping, path):
        return Source("import", path, (path,))
    raise RigIOError("source is a file that is neither a .bag nor matched by the importer "
                     "mapping; pass the folder holding the runs", file=str(path))


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _output_intact(dst: Path, run_id: str, recorded: Any) -> bool:
    """The run's parquet file exists and still has the bytes it was written with."""
    try:
        path = run_file(dst, run_id)
        return isinstance(recorded, str) and path.is_file() and file_sha256(path) == recorded
    except (OSError, RigIOError):
        return False


def _rejection(s: Source, key: str, err: RigIOError) -> dict[str, Any]:
    return {"source": key, "run_id": err.run, "file": err.file, "row": err.row,
            "t_ns": err.t_ns, "reason": str(err)}


def _prune(dst: Path, runs: dict[str, dict[str, Any]]) -> list[str]:
    """Remove output files of runs that are no longer accepted (ours, never raw data)."""
    removed = []
    folder = dst / SAMPLES
    if folder.is_dir():
        for f in sorted(folder.glob("*.parquet")):
            if f.stem not in runs:
                f.unlink()
                removed.append(f.stem)
    return removed
