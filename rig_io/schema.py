"""The processed dataset's schema (one row per sample), checked with pandera at the write edge
(ingest) and at the read edge (:func:`rig_io.dataset.read_dataset`).

Documented in ``docs/dataset-schema.md``; bump :data:`SCHEMA_VERSION` when it changes.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pandas as pd
import pandera.pandas as pa
import pyarrow as pa_arrow

from rig_io.errors import RigIOError, short
from rig_io.run import EVENT_KINDS

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


#: The columns each of :data:`SCHEMA`'s whole-frame checks reads, in its order.
_FRAME_CHECK_COLUMNS = (("run_id", "t_s"), ("run_id", "input_norm"), ("run_id", "t_s", "input"))


@cache
def schema_for(columns: tuple[str, ...]) -> pa.DataFrameSchema:
    """:data:`SCHEMA` for a dataset read with only ``columns`` (in :data:`COLUMNS` order): their
    column checks and the whole-frame checks that read nothing else."""
    if columns == COLUMNS:
        return SCHEMA
    checks = [check for check, needs in zip(SCHEMA.checks, _FRAME_CHECK_COLUMNS, strict=True)
              if set(needs) <= set(columns)]
    return pa.DataFrameSchema({c: SCHEMA.columns[c] for c in columns}, checks=checks,
                              strict=True, ordered=True)


def validate(df: pd.DataFrame, *, where: str, run: str | None = None,
             columns: tuple[str, ...] = COLUMNS, inplace: bool = False) -> pd.DataFrame:
    """Validate ``df`` against :data:`SCHEMA` (restricted to ``columns`` when only those were
    read); a failure is a :class:`RigIOError`. ``inplace``: coerce ``df`` itself instead of
    a copy (a frame nobody else holds, just read)."""
    try:
        return schema_for(tuple(columns)).validate(df, lazy=True, inplace=inplace)
    except (pa.errors.SchemaErrors, pa.errors.SchemaError) as err:
        summary = str(err).strip().splitlines()
        text = "; ".join(line.strip() for line in summary[:12] if line.strip())
        raise RigIOError(f"dataset schema check failed at the {where} edge: {text}",
                         run=run) from None


# ------------------------------------------------------------------------ raw stream schemas

#: Physical bounds of raw stream values (rig-log-format.md section 1). A bridge load cell
#: gives a few mV/V; 1000 mV/V is far beyond any bridge and marks a corrupt cell.
MAX_ABS_MV_PER_V = 1e3
#: Camera and tracker values (mm or deg): far beyond any rig's stroke or tip angle.
MAX_ABS_VISION_VALUE = 1e5


def counter_range(bits: int) -> tuple[int, int]:
    """Values a ``bits``-bit up/down counter can report: signed ``[-2^(b-1), 2^(b-1))`` or,
    from a logger that writes the register unsigned, ``[0, 2^b)``."""
    return -(1 << (bits - 1)), (1 << bits) - 1


@cache
def raw_stream_schema(name: str, *, counter_bits: int | None = None) -> pa.DataFrameSchema:
    """The declared schema of one typed raw stream (after the reader's parsing).

    Encoder counts must fit the manifest's ``counter_bits`` counter (a count of 1e30 or 2^63
    is corruption, not a wrap-around); load-cell readings, camera values and confidences
    must lie in their physical ranges.
    """
    t = pa.Column("int64", nullable=False, title="t_ns")
    if name == "encoder":
        lo, hi = counter_range(counter_bits if counter_bits is not None else 63)
        rng = pa.Check.in_range(lo, hi, error=f"outside the {counter_bits}-bit counter's "
                                f"range [{lo}, {hi}]")
        cols = {"t_ns": t, "input_counts": pa.Column("int64", rng, nullable=False),
                "output_counts": pa.Column("Int64", rng, nullable=True)}
    elif name == "loadcell":
        mv = pa.Check.in_range(-MAX_ABS_MV_PER_V, MAX_ABS_MV_PER_V,
                               error=f"beyond +-{MAX_ABS_MV_PER_V:g} mV/V (no bridge gives it)")
        cols = {"t_ns": t, "input_mv_per_v": pa.Column(float, mv, nullable=False),
                "output_mv_per_v": pa.Column(float, mv, nullable=False)}
    elif name in ("camera", "tracker"):
        cols = {"t_ns": t,
                "frame": pa.Column("int64", pa.Check.ge(0, error="a negative frame number"),
                                   nullable=False),
                "value": pa.Column(float, pa.Check.in_range(
                    -MAX_ABS_VISION_VALUE, MAX_ABS_VISION_VALUE,
                    error=f"beyond +-{MAX_ABS_VISION_VALUE:g}"), nullable=True),
                "confidence": pa.Column(float, pa.Check.in_range(
                    0.0, 1.0, error="confidence outside [0, 1]"), nullable=False)}
    elif name == "events":
        cols = {"t_ns": t,
                "event": pa.Column(None, pa.Check.isin(list(EVENT_KINDS),
                                                       error="unknown event"), nullable=False),
                "detail": pa.Column(None, nullable=True)}
    else:
        raise RigIOError(f"unknown stream {name!r}")
    return pa.DataFrameSchema(cols, strict=False)


def validate_stream(frame: pd.DataFrame, name: str, *, run: str, file: str,
                    counter_bits: int | None = None, first_row: int | None = 2) -> None:
    """Check a typed raw stream against :func:`raw_stream_schema`; the first bad cell is a
    :class:`RigIOError` naming the column, the row (file line, header = 1) and the value."""
    schema = raw_stream_schema(name, counter_bits=counter_bits)
    try:
        schema.validate(frame, lazy=False)
    except pa.errors.SchemaError as err:
        col = getattr(err, "column_name", None)
        cases = err.failure_cases
        row: int | None = None
        value: object = None
        if isinstance(cases, pd.DataFrame) and len(cases):
            index = cases["index"].iloc[0] if "index" in cases else None
            value = cases["failure_case"].iloc[0] if "failure_case" in cases else None
            value = value.item() if isinstance(value, np.generic) else value
            if index is not None and first_row is not None and not pd.isna(index):
                row = int(index) + first_row
        check = err.check
        what = (check.error if isinstance(check, pa.Check) and check.error
                else str(check) if check is not None else "invalid")
        if what == "not_nullable":
            what = "empty or missing value where one is required"
        raise RigIOError(f"{col} = {short(value)}: {what}", run=run, file=file, key=str(col),
                         row=row) from None
