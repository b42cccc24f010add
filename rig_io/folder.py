"""Run folders of the ``tsm-rig-log/1`` format: write a :class:`RawRun`, read one back.

A run folder is ``<run_id>/`` with ``manifest.json`` and one CSV (or ``.csv.gz``) per stream
(rig-log-format.md section 1). The reader checks every bad-input case of section 3 that a
folder can show and raises :class:`RigIOError` naming run, file and row (the 1-based line
number in the file; the header is line 1) or time. Nothing here ever writes into a raw run:
the writer builds the folder under a temporary name and renames it into place.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rig_io import checks
from rig_io.atomic import atomic_path
from rig_io.errors import RigIOError
from rig_io.manifest import check_manifest, parse_manifest
from rig_io.run import EVENT_KINDS, STREAM_COLUMNS, RawRun

MANIFEST = "manifest.json"
STREAMS = ("encoder", "loadcell", "camera", "tracker", "events")
#: Columns that must hold a number in every row.
_REQUIRED_VALUES = {
    "encoder": ("t_ns", "input_counts"),
    "loadcell": ("t_ns", "input_mv_per_v", "output_mv_per_v"),
    "camera": ("t_ns", "frame", "confidence"),
    "tracker": ("t_ns", "frame", "confidence"),
    "events": ("t_ns",),
}
#: Integer columns (timestamps, counts, frame numbers).
_INTEGER = {"t_ns", "input_counts", "output_counts", "frame"}


# ----------------------------------------------------------------------------------- writing

def write_run_folder(run: RawRun, root: str | os.PathLike[str], *,
                     compress: bool = False) -> Path:
    """Write ``run`` as ``<root>/<run_id>/`` (atomically, as a folder); return that path.

    ``compress`` writes ``.csv.gz`` streams (``events.csv`` stays plain, as the format says).
    Gzip headers carry no time stamp, so the same run always gives the same bytes.
    """
    run_id = run.run_id
    if not run_id or "/" in run_id or run_id.startswith("."):
        raise RigIOError("run_id is not a valid folder name", run=run_id)
    target = Path(root) / run_id
    with atomic_path(target) as tmp:
        tmp.mkdir(parents=True)
        (tmp / MANIFEST).write_text(json.dumps(run.manifest, indent=2) + "\n", encoding="utf-8")
        for name, frame in run.streams().items():
            cols = STREAM_COLUMNS[name]
            missing = [c for c in cols if c not in frame.columns]
            if missing:
                raise RigIOError(f"{name} stream lacks columns {missing}", run=run_id,
                                 file=f"{name}.csv")
            gz = compress and name != "events"
            path = tmp / (f"{name}.csv.gz" if gz else f"{name}.csv")
            text = frame.loc[:, list(cols)].to_csv(index=False, lineterminator="\n")
            data = text.encode("utf-8")
            if gz:
                data = gzip.compress(data, compresslevel=6, mtime=0)
            path.write_bytes(data)
    return target


# ----------------------------------------------------------------------------------- reading

def find_stream(folder: Path, name: str) -> Path | None:
    """The file of stream ``name`` in a run folder (``.csv`` or ``.csv.gz``), if any."""
    plain, gz = folder / f"{name}.csv", folder / f"{name}.csv.gz"
    if plain.exists() and gz.exists():
        raise RigIOError(f"both {plain.name} and {gz.name} exist", file=str(folder))
    if plain.exists():
        return plain
    if gz.exists():
        return gz
    return None


def read_manifest(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and check ``manifest.json`` of a run folder (without reading the streams)."""
    folder = Path(folder)
    path = folder / MANIFEST
    if not path.is_file():
        raise RigIOError("missing manifest.json", run=folder.name, file=str(path))
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise RigIOError(f"unreadable manifest: {err}", run=folder.name,
                         file=str(path)) from None
    manifest = parse_manifest(text, run=folder.name, file=str(path))
    present = [n for n in STREAMS if find_stream(folder, n) is not None]
    check_manifest(manifest, file=str(path), streams=present, run_hint=folder.name)
    return manifest


def read_run_folder(path: str | os.PathLike[str], *, check: bool = True) -> RawRun:
    """Read a run folder into a :class:`RawRun`, checking every bad-input case.

    With ``check`` (default) the value checks of :mod:`rig_io.checks` run too: timestamp
    order and gaps, load-cell saturation, e-stop, camera confidence.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise RigIOError("run folder does not exist", run=folder.name, file=str(folder))
    manifest = read_manifest(folder)
    run_id = str(manifest["run_id"])
    frames: dict[str, pd.DataFrame | None] = {}
    for name in STREAMS:
        file = find_stream(folder, name)
        if file is None:
            if name == "encoder":
                raise RigIOError("missing required encoder.csv", run=run_id,
                                 file=str(folder / "encoder.csv"))
            frames[name] = None
            continue
        frames[name] = read_stream_csv(file, name, run=run_id)
    run = RawRun(manifest=manifest, encoder=_not_none(frames["encoder"]),
                 loadcell=frames["loadcell"], camera=frames["camera"],
                 tracker=frames["tracker"], events=frames["events"])
    if check:
        check_raw_run(run, folder=folder)
    return run


def _not_none(frame: pd.DataFrame | None) -> pd.DataFrame:
    assert frame is not None
    return frame


def check_raw_run(run: RawRun, *, folder: Path | None = None) -> None:
    """Value checks of a raw run (timestamps, gaps, saturation, estop, confidence)."""
    run_id = run.run_id

    def fname(name: str) -> str:
        if folder is None:
            return f"{name}.csv"
        found = find_stream(folder, name)
        return str(found if found is not None else folder / f"{name}.csv")

    for name, frame in run.streams().items():
        t = frame["t_ns"].to_numpy(dtype=np.int64)
        checks.check_timestamps(t, run=run_id, file=fname(name), check_gaps=name != "events")
    if run.loadcell is not None:
        cells = run.manifest["channels"]["loadcell"]
        t = run.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for side in ("input", "output"):
            cell = cells[side]
            raw = run.loadcell[f"{side}_mv_per_v"].to_numpy(dtype=float)
            force = (raw - float(cell["zero_mv_per_v"])) * float(cell["newton_per_mv_per_v"])
            checks.check_saturation(t, force, range_n=cell.get("range_n"), side=side,
                                    run=run_id, file=fname("loadcell"))
    checks.check_events(run.events, run=run_id, file=fname("events"))
    for name in ("camera", "tracker"):
        frame = getattr(run, name)
        if frame is not None:
            checks.check_confident(frame, run=run_id, file=fname(name))


def read_stream_csv(path: str | os.PathLike[str], name: str, *, run: str) -> pd.DataFrame:
    """Read one stream CSV (plain or gzip) with the structural checks of format section 3."""
    path = Path(path)
    file = str(path)
    cols = STREAM_COLUMNS[name]
    try:
        data = path.read_bytes()
        if path.suffix == ".gz":
            data = gzip.decompress(data)
    except (EOFError, OSError, zlib.error) as err:
        raise RigIOError(f"unreadable or truncated file: {err}", run=run, file=file) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise RigIOError("not valid UTF-8", run=run, file=file, row=line) from None
    if not text or text.isspace():
        raise RigIOError("empty file", run=run, file=file)
    header_end = text.find("\n")
    header = (text if header_end < 0 else text[:header_end]).rstrip("\r").split(",")
    header = [h.strip() for h in header]
    missing = [c for c in cols if c not in header]
    if missing:
        raise RigIOError(f"missing required column(s) {', '.join(missing)} "
                         f"(header is {','.join(header)})", run=run, file=file, row=1)
    body = text[header_end + 1:] if header_end >= 0 else ""
    if not body or body.isspace():
        raise RigIOError("no data rows after the header", run=run, file=file)
    # A logger killed mid-write leaves a last line without its terminator or short of fields.
    last_start = body.rstrip("\n").rfind("\n") + 1
    last = body.rstrip("\n")[last_start:]
    n_lines = text.rstrip("\n").count("\n") + 1
    if not text.endswith("\n"):
        raise RigIOError(f"truncated last line {last!r} (no line terminator)",
                         run=run, file=file, row=n_lines)
    if last.count(",") != len(header) - 1:
        raise RigIOError(f"truncated last line {last!r} ({last.count(',') + 1} fields, "
                         f"expected {len(header)})", run=run, file=file, row=n_lines)
    try:
        frame = pd.read_csv(io.StringIO(text), sep=",", skip_blank_lines=False,
                            keep_default_na=False, na_values=[""],
                            usecols=list(cols), engine="c")
    except pd.errors.ParserError as err:
        raise RigIOError(f"malformed CSV: {err}".strip(), run=run, file=file,
                         row=_line_from_parser_error(str(err))) from None
    return _typed(frame, name, run=run, file=file)


def _line_from_parser_error(msg: str) -> int | None:
    import re

    m = re.search(r"line (\d+)", msg)
    return int(m.group(1)) if m else None


def _typed(frame: pd.DataFrame, name: str, *, run: str, file: str) -> pd.DataFrame:
    """Check and convert columns to numbers, naming the first bad cell."""
    out: dict[str, Any] = {}
    required = _REQUIRED_VALUES[name]
    for col in STREAM_COLUMNS[name]:
        raw = frame[col]
        if name == "events" and col != "t_ns":
            values = raw.astype(object).where(raw.notna(), "").astype(str)
            if col == "event":
                bad = np.flatnonzero(~values.isin(EVENT_KINDS).to_numpy())
                if bad.size:
                    i = int(bad[0])
                    raise RigIOError(f"unknown event {values.iloc[i]!r} "
                                     f"(expected one of {', '.join(EVENT_KINDS)})",
                                     run=run, file=file, row=i + checks.FIRST_DATA_LINE)
            out[col] = values.to_numpy(dtype=object)
            continue
        empty = raw.isna().to_numpy()
        if pd.api.types.is_numeric_dtype(raw.dtype):
            num = raw.to_numpy(dtype=float, na_value=np.nan)
        else:  # the C parser found something that is not a number somewhere
            num = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
            bad = np.flatnonzero(~empty & ~np.isfinite(num))
            if bad.size:
                i = int(bad[0])
                raise RigIOError(f"non-numeric value {raw.iloc[i]!r} in column {col}",
                                 run=run, file=file, row=i + checks.FIRST_DATA_LINE)
        bad = np.flatnonzero(~empty & ~np.isfinite(num))
        if bad.size:
            i = int(bad[0])
            raise RigIOError(f"non-finite value {raw.iloc[i]!r} in column {col}",
                             run=run, file=file, row=i + checks.FIRST_DATA_LINE)
        if col in required or (col == "output_counts" and 0 < empty.sum() < len(empty)):
            holes = np.flatnonzero(empty)
            if holes.size:
                i = int(holes[0])
                raise RigIOError(f"empty value in column {col}", run=run, file=file,
                                 row=i + checks.FIRST_DATA_LINE)
        if col in _INTEGER:
            ok = ~empty
            frac = ok & (num != np.round(num))
            if frac.any():
                i = int(np.flatnonzero(frac)[0])
                raise RigIOError(f"non-integer value {raw.iloc[i]!r} in column {col}",
                                 run=run, file=file, row=i + checks.FIRST_DATA_LINE)
            if raw.dtype == np.int64:
                out[col] = raw.to_numpy()  # exact, even beyond 2**53
            elif empty.any():
                out[col] = pd.array(np.where(ok, num, 0).astype(np.int64), dtype="Int64")
                out[col][~ok] = pd.NA
            else:
                out[col] = np.round(num).astype(np.int64)
        else:
            out[col] = num
    result = pd.DataFrame(out)
    if name == "encoder":
        result["output_counts"] = result["output_counts"].astype("Int64")
    return result
