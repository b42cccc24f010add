"""Stage ``generate`` (``make data``): the virtual rig writes a campaign of raw runs.

    python -m pipelines.generate                        # 72 standard runs -> data/raw/virtual
    python -m pipelines.generate format=mcap out=<dir>  # the same runs as rosbag2 (.mcap)
    python -m pipelines.generate campaign=quick effects=drift_only out=<dir>

Each run is simulated by :func:`rig_io.virtual.simulate_run` and written by the format's own
writers (:func:`rig_io.folder.write_run_folder`, :func:`rig_io.bag.write_bag`), atomically.
Raw runs are never rewritten: a run that already exists with the same spec is skipped, a
different spec under an existing run id is an error unless ``overwrite=true``. The specs and
their hashes are recorded in ``<out>/campaign.json``: every spec as ``pending`` before any run
is written, then ``done`` as each run lands, so a campaign killed at any point is completed by
the same command (a run folder exists only whole, from the spec the book names). Temporaries
of a killed writer are removed when the stage starts.
"""

from __future__ import annotations

import sys
from typing import Any

from pipelines.core.generate import GenerateError, generate
from rig_io.errors import WriteError


def _command(s: Any) -> dict[str, Any]:
    """``python -m pipelines.generate``: one line of what was done; a bad option or a clash
    is exit 2, an output that cannot be written exit 1."""
    try:
        report = generate(s)
    except (GenerateError, ValueError) as err:
        print(f"generate: error: {err}", file=sys.stderr)
        raise SystemExit(2) from None
    except WriteError as err:  # a full disk ...: the stage failed, one line
        print(f"generate: {err}", file=sys.stderr)
        raise SystemExit(1) from None
    print(f"generate: {len(report['written'])} runs written, {len(report['skipped'])} "
          f"unchanged, {report['seconds']:.1f} s -> {report['out']} ({report['format']})")
    return report


def stage() -> Any:
    """The command's :class:`pipelines.skeleton.Stage`."""
    from pipelines import schemas
    from pipelines.skeleton import Stage

    return Stage("generate", schemas.GenerateConfig, run=_command)


if __name__ == "__main__":
    stage().main()
