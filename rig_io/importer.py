"""Importers for foreign logs, driven by mapping files (``conf/importer/<name>.yaml``).

A mapping says which files are runs (``pattern``), how to read them (``csv``), which column is
time, input, output and tension, with their units and scale, and the rig, configuration and
excitation to record (per-file overrides in ``files``). :func:`import_file` turns one file into
a :class:`~rig_io.calibrate.PhysicalRun` with a ``tsm-rig-log/1`` manifest, so it reaches
ingest exactly like a run folder or a bag. The foreign file is only read.

Mapping keys::

    name: tendon_catheter
    pattern: "data_*_*.txt"          # fnmatch on file names in the source folder
    csv: {delimiter: ",", comment: null}
    run_id: "catheter_{stem}"         # {stem} = file name without suffix
    rig: bending-joint
    configuration: {curve_angle_deg: null, radius_mm: null}
    time:    {column: Time, unit: s, scale: 1.0}
    input:   {column: "Tendon Disp.", unit: mm, scale: 1.0}
    output:  {column: "Angle x", unit: deg, scale: 1.0, source: tracker,
              quantity: tip_angle_deg}
    tension: {column: "Motor Curr.", unit: raw, scale: 1.0, kind: proxy}   # or kind: input_n
    max_gap_periods: 10               # gap rule of format section 3 (periods of median dt)
    excitation: {kind: free}          # default
    files:                            # applied in order to matching names, deep-merged
      - {match: "data_1_*.txt", excitation: {kind: sine_decay_offset}}
"""

from __future__ import annotations

import copy
import fnmatch
import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from rig_io import checks
from rig_io.calibrate import PhysicalRun
from rig_io.errors import RigIOError
from rig_io.limits import DEFAULT_LIMITS, ReadLimits, read_bytes
from rig_io.run import FORMAT

_TIME_TO_NS = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}
_REQUIRED = ("name", "pattern", "rig", "time", "input", "output")
#: Importer version, part of the ingest cache key.
IMPORTER_VERSION = "1"


def load_mapping(path_or_mapping: str | os.PathLike[str] | Mapping[str, Any]) -> dict[str, Any]:
    """A mapping from a YAML file (or an already loaded mapping, e.g. a Hydra config), checked."""
    if isinstance(path_or_mapping, Mapping):
        mapping = _plain(path_or_mapping)
        where = str(mapping.get("name", "<mapping>"))
    else:
        where = str(path_or_mapping)
        try:
            mapping = yaml.safe_load(Path(path_or_mapping).read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError) as err:
            raise RigIOError(f"unreadable importer mapping: {err}", file=where) from None
    if not isinstance(mapping, dict):
        raise RigIOError("importer mapping is not a mapping", file=where)
    missing = [k for k in _REQUIRED if k not in mapping]
    if missing:
        raise RigIOError(f"importer mapping lacks {', '.join(missing)}", file=where)
    for key in ("time", "input", "output", "tension"):
        if key in mapping and mapping[key] is not None and "column" not in mapping[key]:
            raise RigIOError(f"importer mapping '{key}' has no 'column'", file=where)
    unit = mapping["time"].get("unit", "s")
    if unit not in _TIME_TO_NS:
        raise RigIOError(f"unknown time unit {unit!r} (known: {', '.join(_TIME_TO_NS)})",
                         file=where)
    return mapping


def _plain(value: Any) -> Any:
    """Deep copy into plain dicts and lists (OmegaConf containers included)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple) or type(value).__name__ == "ListConfig":
        return [_plain(v) for v in value]
    return copy.deepcopy(value)


def matches(mapping: dict[str, Any], path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a run file of this mapping."""
    return fnmatch.fnmatch(Path(path).name, str(mapping["pattern"]))


def find_files(mapping: dict[str, Any], folder: str | os.PathLike[str]) -> list[Path]:
    """The run files of ``mapping`` directly in ``folder``, sorted."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and matches(mapping, p))


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = _deep_merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k),
                                                                              dict) else v
    return out


def file_settings(mapping: dict[str, Any], path: str | os.PathLike[str]) -> dict[str, Any]:
    """The mapping with the ``files`` overrides that match ``path`` merged in."""
    name = Path(path).name
    merged = {k: v for k, v in mapping.items() if k != "files"}
    for rule in mapping.get("files") or []:
        if fnmatch.fnmatch(name, str(rule.get("match", ""))):
            merged = _deep_merge(merged, {k: v for k, v in rule.items() if k != "match"})
    return merged


def manifest_for(mapping: dict[str, Any], path: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``tsm-rig-log/1`` manifest recorded for one foreign file."""
    s = file_settings(mapping, path)
    stem = Path(Path(path).name.removesuffix(".gz")).stem  # data_1_1.txt.gz -> data_1_1
    out_ch = s["output"]
    channels: dict[str, Any] = {
        "encoder": {"unit": s["input"].get("unit", "mm")},
    }
    source = out_ch.get("source", "encoder")
    if source in ("tracker", "camera"):
        channels[source] = {"quantity": out_ch.get("quantity", "tip_angle_deg"),
                            "source": source}
    return {
        "format": FORMAT,
        "run_id": str(s.get("run_id", "{stem}")).format(stem=stem, name=Path(path).name),
        "rig": s["rig"],
        "started_at": s.get("started_at"),
        "configuration": dict(s.get("configuration") or {"curve_angle_deg": None,
                                                         "radius_mm": None}),
        "excitation": dict(s.get("excitation") or {"kind": "free"}),
        "channels": channels,
        "notes": f"imported from {Path(path).name} with mapping {s['name']!r}",
        "importer": {"mapping": s["name"], "version": IMPORTER_VERSION},
    }


def import_file(mapping: dict[str, Any], path: str | os.PathLike[str], *,
                check: bool = True, limits: ReadLimits = DEFAULT_LIMITS) -> PhysicalRun:
    """Read one foreign log into a :class:`PhysicalRun` (values scaled to the mapping's units).

    Bad cells, missing columns, backward time and long gaps raise :class:`RigIOError`
    naming run, file and row (1-based line, header = line 1). The file is read in one
    bounded read (``limits.max_file_mb``; a ``.gz`` log also ``limits.max_decompressed_mb``),
    never handed to a parser that would decompress or read it without a bound.
    """
    path = Path(path)
    file = str(path)
    s = file_settings(mapping, path)
    manifest = manifest_for(mapping, path)
    run = manifest["run_id"]
    csv_opts = dict(s.get("csv") or {})
    gz = path.suffix.lower() == ".gz"
    data = read_bytes(path, base=None, run=run, limit_mb=limits.max_file_mb,
                      limit_name="max_file_mb",
                      gunzip_limit_mb=limits.max_decompressed_mb if gz else None)
    try:
        df = pd.read_csv(io.BytesIO(data), sep=csv_opts.get("delimiter", ","),
                         comment=csv_opts.get("comment"), skip_blank_lines=False,
                         compression=None)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError,
            pd.errors.EmptyDataError) as err:
        raise RigIOError(f"unreadable file: {err}", run=run, file=file) from None
    if df.empty:
        raise RigIOError("no data rows", run=run, file=file)
    roles = {k: s[k] for k in ("time", "input", "output", "tension") if s.get(k)}
    missing = [f"{r}={c['column']!r}" for r, c in roles.items() if c["column"] not in df]
    if missing:
        raise RigIOError(f"missing column(s) {', '.join(missing)} "
                         f"(columns: {', '.join(map(str, df.columns))})", run=run, file=file,
                         row=1)
    values: dict[str, np.ndarray] = {}
    for role, spec in roles.items():
        col = df[spec["column"]]
        num = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(num))
        if bad.size:
            i = int(bad[0])
            raise RigIOError(f"non-numeric or empty value {col.iloc[i]!r} in column "
                             f"{spec['column']!r}", run=run, file=file,
                             row=i + checks.FIRST_DATA_LINE)
        values[role] = num * float(spec.get("scale", 1.0)) + float(spec.get("offset", 0.0))
    t_ns = np.round(values["time"] * _TIME_TO_NS[s["time"].get("unit", "s")]).astype(np.int64)
    source = s["output"].get("source", "encoder")
    encoder = pd.DataFrame({"t_ns": t_ns, "input": values["input"],
                            "output": values["output"] if source == "encoder"
                            else np.full(t_ns.size, np.nan)})
    phys = PhysicalRun(manifest=manifest, encoder=encoder,
                       files={k: file for k in ("encoder", "loadcell", "camera", "tracker")},
                       applied={"mapping": {role: {"column": spec["column"],
                                                   "scale": float(spec.get("scale", 1.0)),
                                                   "offset": float(spec.get("offset", 0.0))}
                                            for role, spec in roles.items()}})
    if source in ("tracker", "camera"):
        setattr(phys, source, pd.DataFrame({
            "t_ns": t_ns, "frame": np.arange(t_ns.size, dtype=np.int64),
            "value": values["output"], "confidence": np.ones(t_ns.size)}))
    if "tension" in values:
        kind = s["tension"].get("kind", "proxy")
        if kind == "input_n":
            phys.loadcell = pd.DataFrame({"t_ns": t_ns, "tension_in_n": values["tension"],
                                          "tension_out_n": np.full(t_ns.size, np.nan)})
        else:
            phys.extra["tension_proxy"] = values["tension"]
    if check:
        checks.check_physical_run(
            phys, rows=True,
            max_gap_periods=float(s.get("max_gap_periods", checks.MAX_GAP_PERIODS)))
    return phys
