"""The artifact catalog: every file format the stages hand each other, in one place.

A stage reads what another wrote through here, never by importing that stage: fitted
model files (``tsm-fitted-model/1`` JSON, one per family, configuration and identification
excitation, with the SHA-256 of the model they hold), prediction files (parquet, the
validation cache record in their metadata, a ``.sha256`` sidecar), the metrics tables
validate writes and the report reads (``metrics``, ``metrics_by_run``: parquet + csv) and the
unseen-shape summary the report quotes. Every write is atomic
(temporary name, then rename); every read checks the recorded hash and treats a mismatch as
absent, so a damaged file is rewritten rather than trusted.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipelines import cache, stages
from pipelines.stages import Configuration
from rig_io.atomic import atomic_path, contained, write_text_atomic

log = logging.getLogger(__name__)

MODEL_FILE_FORMAT = "tsm-fitted-model/1"
#: Parquet metadata key of a predictions file's cache record.
META_KEY = b"tsm_validate"


# -- fitted models ---------------------------------------------------------------------------

def model_path(models_dir: Path, row: Mapping[str, Any]) -> Path:
    config = stages.Configuration(str(row["rig"]), stages._num(row["curve_angle_deg"]),
                                  stages._num(row["radius_mm"]))
    return contained(models_dir, str(row["family"]),
                     f"{config.label}__{row['fit_excitation']}.json")


def save_models(fits: pd.DataFrame, models_dir: Path) -> list[Path]:
    """Write every freshly fitted row (``cached`` False) as one JSON file, atomically."""
    written = []
    for row in fits[~fits["cached"]].to_dict("records"):
        record = {
            "format": MODEL_FILE_FORMAT,
            **{k: _plain(v) for k, v in row.items() if k not in ("model_json", "cached")},
            "model": json.loads(row["model_json"]) if isinstance(row.get("model_json"), str)
            else None,
        }
        record["model_sha256"] = cache.hash_json(record["model"])
        path = model_path(models_dir, row)
        write_text_atomic(path, json.dumps(record, indent=1, allow_nan=True))
        written.append(path)
    return written


def load_models(models_dir: Path) -> pd.DataFrame:
    """Every model file under ``models_dir`` as a fits table (``cached`` True)."""
    rows = []
    for path in sorted(models_dir.glob("*/*.json")) if models_dir.is_dir() else []:
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            log.warning("ignoring unreadable model file %s: %s", path, exc)
            continue
        if record.get("format") != MODEL_FILE_FORMAT:
            continue
        model = record.pop("model", None)
        stored = record.get("model_sha256")
        if stored is None:  # an older file, or an edit that dropped the hash: refit
            log.warning("ignoring model file %s: it records no model_sha256, so its model "
                        "cannot be checked (fit writes it again)", path)
            continue
        if stored != cache.hash_json(model):  # damaged or edited: refit
            log.warning("ignoring model file %s: content does not match its hash", path)
            continue
        row = {c: record.get(c) for c in stages.FIT_COLUMNS}
        row["model_json"] = json.dumps(model) if model is not None else None
        row["cached"] = True
        rows.append(row)
    return stages.fits_frame(rows)


def _plain(value: Any) -> Any:
    if isinstance(value, float) and value != value:
        return None
    if hasattr(value, "item"):
        return value.item()
    return value


# -- predictions -----------------------------------------------------------------------------

def prediction_path(predictions_dir: Path, config: Configuration) -> Path:
    return contained(predictions_dir, f"{config.label}.parquet")


def read_prediction_meta(path: Path) -> dict[str, Any] | None:
    """The cache record stored in a predictions file's parquet metadata; None when absent
    or when the file's bytes no longer have the SHA-256 recorded beside it (damaged pages
    under an intact footer would otherwise pass for up to date)."""
    if not path.exists():
        return None
    if not cache.digest_matches(path):
        log.warning("predictions file %s does not match its recorded SHA-256 (damaged, edited "
                    "or written before hashes were recorded): not reused; validate rewrites it",
                    path)
        return None
    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, pa.ArrowException):
        return None
    raw = meta.get(META_KEY)
    return json.loads(raw) if raw else None


def write_predictions(path: Path, preds: pd.DataFrame, record: Mapping[str, Any]) -> None:
    """Predictions as parquet with the cache record (key, metrics, errors) in its metadata."""
    table = pa.Table.from_pandas(preds, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[META_KEY] = json.dumps(record, allow_nan=True).encode()
    table = table.replace_schema_metadata(meta)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")
        digest = cache.sha256_file(tmp)
    cache.write_digest(path, digest)


def read_predictions(path: Path) -> pd.DataFrame | None:
    """A predictions file's rows, None when there is none."""
    return pd.read_parquet(path) if path.exists() else None


# -- metrics tables --------------------------------------------------------------------------

#: The per-configuration metrics (columns ``stages.METRICS_COLUMNS``) and the per-run ones.
METRICS = "metrics"
METRICS_BY_RUN = "metrics_by_run"


def write_table_pair(table: pd.DataFrame, stem: Path) -> None:
    """``<stem>.parquet`` and ``<stem>.csv``, atomically, only when the content changed."""
    parquet, csv = stem.with_suffix(".parquet"), stem.with_suffix(".csv")
    new_hash = cache.hash_frame(table)
    if parquet.exists() and csv.exists():
        try:
            if cache.hash_frame(pd.read_parquet(parquet)) == new_hash:
                return
        except (OSError, pa.ArrowException):
            pass
    with atomic_path(parquet) as tmp:
        table.to_parquet(tmp, index=False)
    with atomic_path(csv) as tmp:
        table.to_csv(tmp, index=False)


def read_metrics(reports: Path, name: str = METRICS) -> pd.DataFrame | None:
    """A metrics table validate wrote under ``reports``; None when there is none."""
    path = reports / f"{name}.parquet"
    return pd.read_parquet(path) if path.exists() else None


# -- the unseen-shape summary ------------------------------------------------------------------

UNSEEN_SHAPE_SUMMARY = "unseen_shape_summary.csv"


def read_unseen_shape_summary(reports: Path) -> pd.DataFrame:
    """unseen_shape's per-family summary; empty when the stage did not run (or was skipped)."""
    path = reports / UNSEEN_SHAPE_SUMMARY
    return pd.read_csv(path) if path.exists() else pd.DataFrame()
