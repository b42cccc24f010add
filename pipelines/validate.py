"""Stage ``validate``: every fitted model predicts the runs of its own configuration.

    python -m pipelines.validate
    python -m pipelines.validate cross=true            # the full cross-excitation matrix

What it reads, writes and keeps: :mod:`pipelines.core.validate` (the core; this module is the
command: settings, tracking).
"""

from __future__ import annotations

import pandas as pd

from pipelines import schemas
from pipelines.common import dataset_hash
from pipelines.core.validate import run
from pipelines.skeleton import Stage, TrackContext


def _track(ctx: TrackContext, s: schemas.ValidateConfig,
           result: tuple[pd.DataFrame, list[str]]) -> None:
    """The stage's parent run: its settings, inputs, metrics table and config."""
    from pipelines import lineage

    metrics, _ = result
    paths = ctx.paths
    with ctx.parent_run() as parent:
        ctx.tracker.log(parent, params=ctx.params(s),
                        tags={"dataset_hash": dataset_hash(paths.processed)})
        lineage.log_stage_inputs(ctx.tracker, parent, metrics, processed=paths.processed)
        ctx.tracker.log_table(parent, metrics, "metrics.json")
        ctx.tracker.log_artifact(parent, paths.metrics_csv, "tables")
        ctx.log_hydra(parent)


STAGE = Stage("validate", schemas.ValidateConfig, run=run, track=_track)


if __name__ == "__main__":
    STAGE.main()
