"""The experiments' figures (matplotlib objects; the stage's edge saves and closes them)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from hysteresis.coleman_hodgdon import ColemanHodgdonModel, ColemanHodgdonState
from hysteresis.compensation import LoopResult


def plot_runs(title: str, runs: Mapping[str, LoopResult]) -> Any:
    """Desired vs measured, the input-output loops, and the error over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(9, 9))
    first = next(iter(runs.values()))
    ax[0].plot(first.t_s, first.desired, "k--", lw=1.2, label="desired")
    for name, r in runs.items():
        ax[0].plot(r.t_s, r.output, lw=0.8, label=name)
        ax[1].plot(r.command, r.output, lw=0.6, label=name)
        ax[2].plot(r.t_s, r.error(), lw=0.6, label=name)
    ax[0].set(title=title, xlabel="t [s]", ylabel="output")
    ax[1].set(xlabel="command", ylabel="output", title="input-output map")
    ax[2].set(xlabel="t [s]", ylabel="output - desired")
    for a in ax:
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=7, ncol=3)
    fig.tight_layout()
    return fig


def plot_reference_model(ref: ColemanHodgdonModel,
                         segments: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> Any:
    """Seed 000's Coleman-Hodgdon reference beside each measured stroke segment
    (``segments``: name -> (pull, tip angle))."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, len(segments), figsize=(12, 3.5))
    for a, (name, (pull, alpha)) in zip(np.atleast_1d(ax), segments.items(), strict=True):
        model = ref.predict(pull, state=ColemanHodgdonState(float(pull[0]), float(alpha[0])))
        a.plot(pull, alpha, lw=0.8, label="measured")
        a.plot(pull, model, lw=0.8, label="CH reference")
        a.set(title=f"pull {name} mm", xlabel="pull [mm]", ylabel="tip angle [deg]")
    np.atleast_1d(ax)[0].legend(fontsize=7)
    fig.tight_layout()
    return fig
