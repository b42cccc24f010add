"""The README's two pictures, drawn from the project's own code: ``make docs-figures``.

    python -m pipelines.docs_figures [--out docs/img]

* ``pipeline.svg``: the stages and what flows between them (a diagram, text kept as text);
* ``fitted-loop.png``: one virtual-rig configuration (curve angle 90 deg, radius 30 mm): Gamma
  and the linear baseline identified on the ``sine_decay`` run, then predicting a held-out
  ``triangle_decay`` run: measured and predicted input-output loops.

Both files are small and deterministic (no dates in the SVG, fixed seeds), so they are
committed and redrawn only when the pipeline's shape or the models change.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyBboxPatch  # noqa: E402

REPO = Path(__file__).resolve().parents[1]

#: (x, y, label, detail, colour) of each box; the diagram's coordinates are 0..100 x 0..40.
_BOXES = {
    "raw": (8, 30, "raw runs", "rig or virtual rig\ntsm-rig-log/1, bags", "#e8e8e8"),
    "ingest": (26, 30, "ingest", "calibrate, sync,\nvalidate", "#dbe9f6"),
    "processed": (44, 30, "processed", "parquet + runs.json\n(content hashes)", "#e8e8e8"),
    "fit": (62, 30, "fit", "5 families x\n24 configurations", "#dbe9f6"),
    "validate": (80, 30, "validate", "held-out\nexcitations", "#dbe9f6"),
    "unseen": (80, 15, "unseen_shape", "leave one\nconfiguration out", "#dbe9f6"),
    "report": (62, 15, "report", "report.html, tables,\nfigures", "#dbe9f6"),
    "registry": (44, 15, "registry", "champion per\nconfiguration", "#fde9c9"),
    "compensate": (8, 15, "compensate", "the papers'\nexperiments", "#e3f1df"),
    "discrepancy": (26, 15, "discrepancy", "what is the model\nmissing?", "#e3f1df"),
}
_ARROWS = [("raw", "ingest"), ("ingest", "processed"), ("processed", "fit"),
           ("fit", "validate"), ("validate", "unseen"), ("unseen", "report"),
           ("report", "registry"), ("raw", "discrepancy")]


def pipeline_diagram(path: Path) -> Path:
    """The stages of ``make pipeline`` (blue), the side workflows (green), the registry and
    the MLflow store they all log to."""
    plt.rcParams["svg.fonttype"] = "none"  # text stays text: small and searchable
    plt.rcParams["svg.hashsalt"] = "tsm"  # stable element ids
    fig, ax = plt.subplots(figsize=(9.0, 4.0))
    ax.set_xlim(-2, 92)
    ax.set_ylim(-1, 38)
    ax.axis("off")
    w, h = 15.0, 9.0
    for x, y, label, detail, colour in _BOXES.values():
        ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h,
                                    boxstyle="round,pad=0.4,rounding_size=1.2",
                                    fc=colour, ec="#555555", lw=0.8))
        ax.text(x, y + 2.0, label, ha="center", va="center", fontsize=9, weight="bold")
        ax.text(x, y - 1.6, detail, ha="center", va="center", fontsize=6.5, color="#333333")
    for a, b in _ARROWS:
        xa, ya = float(_BOXES[a][0]), float(_BOXES[a][1])
        xb, yb = float(_BOXES[b][0]), float(_BOXES[b][1])
        if ya == yb:
            start = (xa + w / 2 + 0.5, ya) if xb > xa else (xa - w / 2 - 0.5, ya)
            end = (xb - w / 2 - 0.5, yb) if xb > xa else (xb + w / 2 + 0.5, yb)
        else:
            start, end = (xa, ya - h / 2 - 0.5), (xb, yb + h / 2 + 0.5)
        ax.annotate("", xy=end, xytext=start,
                    arrowprops={"arrowstyle": "-|>", "color": "#444444", "lw": 0.9})
    ax.add_patch(FancyBboxPatch((0.5, 1.0), 87, 4.0, boxstyle="round,pad=0.3",
                                fc="#f4f0fa", ec="#8c6bb1", lw=0.8))
    ax.text(44, 3.0, "MLflow: one parent run per invocation, a child run per fitted model "
            "(params, metrics, datasets, logged models)", ha="center", va="center",
            fontsize=7.5, color="#4b2c7a")
    ax.text(44, 36.5, "make pipeline: generate -> ingest -> fit -> validate -> unseen_shape "
            "-> report -> registry", ha="center", va="center", fontsize=8, color="#333333")
    fig.subplots_adjust(0, 0, 1, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="svg", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return path


def _processed(run: object) -> tuple[np.ndarray, np.ndarray]:
    from rig_io.calibrate import calibrate_raw_run
    from rig_io.process import process_run

    frame, _ = process_run(calibrate_raw_run(run))  # type: ignore[arg-type]
    return frame["input"].to_numpy(dtype=float), frame["output"].to_numpy(dtype=float)


def fitted_loop(path: Path, *, dpi: int = 80) -> Path:
    """Gamma and linear, identified on one configuration's sine_decay run, predicting a
    held-out triangle_decay run of the same configuration."""
    from hysteresis.base import make_family
    from rig_io.virtual import simulate_run, standard_campaign

    specs = {s["excitation"]["kind"]: s for s in standard_campaign()
             if s["curve_angle_deg"] == 90 and s["radius_mm"] == 30}
    runs = {kind: _processed(simulate_run(**spec)) for kind, spec in specs.items()
            if kind in ("sine_decay", "triangle_decay")}
    u_fit, y_fit = runs["sine_decay"]
    u, y = runs["triangle_decay"]
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    ax.plot(u, y, color="k", lw=1.4, label="measured (held-out triangle_decay)")
    for family, colour in (("linear", "#7f7f7f"), ("gamma", "#1f77b4")):
        model = make_family(family).fit(u_fit, y_fit)
        pred = model.predict(u)
        rmse = float(np.sqrt(np.mean((pred - y) ** 2)))
        ax.plot(u, pred, color=colour, lw=0.9, ls="--" if family == "linear" else "-",
                label=f"{family}: RMSE {rmse:.2f} mm")
    ax.set_xlabel("input: tendon pull at the proximal end [mm]", fontsize=8)
    ax.set_ylabel("output: distal displacement [mm]", fontsize=8)
    ax.set_title("Curve angle 90 deg, radius 30 mm: identified on sine_decay", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return path


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipelines.docs_figures",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "docs" / "img"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    for made in (pipeline_diagram(out / "pipeline.svg"), fitted_loop(out / "fitted-loop.png")):
        print(f"{made} ({made.stat().st_size // 1024} KiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
