"""The core of stage ``generate`` (no Hydra, no MLflow; its command
is :mod:`pipelines.generate`; the command line is in its docstring).

Each run is simulated by :func:`rig_io.virtual.simulate_run` and written by the format's own
writers (:func:`rig_io.folder.write_run_folder`, :func:`rig_io.bag.write_bag`), atomically.
Raw runs are never rewritten: a run that already exists with the same spec is skipped, a
different spec under an existing run id is an error unless ``overwrite=true``. The specs and
their hashes are recorded in ``<out>/campaign.json``: every spec as ``pending`` before any run
is written, then ``done`` as each run lands, so a campaign killed at any point is completed by
the same command (a run folder exists only whole, from the spec the book names). Temporaries
of a killed writer are removed when the stage starts.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from rig_io.atomic import clean_leftovers, contained, write_text_atomic
from rig_io.errors import RigIOError
from rig_io.virtual import simulate_run, standard_campaign
from rig_io.virtual.campaign import STANDARD_EXCITATIONS

FORMATS = ("folder", "rosbag1", "sqlite3", "mcap")
CAMPAIGN_FILE = "campaign.json"


class GenerateError(Exception):
    """A campaign that cannot be written as asked (bad option, clash with existing runs)."""


def campaign_specs(*, seed: int = 0, rig: str = "tsm-bench",
                   curve_angles_deg: Iterable[float] | None = None,
                   radii_mm: Iterable[float] | None = None,
                   excitations: Iterable[Mapping[str, Any]] | None = None,
                   effects: Mapping[str, float] | None = None,
                   sensors: Mapping[str, Any] | None = None,
                   params: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """The run specs of a campaign (``standard_campaign`` with the config's choices)."""
    kw: dict[str, Any] = {}
    if curve_angles_deg is not None:
        kw["curve_angles_deg"] = list(curve_angles_deg)
    if radii_mm is not None:
        kw["radii_mm"] = list(radii_mm)
    kw["excitations"] = ([dict(e) for e in excitations] if excitations is not None
                         else list(STANDARD_EXCITATIONS))
    specs = standard_campaign(int(seed), rig=rig,
                              effects={k: float(v) for k, v in (effects or {}).items()},
                              sensors=dict(sensors) if sensors else None, **kw)
    if params:
        for spec in specs:
            spec["params"] = dict(params)
    return specs


def spec_hash(spec: Mapping[str, Any]) -> str:
    """Stable hash of a run spec (what makes the run's bytes)."""
    text = json.dumps(spec, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def target_path(out: Path, run_id: str, fmt: str) -> Path:
    """Where run ``run_id`` goes; :class:`GenerateError` if that is not a plain name in ``out``."""
    try:
        return contained(out, f"{run_id}.bag" if fmt == "rosbag1" else run_id)
    except RigIOError as err:
        raise GenerateError(f"run_id {run_id!r}: {err}") from None


def write_one(spec: dict[str, Any], out: str, fmt: str, compress: bool, *,
              parent_pid: int | None = None) -> dict[str, Any]:
    """Simulate and write one run (runs in a worker process; with ``parent_pid`` the worker
    ends itself when that process is gone)."""
    if parent_pid is not None:
        from pipelines.common import exit_with_parent

        exit_with_parent(parent_pid)
    t0, c0 = time.perf_counter(), time.process_time()
    run = simulate_run(**spec)
    t1, c1 = time.perf_counter(), time.process_time()
    target = target_path(Path(out), run.run_id, fmt)
    if fmt == "folder":
        from rig_io.folder import write_run_folder

        path = write_run_folder(run, out, compress=compress)
    else:
        from rig_io.bag import write_bag

        path = write_bag(run, target, storage=fmt)  # type: ignore[arg-type]
    t2, c2 = time.perf_counter(), time.process_time()
    return {"run_id": run.run_id, "path": str(path), "simulate_s": t1 - t0, "write_s": t2 - t1,
            "simulate_cpu_s": c1 - c0, "write_cpu_s": c2 - c1}


def run_generate(specs: list[dict[str, Any]], out: str | Path, *, fmt: str = "folder",
                 compress: bool = False, n_jobs: int = 2, overwrite: bool = False,
                 progress: bool = True) -> dict[str, Any]:
    """Write every spec's run under ``out``; return a small report (also in campaign.json)."""
    _check_request(specs, fmt, compress)
    out = Path(os.path.abspath(out))  # not resolved: an output link is refused, not followed
    out.mkdir(parents=True, exist_ok=True)
    clean_leftovers(out, recursive=False)
    book_path = out / CAMPAIGN_FILE
    book = _read_book(book_path)
    known: dict[str, Any] = dict(book.get("runs", {}))
    todo, skipped = _plan(specs, out, fmt, known, overwrite=overwrite)
    for spec in todo:
        rid = spec["run_id"]
        known[rid] = _book_entry(spec, fmt, target_path(out, rid, fmt).name, status="pending")
    if todo or known != book.get("runs", {}):
        _write_book(book_path, known)
    t0 = time.perf_counter()
    results: list[dict[str, Any]] = []
    bar = tqdm(total=len(todo), desc="generate", unit="run", disable=not progress,
               file=sys.stderr)
    by_id = {s["run_id"]: s for s in specs}
    for res in _written(todo, out, fmt, compress, n_jobs=n_jobs):
        results.append(res)
        rid = res["run_id"]
        known[rid] = _book_entry(by_id[rid], fmt, Path(res["path"]).name, status="done")
        _write_book(book_path, known)
        bar.update(1)
    bar.close()
    elapsed = time.perf_counter() - t0
    if not book_path.is_file():
        _write_book(book_path, known)
    return {"out": str(out), "format": fmt, "written": sorted(r["run_id"] for r in results),
            "skipped": skipped, "seconds": elapsed,
            "simulate_s": sum(r["simulate_s"] for r in results),
            "write_s": sum(r["write_s"] for r in results),
            "cpu_s": sum(r["simulate_cpu_s"] + r["write_cpu_s"] for r in results)}


def _check_request(specs: list[dict[str, Any]], fmt: str, compress: bool) -> None:
    """A known format, compression only for run folders, every run id once."""
    if fmt not in FORMATS:
        raise GenerateError(f"format must be one of {FORMATS}, got {fmt!r}")
    if compress and fmt != "folder":
        raise GenerateError("compress=true applies to run folders only (format=folder)")
    ids = [s["run_id"] for s in specs]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise GenerateError(f"run ids repeat in the campaign: {dup[:5]}")


def _read_book(book_path: Path) -> dict[str, Any]:
    """The campaign's book (``campaign.json``), empty when there is none yet."""
    if not book_path.is_file():
        return {}
    try:
        book: dict[str, Any] = json.loads(book_path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise GenerateError(f"{book_path} is unreadable ({err}); remove it or the "
                            "folder") from None
    return book


def _plan(specs: list[dict[str, Any]], out: Path, fmt: str, known: dict[str, Any], *,
          overwrite: bool) -> tuple[list[dict[str, Any]], list[str]]:
    """(the specs to write, the run ids already there from the same spec); a run there from
    another spec is an error unless ``overwrite``. ``known`` (the book's runs) is updated."""
    todo: list[dict[str, Any]] = []
    skipped: list[str] = []
    for spec in specs:
        rid, h = spec["run_id"], spec_hash(spec)
        target = target_path(out, rid, fmt)
        if target.exists() and not overwrite:
            old = known.get(rid, {})
            if old.get("spec_hash") == h and old.get("format") == fmt:
                # a run folder exists only whole (atomic rename): one killed before its
                # book entry said "done" is complete
                known[rid] = {**old, "status": "done"}
                skipped.append(rid)
                continue
            raise GenerateError(
                f"run {rid!r} already exists at {target} with a different or unknown spec; "
                "raw runs are never rewritten: use another out=, remove it (make clean-data), "
                "or pass overwrite=true")
        todo.append(spec)
    return todo, skipped


def _written(todo: list[dict[str, Any]], out: Path, fmt: str, compress: bool, *,
             n_jobs: int) -> Iterable[dict[str, Any]]:
    """Each run of ``todo`` written, as it lands (worker processes when n_jobs > 1)."""
    if n_jobs > 1 and len(todo) > 1:
        from joblib import Parallel, delayed

        par = Parallel(n_jobs=n_jobs, backend="loky", return_as="generator_unordered")
        me = os.getpid()
        return par(delayed(write_one)(s, str(out), fmt, compress, parent_pid=me)  # type: ignore[no-any-return]
                   for s in todo)
    return (write_one(s, str(out), fmt, compress) for s in todo)


def _book_entry(spec: Mapping[str, Any], fmt: str, name: str, *, status: str
                ) -> dict[str, Any]:
    return {"spec_hash": spec_hash(spec), "format": fmt, "path": name, "status": status,
            "spec": dict(spec)}


def _write_book(book_path: Path, known: Mapping[str, Any]) -> None:
    book = {"generator": "rig_io.virtual", "runs": dict(sorted(known.items()))}
    write_text_atomic(book_path, json.dumps(book, indent=1, default=str) + "\n")


@dataclass
class RigGroup:
    """The fields of a ``conf/rig/`` group the campaign uses."""

    name: str = "tsm-bench"
    sensors: Any = None
    params: Any = None


@dataclass
class CampaignGroup:
    """The fields of a ``conf/campaign/`` group (each list as written: no type coercion,
    the specs and their hashes keep the config's numbers)."""

    seed: int = 0
    curve_angles_deg: Any = None
    radii_mm: Any = None
    excitations: Any = None


def specs_from_config(settings: Any) -> list[dict[str, Any]]:
    """Run specs of a ``generate`` stage's settings (:class:`schemas.GenerateConfig`, or a
    mapping of its fields: ``rig``, ``campaign``, ``effects``)."""
    from pipelines import schemas

    s = schemas.settings(schemas.GenerateConfig, settings)
    rig = schemas.settings(RigGroup, s.rig or {})
    camp = schemas.settings(CampaignGroup, s.campaign or {})
    return campaign_specs(seed=camp.seed, rig=rig.name, curve_angles_deg=camp.curve_angles_deg,
                          radii_mm=camp.radii_mm, excitations=camp.excitations,
                          effects=s.effects or {}, sensors=rig.sensors or {},
                          params=rig.params or {})


def generate(settings: Any) -> dict[str, Any]:
    """The stage's core: the campaign of ``settings`` (:class:`schemas.GenerateConfig`)
    written under its ``out``; the report of :func:`run_generate`."""
    from pipelines import schemas

    s = schemas.settings(schemas.GenerateConfig, settings)
    return run_generate(specs_from_config(s), s.out, fmt=s.format, compress=s.compress,
                        n_jobs=s.n_jobs, overwrite=s.overwrite, progress=s.progress)
