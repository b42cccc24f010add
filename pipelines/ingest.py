"""Stage ``ingest``: raw rig runs (folders, bags, foreign logs) -> validated parquet dataset.

    python -m pipelines.ingest                # data/raw/virtual -> data/processed/virtual
    python -m pipelines.ingest source=<dir> out=<dir>
    python -m pipelines.ingest importer=tendon_catheter \\
        source=../shared/real-data/tendon-catheter out=data/processed/catheter

Every run is read, checked, calibrated, synchronised and normalised by the pure functions of
``rig_io``; a bad run is rejected with its reason while the others go through. A run whose
source files, ingest version and options are unchanged is not processed again. Writes
``<out>/samples/<run_id>.parquet``, ``<out>/runs.json`` and ``<out>/ingest_report.json``
(all atomically; never anything in the source folder) and exits 1 when a run was rejected.

``source`` may also be one run (a run folder, a ``.bag`` file or a rosbag2 folder): it is
ingested alone, and nothing else in ``out`` is pruned. A source that does not exist, holds
no run is refused (exit 2) and ``out`` is left untouched; one whose runs are all rejected
writes only its ``ingest_report.json`` (``refused``, exit 1). An empty or wrong source never
deletes processed data. An output that cannot be written (a full disk) stops the stage with
one line naming the file and the free space (exit 2): nothing is pruned or removed. A
processed file that no longer matches the hash recorded when it was written (truncated,
edited) is processed again.
"""

from __future__ import annotations

import sys
from typing import Any

from pipelines.ingest_runs import (
    file_sha256,
    options_hash,
    run_ingest,
    single_run_source,
)
from rig_io.errors import RigIOError
from rig_io.limits import ReadLimits
from rig_io.synchronise import SyncOptions

# The work itself lives below the stages (the discrepancy stage ingests a source too); its
# names stay importable from here.
__all__ = ["file_sha256", "options_hash", "run_ingest", "single_run_source"]


def _plain_section(section: Any) -> dict[str, Any]:
    from omegaconf import OmegaConf

    loaded = OmegaConf.to_container(section, resolve=True)
    assert isinstance(loaded, dict)
    return {str(k): v for k, v in loaded.items()}


def _main() -> None:
    import hydra
    from omegaconf import DictConfig

    from pipelines import schemas

    schemas.register()

    @hydra.main(config_path="../conf", config_name="ingest", version_base="1.3")
    def main(cfg: DictConfig) -> None:
        from hydra.utils import to_absolute_path

        mapping = _plain_section(cfg.importer) if cfg.importer is not None else None
        sync = SyncOptions(**_plain_section(cfg.sync))
        try:
            report = run_ingest(to_absolute_path(str(cfg.source)),
                                to_absolute_path(str(cfg.out)), mapping=mapping, sync=sync,
                                force=bool(cfg.force), prune=bool(cfg.prune),
                                progress=bool(cfg.progress), limits=ReadLimits.from_mapping(
                                    _plain_section(cfg.limits)))
        except RigIOError as err:
            print(f"ingest: {err}", file=sys.stderr)
            raise SystemExit(2) from None
        print(f"ingest: {report['n_accepted']} accepted ({report['n_processed']} processed), "
              f"{report['n_rejected']} rejected, {report['n_samples']} samples in "
              f"{report['elapsed_s']:.1f} s -> {report['out']}", file=sys.stderr)
        for r in report["rejected"]:
            print(f"  rejected {r['source']}: {r['reason']}", file=sys.stderr)
        if report["refused"]:
            print(f"ingest: refused: {report['refused']}", file=sys.stderr)
        if report["n_rejected"]:
            raise SystemExit(1)

    main()


if __name__ == "__main__":
    from pipelines.cli import guard

    guard("ingest")
    _main()
