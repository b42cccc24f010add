"""The experiments' statistics rows, Table 4.2's layouts and the headline numbers."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.compensation import LoopResult, reduction

TABLE42_STATS = (("std_error", "S_{n-1}"), ("mean_error", "mean e"), ("error_range", "e max-min"),
                 ("rmse", "RMSE"), ("rsse", "sqrt(SSE)"))
#: The schemes whose seed 001 reductions are headline numbers, after the paper's own.
SEED001_HEADLINE = ("ours", "shape_aware_ff", "shape_aware")


def command_travel(res: LoopResult) -> float:
    """Total travel of the command (sum |du|): a chatter check - a compensator that dithers
    its command across the backlash travels far more than the feed-forward input."""
    return float(np.sum(np.abs(np.diff(res.command))))


def stats_row(res: LoopResult, *, skip_s: float = 0.0, **keys: Any) -> dict[str, Any]:
    s = res.statistics(skip_s=skip_s)
    s["rsse"] = math.sqrt(s["sse"])  # Table 4.2's "RMSE" column is sqrt(SSE) (see docs)
    s["command_travel"] = command_travel(res)
    return {**keys, "scheme": res.scheme, **s}


def table42_wide(t42: pd.DataFrame, shapes: Iterable[str], schemes: Iterable[str]) -> pd.DataFrame:
    """Table 4.2's layout: rows (profile, statistic), columns (shape, scheme)."""
    shapes, schemes = list(shapes), list(schemes)
    sub = t42[t42["shape"].isin(shapes) & t42["scheme"].isin(schemes)]
    out = []
    for prof in sub["profile"].unique():
        at = sub[sub["profile"] == prof]
        for key, label in TABLE42_STATS:
            row: dict[str, Any] = {"type": prof, "statistic": label}
            for shape in shapes:
                for scheme in schemes:
                    hit = at[(at["shape"] == shape) & (at["scheme"] == scheme)]
                    row[f"{shape} {scheme}"] = float(hit[key].iloc[0]) if len(hit) else math.nan
            out.append(row)
    return pd.DataFrame(out)


def shape_aware_table(t42: pd.DataFrame, shapes: Iterable[str]) -> pd.DataFrame:
    """Per shape and profile: RMSE without compensation, with the own-shape schemes and with
    the shape-aware ones, and the shape-aware reductions (percent)."""
    sub = t42[t42["shape"].isin(list(shapes))]
    piv = sub.pivot_table(index=["shape", "profile"], columns="scheme", values="rmse")
    cols = [c for c in ("none", "gamma", "ours", "shape_aware_ff", "shape_aware") if c in piv]
    out = piv[cols].reset_index()
    for c in ("shape_aware_ff", "shape_aware"):
        if c in piv:
            out[f"{c}_reduction_pct"] = [reduction(a, b) for a, b in
                                         zip(out["none"], out[c], strict=True)]
    return out


def present(tables: Mapping[str, pd.DataFrame], name: str) -> pd.DataFrame | None:
    """Table ``name`` when an experiment made it with at least one row."""
    frame = tables.get(name)
    return frame if frame is not None and len(frame) else None


def _seed001_headline(t42: pd.DataFrame, paper_family: str) -> dict[str, float]:
    m: dict[str, float] = {}
    for (shape, prof), g in t42.groupby(["shape", "profile"]):
        base = g[g["scheme"] == "none"]
        for scheme in (paper_family, *SEED001_HEADLINE):
            hit = g[g["scheme"] == scheme]
            if len(base) and len(hit):
                m[f"seed001.{shape}.{prof}.{scheme}.std_reduction_pct"] = reduction(
                    float(base["std_error"].iloc[0]), float(hit["std_error"].iloc[0]))
                m[f"seed001.{shape}.{prof}.{scheme}.rmse_reduction_pct"] = reduction(
                    float(base["rmse"].iloc[0]), float(hit["rmse"].iloc[0]))
    return m


def _seed002_headline(t1: pd.DataFrame) -> dict[str, float]:
    m: dict[str, float] = {}
    mean = t1.groupby("scheme")["rmse"].mean()
    for scheme in mean.index:
        m[f"seed002.{scheme}.mean_rmse"] = float(mean[scheme])
        if scheme != "none":
            m[f"seed002.{scheme}.rmse_reduction_pct"] = reduction(float(mean["none"]),
                                                                  float(mean[scheme]))
    return m


def _seed000_headline(t5: pd.DataFrame | None, t3: pd.DataFrame | None) -> dict[str, float]:
    m: dict[str, float] = {}
    if t5 is not None:
        by = t5.set_index("scheme")
        for scheme in by.index:
            m[f"seed000.{scheme}.abs_err"] = float(by.loc[scheme, "abs_err"])
            if scheme != "pd":
                m[f"seed000.{scheme}.abs_err_reduction_vs_pd_pct"] = reduction(
                    float(by.loc["pd", "abs_err"]), float(by.loc[scheme, "abs_err"]))
    if t3 is not None:
        for row in t3.itertuples():
            seg = str(row.segment).strip("[]").replace(",", "-")
            m[f"seed000.ukf.seg{seg}.abs_err_reduction_pct"] = 100 * (1 - row.abs_err_ratio)
    return m


def headline(tables: Mapping[str, pd.DataFrame], paper_family: str) -> dict[str, float]:
    """Reductions (percent), the unit the targets are stated in; ``paper_family`` is seed
    001's "with compensation" scheme."""
    m: dict[str, float] = {}
    t42 = present(tables, "seed001_table42")
    if t42 is not None:
        m.update(_seed001_headline(t42, paper_family))
    t1 = present(tables, "seed002_table1")
    if t1 is not None:
        m.update(_seed002_headline(t1))
    m.update(_seed000_headline(present(tables, "seed000_tracking"),
                               present(tables, "seed000_estimation")))
    # MLflow metric names: alphanumerics, _ - . space : / only.
    return {re.sub(r"[^\w\-. :/]", "_", k): v for k, v in m.items()}
