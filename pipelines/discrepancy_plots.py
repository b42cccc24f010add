"""The discrepancy report's figures: per configuration, the before/after loops and residuals
of its identification and held-out runs, the located segments shaded.

:func:`loop_figures` draws them from the workflow's full result (figures out, no files);
:func:`save_figures` writes them, each atomically.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from rig_io.atomic import atomic_path, contained


def _breaks(starts: Sequence[int]) -> Callable[[Any], npt.NDArray[np.float64]]:
    """A function inserting NaN before every record start after the first (line breaks)."""
    idx = [int(i) for i in starts if int(i) > 0]

    def cut(x: Any) -> npt.NDArray[np.float64]:
        arr = np.asarray(x, dtype=np.float64)
        return np.insert(arr, idx, np.nan) if idx else arr

    return cut


def _fixed_margins(fig: Any, rows: int, *, left: float = 0.75, right: float = 0.15,
                   bottom: float = 0.5, top: float = 0.7, row_gap: float = 0.8,
                   col_gap: float = 0.7) -> None:
    """Margins and gaps in inches (tick labels, axis labels, the titles and the suptitle's
    strip) whatever the number of rows. A measured layout (tight_layout) draws every figure
    once more and took as long as the discrepancy analysis itself."""
    w, h = fig.get_figwidth(), fig.get_figheight()
    axes_h = (h - bottom - top - (rows - 1) * row_gap) / rows
    axes_w = (w - left - right - col_gap) / 2
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h,
                        top=1.0 - top / h, hspace=row_gap / axes_h, wspace=col_gap / axes_w)


def loop_figures(report: Mapping[str, Any]) -> Iterator[tuple[str, Any]]:
    """Per configuration of the workflow's full result ``report``: (file name, figure) of
    its before/after loops and residuals per run, located segments shaded. Each figure is
    drawn when asked for, so the caller saves and closes one before the next is drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    evs = report["_evaluations"]
    segs = report["located"][0]["segments"] if report["located"] else []
    names = [e["name"] for e in report["effects"]] or ["no missing effect"]
    for g in report["_groups"]:
        runs = [g.ident, *g.heldout]
        fig, axes = plt.subplots(len(runs), 2, figsize=(12, 3.2 * len(runs)), squeeze=False)
        for ax, run in zip(axes, runs, strict=True):
            _draw_run(ax, run, evs[0], evs[-1], segs)
        fig.suptitle(f"{report['base_family']} + {', '.join(names)} | {g.key}", fontsize=10)
        _fixed_margins(fig, len(runs))
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in g.key)
        yield f"discrepancy_{safe}.png", fig


def _draw_run(ax: Any, run: Any, first: Any, last: Any,
              segs: Sequence[Mapping[str, Any]]) -> None:
    """One run's row: its loop (measured, base, base + effects) and its residuals."""
    p0 = first.ident_pred.get(run.run_id, first.held_pred.get(run.run_id))
    p1 = last.ident_pred.get(run.run_id, last.held_pred.get(run.run_id))
    # Several identification records are one concatenated run: break every line at a
    # record start so no stroke joins the end of one record to the start of the next.
    cut = _breaks(run.starts)
    u, y, ts = cut(run.u), cut(run.y), cut(run.ts)
    ax[0].plot(u, y, "k", lw=0.8, label="measured")
    ax[0].plot(u, cut(p0), "C0", lw=0.8, label="base")
    ax[0].plot(u, cut(p1), "C3", lw=0.8, ls="--", label="base + effects")
    ax[0].set_xlabel("input")
    ax[0].set_ylabel("output")
    parts = run.run_id.split("+")
    name = parts[0] if len(parts) == 1 else f"{len(parts)} records ({parts[0]}, ...)"
    ax[0].set_title(f"{name} ({run.role})", fontsize=9)
    ax[0].legend(fontsize=7)
    ax[1].plot(ts, y - cut(p0), "C0", lw=0.7, label="residual, base")
    ax[1].plot(ts, y - cut(p1), "C3", lw=0.7, label="residual, base + effects")
    for s in segs:
        if s["run_id"] == run.run_id:
            ax[1].axvspan(s["t_start_s"], s["t_end_s"], color="orange", alpha=0.2)
    ax[1].set_xlabel("time since start (s)")
    ax[1].legend(fontsize=7)


def save_figures(figures: Iterator[tuple[str, Any]], out_dir: Path) -> list[Path]:
    """Each (file name, figure) as a PNG in ``out_dir`` (atomically), closed once written."""
    import matplotlib.pyplot as plt

    files: list[Path] = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, fig in figures:
        path = contained(out_dir, name)
        with atomic_path(path, suffix=".png", folder=False) as tmp:
            fig.savefig(tmp, dpi=90, format="png")
        plt.close(fig)
        files.append(path)
    return files
