"""The report's figures (matplotlib, Agg backend): one function per figure, file out.

* :func:`configuration_figure` - per evaluation excitation: measured vs the best family,
  every family's residual, and the best family's input-output loop (seed 001 Fig. 4.10-4.21);
* :func:`elementary_figure` - the weighted elementary operators q_i gamma_i of Gamma
  (seed 001 Fig. 4.12);
* :func:`shape_heatmaps` - an error metric over curve angle x radius, one panel per family;
* :func:`error_vs_shape_lines` - the same metric against curve angle, one line per radius.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from rig_io.atomic import atomic_path  # noqa: E402

FAMILY_COLORS = {
    "linear": "#7f7f7f", "gamma": "#1f77b4", "preisach": "#2ca02c", "bouc_wen": "#d62728",
    "coleman_hodgdon": "#9467bd",
}
EXCITATION_ORDER = ("sine_decay", "triangle_decay", "trapezoid_decay")


def _color(family: str, i: int) -> Any:
    return FAMILY_COLORS.get(family, f"C{(i + 4) % 10}")


def _save(fig: Any, path: Path, dpi: int) -> Path:
    with atomic_path(path, suffix=".png", folder=False) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return path


def _thin(n: int, max_points: int) -> slice:
    return slice(None, None, max(1, int(np.ceil(n / max_points))))


def _rmse(f: pd.DataFrame) -> float:
    e = f["predicted"].to_numpy(dtype=float) - f["output"].to_numpy(dtype=float)
    return float(np.sqrt(np.nanmean(e * e))) if e.size else float("nan")


def best_family(preds: pd.DataFrame, fit_excitation: str) -> str | None:
    """The family with the lowest RMSE over the held-out excitations of ``preds`` (over the
    identification record when nothing is held out)."""
    held = preds[np.asarray(preds["eval_excitation"] != fit_excitation, dtype=bool)]
    use = held if len(held) else preds
    if use.empty:
        return None
    scores = {str(f): _rmse(g) for f, g in use.groupby("family", observed=True)}
    scores = {f: v for f, v in scores.items() if v == v}
    return min(scores, key=lambda f: (scores[f], f)) if scores else None


def configuration_figure(preds: pd.DataFrame, path: Path, *, title: str,
                         fit_excitation: str, dpi: int = 72, max_points: int = 1500,
                         units: tuple[str, str] = ("mm", "mm")) -> Path:
    """One row per evaluation excitation: the measured output with the best family's
    prediction (left), every family's residual (middle, legend with its RMSE) and the loop
    of the measured output and the best family (right). Drawing all five families over each
    other hid them; the residuals tell them apart at the scale of their errors.
    ``units``: the input's and the output's unit (axis labels)."""
    u_unit, y_unit = units
    # Group once (no per-filter string conversion of 100k categorical rows).
    preds = preds[np.asarray(preds["fit_excitation"] == fit_excitation, dtype=bool)]
    groups = {(str(k), str(f), str(r)): g for (k, f, r), g in preds.groupby(
        ["eval_excitation", "family", "run_id"], observed=True, sort=True)}
    kinds = sorted({k for k, _, _ in groups},
                   key=lambda k: (k != fit_excitation, EXCITATION_ORDER.index(k)
                                  if k in EXCITATION_ORDER else 99, k))
    families = sorted({f for _, f, _ in groups})
    best = best_family(preds, fit_excitation) or (families[0] if families else "")
    # the worst first, so the better families' residuals are drawn on top
    order = sorted(families, key=lambda f: -_rmse(preds[preds["family"] == f]))
    rows = max(len(kinds), 1)
    fig, axes = plt.subplots(rows, 3, figsize=(13, 2.5 * rows), squeeze=False,
                             gridspec_kw={"width_ratios": [2.0, 2.0, 1.0]})
    for row, kind in enumerate(kinds):
        first_run = min(r for k, _, r in groups if k == kind)
        ax_t, ax_r, ax_l = axes[row]
        base = groups.get((kind, best, first_run))
        if base is None:
            base = next(g for (k, _, r), g in groups.items() if k == kind and r == first_run)
        s = _thin(len(base), max_points)
        t = base["t_s"].to_numpy()[s]
        ax_t.plot(t, base["output"].to_numpy()[s], color="k", lw=1.3, label="measured")
        ax_l.plot(base["input"].to_numpy()[s], base["output"].to_numpy()[s], color="k", lw=1.1,
                  label="measured")
        if (kind, best, first_run) in groups:
            ax_t.plot(t, base["predicted"].to_numpy()[s], color=_color(best, 0), lw=0.9,
                      label=f"{best} (best)")
            ax_l.plot(base["input"].to_numpy()[s], base["predicted"].to_numpy()[s], lw=0.9,
                      color=_color(best, 0), label=best)
        for i, fam in enumerate(order):
            f = groups.get((kind, fam, first_run))
            if f is None:
                continue
            s2 = _thin(len(f), max_points)
            resid = (f["predicted"].to_numpy() - f["output"].to_numpy())[s2]
            ax_r.plot(f["t_s"].to_numpy()[s2], resid, color=_color(fam, i),
                      lw=1.1 if fam == best else 0.6, alpha=1.0 if fam == best else 0.75,
                      label=f"{fam} {_rmse(f):.2g}")
        ax_r.axhline(0.0, color="k", lw=0.5)
        split = "identification" if kind == fit_excitation else "held-out"
        ax_t.set_title(f"{kind} ({split})", fontsize=9, loc="left")
        ax_r.set_title(f"residual, RMSE [{y_unit}] in the legend", fontsize=8, loc="left")
        ax_t.set_ylabel(f"output [{y_unit}]")
        ax_r.set_ylabel(f"residual [{y_unit}]")
        ax_l.set_xlabel(f"input [{u_unit}]", fontsize=8)
        ax_l.set_ylabel(f"output [{y_unit}]")
        ax_r.legend(fontsize=6, loc="upper right", ncol=1, framealpha=0.7)
        for ax in (ax_t, ax_r, ax_l):
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
    axes[-1][0].set_xlabel("t [s]")
    axes[-1][1].set_xlabel("t [s]")
    axes[0][0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"{title}: best family {best}", fontsize=11)
    # fixed margins: tight_layout costs an extra text-layout pass per figure (x 24 figures)
    fig.subplots_adjust(left=0.06, right=0.99, top=0.92, bottom=0.07, hspace=0.45,
                        wspace=0.22)
    return _save(fig, path, dpi)


def elementary_figure(t: np.ndarray, u: np.ndarray, y: np.ndarray, operators: np.ndarray,
                      weights: np.ndarray, thresholds: np.ndarray, path: Path, *,
                      title: str, dpi: int = 72, max_points: int = 3000,
                      units: tuple[str, str] = ("mm", "mm")) -> Path:
    """Weighted elementary operators q_i gamma_i (seed 001 Fig. 4.12) and their sum."""
    u_unit, y_unit = units
    s = _thin(t.size, max_points)
    weighted = operators * weights[None, :]
    fig, (ax_t, ax_l) = plt.subplots(1, 2, figsize=(11, 3.6), gridspec_kw={"width_ratios":
                                                                           [2.2, 1]})
    cmap = plt.get_cmap("viridis")
    for i in range(weights.size):
        c = cmap(i / max(weights.size - 1, 1))
        label = f"q{i + 1}={weights[i]:+.3f}, p={thresholds[i]:g}"
        ax_t.plot(t[s], weighted[s, i], lw=0.8, color=c, label=label)
        ax_l.plot(u[s], weighted[s, i], lw=0.8, color=c)
    ax_t.plot(t[s], weighted.sum(axis=1)[s], color="r", lw=1.2, label="sum (Gamma)")
    ax_t.plot(t[s], y[s], color="k", lw=0.8, ls="--", label="measured")
    ax_t.set_xlabel("t [s]")
    ax_t.set_ylabel(f"q_i gamma_i [{y_unit}]")
    ax_l.set_xlabel(f"input [{u_unit}]")
    ax_t.legend(fontsize=6, ncol=2, loc="upper right")
    for ax in (ax_t, ax_l):
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return _save(fig, path, dpi)


def shape_heatmaps(metrics: pd.DataFrame, path: Path, *, metric: str, split: str,
                   title: str, dpi: int = 72) -> Path | None:
    """``metric`` (mean over the excitations of ``split``) on the curve angle x radius grid."""
    m = metrics[(metrics["split"] == split)].dropna(subset=["curve_angle_deg", "radius_mm"])
    if m.empty:
        return None
    families = sorted(m["family"].astype(str).unique())
    grid = m.groupby(["family", "curve_angle_deg", "radius_mm"], observed=True)[metric].mean()
    angles = sorted(m["curve_angle_deg"].unique())
    radii = sorted(m["radius_mm"].unique())
    values = grid.to_numpy(dtype=float)
    positive = values[np.isfinite(values) & (values > 0)]
    # A log colour scale: the linear baseline is often 5-10x worse than the hysteresis
    # families, and on a linear scale it would flatten their shape dependence to one colour.
    vmin = float(positive.min()) if positive.size else 1e-12
    vmax = float(positive.max()) if positive.size else 1.0
    norm = LogNorm(vmin=vmin, vmax=max(vmax, vmin * (1 + 1e-9)))
    mid = float(np.sqrt(vmin * vmax))
    fig, axes = plt.subplots(1, len(families), figsize=(3.4 * len(families) + 1.2, 3.4),
                             squeeze=False)
    image = None
    for ax, fam in zip(axes[0], families, strict=True):
        z = np.full((len(radii), len(angles)), np.nan)
        for (f, a, r), v in grid.items():
            if f == fam:
                z[radii.index(r), angles.index(a)] = v
        image = ax.imshow(np.where(z > 0, z, np.nan), origin="lower", aspect="auto",
                          cmap="magma_r", norm=norm)
        ax.set_xticks(range(len(angles)), [f"{a:g}" for a in angles], fontsize=7)
        ax.set_yticks(range(len(radii)), [f"{r:g}" for r in radii], fontsize=7)
        ax.set_title(fam, fontsize=9)
        ax.set_xlabel("curve angle [deg]", fontsize=8)
        for i in range(len(radii)):
            for j in range(len(angles)):
                if np.isfinite(z[i, j]):
                    # Two significant digits without the leading "0" so labels fit the cell.
                    label = f"{z[i, j]:.2g}"
                    label = label[1:] if label.startswith("0.") else label
                    ax.text(j, i, label, ha="center", va="center", fontsize=6,
                            color="w" if z[i, j] > mid else "k")
    axes[0][0].set_ylabel("radius [mm]", fontsize=8)
    if image is not None:
        fig.colorbar(image, ax=list(axes[0]), shrink=0.85, label=f"{split} {metric}")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path, max(dpi, 100))


def error_vs_shape_lines(metrics: pd.DataFrame, path: Path, *, metric: str, split: str,
                         title: str, dpi: int = 72) -> Path | None:
    """``metric`` against curve angle, one line per radius, one panel per family."""
    m = metrics[(metrics["split"] == split)].dropna(subset=["curve_angle_deg", "radius_mm"])
    if m.empty:
        return None
    families = sorted(m["family"].astype(str).unique())
    g = m.groupby(["family", "radius_mm", "curve_angle_deg"], observed=True)[metric].mean()
    fig, axes = plt.subplots(1, len(families), figsize=(2.6 * len(families) + 0.5, 3.0),
                             squeeze=False, sharey=True)
    for ax, fam in zip(axes[0], families, strict=True):
        sub = g.loc[fam]
        for k, r in enumerate(sorted(sub.index.get_level_values(0).unique())):
            line = sub.loc[r]
            ax.plot(line.index, line.to_numpy(), marker="o", ms=3, lw=1, color=f"C{k}",
                    label=f"r={r:g} mm")
        ax.set_title(fam, fontsize=9)
        ax.set_xlabel("curve angle [deg]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel(f"{split} {metric}", fontsize=8)
    axes[0][0].legend(fontsize=6)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path, dpi)
