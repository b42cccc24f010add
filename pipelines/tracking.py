"""All MLflow glue of the pipeline, in one place.

* The store is the ``tracking`` config group: by default a local SQLite file
  ``sqlite:///<root>/mlflow.db`` with artifacts in ``<root>/mlartifacts``; a shared tracking
  server (``tracking=server``) needs no code change.
* One *parent* run per pipeline invocation (``make pipeline``, one stage, or one Hydra
  multirun sweep); one nested *child* run per (family, configuration, identification
  excitation) with the flattened config as params, consistent metric keys, tables, plots, the
  model JSON and the ``.hydra`` folder.
* Parallel writers: the store is created once, before any parallel job starts
  (:func:`init_store`, or :class:`MlflowSweepCallback` for multiruns); every call retries on
  SQLite's ``database is locked``.

Only :class:`mlflow.MlflowClient` is used (no global "active run"), so several processes and
nested runs never step on each other.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import pandas as pd

from pipelines.stages import PipelineError

log = logging.getLogger(__name__)

#: Environment variable through which a parent run id reaches stage processes and sweep jobs.
PARENT_ENV = "TSM_MLFLOW_PARENT_RUN_ID"
#: File written into a Hydra sweep folder with the sweep's parent run id (fallback to the env).
PARENT_FILE = "mlflow_parent_run_id"
REPO_ROOT = Path(__file__).resolve().parents[1]
#: Metric keys are ``<scope>.<metric>``; scope is ``fit``, ``heldout`` (mean over held-out
#: excitations) or ``eval.<excitation>`` -- the same keys in every child run, so MLflow's
#: compare view charts families against each other across configurations.
MAX_PARAM_CHARS = 6000

#: The run tag MLflow's UI shows as a run's description.
NOTE_TAG = "mlflow.note.content"

T = TypeVar("T")


# --------------------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackingSettings:
    """Where runs go. ``uri=None`` means the local SQLite store under ``root``."""

    enabled: bool = True
    uri: str | None = None
    artifact_location: str | None = None
    experiment: str = "tsm-hysteresis"
    root: Path = REPO_ROOT

    @property
    def tracking_uri(self) -> str:
        if self.uri:
            return self.uri
        return f"sqlite:///{(self.root / 'mlflow.db').resolve()}"

    @property
    def artifact_uri(self) -> str | None:
        if self.artifact_location:
            return self.artifact_location
        if self.uri:  # a server decides where artifacts go (proxied artifact store)
            return None
        return (self.root / "mlartifacts").resolve().as_uri()


@dataclass
class RegistryGroup:
    """``tracking.registry``: register each configuration's champion after ``make pipeline``
    as ``<prefix>.<configuration label>`` with ``alias``."""

    enabled: bool = False
    prefix: str = "tsm"
    alias: str = "champion"


@dataclass
class TrackingGroup:
    """The ``tracking`` config group (conf/tracking/): where MLflow logs."""

    enabled: bool = True
    uri: str | None = None
    artifact_location: str | None = None
    experiment: str = "tsm-hysteresis"
    registry: RegistryGroup = field(default_factory=RegistryGroup)


def tracking_group(tracking: Any) -> TrackingGroup:
    """The ``tracking`` group (a mapping, None = every default) as typed settings."""
    from pipelines import schemas

    return schemas.settings(TrackingGroup, tracking or {})


def settings_from_config(tracking: Any, *, root: str | Path) -> TrackingSettings:
    """Build :class:`TrackingSettings` from the ``tracking`` config group."""
    group = tracking_group(tracking)
    return TrackingSettings(
        enabled=group.enabled,
        uri=group.uri or None,
        artifact_location=group.artifact_location or None,
        experiment=group.experiment,
        root=Path(root).resolve(),
    )


# --------------------------------------------------------------------------------------
# retries
# --------------------------------------------------------------------------------------


def _is_transient(exc: BaseException) -> bool:
    text = f"{type(exc).__name__}: {exc}".lower()
    return any(s in text for s in (
        "database is locked", "database table is locked", "temporarily_unavailable",
        "unable to open database", "disk i/o error", "connection refused", "timed out",
    ))


def retry(fn: Callable[..., T], *args: Any, attempts: int = 8, **kwargs: Any) -> T:
    """Call ``fn``; on a transient store error (SQLite lock ...) back off and try again."""
    delay = 0.05
    for attempt in range(1, attempts + 1):
        try:
            return fn(*args, **kwargs)
        except Exception as exc:
            if attempt == attempts or not _is_transient(exc):
                raise
            log.warning("MLflow store busy (%s); retry %d/%d", exc, attempt, attempts)
            time.sleep(delay * (1 + random.random()))
            delay = min(delay * 2, 2.0)
    raise AssertionError("unreachable")  # pragma: no cover


def store_error(settings: TrackingSettings, exc: BaseException) -> Exception:
    """A store that cannot be opened, as one line naming it and what to do (a
    :class:`~pipelines.stages.PipelineError`; the stage entry points print it alone)."""

    uri = settings.tracking_uri
    text = f"{type(exc).__name__}: {exc}"
    low = text.lower()
    first = next((line.strip() for line in str(exc).splitlines() if line.strip()),
                 type(exc).__name__)[:160]
    if not uri.startswith("sqlite:///"):
        return PipelineError(
            f"MLflow store {uri} cannot be opened ({first}): check tracking.uri "
            "(MLFLOW_TRACKING_URI), the credentials and that the server is up, or run with "
            "tracking=off")
    db = uri[len("sqlite:///"):]
    if "database is locked" in low or "database table is locked" in low:
        return PipelineError(
            f"MLflow store {db} is locked by another process (still locked after retrying): "
            f"let the other stage or sweep finish, or find it with `fuser {db}` and stop it, "
            "then run again")
    if any(s in low for s in ("malformed", "not a database", "file is encrypted")):
        return PipelineError(
            f"MLflow store {db} is damaged ({first}): move it aside (`mv {db} {db}.damaged`) "
            "and run again to start a new, empty store (restore a backup to keep its runs), "
            "or run with tracking=off")
    return PipelineError(f"MLflow store {db} cannot be opened ({first}); move it aside or "
                         "run with tracking=off")


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def flatten(obj: Any, prefix: str = "") -> dict[str, str]:
    """Nested dicts/lists -> ``{"a.b.0": "value"}`` strings (MLflow params)."""
    out: dict[str, str] = {}
    if isinstance(obj, Mapping):
        for key, value in obj.items():
            out.update(flatten(value, f"{prefix}{key}."))
    elif isinstance(obj, (list, tuple)) and obj and any(isinstance(v, (Mapping, list, tuple))
                                                         for v in obj):
        for i, value in enumerate(obj):
            out.update(flatten(value, f"{prefix}{i}."))
    else:
        text = "null" if obj is None else str(list(obj) if isinstance(obj, tuple) else obj)
        out[prefix[:-1] if prefix else "value"] = text[:MAX_PARAM_CHARS]
    return out


@functools.lru_cache(maxsize=4)
def git_commit(repo: Path = REPO_ROOT) -> str:
    """Current commit (``+dirty`` when the work tree has changes); ``unknown`` outside git."""
    try:
        sha = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], check=True,
                             capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain",
                                "--untracked-files=no"], check=True, capture_output=True,
                               text=True, timeout=10).stdout.strip()
        return f"{sha}+dirty" if dirty else sha
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def metric_key(scope: str, name: str) -> str:
    return f"{scope}.{name}"


def child_metrics(metrics: pd.DataFrame) -> dict[str, float]:
    """One model's metrics rows -> MLflow metrics with the consistent keys.

    ``fit.<m>`` on the identification record, ``eval.<excitation>.<m>`` per held-out
    excitation, ``heldout.<m>`` the mean over the held-out excitations. The identification
    record is ``fit.*`` only: an ``eval.<fit excitation>.*`` copy would repeat it.
    """
    from hysteresis.metrics import METRIC_NAMES

    out: dict[str, float] = {}
    for row in metrics.to_dict("records"):
        scope = "fit" if row["split"] == "fit" else f"eval.{row['eval_excitation']}"
        for name in METRIC_NAMES:
            out[metric_key(scope, name)] = float(row[name])
    held = metrics[metrics["split"] == "heldout"]
    if not held.empty:
        for name in METRIC_NAMES:
            out[metric_key("heldout", name)] = float(held[name].astype(float).mean())
    return {k: v for k, v in out.items() if v == v}  # MLflow rejects nothing, NaN is noise


# --------------------------------------------------------------------------------------
# the experiment's kind
# --------------------------------------------------------------------------------------


#: Experiment tag the MLflow UI reads to pick an experiment's landing page: with
#: ``custom_model_development`` it opens the runs table (not the GenAI traces overview).
EXPERIMENT_KIND_TAG = "mlflow.experimentKind"
EXPERIMENT_KIND = "custom_model_development"


def set_experiment_kind(client: Any, experiment_id: str, experiment: Any = None) -> None:
    """Tag the experiment as classic model development (idempotent; one read, at most one
    write) so the UI lands on its runs, whatever MLflow would otherwise infer."""
    tags = dict(getattr(experiment, "tags", None) or {}) if experiment is not None else {}
    if tags.get(EXPERIMENT_KIND_TAG) != EXPERIMENT_KIND:
        retry(client.set_experiment_tag, experiment_id, EXPERIMENT_KIND_TAG, EXPERIMENT_KIND)


# --------------------------------------------------------------------------------------
# the tracker
# --------------------------------------------------------------------------------------


class Tracker:
    """Thin, retrying wrapper around :class:`mlflow.MlflowClient` for one experiment."""

    def __init__(self, settings: TrackingSettings) -> None:
        self.settings = settings
        self._client: Any = None
        self._experiment_id: str | None = None

    @property
    def enabled(self) -> bool:
        return self.settings.enabled

    @property
    def client(self) -> Any:
        if self._client is None:
            from mlflow import MlflowClient

            self._client = MlflowClient(tracking_uri=self.settings.tracking_uri)
        return self._client

    @property
    def experiment_id(self) -> str:
        if self._experiment_id is None:
            self._experiment_id = self.init_store()
        return self._experiment_id

    def init_store(self) -> str:
        """Create the store (schema migrations) and the experiment; idempotent.

        A local SQLite store is created under an exclusive lock on ``mlflow.db.lock``, so two
        processes starting at once never both run the schema migration. Runs left RUNNING by
        a process that died are then ended as FAILED (:func:`end_dead_runs`).
        """
        with store_lock(self.settings):
            try:
                exp_id = self._init_store_locked()
            except Exception as exc:
                raise store_error(self.settings, exc) from exc
        with contextlib.suppress(Exception):  # housekeeping must never stop a stage
            end_dead_runs(self)
        clean_staging_leftovers()
        return exp_id

    def _init_store_locked(self) -> str:
        client = self.client
        name = self.settings.experiment
        exp = retry(client.get_experiment_by_name, name)
        if exp is None:
            try:
                exp_id = retry(client.create_experiment, name,
                               artifact_location=self.settings.artifact_uri)
            except Exception:  # another process created it in between
                exp = retry(client.get_experiment_by_name, name)
                if exp is None:
                    raise
                exp_id = exp.experiment_id
        else:
            exp_id = exp.experiment_id
        set_experiment_kind(client, str(exp_id), exp)
        self._experiment_id = str(exp_id)
        return self._experiment_id

    # -- runs -------------------------------------------------------------------------
    def start_run(self, name: str, *, parent_id: str | None = None,
                  tags: Mapping[str, Any] | None = None, note: str | None = None,
                  start_time: float | None = None) -> str:
        """A new run; ``note`` is its description (the UI's *Description*),
        ``start_time`` (epoch seconds) when the work it records began earlier."""
        all_tags = {"git_commit": git_commit(), **owner_tags(),
                    **{k: str(v) for k, v in (tags or {}).items()}}
        if parent_id:
            all_tags["mlflow.parentRunId"] = parent_id
        if note:
            all_tags[NOTE_TAG] = note
        run = retry(self.client.create_run, self.experiment_id, run_name=name, tags=all_tags,
                    start_time=None if start_time is None else int(start_time * 1000))
        return str(run.info.run_id)

    def end_run(self, run_id: str, *, status: str = "FINISHED") -> None:
        retry(self.client.set_terminated, run_id, status=status)

    @contextlib.contextmanager
    def run(self, name: str, *, parent_id: str | None = None,
            tags: Mapping[str, Any] | None = None, note: str | None = None,
            start_time: float | None = None) -> Iterator[str]:
        """A run that ends FINISHED, or FAILED when the block raises (so none stays RUNNING)."""
        run_id = self.start_run(name, parent_id=parent_id, tags=tags, note=note,
                                start_time=start_time)
        try:
            yield run_id
        except BaseException:
            self.end_run(run_id, status="FAILED")
            raise
        self.end_run(run_id)

    def log(self, run_id: str, *, params: Mapping[str, Any] | None = None,
            metrics: Mapping[str, float] | None = None,
            tags: Mapping[str, Any] | None = None) -> None:
        from mlflow.entities import Metric, Param, RunTag

        ts = int(time.time() * 1000)
        p = [Param(k, str(v)[:MAX_PARAM_CHARS]) for k, v in (params or {}).items()]
        m = [Metric(k, float(v), ts, 0) for k, v in (metrics or {}).items()]
        t = [RunTag(k, str(v)) for k, v in (tags or {}).items()]
        # log_batch takes at most 100 params / 1000 metrics per call.
        for i in range(0, max(len(p), len(m), len(t), 1), 100):
            retry(self.client.log_batch, run_id, metrics=m[i:i + 100], params=p[i:i + 100],
                  tags=t[i:i + 100])

    def log_table(self, run_id: str, frame: pd.DataFrame, artifact_file: str) -> None:
        retry(self.client.log_table, run_id, _jsonable(frame), artifact_file)

    def log_text(self, run_id: str, text: str, artifact_file: str) -> None:
        retry(self.client.log_text, run_id, text, artifact_file)

    def log_artifact(self, run_id: str, path: Path, artifact_path: str | None = None) -> None:
        path = Path(path)
        if path.is_dir():
            retry(self.client.log_artifacts, run_id, str(path), artifact_path)
        elif path.exists():
            retry(self.client.log_artifact, run_id, str(path), artifact_path)

    def child_runs(self, parent_id: str) -> list[Any]:
        return list(retry(self.client.search_runs, [self.experiment_id],
                          filter_string=f"tags.mlflow.parentRunId = '{parent_id}'",
                          max_results=5000))

    def logged_model_keys(self, stage: str) -> set[str]:
        """The ``model_key`` of every finished model run ``stage`` logged in this store: a
        fit found here again (same data, config and code) needs no new run."""
        runs = self.find_runs(f"tags.stage = '{stage}' and tags.kind = 'model' and "
                              "attributes.status = 'FINISHED'", max_results=50_000)
        return {str(r.data.tags["model_key"]) for r in runs if "model_key" in r.data.tags}

    def find_runs(self, filter_string: str, *, max_results: int = 1) -> list[Any]:
        return list(retry(self.client.search_runs, [self.experiment_id],
                          filter_string=filter_string, max_results=max_results,
                          order_by=["attributes.start_time DESC"]))


def _jsonable(frame: pd.DataFrame) -> pd.DataFrame:
    out = frame.copy()
    for col in out.columns:
        if out[col].dtype == object or str(out[col].dtype) == "string":
            out[col] = out[col].astype(object).where(out[col].notna(), None)
    return out


# --------------------------------------------------------------------------------------
# run lifecycle: no run stays RUNNING after its process is gone
# --------------------------------------------------------------------------------------

#: Tags naming the process that owns a run (host tag, pid): a RUNNING run whose process no
#: longer exists on this host was killed, and the next stage ends it as FAILED.
HOST_TAG, PID_TAG = "tsm.host", "tsm.pid"
STAGING_TAG = "tsm-mlflow"

def owner_tags() -> dict[str, str]:
    from rig_io.atomic import host_tag

    return {HOST_TAG: host_tag(), PID_TAG: str(os.getpid())}


@contextlib.contextmanager
def store_lock(settings: TrackingSettings) -> Iterator[None]:
    """Exclusive lock beside a local SQLite store (``mlflow.db.lock``); nothing for a server."""
    uri = settings.tracking_uri
    if not uri.startswith("sqlite:///"):
        yield
        return
    import fcntl

    db = Path(uri[len("sqlite:///"):])
    db.parent.mkdir(parents=True, exist_ok=True)
    with open(db.with_name(db.name + ".lock"), "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


@contextlib.contextmanager
def key_lock(settings: TrackingSettings, key: str) -> Iterator[None]:
    """Exclusive lock for one key (a registered model's name) among the processes using a
    local SQLite store: ``flock`` on ``mlflow.db.locks/<hash of key>.lock`` beside the store,
    so a check and the write it decides (the champion alias, a new version) are one step for
    every process. Other keys are not held up. Nothing for a server store, whose callers
    create if absent instead."""
    uri = settings.tracking_uri
    if not uri.startswith("sqlite:///"):
        yield
        return
    import fcntl
    import hashlib

    db = Path(uri[len("sqlite:///"):])
    folder = db.with_name(db.name + ".locks")
    folder.mkdir(parents=True, exist_ok=True)
    name = hashlib.sha256(key.encode("utf-8")).hexdigest()[:24]  # no data in a file name
    with open(folder / f"{name}.lock", "a+b") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def end_dead_runs(tracker: Tracker) -> list[str]:
    """End as FAILED every RUNNING run whose owner process (tags :data:`HOST_TAG`,
    :data:`PID_TAG`) ran on this host and is gone; return their ids. Runs of other hosts,
    of live processes and without owner tags are left alone."""
    from rig_io.atomic import owner_gone

    assert tracker._experiment_id is not None
    running = retry(tracker.client.search_runs, [tracker._experiment_id],
                    filter_string="attributes.status = 'RUNNING'", max_results=5000)
    ended = []
    for run in running:
        tags = run.data.tags
        host, pid = tags.get(HOST_TAG), tags.get(PID_TAG)
        if host is None or pid is None or not str(pid).isdigit():
            continue
        if owner_gone(str(host), int(pid)):
            tracker.end_run(run.info.run_id, status="FAILED")
            ended.append(str(run.info.run_id))
    if ended:
        log.warning("ended %d MLflow run(s) left RUNNING by a dead process as FAILED",
                    len(ended))
    return ended


def staging_prefix() -> str:
    """Prefix of a staging folder in the temp dir, naming its owner (host tag, pid)."""
    from rig_io.atomic import owned_prefix

    return owned_prefix(STAGING_TAG)


def clean_staging_leftovers(folder: str | Path | None = None) -> list[Path]:
    """Remove staging folders (``tsm-mlflow-<host>-<pid>-*``) of dead processes."""
    from rig_io.atomic import clean_owned_temp

    return clean_owned_temp(STAGING_TAG, folder)


# --------------------------------------------------------------------------------------
# parent runs: one per invocation, shared by stage processes and sweep jobs
# --------------------------------------------------------------------------------------


def inherited_parent(sweep_dir: str | Path | None = None) -> str | None:
    """The parent run id handed down by ``run_all`` or a sweep (env var, then sweep file)."""
    env = os.environ.get(PARENT_ENV)
    if env:
        return env
    if sweep_dir is not None:
        marker = Path(sweep_dir) / PARENT_FILE
        if marker.is_file():
            return marker.read_text(encoding="utf-8").strip() or None
    return None


#: What a stage's own parent run is, for its description.
STAGE_NOTES = {
    "fit": "One fit invocation: its child runs are the fitted models (family x sheath "
           "configuration x identification excitation).",
    "validate": "One validate invocation: every model scored on its configuration's held-out "
                "runs; the inputs are each configuration's training and validation data.",
    "unseen_shape": "Leave-one-configuration-out: each shape predicted by its own model, the "
                    "nearest other shape's and the shape-aware model fitted without it.",
    "report": "The report (report.md/html, tables, figures) of the metrics on disk.",
    "discrepancy": "What is the model missing? The discrepancy workflow on measured runs.",
    "compensate": "The papers' compensation experiments on the (virtual) rig.",
}


class StageRun:
    """Context for one stage invocation: attach to an inherited parent or own a new one."""

    def __init__(self, tracker: Tracker, stage: str, *, sweep_dir: str | Path | None = None,
                 tags: Mapping[str, Any] | None = None, note: str | None = None,
                 start_time: float | None = None) -> None:
        self.tracker = tracker
        self.stage = stage
        self.parent_id: str | None = None
        self._own = False
        self._sweep_dir = sweep_dir
        self._tags = dict(tags or {})
        self._note = note or STAGE_NOTES.get(stage)
        self._start = start_time

    def __enter__(self) -> StageRun:
        if not self.tracker.enabled:
            return self
        self.parent_id = inherited_parent(self._sweep_dir)
        if self.parent_id is None:
            self.parent_id = self.tracker.start_run(
                self.stage, tags={"stage": self.stage, "kind": "parent", **self._tags},
                note=self._note, start_time=self._start)
            self._own = True
        return self

    @property
    def owns(self) -> bool:
        """True when this stage opened its parent run (not inherited from a pipeline or
        sweep)."""
        return self._own

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if self._own and self.parent_id is not None:
            self.tracker.end_run(self.parent_id,
                                 status="FAILED" if exc_type is not None else "FINISHED")


def log_model_runs(
    tracker: Tracker,
    parent_id: str,
    *,
    fits: pd.DataFrame,
    metrics: pd.DataFrame | None,
    base_params: Mapping[str, Any],
    tags: Mapping[str, Any],
    hydra_dir: Path | None = None,
    plots: Mapping[str, Iterable[Path]] | None = None,
    stage: str = "pipeline",
    progress: bool = False,
    units: tuple[str, str] = ("?", "?"),
) -> list[str]:
    """One child run per fitted model (family x configuration x identification excitation).

    Each run: tags (family, rig, configuration, curve_angle_deg, radius_mm, fit_excitation,
    model key, dataset hash, git commit), params (the flattened stage config plus
    ``family.*`` hyper-parameters), metrics (:func:`child_metrics`), and artifacts: the model
    JSON, its metrics table (``metrics.json``, the file and tag ``mlflow.log_table`` writes),
    the figures of its configuration (``plots`` maps a configuration label to files) and the
    ``.hydra`` folder. The artifacts are staged locally and uploaded in one call, so a run
    costs three store writes (create, log_batch, terminate) instead of one per file.
    Runs are named short (:func:`model_run_name`) and described (:func:`model_run_note`,
    ``units``: the input's and output's unit).
    """
    import json
    import tempfile

    from pipelines.stages import Configuration

    by_model = _metrics_by_model(metrics)
    ids: list[str] = []
    several_rigs = fits["rig"].nunique() > 1 if len(fits) else False
    several_excitations = fits["fit_excitation"].nunique() > 1 if len(fits) else False
    records: Iterable[dict[str, Any]] = fits.to_dict("records")
    if progress:
        from tqdm import tqdm

        records = tqdm(records, total=len(fits), desc="mlflow", unit="run")
    with tempfile.TemporaryDirectory(prefix=staging_prefix()) as tmp:
        for i, fit in enumerate(records):
            config = Configuration(str(fit["rig"]), finite_or_none(fit["curve_angle_deg"]),
                                   finite_or_none(fit["radius_mm"]))
            failed = _present(fit.get("error"))
            mine = by_model.get(_model_key(fit["family"], config.rig, config.curve_angle_deg,
                                           config.radius_mm, fit["fit_excitation"]))
            staged = Path(tmp) / str(i)
            staged.mkdir()
            run_tags: dict[str, Any] = {
                **tags, "stage": stage, "kind": "model", "family": fit["family"],
                "rig": config.rig, "configuration": config.label,
                "curve_angle_deg": _tag_num(config.curve_angle_deg),
                "radius_mm": _tag_num(config.radius_mm),
                "fit_excitation": fit["fit_excitation"], "fit_run_ids": fit["fit_run_ids"],
                "model_key": fit["key"], "status": "failed" if failed else "ok",
            }
            figures = [Path(p) for p in (plots or {}).get(config.label, ()) if Path(p).exists()]
            run_tags |= _stage_artifacts(staged, fit, mine, figures, hydra_dir)

            name = model_run_name(str(fit["family"]), config, str(fit["fit_excitation"]),
                                  rig=several_rigs, excitation=several_excitations)
            note = model_run_note(fit, config, mine, units=units)
            run_id = tracker.start_run(name, parent_id=parent_id, tags=run_tags, note=note)
            family_params = flatten(json.loads(str(fit["params_json"])), "family.")
            params = {**base_params, **family_params, "family.name": fit["family"]}
            values: dict[str, float] = {"fit_seconds": float(fit["fit_seconds"]),
                                        "n_samples": float(fit["n_samples"])}
            if mine is not None:
                values.update(child_metrics(mine))
            try:
                tracker.log(run_id, params=params, metrics=values)
                tracker.log_artifact(run_id, staged)
            except BaseException:
                tracker.end_run(run_id, status="FAILED")
                raise
            tracker.end_run(run_id, status="FAILED" if failed else "FINISHED")
            ids.append(run_id)
    return ids


def _metrics_by_model(metrics: pd.DataFrame | None) -> dict[tuple[Any, ...], pd.DataFrame]:
    """Each model's rows of the metrics table (:func:`_model_key`)."""
    by_model: dict[tuple[Any, ...], pd.DataFrame] = {}
    if metrics is not None and not metrics.empty:
        keys = ["family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation"]
        for key, group in metrics.groupby(keys, dropna=False, observed=True, sort=False):
            by_model[_model_key(*key)] = group.reset_index(drop=True)
    return by_model


def _stage_artifacts(staged: Path, fit: Mapping[str, Any], mine: pd.DataFrame | None,
                     figures: Iterable[Path], hydra_dir: Path | None) -> dict[str, Any]:
    """A model run's files in ``staged`` (uploaded in one call): its metrics table, model,
    error, figures and ``.hydra``; the tags saying what was logged."""
    import json

    from mlflow.utils.mlflow_tags import MLFLOW_LOGGED_ARTIFACTS

    tags: dict[str, Any] = {}
    if mine is not None:
        _jsonable(mine).to_json(staged / "metrics.json", orient="split", index=False,
                                date_format="iso")
        tags[MLFLOW_LOGGED_ARTIFACTS] = json.dumps([{"path": "metrics.json", "type": "table"}])
    if _present(fit.get("model_json")):
        (staged / "model").mkdir()
        (staged / "model" / "model.json").write_text(str(fit["model_json"]))
    if _present(fit.get("error")):
        (staged / "error.txt").write_text(str(fit["error"]))
    figures = list(figures)
    if figures:
        (staged / "plots").mkdir()
        for fig in figures:  # symlinks: the upload copies the real file once
            (staged / "plots" / fig.name).symlink_to(fig.resolve())
    if hydra_dir is not None and hydra_dir.is_dir():
        (staged / ".hydra").mkdir()
        for f in hydra_dir.iterdir():
            if f.is_file():
                (staged / ".hydra" / f.name).symlink_to(f.resolve())
    return tags


def shape_text(config: Any) -> str:
    """``90°/30 mm`` (curve angle / bend radius), or the rig for a rig without a shape."""
    if config.curve_angle_deg is None and config.radius_mm is None:
        return str(config.rig)
    phi = "?" if config.curve_angle_deg is None else f"{config.curve_angle_deg:g}°"
    r = "?" if config.radius_mm is None else f"{config.radius_mm:g} mm"
    return f"{phi}/{r}"


def model_run_name(family: str, config: Any, fit_excitation: str, *, rig: bool = False,
                   excitation: bool = False) -> str:
    """A model run's name, short enough for the runs table: ``gamma 90°/30 mm``; the rig
    and the identification excitation only when the runs differ in them (the tags
    ``configuration`` and ``fit_excitation`` always hold both)."""
    parts = [family]
    if rig and config.has_shape:
        parts.append(str(config.rig))
    parts.append(shape_text(config))
    if excitation:
        parts.append(f"on {fit_excitation}")
    return " ".join(parts)


def model_run_note(fit: Mapping[str, Any], config: Any, metrics: pd.DataFrame | None, *,
                   units: tuple[str, str] = ("?", "?")) -> str:
    """A model run's description: what was fitted on which runs, and how it scored."""
    unit = units[1] if units[1] not in ("?", "") else ""
    shape = (f"curve angle {config.curve_angle_deg:g} deg, bend radius {config.radius_mm:g} mm"
             if config.has_shape else "no recorded sheath shape")
    text = (f"{fit['family']} model of rig {config.rig} ({shape}), identified on "
            f"{fit['fit_excitation']} (run {fit['fit_run_ids']}).")
    if _present(fit.get("error")):
        return text + f" The fit failed: {' '.join(str(fit['error']).split())[:300]}"
    if metrics is not None and not metrics.empty:
        held = metrics[metrics["split"] == "heldout"]
        if not held.empty:
            kinds = ", ".join(sorted(held["eval_excitation"].astype(str).unique()))
            text += (f" Held-out RMSE {float(held['rmse'].astype(float).mean()):.3g} {unit} "
                     f"(mean over {kinds}).").replace("  ", " ")
        fit_rows = metrics[metrics["split"] == "fit"]
        if not fit_rows.empty:
            text += (f" RMSE on its identification record "
                     f"{float(fit_rows['rmse'].astype(float).mean()):.3g} {unit}.").replace(
                         "  ", " ")
    return text


def _model_key(family: Any, rig: Any, phi: Any, radius: Any, fit_exc: Any) -> tuple[Any, ...]:
    return (str(family), str(rig), finite_or_none(phi), finite_or_none(radius), str(fit_exc))


def _present(value: Any) -> bool:
    """Not None/NaN/NA (pandas turns a missing string into NaN)."""
    return value is not None and not (isinstance(value, float) and value != value) \
        and value is not pd.NA


def finite_or_none(value: Any) -> float | None:
    """``value`` as a float, or None when it is missing, not a number or NaN."""
    try:
        f = float(value)
    except (TypeError, ValueError):
        return None
    return None if f != f else f


def _tag_num(value: float | None) -> str:
    if value is None:
        return "NA"
    return f"{value:g}"


def _eq(column: pd.Series, value: float | None) -> pd.Series:
    col = pd.to_numeric(column, errors="coerce")
    return col.isna() if value is None else (col - value).abs() < 1e-9


# --------------------------------------------------------------------------------------
# Hydra multirun: one parent per sweep, created before any job starts
# --------------------------------------------------------------------------------------

from hydra.experimental.callback import Callback as _HydraCallback  # noqa: E402


class MlflowSweepCallback(_HydraCallback):
    """Hydra callback: before a multirun's jobs start, initialise the store and open the
    sweep's parent run; every job (any launcher, any process) then logs under it.

    The parent id travels by environment variable (inherited by joblib/loky workers) and by
    a file in the sweep folder (for launchers whose jobs do not inherit the environment,
    e.g. submitit on a shared file system).
    """

    def __init__(self) -> None:
        self._tracker: Tracker | None = None
        self._parent: str | None = None
        self._prev_env: str | None = None

    def on_multirun_start(self, config: Any, **kwargs: Any) -> None:
        from omegaconf import OmegaConf

        tracking = (OmegaConf.to_container(config.tracking, resolve=True)
                    if "tracking" in config else {})
        root = config.paths.root if "paths" in config else "."
        settings = settings_from_config(tracking, root=root)
        if not settings.enabled:
            return
        self._tracker = Tracker(settings)
        try:
            self._tracker.init_store()
        except PipelineError as err:  # before any job: one line, not a traceback
            print(f"{config.hydra.job.name}: {err}", file=sys.stderr)
            raise SystemExit(2) from None
        task = config.hydra.job.name
        overrides = list(config.hydra.overrides.task)
        self._parent = self._tracker.start_run(
            f"sweep:{task}",
            tags={"stage": task, "kind": "parent", "sweep": "true",
                  "sweep_dir": config.hydra.sweep.dir, "overrides": " ".join(overrides)},
            note=f"A Hydra sweep of {task} ({' '.join(overrides) or 'no overrides'}): the "
                 "runs of every job of the sweep are its children.",
        )
        sweep_dir = Path(config.hydra.sweep.dir)
        sweep_dir.mkdir(parents=True, exist_ok=True)
        (sweep_dir / PARENT_FILE).write_text(self._parent, encoding="utf-8")
        self._prev_env = os.environ.get(PARENT_ENV)
        os.environ[PARENT_ENV] = self._parent
        import atexit

        atexit.register(self._end_if_open)

    def _end_if_open(self) -> None:
        """At exit without ``on_multirun_end`` (a job raised): the sweep failed."""
        if self._tracker is not None and self._parent is not None:
            with contextlib.suppress(Exception):
                self._tracker.end_run(self._parent, status="FAILED")
            self._parent = None

    def on_multirun_end(self, config: Any, **kwargs: Any) -> None:
        if self._tracker is None or self._parent is None:
            return
        self._tracker.end_run(self._parent)
        self._parent = None
        if self._prev_env is None:
            os.environ.pop(PARENT_ENV, None)
        else:
            os.environ[PARENT_ENV] = self._prev_env
