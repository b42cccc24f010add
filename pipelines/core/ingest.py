"""The core of stage ``ingest`` (no Hydra, no MLflow; its command
is :mod:`pipelines.ingest`; the command line is in its docstring).

Every run is read, checked, calibrated, synchronised and normalised by the pure functions of
``rig_io``; a bad run is rejected with its reason while the others go through. A run whose
source files, ingest version and options are unchanged is not processed again. Writes
``<out>/samples/<run_id>.parquet``, ``<out>/runs.json`` and ``<out>/ingest_report.json``
(all atomically; never anything in the source folder) and exits 1 when a run was rejected.

``source`` may also be one run (a run folder, a ``.bag`` file or a rosbag2 folder): it is
ingested alone, and nothing else in ``out`` is pruned. A source that does not exist, holds
no run is refused (exit 2) and ``out`` is left untouched; one whose runs are all rejected
writes only its ``ingest_report.json`` (``refused``, exit 1). An empty or wrong source never
deletes processed data. An output that cannot be written (a full disk) stops the stage with
one line naming the file and the free space (exit 2): nothing is pruned or removed. A
processed file that no longer matches the hash recorded when it was written (truncated,
edited) is processed again.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tqdm import tqdm

from rig_io.atomic import clean_leftovers, write_text_atomic
from rig_io.dataset import REPORT, SAMPLES, read_runs, run_file, write_run_rows, write_runs
from rig_io.errors import RigIOError, WriteError
from rig_io.importer import IMPORTER_VERSION, load_mapping
from rig_io.limits import ReadLimits
from rig_io.process import INGEST_VERSION, process_run
from rig_io.sources import Source, discover, hash_files, load, source_at
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
    src, sources, single = _sources(given, dst, plain)
    prune = prune and not single  # one run given: the other processed runs are not "gone"
    clean_leftovers(dst)
    try:
        old = read_runs(dst)
    except RigIOError:
        if not force:
            raise
        old = {}  # force reprocesses every run anyway: the index is written anew below
    batch = _Batch(src, dst, plain, sync, options_hash(sync, plain), limits or ReadLimits(),
                   force, {str(m.get("source_key")): (rid, m) for rid, m in old.items()})
    bar = tqdm(sources, desc="ingest", unit="run", disable=not progress, file=sys.stderr)
    for s in bar:
        bar.set_postfix_str(s.key(src)[-40:])
        batch.ingest(s)
    runs, accepted, rejected = batch.runs, batch.accepted, batch.rejected
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
        "options_hash": batch.opts,
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "elapsed_s": round(time.perf_counter() - started, 3),
        "n_sources": len(sources), "n_accepted": len(accepted), "n_rejected": len(rejected),
        "n_processed": sum(a["status"] == "processed" for a in accepted),
        "n_samples": int(sum(int(runs[a["run_id"]]["n_samples"]) for a in accepted)),
        "accepted": accepted, "rejected": rejected, "removed": removed, "refused": refused,
    }
    write_text_atomic(dst / REPORT, json.dumps(report, indent=1, default=str) + "\n")
    return report


def _sources(given: Path, dst: Path, plain: dict[str, Any] | None
             ) -> tuple[Path, list[Source], bool]:
    """(the folder holding the runs, the runs, whether ``given`` is one run); the output
    must not be inside the source, and a source without a run is refused."""
    single = single_run_source(given, mapping=plain)
    # keys (the cache) are relative to the folder holding the runs, as when it is the source
    src = given.parent if single is not None else given
    real_dst = dst.resolve()
    if real_dst == src or src in real_dst.parents:
        raise RigIOError("the output folder must not be inside the source folder "
                         "(raw runs are never written)", file=str(dst))
    sources = [single] if single is not None else discover(src, mapping=plain)
    if not sources:
        raise RigIOError("no raw run found in the source (run folders, .bag files, rosbag2 "
                         "folders); nothing ingested, nothing removed", file=str(given))
    return src, sources, single is not None


@dataclass
class _Batch:
    """One ingest's runs as they go through: accepted (processed or unchanged) or rejected."""

    src: Path
    dst: Path
    mapping: dict[str, Any] | None
    sync: SyncOptions
    opts: str
    limits: ReadLimits
    force: bool
    #: the previous index by source key: (run id, its record)
    by_key: dict[str, tuple[str, dict[str, Any]]]
    runs: dict[str, dict[str, Any]] = field(default_factory=dict)
    accepted: list[dict[str, Any]] = field(default_factory=list)
    rejected: list[dict[str, Any]] = field(default_factory=list)

    def ingest(self, s: Source) -> None:
        """Source ``s``: left as it is when unchanged, else processed, or rejected."""
        key = s.key(self.src)
        try:
            digest, hashes = hash_files(s.files, root=self.src)
        except OSError as err:
            self.rejected.append(_rejection(s, key, RigIOError(f"unreadable: {err}",
                                                               file=str(s.path))))
            return
        if self._unchanged(key, digest):
            return
        try:
            run_id, meta = self._process(s, key, digest, hashes)
        except WriteError:
            # the run was fine, its output could not be stored (disk full ...): the stage
            # stops here, before any prune, and removes nothing
            raise
        except RigIOError as err:
            self.rejected.append(_rejection(s, key, err))
            return
        except Exception as err:  # one broken run must not stop the batch
            self.rejected.append(_rejection(s, key, RigIOError(
                f"{type(err).__name__} while processing: {err}", run=s.path.name,
                file=str(s.path))))
            return
        self.runs[run_id] = meta
        self.accepted.append({"run_id": run_id, "source": key, "status": "processed",
                              "n_samples": meta["n_samples"]})

    def _unchanged(self, key: str, digest: str) -> bool:
        """The source's run is processed already from the same files, ingest version and
        options, and its output is intact: it is kept as it is."""
        cached = self.by_key.get(key)
        if (self.force or cached is None or cached[1].get("source_hash") != digest
                or cached[1].get("ingest_version") != INGEST_VERSION
                or cached[1].get("options_hash") != self.opts
                or cached[0] in self.runs
                or not _output_intact(self.dst, cached[0], cached[1].get("output_sha256"))):
            return False
        self.runs[cached[0]] = cached[1]
        self.accepted.append({"run_id": cached[0], "source": key, "status": "unchanged",
                              "n_samples": cached[1].get("n_samples")})
        return True

    def _process(self, s: Source, key: str, digest: str, hashes: Any
                 ) -> tuple[str, dict[str, Any]]:
        """Read, check, process and write one run: (its run id, its index record)."""
        phys = load(s, mapping=self.mapping, limits=self.limits)
        if phys.run_id in self.runs:
            raise RigIOError(f"duplicate run_id: already ingested from "
                             f"{self.runs[phys.run_id]['source_key']!r}", run=phys.run_id,
                             file=str(s.path))
        frame, info = process_run(phys, sync=self.sync)
        meta = {**info, "source_key": key, "source_kind": s.kind, "source_path": str(s.path),
                "source_hash": digest, "source_files": hashes, "manifest": phys.manifest,
                "options_hash": self.opts, "sync_options": asdict(self.sync),
                "ingested_at": datetime.now(UTC).isoformat(timespec="seconds")}
        written = write_run_rows(self.dst, frame, meta)
        meta["output_sha256"] = file_sha256(written)
        return phys.run_id, meta


def single_run_source(path: Path, *, mapping: dict[str, Any] | None = None) -> Source | None:
    """``path`` as one raw run (run folder, ``.bag``, rosbag2 folder, importable log), or
    None when it is a folder of runs; a file that is none of these is refused."""
    source = source_at(path, mapping)
    if source is None and not path.is_dir():
        raise RigIOError("source is a file that is neither a .bag nor matched by the importer "
                         "mapping; pass the folder holding the runs", file=str(path))
    return source


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


def ingest(settings: Any) -> dict[str, Any]:
    """The stage's core: ``source`` of ``settings`` (:class:`schemas.IngestConfig`, or a
    mapping of its fields) ingested into its ``out``; the report of :func:`run_ingest`.
    Relative folders are taken against the working folder."""
    from pipelines import schemas

    s = schemas.settings(schemas.IngestConfig, settings)
    return run_ingest(s.source, s.out, mapping=s.importer, sync=s.sync,
                      force=s.force, prune=s.prune, progress=s.progress, limits=s.limits)
