"""Stage ``discrepancy``: find where model and measurement disagree, name the missing effect,
add it, show the gap shrink (method in ``docs/discrepancy.md``).

    python -m pipelines.discrepancy source=<dir of raw runs or bags> report=<file.json>

The edge of :func:`hysteresis.discrepancy.analysis.analyse` (base choice, the workflow, the
base check, the headline): :func:`run` ingests the source into a temporary folder (so a
source of raw runs, bags or foreign logs all work and nothing is written next to them) and
analyses its runs, :func:`write` writes the report JSON (atomic) and the before/after plots
beside it, :func:`track` logs one MLflow run with the metrics, the plots and the report.
:func:`stage` is all three from a config.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf.errors import MissingMandatoryValue, OmegaConfBaseException

from hysteresis.base import HysteresisError
from hysteresis.discrepancy.analysis import HISTORY_MODES, analyse
from hysteresis.discrepancy.base_check import asks_best_family, best_family_answers
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.ranking import choose_base
from hysteresis.discrepancy.runs import RunData, split_single_runs
from hysteresis.discrepancy.workflow import WorkflowSettings
from pipelines import schemas
from pipelines.discrepancy_data import ingest_source, runs_from_dataset
from pipelines.discrepancy_plots import loop_figures, save_figures
from pipelines.skeleton import Stage, TrackContext
from rig_io.atomic import (
    check_output,
    clean_leftovers,
    clean_owned_temp,
    owned_prefix,
    write_text_atomic,
)
from rig_io.errors import RigIOError

#: The stage's edge, and what the benches import from here (the science's home is
#: ``hysteresis.discrepancy``; the data step's ``pipelines.discrepancy_data``).
__all__ = ["DiscrepancyError", "Result", "Settings", "analyse", "asks_best_family",
           "best_family_answers", "choose_base", "ingest_source", "plots_dir", "report_path",
           "run", "runs_from_dataset", "settings", "stage", "track", "workflow_settings",
           "write"]

log = logging.getLogger(__name__)
#: Work folders in the temp dir: ``tsm-discrepancy-<host>-<pid>-*`` (leaks of killed runs
#: are removed when the stage starts).
TEMP_TAG = "tsm-discrepancy"

Settings = schemas.DiscrepancyConfig


@dataclass
class Result:
    """What :func:`run` found: the JSON-ready report (its ``plots`` and ``elapsed_s`` are
    added by :func:`write`), the workflow's full result the plots are drawn from, and the
    source's per-run metadata (the lineage of the MLflow run)."""

    report: dict[str, Any]
    full: dict[str, Any]
    runs: dict[str, dict[str, Any]]
    started: float


#: What a config must give, and the message when it does not.
REQUIRED = {"source": "source=<dir of raw runs or bags> is required",
            "report": "report=<file.json> is required"}


def settings(cfg: Any) -> Settings:
    """The stage's typed settings (:func:`pipelines.schemas.settings`); a missing or empty
    ``source`` or ``report``, an unknown or mistyped setting (a forced ``+workflow.<typo>``)
    is named in one line."""
    try:
        s = schemas.settings(Settings, cfg)
    except MissingMandatoryValue as err:
        raise DiscrepancyError(REQUIRED.get(str(err.full_key), str(err))) from None
    except OmegaConfBaseException as err:
        raise DiscrepancyError(f"{err.full_key}: {str(err).splitlines()[0]}") from None
    if not s.source:
        raise DiscrepancyError(REQUIRED["source"])
    if not s.report:
        raise DiscrepancyError(REQUIRED["report"])
    if s.history not in HISTORY_MODES:
        raise DiscrepancyError(
            f"history={s.history}: must be one of {', '.join(HISTORY_MODES)}")
    if s.workers < 0:
        raise DiscrepancyError(f"workers={s.workers}: must be >= 0 (0: one per core)")
    return s


def report_path(s: Settings) -> Path:
    """The report file; never resolved: a link given as the report is refused, not followed
    to what it names."""
    return Path(os.path.abspath(os.path.expanduser(s.report)))


def plots_dir(s: Settings) -> Path:
    """The plots' folder, beside the report: ``<report stem>_plots/``."""
    path = report_path(s)
    return path.parent / f"{path.stem}_plots"


def run(cfg: Any) -> Result:
    """Read the source and analyse it (:func:`analyse`); writes nothing but checks, before
    any work, that the outputs can be written where they go.

    ``cfg``: the stage's :class:`Settings`, a composed ``conf/discrepancy.yaml`` or a
    hand-written mapping (settings it leaves out take their defaults)."""
    started = time.perf_counter()
    s = settings(cfg)
    _check_outputs(s)
    clean_owned_temp(TEMP_TAG)  # work folders of killed runs
    with tempfile.TemporaryDirectory(prefix=owned_prefix(TEMP_TAG)) as tmp:
        rows, meta, ingest_rep = ingest_source(s.source, Path(tmp), mapping=s.importer,
                                               progress=s.progress)
    channels: dict[str, dict[str, str]] = {}
    runs = runs_from_dataset(
        rows, meta, identify_excitations=list(s.identify_excitations),
        input_col=s.signals.input, output_col=s.signals.output,
        rate_hz=s.analysis_rate_hz, channels=channels)
    _log_channels(channels)
    runs, run_choice = _split_single_runs(runs, s.single_run_heldout_fraction)
    report, full = analyse(
        runs, base_family=s.base_family, base_params=s.base_params,
        auto_families=s.auto_families, settings=workflow_settings(s),
        ukf_evidence=s.ukf_evidence, base_check=s.base_check,
        base_misfit_factor=s.base_misfit_factor, base_misfit_fallback=s.base_misfit_fallback,
        max_bases=s.max_bases, base_retry_factor=s.base_retry_factor, history=s.history)
    report["run_choice"] = run_choice or None
    report["channels"] = channels
    report["source"] = str(Path(s.source).resolve())
    report["ingest"] = {"accepted": ingest_rep["n_accepted"], "rejected": ingest_rep["rejected"]}
    return Result(report=report, full=full, runs=meta, started=started)


def workflow_settings(s: Settings) -> WorkflowSettings:
    """The workflow's knobs as the stage runs them: its progress bars and its number of
    worker processes follow the stage's."""
    return dataclasses.replace(s.workflow, candidates=tuple(s.workflow.candidates),
                               progress=s.progress, workers=s.workers)


def _check_outputs(s: Settings) -> None:
    """A wrong kind of output path fails now, not after the analysis; temporaries a killed
    run left beside the outputs are removed."""
    path, plots = report_path(s), plots_dir(s)
    try:
        check_output(path, folder=False)
        if s.plots:
            check_output(plots, folder=True)
    except RigIOError as err:
        raise DiscrepancyError(f"report={s.report}: {err}") from None
    clean_leftovers(path.parent, recursive=False)
    clean_leftovers(plots)


def _log_channels(channels: dict[str, dict[str, str]]) -> None:
    for run_id, notes in channels.items():
        for name, note in notes.items():
            if note not in ("used (complete)", "absent"):
                log.info("discrepancy: %s: %s %s", run_id, name, note)


def _split_single_runs(runs: list[RunData], heldout_fraction: float
                       ) -> tuple[list[RunData], dict[str, str]]:
    """One run per configuration (a common way to record): its head identifies, its tail
    judges."""
    try:
        runs, run_choice = split_single_runs(runs, heldout_fraction=heldout_fraction)
    except HysteresisError as err:
        raise DiscrepancyError(str(err)) from None
    for key, note in run_choice.items():
        log.info("discrepancy: %s: %s", key, note)
    return runs, run_choice


def write(result: Result, s: Settings) -> list[Path]:
    """The plots (unless ``plots=false``) and then the report JSON, which lists them; returns
    the plots' paths."""
    report = result.report
    plots = save_figures(loop_figures(result.full), plots_dir(s)) if s.plots else []
    report["plots"] = [str(p) for p in plots]
    report["elapsed_s"] = round(time.perf_counter() - result.started, 3)
    write_text_atomic(report_path(s), json.dumps(report, indent=1, default=_json_default) + "\n")
    return plots


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def track(tracker: Any, result: Result, s: Settings) -> None:
    """One MLflow run under the stage's parent: the metrics, the settings, the report and the
    plots, and the measured runs it analysed as its input."""
    from pipelines import lineage
    from pipelines.tracking import StageRun

    report = result.report
    # the measured runs it analysed: on the analysis run and on its stage's own parent
    data = lineage.source_input(s.source, result.runs, context="analysis")
    with StageRun(tracker, "discrepancy") as stage_run:
        with tracker.run(f"discrepancy {Path(str(report['source'])).name}",
                         parent_id=stage_run.parent_id, note=str(report["headline"]),
                         tags={"stage": "discrepancy", "kind": "analysis",
                               "verdict": report["verdict"]}) as run_id:
            lineage.log_input(tracker, [run_id, stage_run.parent_id if stage_run.owns else None],
                              data)
            metrics = _metrics(report)
            tracker.log(run_id, params=_params(report, s),
                        metrics={k: float(v) for k, v in metrics.items() if math.isfinite(v)})
            tracker.log_artifact(run_id, report_path(s), "reports")
            for p in report["plots"]:
                tracker.log_artifact(run_id, Path(p), "plots")


def _metrics(report: dict[str, Any]) -> dict[str, float]:
    s = report["summary"]
    metrics = {
        "before.rmse": s["rmse_before"], "after.rmse": s["rmse_after"],
        "before.heldout_rmse": s["heldout_rmse_before"],
        "after.heldout_rmse": s["heldout_rmse_after"],
        "heldout_reduction": s["heldout_reduction"],
        "n_effects": float(len(report["effects"])),
    }
    for i, e in enumerate(report["effects"]):
        metrics[f"effect{i + 1}.heldout_rmse_after"] = e["heldout_rmse_after"]
    if report.get("base_misfit"):
        metrics["base_misfit_ratio"] = report["base_misfit"]["ratio"]
    return metrics


def _params(report: dict[str, Any], s: Settings) -> dict[str, Any]:
    params = {"source": report["source"], "base_family": report["base_family"],
              "base_params": json.dumps(report["base_params"]),
              "effects": ",".join(e["name"] for e in report["effects"]) or "none",
              "measured_within_reach": ",".join(
                  m["name"] for m in report.get("measured_within_reach", [])) or "none",
              **{f"workflow.{k}": v for k, v in dataclasses.asdict(s.workflow).items()}}
    if report.get("given_base"):
        params["given_base"] = report["given_base"]["base"]
        params["given_base.effects"] = ",".join(report["given_base"]["effects"]) or "none"
    return params


def _run_and_write(s: Settings) -> Result:
    result = run(s)
    write(result, s)
    log.info("%s", result.report["headline"])
    return result


def _track(ctx: TrackContext, s: Settings, result: Result) -> None:
    track(ctx.tracker, result, s)


STAGE = Stage("discrepancy", Settings, run=_run_and_write, track=_track, convert=settings,
              errors=(DiscrepancyError,), announce=lambda s, r: str(r.report["headline"]))


def stage(cfg: Any) -> dict[str, Any]:
    """The whole stage from a config (:func:`run`, :func:`write`, :func:`track`); returns the
    report as written."""
    result: Result = STAGE.execute(cfg)
    return result.report


if __name__ == "__main__":
    STAGE.main()
