"""The report section's markdown (``compensation.md``): each experiment's tables and the
headline numbers. Text only; the stage's edge writes it."""

from __future__ import annotations

from collections.abc import Mapping

import pandas as pd

from pipelines.compensation.settings import CompensateConfig, Seed001Settings
from pipelines.compensation.tables import present, shape_aware_table, table42_wide

#: Table I's rows, in the paper's order.
TABLE1_SCHEMES = ("none", "vision_feedback", "bouc_wen_ff", "ours")


def md(frame: pd.DataFrame, floatfmt: str = "{:.3f}") -> str:
    cols = [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in frame.itertuples(index=False):
        cells = [floatfmt.format(v) if isinstance(v, float) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _table42_parts(t42: pd.DataFrame, s1: Seed001Settings) -> list[str]:
    shapes = list(s1.shapes)
    parts = ["## Seed 001 section 4.7: Table 4.2 (shapes "
             + ", ".join(f"{k} = {v[0]} deg / {v[1]} mm" for k, v in s1.shapes.items())
             + ")", "",
             "Error e = measured - desired (mm). `none`: the desired output played as input; "
             f"`{s1.paper_family}`: the thesis' scheme (its inverse, open loop); `ours`: "
             "exact Gamma inverse + online model-error estimate. `RMSE` is the true root "
             "*mean* square; `sqrt(SSE)` is what the thesis' column labelled RMSE holds "
             "(it equals sqrt(N) x RMS for its 30/80/20 s records).", "",
             md(table42_wide(t42, shapes, ["none", s1.paper_family, "ours"])), ""]
    if "shape_aware" in set(t42["scheme"]):
        parts += ["### Shapes A and B compensated by a model that never saw them", "",
                  f"`shape_aware`: the {s1.shape_aware.family} family's parameters regressed "
                  "on wrap angle and curvature over the other configurations' fits "
                  "(`hysteresis.shape_aware`, `docs/unseen-shape.md`), asked for shapes A "
                  "and B; `shape_aware_ff` plays its inverse open loop, `shape_aware` adds "
                  "the online model-error estimate of `ours`. RMSE (mm) and reduction:", "",
                  md(shape_aware_table(t42, shapes)), ""]
    allfam = t42[t42["shape"].isin(shapes)].pivot_table(
        index=["shape", "profile"], columns="scheme", values="rmse").reset_index()
    parts += ["RMSE (mm) of every family's inverse, shapes A and B:", "", md(allfam), ""]
    quick = t42[~t42["shape"].isin(shapes)]
    if len(quick):
        piv = quick.pivot_table(index=["curve_angle_deg", "radius_mm", "profile"],
                                columns="scheme", values="rmse").reset_index()
        parts += [f"All other configurations ({s1.all_configurations} pass), RMSE (mm):",
                  "", md(piv), ""]
    return parts


def _table44_parts(t44: pd.DataFrame) -> list[str]:
    return ["## Seed 001 Table 4.4: per-step inversion time (ms)", "",
            "The thesis' LSQ_Opt solvers on the same fitted Gamma_11 (P = 0..2 mm): "
            "FMINSEARCH = Nelder-Mead, FMINCON = SLSQP / SciPy's interior-point "
            "`trust-constr`, FMINBND = bounded Brent search; `exact` = ours. Slow solvers "
            "are timed on a prefix of each profile (`steps`).", "",
            md(t44[["shape", "profile", "method", "steps", "mean_ms", "ratio_to_ours",
                    "max_abs_residual"]], "{:.4g}"), ""]


def _table1_parts(t1: pd.DataFrame, trials: int) -> list[str]:
    g = t1.groupby(["scheme", "case", "signal"])["rmse"].agg(["mean", "std"]).reset_index()
    g["rmse"] = [f"{a:.2f} ± {b:.2f}" for a, b in zip(g["mean"], g["std"].fillna(0.0),
                                                      strict=True)]
    wide = g.pivot_table(index="scheme", columns=["case", "signal"], values="rmse",
                         aggfunc="first")
    # The paper's order: cases as configured, periodic motions by frequency, then N-P.
    cases = list(dict.fromkeys(t1["case"]))
    sigs = list(dict.fromkeys(t1["signal"]))
    wide = wide.reindex(columns=[(c, x) for c in cases for x in sigs if (c, x) in wide])
    wide.columns = [f"{c} {x}" for c, x in wide.columns]
    order = [x for x in TABLE1_SCHEMES if x in wide.index]
    wide = wide.reindex(order)
    avg = t1.groupby(["scheme", "case"])["rmse"].mean().unstack().reindex(order)
    avg = avg.reindex(columns=cases)
    avg.columns = [f"{c} avg" for c in avg.columns]
    return ["## Seed 002 Table I: RMSE (deg) against the tracker", "",
            f"{trials} trials per cell (mean ± sd), omega in rad/s; "
            "calibration 30 sin(wt)+30 deg at 0.1592 Hz on the 30 Hz delayed camera.", "",
            md(wide.reset_index()), "", md(avg.reset_index()), ""]


def _seed000_parts(t3: pd.DataFrame, reference: pd.DataFrame, t5: pd.DataFrame) -> list[str]:
    ref = reference.iloc[0]
    return ["## Seed 000 Tables 2-4: reference model and UKF active estimation", "",
            f"GA-identified Coleman-Hodgdon reference: A = {ref.A:.3f}, B = {ref.B:.3f}, "
            f"C = {ref.C:.3f}, O_alpha = {ref.O_alpha:.2f} (paper: 0.95, -0.92, 18.53).",
            "", md(t3, "{:.4f}"), "",
            "## Seed 000 Table 5: PD vs AME-PD (and ours) tracking eq. 32", "",
            md(t5, "{:.4f}"), ""]


def _headline_parts(metrics: Mapping[str, float], s1: Seed001Settings) -> list[str]:
    prefixes = tuple(f"seed001.{k}." for k in s1.shapes)
    shown = {k: v for k, v in metrics.items()
             if not k.startswith("seed001.") or k.startswith(prefixes)}
    return ["## Headline numbers", "",
            "Reductions in %, errors in the output's unit; the other configurations' "
            "reductions are in MLflow.", "",
            md(pd.DataFrame(sorted(shown.items()), columns=["metric", "value"]), "{:.2f}"),
            ""]


def report_text(tables: Mapping[str, pd.DataFrame], settings: CompensateConfig,
                metrics: Mapping[str, float], elapsed_s: float) -> str:
    """The report section: every table present, then the headline numbers (the other
    configurations' seed 001 numbers are left to MLflow)."""
    parts = ["# Compensation experiments (virtual rig)", "",
             f"Generated by `python -m pipelines.compensate` in {elapsed_s:.0f} s. Tables are "
             "also under `data/reports/compensation/*.parquet` and in MLflow; method in "
             "`docs/compensation.md`.", ""]
    t42 = present(tables, "seed001_table42")
    if t42 is not None:
        parts += _table42_parts(t42, settings.seed001)
    t44 = present(tables, "seed001_table44")
    if t44 is not None:
        parts += _table44_parts(t44)
    t1 = present(tables, "seed002_table1")
    if t1 is not None:
        parts += _table1_parts(t1, settings.seed002.trials)
    t3 = present(tables, "seed000_estimation")
    if t3 is not None:
        parts += _seed000_parts(t3, tables["seed000_reference"], tables["seed000_tracking"])
    parts += _headline_parts(metrics, settings.seed001)
    return "\n".join(parts)
