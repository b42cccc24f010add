"""Stage ``unseen_shape``: can a family predict a sheath shape it was never fitted on?

    python -m pipelines.unseen_shape
    python -m pipelines.unseen_shape families=[gamma] estimator.method=rbf

What it reads, writes and keeps: :mod:`pipelines.core.unseen_shape` (the core; this module is the
command: settings, tracking).
"""

from __future__ import annotations

from pipelines import schemas
from pipelines.common import dataset_hash
from pipelines.core.unseen_shape import UnseenShapeResult, log_result, run
from pipelines.skeleton import Stage, TrackContext


def _track(ctx: TrackContext, s: schemas.UnseenShapeConfig,
           result: UnseenShapeResult) -> None:
    """The stage's parent run: its settings, the study's numbers and files, its input."""
    from pipelines import lineage

    paths = ctx.paths
    with ctx.parent_run() as parent:
        ctx.tracker.log(parent, params=ctx.params(s),
                        tags={"dataset_hash": dataset_hash(paths.processed)})
        log_result(ctx.tracker, parent, result)
        if paths.processed.is_dir():  # the study reads every run of the dataset
            lineage.log_input(ctx.tracker, [parent], lineage.processed_input(
                paths.processed, context="evaluation"))
        ctx.log_hydra(parent)


STAGE = Stage("unseen_shape", schemas.UnseenShapeConfig, run=run, track=_track)


if __name__ == "__main__":
    STAGE.main()
