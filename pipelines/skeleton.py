"""One shape for every stage's edge: settings -> core -> tracking.

A stage is three pieces, and this module joins them the same way for every one:

* its **settings**: the typed dataclass of :mod:`pipelines.schemas`, made once from the
  composed config (or a hand-written mapping) by :func:`pipelines.schemas.settings`;
* its **core** (``run(settings) -> result``, in :mod:`pipelines.core`): data in, tables and
  figures out, no Hydra and no MLflow; the files it keeps go through
  :mod:`pipelines.artifacts` and its up-to-date check through :class:`KeyFile`;
* its **tracking** (``track(context, settings, result)``, optional): what goes to MLflow.

:class:`Stage` builds the command from them::

    STAGE = Stage("validate", schemas.ValidateConfig, run=core.run, track=_track)

    if __name__ == "__main__":
        STAGE.main()

``Stage.main`` checks the command line first (:func:`pipelines.cli.guard`), composes
``conf/<config>.yaml`` with Hydra, and calls :meth:`Stage.execute` inside
:func:`pipelines.common.run_stage` (a known error is one line on stderr and exit 2).
``execute`` converts the config once, builds the tracker once (:func:`tracker_for`: from
``settings.tracking`` and ``paths.root``; a damaged store stops the stage before the work),
runs the core and hands the result to ``track`` with a :class:`TrackContext` (the tracker,
the stage's parent run on demand, the Hydra folder to attach). ``run_all`` calls the same
cores with settings it derives from its own (:mod:`pipelines.run_all`).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

from pipelines import cache, schemas
from pipelines.common import CONF_DIR, Paths, hydra_output_dir, hydra_sweep_dir, run_stage

S = TypeVar("S")
R = TypeVar("R")


@dataclass
class _Root:
    """The one path the tracker needs (a hand-written config may give ``paths.root`` only)."""

    root: str = "."


def tracker_for(settings: Any) -> Any:
    """The MLflow tracker of a stage's settings: its ``tracking`` group (not given, as in a
    hand-written config, or ``enabled: false`` = off) with the store under ``paths.root``."""
    from pipelines import tracking

    group = settings.tracking if isinstance(settings.tracking, Mapping) else {"enabled": False}
    root = Path(schemas.settings(_Root, settings.paths or {}).root).expanduser().resolve()
    return tracking.Tracker(tracking.settings_from_config(group, root=root))


@dataclass
class TrackContext:
    """What a stage's ``track`` gets besides its settings and result."""

    stage: str
    tracker: Any
    #: the settings' ``paths`` group as given (a hand-written config may name only the root)
    paths_given: Any
    #: epoch seconds when the command started: the stage's parent run spans the work
    started: float

    @property
    def paths(self) -> Paths:
        """The project's folders (every one named by the composed config)."""
        return Paths.from_config(self.paths_given)

    @contextmanager
    def parent_run(self, **tags: str) -> Iterator[str]:
        """The stage's parent run (inherited from a sweep, or opened and ended here)."""
        from pipelines import tracking

        with tracking.StageRun(self.tracker, self.stage, sweep_dir=hydra_sweep_dir(),
                                tags=tags or None, start_time=self.started) as stage_run:
            assert stage_run.parent_id is not None
            yield stage_run.parent_id

    @staticmethod
    def params(settings: Any, *leave_out: str) -> dict[str, str]:
        """The settings as MLflow params (flattened), without ``tracking`` and ``leave_out``."""
        from pipelines import tracking

        skip = {"tracking", *leave_out}
        return tracking.flatten({k: v for k, v in asdict(settings).items() if k not in skip})

    def log_hydra(self, run_id: str) -> None:
        """The composed config Hydra saved (``.hydra/``) onto ``run_id``, when under Hydra."""
        hydra_dir = hydra_output_dir()
        if hydra_dir is not None:
            self.tracker.log_artifact(run_id, hydra_dir / ".hydra", ".hydra")


@dataclass(frozen=True)
class Stage(Generic[S, R]):
    """A stage command: its name, its settings' schema, its core and its tracking."""

    #: the command (``python -m pipelines.<module>``) and the name its errors carry
    name: str
    schema: type[S]
    run: Callable[[S], R]
    track: Callable[[TrackContext, S, R], None] | None = None
    #: ``conf/<config>.yaml``; the stage's name when not given (run_all's is ``pipeline``)
    config: str | None = None
    #: the stage's own errors ended as one line and exit 2 (besides PipelineError and
    #: RigIOError)
    errors: tuple[type[Exception], ...] = field(default=())
    #: the conversion of a config into the settings, where the stage words a missing setting
    #: its own way (default :func:`pipelines.schemas.settings`)
    convert: Callable[[Any], S] | None = None
    #: after tracking: the stage's verdict on its result (raises when the result falls short;
    #: the result is written and tracked first)
    after: Callable[[S, R], None] | None = None
    #: what the command prints when done (one line for the person at the terminal)
    announce: Callable[[S, R], str] | None = None

    @property
    def config_name(self) -> str:
        return self.config or self.name

    def settings(self, cfg: Any) -> S:
        """The typed settings of ``cfg`` (a settings object comes back as it is)."""
        if isinstance(cfg, self.schema):
            return cfg
        return self.convert(cfg) if self.convert else schemas.settings(self.schema, cfg)

    def execute(self, cfg: Any) -> R:
        """Settings once, tracker once, core, then tracking (``cfg``: composed or plain)."""
        started = time.time()
        settings = self.settings(cfg)
        tracker = tracker_for(settings) if self.track is not None else None
        if tracker is not None and tracker.enabled:
            tracker.init_store()  # a locked or damaged store stops the stage before the work
        result = self.run(settings)
        if tracker is not None and tracker.enabled and self.track is not None:
            self.track(TrackContext(self.name, tracker,
                                    settings.paths, started),  # type: ignore[attr-defined]
                       settings, result)
        if self.after is not None:
            self.after(settings, result)
        return result

    def main(self) -> None:
        """The command: the guard, then Hydra composing the stage's config."""
        import hydra

        from pipelines.cli import guard

        guard(self.config_name)

        def entry(cfg: Any) -> None:
            def once() -> tuple[S, R]:  # converted once, inside run_stage's one-line errors
                settings = self.settings(cfg)
                return settings, self.execute(settings)

            settings, result = run_stage(self.name, once, self.errors)
            if self.announce is not None:
                print(self.announce(settings, result))

        # Hydra names the job (its log file, a sweep's parent run) after the task
        # function's module: the command's (``pipelines.fit`` -> ``fit``), not this one
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        entry.__module__ = spec.name if spec is not None else f"pipelines.{self.name}"
        hydra.main(config_path=str(CONF_DIR), config_name=self.config_name,
                   version_base="1.3")(entry)()


class KeyFile:
    """The content-key cache of a stage's outputs: ``<name>.json`` beside them records the
    key they were made from (and, with ``files``, each file's content hash).

    :meth:`hit` gives the record when its key is ``key``, every file in ``needs`` exists and
    (``with_files``) every recorded file still has its hash; otherwise None (the stage
    recomputes).
    """

    def __init__(self, path: Path, *, enabled: bool = True, needs: tuple[Path, ...] = (),
                 with_files: bool = False) -> None:
        self.path = path
        self.enabled = enabled
        self.needs = needs
        self.with_files = with_files

    def hit(self, key: str) -> dict[str, Any] | None:
        if not self.enabled or not self.path.exists() \
                or not all(p.exists() for p in self.needs):
            return None
        try:
            record = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            return None
        if not isinstance(record, dict) or record.get("key") != key:
            return None
        if self.with_files:
            digests = record.get("sha256") or {}
            if set(digests) != set(record.get("files") or []) \
                    or not cache.files_intact(digests):
                return None
        return record

    def store(self, key: str, *, files: list[Path] | None = None,
              **extra: Any) -> None:
        """Record ``key`` (with ``files``: their paths and content hashes, then ``extra``)."""
        from rig_io.atomic import write_text_atomic

        record: dict[str, Any] = {"key": key}
        if files is not None:
            record["files"] = [str(f) for f in files]
            record["sha256"] = cache.file_digests(files)
        record.update(extra)
        write_text_atomic(self.path, json.dumps(record, indent=1))
