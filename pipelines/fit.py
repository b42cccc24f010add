"""Stage ``fit``: every model family x every configuration, identified on the
identification excitation (default ``sine_decay``) of the processed dataset.

    python -m pipelines.fit
    python -m pipelines.fit family=gamma config.curve_angle_deg=90
    python -m pipelines.fit -m family=gamma,bouc_wen config.curve_angle_deg=15,90

What it reads, writes and keeps: :mod:`pipelines.core.fit` (the core; this module is the
command: settings, tracking).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass

import pandas as pd

from pipelines import schemas
from pipelines.common import (
    Paths,
    dataset_hash,
    dataset_units,
    hydra_output_dir,
    identification_plan,
    read_processed,
)
from pipelines.core.fit import fit_metrics, run
from pipelines.skeleton import Stage, TrackContext

log = logging.getLogger("pipelines.fit")


@dataclass
class FitOutcome:
    """What the command's core gives its tracking: the fits and the dataset they came from."""

    fits: pd.DataFrame
    dataset: pd.DataFrame


def _run_command(s: schemas.FitConfig) -> FitOutcome:
    """The command reads every column once: the tracking logs the data each model saw."""
    dataset = read_processed(Paths.from_config(s.paths).processed)
    return FitOutcome(run(s, dataset=dataset), dataset)


def _track(ctx: TrackContext, s: schemas.FitConfig, out: FitOutcome) -> None:
    """The stage's parent run and one child run per model this store does not hold yet (same
    key: data, config and code): a re-run that changes nothing adds no run."""
    from pipelines import lineage, tracking

    fresh = out.fits[~out.fits["key"].astype(str).isin(ctx.tracker.logged_model_keys("fit"))]
    if fresh.empty:
        log.info("fit: every model is already in the MLflow store; nothing new logged")
        return
    paths = ctx.paths
    with ctx.parent_run() as parent:
        base = ctx.params(s, "family", "family_overrides")
        plan = identification_plan(s, out.dataset, paths)
        if plan.notes:
            ctx.tracker.log_text(parent, json.dumps(dict(plan.notes), indent=1),
                                 "identification_plan.json")
        hydra_dir = hydra_output_dir()
        ids = tracking.log_model_runs(
            ctx.tracker, parent, fits=fresh,
            metrics=fit_metrics(fresh, plan.dataset, s.signals), base_params=base,
            tags={"dataset_hash": dataset_hash(paths.processed)},
            hydra_dir=hydra_dir / ".hydra" if hydra_dir else None, stage="fit",
            units=dataset_units(paths.processed),
        )
        lineage.log_model_inputs(ctx.tracker, ids, fresh, None, processed=paths.processed,
                                 dataset=out.dataset)


STAGE = Stage("fit", schemas.FitConfig, run=_run_command, track=_track)


if __name__ == "__main__":
    STAGE.main()
