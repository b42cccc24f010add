"""Stage ``report``: the seed 001 Table 4.1 equivalent, a leaderboard of families per
configuration, plots, and a static report (``report.md`` + ``report.html``).

    python -m pipelines.report

Reads only the other stages' outputs: ``metrics.parquet``, the model files and the
predictions files. Writes under ``${paths.reports}``: ``gamma_weights.parquet|csv``,
``leaderboard.parquet|csv``, ``family_summary.csv``, ``generalisation.csv`` (held-out /
in-sample RMSE per family and excitation), ``plots/*.png``, ``report.md``,
``report.html``. Nothing is redrawn when its inputs are unchanged (``report_key.json``).
"""

from __future__ import annotations

from pipelines import schemas
from pipelines.core.report import ReportResult, log_report, run
from pipelines.skeleton import Stage, TrackContext


def _track(ctx: TrackContext, s: schemas.ReportConfig, result: ReportResult) -> None:
    """The stage's parent run holds the report's files and tables."""
    with ctx.parent_run() as parent:
        log_report(ctx.tracker, parent, result)
        ctx.log_hydra(parent)


STAGE = Stage("report", schemas.ReportConfig, run=run, track=_track)


if __name__ == "__main__":
    STAGE.main()
