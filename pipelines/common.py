"""Small I/O helpers shared by the stage entry points (paths, dataset, Hydra context)."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import pandas as pd

from pipelines import cache
from pipelines.stages import PipelineError

REPO_ROOT = Path(__file__).resolve().parents[1]
CONF_DIR = REPO_ROOT / "conf"
#: Environment variable holding the id of the current Hydra sweep (its folder's suffix).
SWEEP_ID_ENV = "TSM_SWEEP_ID"
T = TypeVar("T")


def sweep_id() -> str:
    """One id per sweep, the same in every job process of it: made once by the launching
    process (pid + random) and passed down the environment, so two sweeps started in the
    same second never share a ``multirun/`` folder (``${tsm_sweep_id:}`` in conf/hydra)."""
    value = os.environ.get(SWEEP_ID_ENV)
    if not value:
        import secrets

        value = f"{os.getpid()}-{secrets.token_hex(3)}"
        os.environ[SWEEP_ID_ENV] = value
    return value


def _register_resolvers() -> None:
    from omegaconf import OmegaConf

    from pipelines import schemas

    if not OmegaConf.has_resolver("tsm_sweep_id"):
        OmegaConf.register_new_resolver("tsm_sweep_id", sweep_id, use_cache=True)
    schemas.register()


_register_resolvers()

_WATCHING_PARENT = False


def exit_with_parent(parent_pid: int, *, poll_s: float = 0.5) -> None:
    """In a pool worker: exit as soon as the process ``parent_pid`` is gone.

    A pool's workers outlive a parent killed with SIGKILL: they run the tasks already queued
    to them and then idle forever. A daemon thread polls the parent id (a reparented worker
    sees another one) and ends the worker; its half-written temporaries are removed by the
    next run of the stage. Idempotent; a no-op in the parent itself.
    """
    global _WATCHING_PARENT
    if _WATCHING_PARENT or os.getpid() == parent_pid:
        return
    _WATCHING_PARENT = True
    import threading
    import time

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def run_stage(stage: str, entry: Callable[[], T],
              errors: tuple[type[Exception], ...] = ()) -> T:
    """A stage's Hydra entry point: a :class:`PipelineError` (a store that cannot be opened,
    nothing to fit ...), a :class:`~rig_io.errors.RigIOError` (an unreadable dataset or run
    index, an output that cannot be written: a full disk) or one of the stage's own
    ``errors`` ends it with one line on stderr and exit status 2 instead of a traceback.
    Inside a sweep job the error propagates, so the launcher records the job as failed."""
    from rig_io.errors import RigIOError

    caught: tuple[type[Exception], ...] = (PipelineError, RigIOError, *errors)
    try:
        return entry()
    except caught as err:
        if hydra_sweep_dir() is not None:
            raise
        print(f"{stage}: {err}", file=sys.stderr)
        raise SystemExit(2) from None


@dataclass(frozen=True)
class Paths:
    root: Path
    raw: Path
    processed: Path
    interim: Path
    models: Path
    predictions: Path
    reports: Path

    @classmethod
    def from_config(cls, paths: Mapping[str, Any]) -> Paths:
        def p(key: str) -> Path:
            return Path(os.path.expanduser(str(paths[key]))).resolve()

        return cls(**{k: p(k) for k in cls.__dataclass_fields__})

    @property
    def metrics_parquet(self) -> Path:
        return self.reports / "metrics.parquet"

    @property
    def metrics_csv(self) -> Path:
        return self.reports / "metrics.csv"


def to_container(cfg: Any) -> dict[str, Any]:
    """A DictConfig (or plain mapping) as a resolved plain dict, without the ``hydra`` node:
    for looking at a composed config (tests, benches); no stage reads its settings this way
    (they are :func:`pipelines.schemas.settings`)."""
    from omegaconf import DictConfig, OmegaConf

    if isinstance(cfg, DictConfig):
        data = OmegaConf.to_container(cfg, resolve=True)
    else:
        data = dict(cfg)
    assert isinstance(data, dict)
    data.pop("hydra", None)
    return {str(k): v for k, v in data.items()}


def read_processed(path: Path, columns: Sequence[str] | None = None) -> pd.DataFrame:
    """The processed dataset: ``rig_io.dataset.read_dataset`` (validated) when available;
    ``columns``: only these (:func:`stage_columns`)."""
    if not path.exists():
        raise PipelineError(
            f"processed dataset {path} does not exist; run `make ingest` (or `make pipeline`)"
        )
    try:
        from rig_io.dataset import read_dataset
    except ImportError:  # ingest not landed yet: plain parquet
        return pd.read_parquet(path, columns=list(columns) if columns else None)
    from rig_io.schema import COLUMNS

    # a signal the schema does not know is left to the stage's own check (which names it)
    return read_dataset(path, columns=None if columns is None
                        else [c for c in columns if c in COLUMNS])


def stage_columns(signals: Any) -> list[str]:
    """The dataset columns fit, validate and unseen_shape read: the configuration, run and
    time columns and the two signals (a stage's ``signals``: :class:`schemas.Signals`, or
    a mapping of its fields)."""
    from pipelines import schemas
    from pipelines.stages import REQUIRED_DATASET_COLUMNS

    sig = schemas.settings(schemas.Signals, signals)
    return list(dict.fromkeys([*REQUIRED_DATASET_COLUMNS, sig.input, sig.output]))


def dataset_units(path: Path) -> tuple[str, str]:
    """(input unit, output unit) of the processed dataset at ``path``, from ingest's run index:
    the one each signal has in every run, ``"mixed units"`` where runs disagree, ``"?"`` where
    the index does not say."""
    from rig_io.dataset import read_runs

    found: list[set[str]] = [set(), set()]
    for meta in read_runs(path).values():
        units = meta.get("units") or {}
        for i, key in enumerate(("input", "output")):
            if units.get(key):
                found[i].add(str(units[key]))
    pair = tuple(next(iter(f)) if len(f) == 1 else ("mixed units" if f else "?")
                 for f in found)
    return pair[0], pair[1]


def dataset_hash(path: Path) -> str:
    """Content hash of the processed dataset's parquet files (contents, not times).

    The ingest report and run index beside them carry timings, so they are left out.
    """
    if not path.exists():
        return "missing"
    if path.is_file():
        return cache.hash_files([path])
    return cache.hash_files(sorted(path.rglob("*.parquet")))


def hydra_output_dir() -> Path | None:
    """The running Hydra job's output folder (holds ``.hydra``), or None outside Hydra."""
    try:
        from hydra.core.hydra_config import HydraConfig

        return Path(HydraConfig.get().runtime.output_dir)
    except Exception:  # noqa: BLE001 - not inside a Hydra app
        return None


def hydra_sweep_dir() -> Path | None:
    """The sweep folder when running as a multirun job, else None."""
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.types import RunMode

        hc = HydraConfig.get()
        if hc.mode == RunMode.MULTIRUN:
            return Path(hc.sweep.dir)
    except Exception:  # noqa: BLE001
        return None
    return None


def identification_plan(settings: Any, dataset: pd.DataFrame, paths: Any) -> Any:
    """The stage edge of :func:`pipelines.stages.identification_plan`: manifest roles from
    ingest's ``runs.json``, the rule's settings from a fit or validate stage's
    (:class:`pipelines.schemas.IdentificationConfig`); every decision is logged."""
    import logging

    from pipelines import schemas, stages
    from rig_io.dataset import read_runs

    # fit's settings have no held-out kinds: they never change which data identifies
    heldout = settings.heldout if isinstance(settings, schemas.ValidateConfig) else []
    plan = stages.identification_plan(
        dataset, fit_excitations=list(settings.fit_excitations), heldout=list(heldout),
        fit_runs=list(settings.fit_runs),
        roles=stages.manifest_roles(read_runs(Path(paths.processed))),
        single_run_heldout_fraction=float(settings.single_run_heldout_fraction))
    log = logging.getLogger("pipelines")
    for label, note in plan.notes.items():
        log.info("identification: %s: %s", label, note)
    return plan
