"""The processed dataset on disk: one parquet file per run plus a JSON index of the runs.

Layout of an ingest output folder ``<out>/``::

    samples/<run_id>.parquet   the rows of one run (schema: rig_io.schema, docs/dataset-schema.md)
    runs.json                  per-run metadata: manifest, source file hashes, ingest version,
                               camera latency used and how, units, offsets, ...
    ingest_report.json         accepted and rejected runs of the last ingest, with reasons

``pandas.read_parquet(<out>/samples)`` reads every run as one table (all files share one arrow
schema); :func:`read_dataset` does that and validates the result.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from rig_io.atomic import atomic_path, contained, safe_part, write_text_atomic
from rig_io.errors import RigIOError
from rig_io.schema import ARROW_SCHEMA, COLUMNS, SCHEMA_VERSION, STRING_COLUMNS, validate

SAMPLES = "samples"
RUNS = "runs.json"
REPORT = "ingest_report.json"
#: Key of the run metadata in each parquet file's key-value metadata.
META_KEY = b"tsm_run"


def run_file(out: str | os.PathLike[str], run_id: str) -> Path:
    """``<out>/samples/<run_id>.parquet``; a run id that is not one plain file name (``/``,
    ``..``, absolute) is refused, so no run is written outside ``out`` or lost in a subfolder."""
    try:
        name = safe_part(run_id, what="run_id")
    except RigIOError as err:
        raise RigIOError(err.reason, run=str(run_id)) from None
    return contained(out, SAMPLES, f"{name}.parquet")


def write_run_rows(out: str | os.PathLike[str], frame: pd.DataFrame,
                   meta: dict[str, Any]) -> Path:
    """Validate (write edge) and write one run's rows atomically, metadata embedded."""
    run_id = str(meta["run_id"])
    frame = validate(frame, where="write", run=run_id)
    # Column by column from numpy (pandas' converter spins up a thread pool per call).
    arrays = []
    for field in ARROW_SCHEMA:
        col = frame[field.name]
        if pa.types.is_string(field.type):
            values = col.unique()
            if len(values) == 1:
                arrays.append(pa.repeat(pa.scalar(str(values[0]), pa.string()), len(col)))
                continue
            arrays.append(pa.array(col.astype(str).tolist(), type=pa.string()))
        else:
            arrays.append(pa.array(col.to_numpy(dtype=float), type=field.type))
    table = pa.Table.from_arrays(arrays, schema=ARROW_SCHEMA)
    # No wall-clock fields in the file: the same rows give the same bytes (stages hash them).
    embedded = {k: v for k, v in meta.items() if k != "ingested_at"}
    table = table.replace_schema_metadata(
        {META_KEY: json.dumps(embedded, default=str, sort_keys=True).encode()})
    target = run_file(out, run_id)
    with atomic_path(target, suffix=".parquet", folder=False) as tmp:
        pq.write_table(table, tmp, compression="zstd")
    return target


def _dataset_files(p: Path, runs: list[str] | None) -> list[Path]:
    """The parquet files of a dataset folder (only ``runs``' when given) or the one file."""
    if p.is_file():
        return [p]
    if not p.is_dir():
        raise RigIOError("dataset does not exist", file=str(p))
    files = sorted(p.glob("*.parquet"))
    nested = sorted(str(f.relative_to(p)) for f in p.rglob("*.parquet") if f.parent != p)
    if nested:
        raise RigIOError(f"parquet files in subfolders of the dataset ({nested[:5]}): run "
                         "ids must be plain names; re-ingest into a fresh folder", file=str(p))
    if runs is not None:
        wanted = {safe_part(r, what="run_id") for r in runs}
        files = [f for f in files if f.stem in wanted]
        missing = sorted(wanted - {f.stem for f in files})
        if missing:
            raise RigIOError(f"run(s) {missing[:10]} not in dataset", file=str(p))
    if not files:
        raise RigIOError("no runs in dataset", file=str(p))
    return files


def read_dataset(path: str | os.PathLike[str], *, runs: list[str] | None = None,
                 validate_rows: bool = True,
                 columns: Sequence[str] | None = None) -> pd.DataFrame:
    """All rows of a processed dataset (an ingest output folder, its ``samples`` folder or
    one parquet file), ordered by run then time, validated at the read edge.

    ``columns``: read only these (kept in the dataset's column order); a stage that needs
    a few of the fifteen columns holds a third of the memory.
    """
    keep = COLUMNS if columns is None else tuple(c for c in COLUMNS if c in set(columns))
    unknown = sorted(set(columns or ()) - set(COLUMNS))
    if unknown:
        raise RigIOError(f"column(s) {unknown} not in the dataset schema; it has {list(COLUMNS)}",
                         file=str(path))
    p = Path(path)
    if p.is_dir() and (p / SAMPLES).is_dir():
        p = p / SAMPLES
    files = _dataset_files(p, runs)
    try:
        tables = [pq.read_table(f, schema=ARROW_SCHEMA, columns=list(keep)) for f in files]
    except (OSError, pa.ArrowException) as err:
        raise RigIOError(f"unreadable dataset: {err}", file=str(p)) from None
    table = pa.concat_tables(tables)
    del tables
    # Strings stay Arrow arrays in pandas; one chunk per file would make every row selection
    # (one configuration's rows) concatenate the whole column first.
    for name in STRING_COLUMNS:
        if name in table.column_names:
            table = table.set_column(table.column_names.index(name), name,
                                     table.column(name).combine_chunks())
    frame = table.to_pandas()
    del table
    frame = frame.loc[:, list(keep)]
    for col in ("run_id", "rig", "excitation"):
        if col in frame:
            frame[col] = frame[col].astype("str")
    if validate_rows:
        frame = validate(frame, where="read", columns=keep, inplace=True)
    return frame.reset_index(drop=True)


def read_runs(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """Per-run metadata of an ingest output folder (``runs.json``), keyed by run id."""
    p = Path(path)
    file = p / RUNS if p.is_dir() else p
    if not file.is_file():
        return {}
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise RigIOError(f"unreadable run index ({err}): run ingest with force=true to "
                         f"rebuild it from the sources, or delete {RUNS} and run ingest "
                         "again", file=str(file)) from None
    runs = data.get("runs", {}) if isinstance(data, dict) else None
    if not isinstance(runs, dict):
        raise RigIOError(f"run index without a 'runs' table: run ingest with force=true to "
                         f"rebuild it from the sources, or delete {RUNS} and run ingest again",
                         file=str(file))
    return dict(runs)


def write_runs(out: str | os.PathLike[str], runs: dict[str, dict[str, Any]]) -> Path:
    """Write the run index atomically."""
    doc = {"schema_version": SCHEMA_VERSION, "runs": dict(sorted(runs.items()))}
    return write_text_atomic(Path(out) / RUNS, json.dumps(doc, indent=1, default=str) + "\n")
