"""Stage ``generate`` (``make data``): the virtual rig writes a campaign of raw runs.

    python -m pipelines.generate                        # 72 standard runs -> data/raw/virtual
    python -m pipelines.generate format=mcap out=<dir>  # the same runs as rosbag2 (.mcap)
    python -m pipelines.generate campaign=quick effects=drift_only out=<dir>

What it reads, writes and keeps: :mod:`pipelines.core.generate` (the core; this module is the
command: settings, tracking).
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
