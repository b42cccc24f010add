"""kill -9 a stage (generate, ingest, fit, validate, report, unseen_shape, discrepancy,
compensate, and a pipeline that registers its champions) at a random moment, run the same
command again: it completes, leaves no temporary file and no RUNNING MLflow run, and its
outputs are byte-identical to those of an uninterrupted run.

Each round kills ``TSM_CRASH_KILLS`` (default 2, so `make test` stays inside its 5 minutes) of
the nine stages, chosen at random, each at a random moment within its uninterrupted duration,
and kills fit once more the moment it has a RUNNING MLflow run (a window random moments seldom
hit). A killed stage starts from the folder and MLflow store the uninterrupted pipeline left
before it, and after the same command again the whole folder's outputs must equal what the
uninterrupted pipeline had after that stage.
``TSM_CRASH_ROUNDS=<n>`` repeats the round n times (default 1: about a minute);
``TSM_CRASH_KILLS=9`` kills every stage; ``TSM_CRASH_SEED`` replays one sequence.

Each stage is its own process, started from a fork server that has imported the stage
modules once (:mod:`tests.pipelines.stage_process`): the same command and a real SIGKILL,
without four seconds of imports before every start.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import sqlite3
import tempfile
import time
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from mlflow import MlflowClient

from rig_io.atomic import host_tag, is_temporary
from tests.pipelines import stage_process
from tests.pipelines.pipeline_data import mlflow_store

# kill -9 of stages in subprocesses: `make test-fast` leaves these out
pytestmark = pytest.mark.slow

#: Wall-clock columns of the compensation tables (solver and fit times).
TIMING_COLUMNS = ("fit_s", "mean_ms", "median_ms", "ratio_to_ours")

STAGES: dict[str, list[str]] = {
    "generate": ["pipelines.generate", "campaign=quick", "campaign.radii_mm=[30,60,75]",
                 "campaign.excitations=[{kind:sine_decay,amplitudes_mm:[3.0],"
                 "periods_per_amplitude:2,frequency_hz:0.5}]", "n_jobs=1"],
    "ingest": ["pipelines.ingest"],
    "fit": ["pipelines.fit", "families=[linear,gamma]", "n_jobs=1"],
    "validate": ["pipelines.validate", "n_jobs=1", "progress=false"],
    "report": ["pipelines.report", "n_jobs=1", "plots.per_configuration=false"],
    "unseen_shape": ["pipelines.unseen_shape", "n_jobs=1"],
    # one run per configuration here: the workflow splits each in time
    # (no plots and no check of the base against the other families: what is killed here is
    # the stage's writing of its report and MLflow run, the report stage writes plots)
    "discrepancy": ["pipelines.discrepancy", "base_family=gamma", "progress=false",
                    "plots=false", "base_check=false"],
    # the papers' compensation experiments (the smoke size, shorter profiles: what is killed
    # and recovered is the stage's writing, not the length of its runs), on the virtual rig
    "compensate": ["pipelines.compensate", "experiment=compensation_quick", "plots=false",
                   "seed001.profiles={mixed:1.0}",
                   "seed001.families=[gamma]", "seed001.shape_aware.curve_angles_deg=[15,75]",
                   "seed001.timing.steps={exact:20,bounded:5,nelder-mead:2,slsqp:2,"
                   "interior-point:1}",
                   "seed000.tracking.duration_s=2.0", "seed002.duration_s=1.0",
                   "seed000.ga={maxiter:3,popsize:4,max_samples:200}"],
    # the champions' registration runs at the end of a pipeline that fitted and validated
    "registry": ["pipelines.run_all", "stages=[fit,validate]", "n_jobs=1",
                 "tracking.registry.enabled=true", 'overrides.fit=["families=[linear,gamma]"]'],
}


def _args(stage: str, root: Path) -> list[str]:
    _, *args = STAGES[stage]
    quiet = [] if stage in ("validate", "report", "unseen_shape", "discrepancy") \
        else ["progress=false"]
    return [*args, f"paths.root={root}", *quiet, f"hydra.run.dir={root}/outputs/{stage}"]


def _env() -> dict[str, str]:
    env = {**os.environ, "MPLBACKEND": "Agg", "HYDRA_FULL_ERROR": "1"}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    return env


def _start(stage: str, root: Path) -> BaseProcess:
    """``python -m pipelines.<stage> ...`` in ``root``, as its own process (stage_process)."""
    return stage_process.start(STAGES[stage][0], _args(stage, root), cwd=root, env=_env(),
                               log=root.parent / f"{stage}.log")


def _run(stage: str, root: Path) -> float:
    t0 = time.perf_counter()
    log = root.parent / f"{stage}.log"
    status = stage_process.run(STAGES[stage][0], _args(stage, root), cwd=root, env=_env(),
                               log=log, timeout=300)
    assert status == 0, f"{stage}: {log.read_text()[-3000:]}"
    return time.perf_counter() - t0


def _kill_at(stage: str, root: Path, after_s: float) -> tuple[int, bool]:
    """Start ``stage``, SIGKILL it after ``after_s``; (pid, whether it was still running)."""
    proc = _start(stage, root)
    assert proc.pid is not None
    proc.join(after_s)
    if proc.exitcode is None:
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        return proc.pid, True
    return proc.pid, False


def _kill_when_running(stage: str, root: Path) -> tuple[int, bool]:
    """Start ``stage`` and SIGKILL it the moment it has a RUNNING run in the MLflow store
    (the window a random moment seldom hits); (pid, whether it was killed there)."""
    db = root / "mlflow.db"
    proc = _start(stage, root)
    assert proc.pid is not None
    deadline = time.monotonic() + 120
    while proc.exitcode is None and time.monotonic() < deadline:
        try:
            with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=0.2) as con:
                n = con.execute("SELECT count(*) FROM runs WHERE status = 'RUNNING' "
                                "AND run_uuid IN (SELECT run_uuid FROM tags WHERE key = "
                                "'tsm.pid' AND value = ?)", (str(proc.pid),)).fetchone()[0]
        except sqlite3.Error:
            n = 0
        if n:
            os.kill(proc.pid, signal.SIGKILL)
            proc.join()
            return proc.pid, True
        time.sleep(0.01)
    proc.join()
    return proc.pid, False


def _outputs(root: Path) -> dict[str, object]:
    """Every output file under ``root/data`` as bytes, except those that carry wall-clock
    time: ``runs.json`` without its ``ingested_at`` fields, a model file without
    ``fit_seconds``, the discrepancy report without ``elapsed_s``, the compensation tables
    without their timing columns (everything else of these is compared), the compensation
    report by its headings, the pipeline's stage timings by their names, and the ingest
    report, which describes the last invocation (timings, "unchanged" vs "processed"), by its
    accepted ids."""
    out: dict[str, object] = {}
    for p in sorted((root / "data").rglob("*")):
        if not p.is_file():
            continue
        rel = p.relative_to(root).as_posix()
        if p.name == "runs.json":
            doc = json.loads(p.read_text())
            for meta in doc["runs"].values():
                meta.pop("ingested_at")
            out[rel] = doc
        elif p.name == "ingest_report.json":
            out[rel] = sorted(a["run_id"] for a in json.loads(p.read_text())["accepted"])
        elif p.name == "pipeline_timing.json":  # wall-clock seconds per stage
            out[rel] = sorted(json.loads(p.read_text()))
        elif p.suffix == ".parquet" and "reports/compensation" in rel:
            # solver and fit timings are wall-clock; every result column is compared
            df = pd.read_parquet(p)
            out[rel] = df.drop(columns=[c for c in TIMING_COLUMNS if c in df]).to_dict("list")
        elif p.name == "compensation.md":  # its timing table is wall-clock: the headings
            out[rel] = [ln for ln in p.read_text().splitlines() if ln.startswith("#")]
        elif p.name == "discrepancy.json":
            doc = json.loads(p.read_text())
            doc.pop("elapsed_s")
            out[rel] = doc
        elif "interim/models" in rel:
            doc = json.loads(p.read_text())
            doc.pop("fit_seconds")
            out[rel] = doc
        else:
            out[rel] = p.read_bytes()
    return out


def _check_recovered(root: Path, expected: dict[str, object], killed: list[Any],
                     where: str) -> None:
    """No temporary file, no staging folder of a killed process, no RUNNING run, and the
    outputs of an uninterrupted run."""
    leftovers = [p for p in root.rglob("*") if is_temporary(p.name)]
    assert leftovers == [], where
    staging = [p for p in Path(tempfile.gettempdir()).glob(f"tsm-mlflow-{host_tag()}-*")
               if any(p.name.startswith(f"tsm-mlflow-{host_tag()}-{pid}-")
                      for _, _, pid, _ in killed)]
    assert staging == [], where
    client = MlflowClient(f"sqlite:///{root}/mlflow.db")
    ids = [e.experiment_id for e in client.search_experiments()]
    running = client.search_runs(ids, "attributes.status = 'RUNNING'") if ids else []
    assert running == [], where
    assert _outputs(root) == expected, where


def test_kill_minus_9_at_random_moments_then_the_same_command_recovers(
        tmp_path: Path) -> None:
    seed = int(os.environ.get("TSM_CRASH_SEED", time.time_ns() % 1_000_000))
    rounds = int(os.environ.get("TSM_CRASH_ROUNDS", "1"))
    n_kills = int(os.environ.get("TSM_CRASH_KILLS", "2"))
    rng = random.Random(seed)
    root = tmp_path / "root"
    root.mkdir()
    mlflow_store(root)
    # The victims of every round: a random moment for each, and fit once more inside its
    # MLflow logging every round (a window random moments seldom hit).
    names = list(STAGES)
    plan = [sorted(rng.sample(names, min(n_kills, len(names))), key=names.index)
            for _ in range(rounds)]
    # The uninterrupted pipeline up to the last victim, keeping the folder (files and MLflow
    # store) as each stage found it and the outputs each stage left: a killed stage is
    # replayed from the state it started from, so the stages before it need not run again.
    last = max(names.index(v) for victims in plan for v in [*victims, "fit"])
    durations: dict[str, float] = {}
    after: dict[str, dict[str, object]] = {}
    before: dict[str, Path] = {}
    for stage in names[:last + 1]:
        before[stage] = tmp_path / "before" / stage
        shutil.copytree(root, before[stage], symlinks=True)
        durations[stage] = _run(stage, root)
        after[stage] = _outputs(root)
    assert len([k for k in after["ingest"] if "/samples/" in k]) == 6
    if "report" in after:
        assert "data/reports/report.md" in after["report"]
    killed: list[tuple[str, float, int, bool]] = []
    for victims in plan:
        for stage in names[:last + 1]:
            kills = (["random"] if stage in victims else []) + (["mlflow"] if stage == "fit"
                                                                else [])
            for kind in kills:
                shutil.rmtree(root)
                shutil.copytree(before[stage], root, symlinks=True)
                if kind == "random":
                    moment = rng.uniform(0.2, 0.9 * durations[stage])
                    killed.append((stage, round(moment, 2), *_kill_at(stage, root, moment)))
                else:
                    pid, hit = _kill_when_running(stage, root)
                    assert hit, "fit never showed a RUNNING run to be killed in"
                    killed.append(("fit@mlflow", -1.0, pid, hit))
                _run(stage, root)
                _check_recovered(root, after[stage], killed, f"seed {seed}, kills {killed}")
    assert any(hit for *_, hit in killed), f"no kill landed while a stage ran: {killed}"


def test_a_campaign_killed_before_its_book_is_final_is_completed(tmp_path: Path) -> None:
    """The case that used to break every later run: runs on disk the book did not list."""
    root = tmp_path / "root"
    root.mkdir()
    _run("generate", root)
    raw = root / "data" / "raw" / "virtual"
    book = json.loads((raw / "campaign.json").read_text())
    reference = {p.relative_to(raw).as_posix(): p.read_bytes() for p in raw.rglob("*")
                 if p.is_file()}
    # as if killed after the second run landed and before the book said so
    for rid in list(book["runs"])[1:]:
        book["runs"][rid]["status"] = "pending"
    (raw / "campaign.json").write_text(json.dumps(book))
    shutil.rmtree(raw / list(book["runs"])[-1])
    _run("generate", root)
    again = {p.relative_to(raw).as_posix(): p.read_bytes() for p in raw.rglob("*")
             if p.is_file()}
    assert again == reference
