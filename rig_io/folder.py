"""Run folders of the ``tsm-rig-log/1`` format: write a :class:`RawRun`, read one back.

A run folder is ``<run_id>/`` with ``manifest.json`` and one CSV (or ``.csv.gz``) per stream
(rig-log-format.md section 1). The reader checks every bad-input case of section 3 that a
folder can show and raises :class:`RigIOError` naming run, file and row (the 1-based line
number in the file; the header is line 1) or time. Nothing here ever writes into a raw run:
the writer builds the folder under a temporary name and renames it into place.
"""

from __future__ import annotations

import csv
import gzip
import io
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rig_io import checks
from rig_io.atomic import atomic_path
from rig_io.errors import RigIOError, short
from rig_io.limits import DEFAULT_LIMITS, ReadLimits, read_bytes
from rig_io.manifest import LOADCELL_CALIBRATION, check_manifest, is_safe_identifier, parse_manifest
from rig_io.run import EVENT_KINDS, STREAM_COLUMNS, RawRun
from rig_io.schema import validate_stream

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
    if not is_safe_identifier(run_id):
        raise RigIOError(f"run_id {short(run_id)} is not a safe folder name", key="run_id")
    target = Path(root) / run_id
    with atomic_path(target, folder=True) as tmp:
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
    """The file of stream ``name`` in a run folder (``.csv`` or ``.csv.gz``), if any.

    Found by name only (``lexists``: a dangling symlink or a FIFO is found, then refused by
    the reader rather than silently treated as absent); nothing is opened here.
    """
    plain, gz = folder / f"{name}.csv", folder / f"{name}.csv.gz"
    has_plain, has_gz = os.path.lexists(plain), os.path.lexists(gz)
    if has_plain and has_gz:
        raise RigIOError(f"both {plain.name} and {gz.name} exist", run=folder.name,
                         file=str(folder), key=name)
    if has_plain:
        return plain
    if has_gz:
        return gz
    return None


def read_manifest(folder: str | os.PathLike[str], *,
                  limits: ReadLimits = DEFAULT_LIMITS) -> dict[str, Any]:
    """Read and check ``manifest.json`` of a run folder (without reading the streams)."""
    folder = Path(folder)
    path = folder / MANIFEST
    if not os.path.lexists(path):
        raise RigIOError("missing manifest.json", run=folder.name, file=str(path))
    data = read_bytes(path, base=folder, run=folder.name, limit_mb=limits.max_manifest_mb,
                      limit_name="max_manifest_mb")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise RigIOError("manifest is not valid UTF-8", run=folder.name, file=str(path),
                         row=line) from None
    manifest = parse_manifest(text, run=folder.name, file=str(path))
    present = [n for n in STREAMS if find_stream(folder, n) is not None]
    check_manifest(manifest, file=str(path), streams=present, run_hint=folder.name)
    return manifest


def read_run_folder(path: str | os.PathLike[str], *, check: bool = True,
                    limits: ReadLimits = DEFAULT_LIMITS) -> RawRun:
    """Read a run folder into a :class:`RawRun`, checking every bad-input case.

    With ``check`` (default) the value checks of :mod:`rig_io.checks` run too: timestamp
    order and gaps, load-cell saturation, e-stop, camera confidence, stream overlap.
    ``limits`` bounds what is read (sizes; special files are always refused).
    """
    folder = Path(path)
    if not folder.is_dir():
        raise RigIOError("run folder does not exist", run=folder.name, file=str(folder))
    manifest = read_manifest(folder, limits=limits)
    run_id = str(manifest["run_id"])
    bits = int(manifest["channels"]["encoder"]["counter_bits"])
    frames: dict[str, pd.DataFrame | None] = {}
    for name in STREAMS:
        file = find_stream(folder, name)
        if file is None:
            if name == "encoder":
                raise RigIOError("missing required encoder.csv", run=run_id,
                                 file=str(folder / "encoder.csv"))
            frames[name] = None
            continue
        frames[name] = read_stream_csv(file, name, run=run_id, limits=limits,
                                       counter_bits=bits, base=folder)
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
    """Value checks of a raw run (timestamps, gaps, saturation, estop, confidence, overlap)."""
    run_id = run.run_id

    def fname(name: str) -> str:
        if folder is None:
            return f"{name}.csv"
        found = find_stream(folder, name)
        return str(found if found is not None else folder / f"{name}.csv")

    for name, frame in run.streams().items():
        t = frame["t_ns"].to_numpy(dtype=np.int64)
        checks.check_timestamps(t, run=run_id, file=fname(name), check_gaps=name != "events",
                                min_samples=1 if name == "events" else 2)
    if run.loadcell is not None:
        cells = run.manifest["channels"].get("loadcell")
        t = run.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for side in ("input", "output"):
            cell = (cells or {}).get(side) or {}
            if any(cell.get(k) is None for k in LOADCELL_CALIBRATION):
                continue  # kept raw (no newtons to compare with a range in newtons)
            raw = run.loadcell[f"{side}_mv_per_v"].to_numpy(dtype=float)
            force = (raw - float(cell["zero_mv_per_v"])) * float(cell["newton_per_mv_per_v"])
            checks.check_saturation(t, force, range_n=cell.get("range_n"), side=side,
                                    run=run_id, file=fname("loadcell"))
    checks.check_events(run.events, run=run_id, file=fname("events"))
    for name in ("camera", "tracker"):
        frame = getattr(run, name)
        if frame is not None:
            checks.check_confident(frame, run=run_id, file=fname(name))
    t_enc = run.encoder["t_ns"].to_numpy(dtype=np.int64)
    for name in ("loadcell", "camera", "tracker"):
        frame = getattr(run, name)
        if frame is not None:
            checks.check_overlap(frame, t_enc, stream=name, run=run_id, file=fname(name))


#: Longest header line accepted (a header is a handful of column names).
MAX_HEADER_CHARS = 4096
_DECIMAL_COMMA = re.compile(r"-?\d+")


def read_stream_csv(path: str | os.PathLike[str], name: str, *, run: str,
                    limits: ReadLimits = DEFAULT_LIMITS, counter_bits: int | None = None,
                    base: Path | None = None) -> pd.DataFrame:
    """Read one stream CSV (plain or gzip) with the structural checks of format section 3
    and the value ranges of :func:`rig_io.schema.raw_stream_schema`.

    ``base`` is the run folder a symlinked stream must resolve inside (default: the file's
    folder); ``counter_bits`` bounds the encoder counts.
    """
    path = Path(path)
    file = str(path)
    cols = STREAM_COLUMNS[name]
    gz = path.name.endswith(".gz")
    data = read_bytes(path, base=base if base is not None else path.parent, run=run,
                      limit_mb=limits.max_file_mb, limit_name="max_file_mb",
                      gunzip_limit_mb=limits.max_decompressed_mb if gz else None)
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise RigIOError("not valid UTF-8", run=run, file=file, row=line) from None
    if not data or data.isspace():
        raise RigIOError("empty file", run=run, file=file, row=1)
    nul = data.find(b"\0")
    if nul >= 0:
        raise RigIOError("NUL byte in a text file", run=run, file=file,
                         row=data[:nul].count(b"\n") + 1)
    header_end = data.find(b"\n")
    head = data if header_end < 0 else data[:header_end]
    if len(head) > MAX_HEADER_CHARS:
        raise RigIOError(f"header line is {len(head)} characters long; not a CSV header",
                         run=run, file=file, row=1)
    header = [h.strip() for h in head.decode("utf-8").rstrip("\r").split(",")]
    missing = [c for c in cols if c not in header]
    if missing:
        raise RigIOError(f"missing required column(s) {', '.join(missing)} "
                         f"(header is {short(','.join(header))})", run=run, file=file, row=1,
                         key=missing[0])
    body = data[header_end + 1:] if header_end >= 0 else b""
    if not body or body.isspace():
        raise RigIOError("no data rows after the header", run=run, file=file,
                         row=checks.FIRST_DATA_LINE)
    if not data.endswith(b"\n"):
        last = body[body.rfind(b"\n") + 1:].decode("utf-8", "replace")
        raise RigIOError(f"truncated last line {short(last)} (no line terminator)",
                         run=run, file=file, row=data.count(b"\n") + 1)
    _check_field_counts(body, header, quoted=name == "events" or b'"' in body, run=run,
                        file=file, truncated_if_last=True)
    try:
        frame = pd.read_csv(io.BytesIO(data), sep=",", skip_blank_lines=False,
                            keep_default_na=False, na_values=[""], encoding="utf-8",
                            usecols=list(cols), engine="c", index_col=False)
    except (pd.errors.ParserError, ValueError) as err:
        raise RigIOError(f"malformed CSV: {err}".strip(), run=run, file=file,
                         row=_line_from_parser_error(str(err))) from None
    del data, body
    typed = _typed(frame, name, run=run, file=file)
    validate_stream(typed, name, run=run, file=file, counter_bits=counter_bits,
                    first_row=checks.FIRST_DATA_LINE)
    return typed


def _check_field_counts(body: bytes, header: list[str], *, quoted: bool, run: str, file: str,
                        truncated_if_last: bool) -> None:
    """Every data line has the header's number of fields (a decimal comma, ``1,5``, adds
    one; a logger killed mid-line leaves fewer). Quoted fields are honoured."""
    expected = len(header)
    if quoted:
        lines = body.decode("utf-8").split("\n")[:-1]
        reader = csv.reader(line.rstrip("\r") for line in lines)
        counts = np.array([len(r) if r else 1 for r in reader], dtype=np.int64)
        if counts.size != len(lines):  # a quote spanning lines
            odd = next((k for k, line in enumerate(lines) if line.count('"') % 2), 0)
            raise RigIOError(f"unbalanced quote in {short(lines[odd])}", run=run,
                             file=file, row=odd + checks.FIRST_DATA_LINE)
    else:
        arr = np.frombuffer(body, dtype=np.uint8)
        ends = np.flatnonzero(arr == 10)
        commas = np.flatnonzero(arr == 44)
        starts = np.concatenate([[0], ends[:-1] + 1])
        counts = (np.searchsorted(commas, ends) - np.searchsorted(commas, starts)) + 1
        lines = None
    bad = np.flatnonzero(counts != expected)
    if not bad.size:
        return
    i = int(bad[0])
    row = i + checks.FIRST_DATA_LINE
    if lines is not None:
        line = lines[i].rstrip("\r")
    else:
        lo = 0 if i == 0 else int(ends[i - 1]) + 1
        line = body[lo:int(ends[i])].decode("utf-8", "replace").rstrip("\r")
    n = int(counts[i])
    if n > expected:
        fields = line.split(",")
        # A decimal comma splits a real-valued column (integer columns have no decimals).
        candidates = [j for j in range(min(len(fields) - 1, expected))
                      if _DECIMAL_COMMA.fullmatch(fields[j].strip())
                      and fields[j + 1].strip().isdigit()]
        candidates.sort(key=lambda j: header[j] in _INTEGER)
        for j in candidates[:1]:
                raise RigIOError(
                    f"{n} fields, expected {expected}: {short(fields[j] + ',' + fields[j + 1])}"
                    f" in column {header[j]} looks like a decimal comma (the format uses '.')",
                    run=run, file=file, row=row, key=header[j])
    what = ("truncated last line" if truncated_if_last and i == counts.size - 1
            and n < expected else "line")
    raise RigIOError(f"{what} {short(line)} has {n} fields, expected {expected}",
                     run=run, file=file, row=row)


def _line_from_parser_error(msg: str) -> int | None:
    m = re.search(r"line (\d+)", msg)
    return int(m.group(1)) if m else None


#: Largest magnitude an int64 column holds (t_ns, counts, frame numbers).
_INT64_LIMIT = float(2**63)


def _typed(frame: pd.DataFrame, name: str, *, run: str, file: str) -> pd.DataFrame:
    """Check and convert columns to numbers, naming the first bad cell."""
    out: dict[str, Any] = {}
    required = _REQUIRED_VALUES[name]
    for col in STREAM_COLUMNS[name]:
        cell = _CellError(run=run, file=file, key=col)
        raw = frame[col]
        if name == "events" and col != "t_ns":
            out[col] = _event_column(raw, col, cell)
            continue
        empty = raw.isna().to_numpy()
        num = _numbers(raw, empty, col, cell)
        if col in required or (col == "output_counts" and 0 < empty.sum() < len(empty)):
            holes = np.flatnonzero(empty)
            if holes.size:
                raise cell(f"empty value in column {col}", int(holes[0]))
        out[col] = _integers(raw, num, empty, col, cell) if col in _INTEGER else num
    result = pd.DataFrame(out)
    if name == "encoder":
        result["output_counts"] = result["output_counts"].astype("Int64")
    return result


@dataclass(frozen=True)
class _CellError:
    """Builds the error naming one bad cell of a stream column (its data row from 0)."""

    run: str
    file: str
    key: str

    def __call__(self, message: str, i: int) -> RigIOError:
        return RigIOError(message, run=self.run, file=self.file,
                          row=i + checks.FIRST_DATA_LINE, key=self.key)


def _event_column(raw: pd.Series, col: str, cell: _CellError) -> np.ndarray:
    values = raw.astype(object).where(raw.notna(), "").astype(str)
    if col == "event":
        bad = np.flatnonzero(~values.isin(EVENT_KINDS).to_numpy())
        if bad.size:
            i = int(bad[0])
            raise cell(f"unknown event {short(values.iloc[i])} "
                       f"(expected one of {', '.join(EVENT_KINDS)})", i)
    return np.asarray(values.to_numpy(dtype=object))


def _numbers(raw: pd.Series, empty: np.ndarray, col: str, cell: _CellError) -> np.ndarray:
    """A column as floats (NaN where empty); a word or a non-finite value is refused."""
    if raw.dtype == bool:  # a column of True/False: words, not numbers
        raise cell(f"non-numeric value {short(raw.iloc[0])} in column {col}", 0)
    if raw.dtype == np.uint64:  # only values beyond int64 make pandas choose uint64
        num = raw.to_numpy(dtype=float)
    elif pd.api.types.is_numeric_dtype(raw.dtype):
        num = raw.to_numpy(dtype=float, na_value=np.nan)
    else:  # the C parser found something that is not a number somewhere
        num = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
        bad = np.flatnonzero(~empty & ~np.isfinite(num))
        if bad.size:
            i = int(bad[0])
            raise cell(f"non-numeric value {short(raw.iloc[i])} in column {col}", i)
    bad = np.flatnonzero(~empty & ~np.isfinite(num))
    if bad.size:
        i = int(bad[0])
        raise cell(f"non-finite value {short(raw.iloc[i])} in column {col}", i)
    return np.asarray(num, dtype=float)


def _integers(raw: pd.Series, num: np.ndarray, empty: np.ndarray, col: str,
              cell: _CellError) -> Any:
    """An integer column: exact where pandas read int64, else checked in range and whole."""
    exact_int = raw.dtype == np.int64
    ok = ~empty
    if not exact_int:
        huge = ok & (np.abs(np.where(ok, num, 0.0)) >= _INT64_LIMIT)
        if huge.any():
            i = int(np.flatnonzero(huge)[0])
            raise cell(f"value {short(raw.iloc[i])} in column {col} is beyond "
                       "the 64-bit integer range", i)
    frac = ok & (num != np.round(num))
    if frac.any():
        i = int(np.flatnonzero(frac)[0])
        raise cell(f"non-integer value {short(raw.iloc[i])} in column {col}", i)
    if exact_int:
        return raw.to_numpy()  # exact, even beyond 2**53
    if empty.any():
        ints = pd.array(np.where(ok, num, 0).astype(np.int64), dtype="Int64")
        ints[~ok] = pd.NA
        return ints
    return np.round(num).astype(np.int64)
