"""The processed dataset's schema (one row per sample), checked with pandera at the write edge
(ingest) and at the read edge (:func:`rig_io.dataset.read_dataset`).

Documented in ``docs/dataset-schema.md``; bump :data:`SCHEMA_VERSION` when it changes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pandera.pandas as pa
import pyarrow as pa_arrow

from rig_io.errors import RigIOError

SCHEMA_VERSION = "1"

#: Column order of the dataset.
COLUMNS = ("run_id", "rig", "curve_angle_deg", "radius_mm", "excitation", "t_s", "input",
           "output", "input_norm", "output_norm", "tension_in_n", "tension_out_n", "camera",
           "tracker", "tension_proxy")
STRING_COLUMNS = ("run_id", "rig", "excitation")
NULLABLE = ("curve_angle_deg", "radius_mm", "tension_in_n", "tension_out_n", "camera",
            "tracker", "tension_proxy")

#: Arrow schema of every parquet file (identical for all runs, so a folder reads as one table).
ARROW_SCHEMA = pa_arrow.schema(
    [(c, pa_arrow.string()) if c in STRING_COLUMNS else (c, pa_arrow.float64())
     for c in COLUMNS])


def _finite(s: pd.Series) -> bool:
    return bool(np.isfinite(s.to_numpy(dtype=float)).all())


def _time_increases(df: pd.DataFrame) -> bool:
    t = df["t_s"].to_numpy(dtype=float)
    runs = df["run_id"].to_numpy()
    same = runs[1:] == runs[:-1]
    return bool(np.all(np.diff(t)[same] > 0))


def _norm_peak_is_one(df: pd.DataFrame) -> bool:
    peak = df["input_norm"].abs().groupby(df["run_id"], sort=False).max()
    return bool(np.allclose(peak.to_numpy(dtype=float), 1.0, atol=1e-9))


def _starts_at_zero(df: pd.DataFrame) -> bool:
    first = df.groupby("run_id", sort=False)[["t_s", "input"]].first()
    return bool(np.allclose(first.to_numpy(dtype=float), 0.0, atol=1e-9))


def _float(nullable: bool, *checks: pa.Check) -> pa.Column:
    return pa.Column(float, nullable=nullable, checks=list(checks), coerce=True)


SCHEMA = pa.DataFrameSchema(
    {
        "run_id": pa.Column(str, pa.Check.str_length(min_value=1)),
        "rig": pa.Column(str, pa.Check.str_length(min_value=1)),
        "curve_angle_deg": _float(True, pa.Check.in_range(0.0, 360.0)),
        "radius_mm": _float(True, pa.Check.gt(0.0)),
        "excitation": pa.Column(str, pa.Check.str_length(min_value=1)),
        "t_s": _float(False, pa.Check(_finite, element_wise=False), pa.Check.ge(0.0)),
        "input": _float(False, pa.Check(_finite, element_wise=False)),
        "output": _float(False, pa.Check(_finite, element_wise=False)),
        "input_norm": _float(False, pa.Check.in_range(-1.0 - 1e-9, 1.0 + 1e-9)),
        "output_norm": _float(False, pa.Check(_finite, element_wise=False)),
        "tension_in_n": _float(True),
        "tension_out_n": _float(True),
        "camera": _float(True),
        "tracker": _float(True),
        "tension_proxy": _float(True),
    },
    checks=[
        pa.Check(_time_increases, error="t_s must increase within each run"),
        pa.Check(_norm_peak_is_one, error="max |input_norm| of each run must be 1"),
        pa.Check(_starts_at_zero, error="each run must start at t_s = 0 with input = 0"),
    ],
    strict=True,
    ordered=True,
)


def validate(df: pd.DataFrame, *, where: str, run: str | None = None) -> pd.DataFrame:
    """Validate ``df`` against :data:`SCHEMA`; a failure is a :class:`RigIOError`."""
    try:
        return SCHEMA.validate(df, lazy=True)
    except (pa.errors.SchemaErrors, pa.errors.SchemaError) as err:
        summary = str(err).strip().splitlines()
        text = "; ".join(line.strip() for line in summary[:12] if line.strip())
        raise RigIOError(f"dataset schema check failed at the {where} edge: {text}",
                         run=run) from None
