"""The stage's core: the enabled experiments on a rig, their tables, figures and headline
numbers. No file is written and nothing is tracked here (:mod:`pipelines.compensate` does)."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from pipelines.compensation.result import CompensationResult, Outcome
from pipelines.compensation.rig import RigBackend, virtual_backend
from pipelines.compensation.seed000 import run_seed000
from pipelines.compensation.seed001 import Champion, run_seed001
from pipelines.compensation.seed002 import run_seed002
from pipelines.compensation.settings import CompensateConfig
from pipelines.compensation.tables import headline

log = logging.getLogger(__name__)


def _timed(name: str, experiment: Callable[[], Outcome], result: CompensationResult) -> None:
    t0 = time.perf_counter()
    result.add(experiment())
    log.info("%s done in %.1f s", name, time.perf_counter() - t0)


def run(settings: CompensateConfig, *, backend: RigBackend | None = None,
        champion: Champion | None = None) -> CompensationResult:
    """Seed 001, seed 002 and seed 000, each if enabled, on ``backend`` (default: the
    virtual rig).

    ``champion`` gives seed 001's ours per configuration when ``seed001.ours.registry`` is
    set (:func:`pipelines.compensate.champion_loader` reads it from the model registry);
    without one such a setting is refused rather than silently identified here.
    """
    backend = backend or virtual_backend()
    seed, bar, plots = settings.seed, settings.progress, settings.plots
    result = CompensationResult(started_s=time.perf_counter())
    s1, s2, s0 = settings.seed001, settings.seed002, settings.seed000
    if s1.enabled:
        if s1.ours.registry and champion is None:
            raise ValueError("seed001.ours.registry is set: pass the registry's champions "
                             "(pipelines.compensate.champion_loader)")
        _timed("seed001", lambda: run_seed001(s1, backend, seed=seed, progress_bar=bar,
                                              plots=plots, champion=champion), result)
    if s2.enabled:
        _timed("seed002", lambda: run_seed002(s2, backend, seed=seed, progress_bar=bar,
                                              plots=plots), result)
    if s0.enabled:
        _timed("seed000", lambda: run_seed000(s0, backend, seed=seed, progress_bar=bar,
                                              plots=plots), result)
    result.metrics = headline(result.tables, s1.paper_family)
    return result
