"""Stage ``report``: the seed 001 Table 4.1 equivalent, a leaderboard of families per
configuration, plots, and a static report (``report.md`` + ``report.html``).

    python -m pipelines.report

What it reads, writes and keeps: :mod:`pipelines.core.report` (the core; this module is the
command: settings, tracking).
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
