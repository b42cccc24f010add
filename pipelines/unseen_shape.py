"""Stage ``unseen_shape``: can a family predict a sheath shape it was never fitted on?

    python -m pipelines.unseen_shape
    python -m pipelines.unseen_shape families=[gamma] estimator.method=rbf

Leave-one-configuration-out over every configuration of the rig: for each configuration and
family, three predictors score the configuration's evaluation runs (``eval_excitations``):

* ``own``: the configuration's own model (identified on its own record: the reference);
* ``nearest``: the model of the nearest other configuration (scaled wrap angle x curvature);
* ``shape_aware``: :class:`hysteresis.shape_aware.ShapeAwareModel` fitted on the models of
  every *other* configuration, asked for this one.

Writes ``${paths.reports}/unseen_shape.parquet`` (columns :data:`COLUMNS`, one row per family x
configuration x predictor), ``unseen_shape_summary.csv`` (per family: median RMSE of each
predictor, the shape-aware / own ratio, in how many configurations shape-aware beats nearest,
whether the targets hold) and ``plots/unseen_shape.png``; reads only the fit stage's model
files and the processed dataset. Nothing is recomputed when its inputs are unchanged.
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
