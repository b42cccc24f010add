"""Stage ``ingest``: raw rig runs (folders, bags, foreign logs) -> validated parquet dataset.

    python -m pipelines.ingest                # data/raw/virtual -> data/processed/virtual
    python -m pipelines.ingest source=<dir> out=<dir>
    python -m pipelines.ingest importer=tendon_catheter \\
        source=../shared/real-data/tendon-catheter out=data/processed/catheter

What it reads, writes and keeps: :mod:`pipelines.core.ingest` (the core; this module is the
command: settings, tracking).
"""

from __future__ import annotations

import sys
from typing import Any

from pipelines.core.ingest import ingest

# the discrepancy stage ingests its source with the same function
from pipelines.core.ingest import run_ingest as run_ingest

__all__ = ["run_ingest"]


def _command(s: Any) -> dict[str, Any]:
    """``python -m pipelines.ingest``: a summary on stderr; exit 1 when a run was rejected."""
    from dataclasses import replace

    from hydra.utils import to_absolute_path

    # relative folders are the ones the command was started in
    report = ingest(replace(s, source=to_absolute_path(s.source), out=to_absolute_path(s.out)))
    print(f"ingest: {report['n_accepted']} accepted ({report['n_processed']} processed), "
          f"{report['n_rejected']} rejected, {report['n_samples']} samples in "
          f"{report['elapsed_s']:.1f} s -> {report['out']}", file=sys.stderr)
    for r in report["rejected"]:
        print(f"  rejected {r['source']}: {r['reason']}", file=sys.stderr)
    if report["refused"]:
        print(f"ingest: refused: {report['refused']}", file=sys.stderr)
    if report["n_rejected"]:
        raise SystemExit(1)
    return report


def stage() -> Any:
    """The command's :class:`pipelines.skeleton.Stage`."""
    from pipelines import schemas
    from pipelines.skeleton import Stage

    return Stage("ingest", schemas.IngestConfig, run=_command)


if __name__ == "__main__":
    stage().main()
