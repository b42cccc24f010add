"""Are two pipeline runs' results the same? Tables compared with tolerances on float columns.

    python -m bench.compare_results <root-a> <root-b>

Compares the tables ``make pipeline`` writes under ``data/reports/`` of two project roots
(e.g. the standard campaign run by the commit before a speed change and by the one after):
the metrics, the per-run metrics, the unseen-shape table and summary, the leaderboard and
Gamma's weights. Rows are matched by their key columns, never by position; text and integer
columns must be equal, float columns equal within ``--rtol``/``--atol`` (a faster solver may
change the last bits, not the result). Exits 1 naming every difference.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: table (under data/reports/) -> its key columns
TABLES: dict[str, tuple[str, ...]] = {
    "metrics.parquet": ("family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation",
                        "eval_excitation", "split"),
    "metrics_by_run.parquet": ("family", "rig", "curve_angle_deg", "radius_mm",
                               "fit_excitation", "eval_excitation", "split", "run_id"),
    "unseen_shape.parquet": ("family", "curve_angle_deg", "radius_mm", "predictor"),
    "unseen_shape_summary.csv": ("family",),
    "leaderboard.parquet": ("rig", "curve_angle_deg", "radius_mm", "fit_excitation", "family"),
    "gamma_weights.parquet": ("rig", "curve_angle_deg", "radius_mm", "fit_excitation"),
}
RTOL = 1e-6
ATOL = 1e-9


def _read(path: Path) -> pd.DataFrame:
    return pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)


def compare_frames(a: pd.DataFrame, b: pd.DataFrame, keys: tuple[str, ...], *,
                   rtol: float = RTOL, atol: float = ATOL) -> list[str]:
    """Differences between two tables (empty when equal within the tolerances)."""
    problems: list[str] = []
    if sorted(a.columns) != sorted(b.columns):
        return [f"columns differ: {sorted(set(a.columns) ^ set(b.columns))}"]
    if len(a) != len(b):
        problems.append(f"{len(a)} rows vs {len(b)}")
    keys = tuple(k for k in keys if k in a.columns)
    a = a.sort_values(list(keys), kind="stable").reset_index(drop=True)
    b = b.sort_values(list(keys), kind="stable").reset_index(drop=True)
    if problems:
        return problems
    for col in keys:
        left, right = a[col].astype(str).to_numpy(), b[col].astype(str).to_numpy()
        if not np.array_equal(left, right):
            return [f"key column {col!r} differs (e.g. {left[left != right][:3].tolist()} vs "
                    f"{right[left != right][:3].tolist()})"]
    for col in a.columns:
        if col in keys:
            continue
        x, y = a[col], b[col]
        if pd.api.types.is_float_dtype(x) and pd.api.types.is_float_dtype(y):
            xv, yv = x.to_numpy(dtype=float), y.to_numpy(dtype=float)
            same = np.isclose(xv, yv, rtol=rtol, atol=atol, equal_nan=True)
            if not same.all():
                i = int(np.flatnonzero(~same)[0])
                worst = float(np.nanmax(np.abs(xv - yv)[~same]))
                problems.append(f"{col}: {int((~same).sum())} value(s) beyond rtol={rtol:g} "
                                f"atol={atol:g} (first at {dict(a.loc[i, list(keys)])}: "
                                f"{xv[i]!r} vs {yv[i]!r}; largest difference {worst:.3g})")
        else:
            left, right = x.astype(str).to_numpy(), y.astype(str).to_numpy()
            if not np.array_equal(left, right):
                problems.append(f"{col}: {int((left != right).sum())} value(s) differ")
    return problems


def compare_roots(root_a: Path, root_b: Path, *, rtol: float = RTOL,
                  atol: float = ATOL) -> dict[str, list[str]]:
    """Per table: its differences (``[]`` = equal; a table missing in both is left out)."""
    out: dict[str, list[str]] = {}
    for name, keys in TABLES.items():
        pa, pb = (r / "data" / "reports" / name for r in (root_a, root_b))
        if not pa.exists() and not pb.exists():
            continue
        if not (pa.exists() and pb.exists()):
            out[name] = [f"only in {root_a if pa.exists() else root_b}"]
            continue
        out[name] = compare_frames(_read(pa), _read(pb), keys, rtol=rtol, atol=atol)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root_a", type=Path)
    parser.add_argument("root_b", type=Path)
    parser.add_argument("--rtol", type=float, default=RTOL)
    parser.add_argument("--atol", type=float, default=ATOL)
    args = parser.parse_args(argv)
    result = compare_roots(args.root_a, args.root_b, rtol=args.rtol, atol=args.atol)
    for name, problems in result.items():
        print(f"{name}: {'equal' if not problems else 'DIFFERENT'}")
        for p in problems:
            print(f"  {p}")
    if not result:
        print("no table found under data/reports/ of either root", file=sys.stderr)
        return 1
    return 1 if any(result.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
