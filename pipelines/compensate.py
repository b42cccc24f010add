"""Stage `compensate`: the papers' compensation experiments against the virtual rig.

    python -m pipelines.compensate                                  # make compensate
    python -m pipelines.compensate experiment=compensation_full     # every configuration in full
    python -m pipelines.compensate seed002.trials=5 tracking=off

Three experiments (``conf/experiment/compensation_*.yaml``), each with "ours" beside the
papers' schemes on the same plant and the same desired trajectories:

* ``seed001`` - thesis section 4.7: each family's inverse identified on the configuration's
  ``sine_decay`` run, fed open loop to the tsm-bench (Table 4.2 statistics: S_{n-1}, mean,
  max-min range, RMSE), and the per-step inversion time of Table 4.4's solvers;
* ``seed002`` - ViO-Com Table I: Bouc-Wen calibrated on the 30 Hz camera estimate, then no
  compensation / vision feedback / Bouc-Wen feed-forward (RMSE against the tracker);
* ``seed000`` - Tables 2-5: Coleman-Hodgdon reference by GA, the UKF active estimation per
  stroke segment, PD vs AME-PD tracking eq. 32.

This module is the stage's edge; the experiments are the package :mod:`pipelines.compensation`.
:data:`STAGE` (the shared skeleton, :mod:`pipelines.skeleton`) = typed settings -> :func:`run`
(the pure core :func:`pipelines.compensation.experiments.run`: tables, figures, headline
numbers; plus seed 001's registered models when asked for) -> :func:`write` -> :func:`track`.
Outputs (atomic): ``<out_dir>/*.parquet`` (tidy tables), ``<out_dir>/plots/*.png``, the report
section ``<report>`` (markdown), and an MLflow run (``pipelines.tracking``) with the tables,
plots and headline metrics. The physics is reached only through a
:class:`~pipelines.compensation.rig.RigBackend` (default: ``rig_io.virtual``), so tests can
swap in stand-in plants.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from pathlib import Path
from typing import Any

from pipelines.compensation import experiments
from pipelines.compensation.report_section import report_text
from pipelines.compensation.result import CompensationResult
from pipelines.compensation.rig import RigBackend
from pipelines.compensation.seed001 import Champion
from pipelines.compensation.settings import CompensateConfig, Seed001Ours
from pipelines.skeleton import Stage, TrackContext
from rig_io.atomic import atomic_path, clean_leftovers, contained, write_text_atomic

__all__ = ["champion_loader", "output_files", "registry_model", "run", "stage", "track",
           "write"]
log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------
# Reading (the registry's champions, seed001.ours.registry) and running
# ---------------------------------------------------------------------------------------------
def registry_model(ours: Seed001Ours, rig: str, phi: float, r: float, *,
                   tracking_uri: str) -> Any:
    """The configuration's registered champion (``ours.registry``: the registered-model
    prefix, ``ours.registry_alias`` the alias loaded) from the store at ``tracking_uri``."""
    from pipelines import registry

    name = registry.registered_name(rig, phi, r, prefix=str(ours.registry))
    return registry.load_champion(name, tracking_uri=tracking_uri, alias=ours.registry_alias)


def _tracking_uri(settings: CompensateConfig) -> str:
    """The store of the stage's ``tracking`` group (whether or not the stage tracks)."""
    from pipelines.common import Paths
    from pipelines.tracking import settings_from_config

    root = Paths.from_config(settings.paths).root if settings.paths else Path(".")
    return settings_from_config(settings.tracking or {}, root=root).tracking_uri


def champion_loader(settings: CompensateConfig) -> Champion | None:
    """Seed 001's ours per configuration from the model registry, when
    ``seed001.ours.registry`` names a prefix (instead of identifying it); else None."""
    s1 = settings.seed001
    if not (s1.enabled and s1.ours.registry):
        return None
    return functools.partial(registry_model, s1.ours, s1.rig,
                             tracking_uri=_tracking_uri(settings))


def run(settings: CompensateConfig, *, backend: RigBackend | None = None) -> CompensationResult:
    """The enabled experiments (:func:`pipelines.compensation.experiments.run`, the pure
    core) with seed 001's registered champions read in when ``seed001.ours.registry`` is set:
    the only input the stage reads."""
    return experiments.run(settings, backend=backend, champion=champion_loader(settings))


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------
def _table_path(out_dir: Path, name: str) -> Path:
    return contained(out_dir, f"{name}.parquet")


def _figure_path(out_dir: Path, name: str) -> Path:
    return contained(out_dir, "plots", f"{name}.png")


def output_files(result: CompensationResult, settings: CompensateConfig) -> list[Path]:
    """Where :func:`write` puts the result: each table, each plot, then the report section."""
    out_dir = Path(settings.out_dir)
    return [*(_table_path(out_dir, name) for name in result.tables),
            *(_figure_path(out_dir, name) for name in result.figures),
            Path(settings.report)]


def _save_figure(path: Path, fig: Any) -> None:
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)


def write(result: CompensationResult, settings: CompensateConfig) -> list[Path]:
    """Write every table (parquet), figure (png, then closed) and the report section, each
    atomically, after removing the temporaries of a killed run; returns the files
    (:func:`output_files`)."""
    out_dir = Path(settings.out_dir)
    clean_leftovers(out_dir)
    for name, frame in result.tables.items():
        path = _table_path(out_dir, name)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            frame.to_parquet(tmp, index=False)
    for name, fig in result.figures.items():
        _save_figure(_figure_path(out_dir, name), fig)
    elapsed = time.perf_counter() - result.started_s
    write_text_atomic(Path(settings.report),
                      report_text(result.tables, settings, result.metrics, elapsed))
    return output_files(result, settings)


# ---------------------------------------------------------------------------------------------
# Tracking
# ---------------------------------------------------------------------------------------------
def track(tracker: Any, result: CompensationResult, settings: CompensateConfig) -> None:
    """One MLflow run under the invocation's parent: the experiments' settings as params, the
    finite headline numbers as metrics, every table, plot and the report as artifacts, and
    the measured tables as its input."""
    from pipelines import lineage
    from pipelines.tracking import StageRun, flatten

    exps = {"seed001": dataclasses.asdict(settings.seed001),
            "seed002": dataclasses.asdict(settings.seed002),
            "seed000": dataclasses.asdict(settings.seed000)}
    # what the experiments measured on the plant (closed loops, identification records)
    data = lineage.measured_input(
        f"compensation:{'+'.join(exps)}", result.tables, source="rig_io.virtual (RigBackend)",
        context="evaluation", tags={"experiments": ",".join(exps)})
    with StageRun(tracker, "compensate") as stage_run:
        with tracker.run(f"compensation {' '.join(exps)}", parent_id=stage_run.parent_id,
                         note="The papers' compensation experiments (" + ", ".join(exps)
                              + ") with our models beside the papers' schemes on the same "
                              "plant; tables, plots and the report section are artifacts.",
                         tags={"stage": "compensate", "kind": "experiment"}) as run_id:
            lineage.log_input(tracker, [run_id, stage_run.parent_id if stage_run.owns else None],
                              data)
            tracker.log(run_id, params=flatten(exps),
                        metrics={k: v for k, v in result.metrics.items() if math.isfinite(v)})
            for name, frame in result.tables.items():
                tracker.log_table(run_id, frame, f"tables/{name}.json")
            for path in output_files(result, settings):
                tracker.log_artifact(run_id, path, "plots" if path.suffix == ".png" else "reports")


# ---------------------------------------------------------------------------------------------
# The stage
# ---------------------------------------------------------------------------------------------
def _run_and_write(settings: CompensateConfig, *,
                   backend: RigBackend | None = None) -> CompensationResult:
    result = run(settings, backend=backend)
    write(result, settings)
    for name, frame in result.tables.items():
        log.info("%s: %d rows", name, len(frame))
    return result


def _track(ctx: TrackContext, settings: CompensateConfig, result: CompensationResult) -> None:
    track(ctx.tracker, result, settings)


STAGE = Stage("compensate", CompensateConfig, run=_run_and_write, track=_track)


def stage(cfg: Any, *, backend: RigBackend | None = None) -> CompensationResult:
    """The whole stage on a composed config, a hand-written mapping or a
    :class:`CompensateConfig`: run the enabled experiments, write, track; returns the result.
    ``backend``: another plant than the virtual rig (tests)."""
    if backend is None:
        return STAGE.execute(cfg)
    return dataclasses.replace(
        STAGE, run=functools.partial(_run_and_write, backend=backend)).execute(cfg)


if __name__ == "__main__":
    STAGE.main()
