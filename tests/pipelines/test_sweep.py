"""Hydra multirun sweep with the joblib launcher: 16 parallel jobs, every one lands in MLflow
under the sweep's single parent run (no lost run, no SQLite failure)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from mlflow import MlflowClient

from tests.pipelines.pipeline_data import make_dataset, mlflow_store, write_dataset

# a 16-job Hydra sweep in subprocesses: `make test-fast` leaves these out
pytestmark = pytest.mark.slow

ANGLES = (15, 30, 45, 60)
RADII = (30, 45, 60, 75)


def test_sixteen_job_sweep_lands_under_one_parent(tmp_path: Path) -> None:
    write_dataset(make_dataset(angles=ANGLES, radii=RADII, dt=0.25, periods=1,
                               kinds=("sine_decay",)), tmp_path)
    mlflow_store(tmp_path)
    cmd = [sys.executable, "-m", "pipelines.fit", "-m", "families=[linear]",
           f"config.curve_angle_deg={','.join(map(str, ANGLES))}",
           f"config.radius_mm={','.join(map(str, RADII))}",
           f"paths.root={tmp_path}", f"hydra.sweep.dir={tmp_path / 'multirun'}",
           "progress=false"]
    env = {**os.environ, "HYDRA_FULL_ERROR": "1", "MPLBACKEND": "Agg"}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    runs = client.search_runs([exp.experiment_id], max_results=1000)
    parents = [r for r in runs if r.data.tags.get("kind") == "parent"]
    children = [r for r in runs if r.data.tags.get("kind") == "model"]
    assert len(parents) == 1 and len(runs) == 17
    parent = parents[0]
    assert parent.data.tags["sweep"] == "true" and parent.info.status == "FINISHED"
    assert parent.data.tags["mlflow.note.content"].startswith("A Hydra sweep of fit (")
    assert (tmp_path / "multirun" / "mlflow_parent_run_id").read_text() == parent.info.run_id
    assert len(children) == 16
    assert {r.data.tags["mlflow.parentRunId"] for r in children} == {parent.info.run_id}
    assert {r.info.status for r in children} == {"FINISHED"}
    shapes = {(r.data.tags["curve_angle_deg"], r.data.tags["radius_mm"]) for r in children}
    assert shapes == {(str(a), str(r)) for a in ANGLES for r in RADII}
    assert all("fit.rmse" in r.data.metrics for r in children)
    # each job saved its model and its own .hydra folder went to its run
    assert len(list((tmp_path / "data/interim/models/linear").glob("*.json"))) == 16
    arts = {a.path for a in client.list_artifacts(children[0].info.run_id)}
    assert ".hydra" in arts and "model" in arts


def test_a_fit_that_changes_nothing_logs_nothing_new(tmp_path: Path) -> None:
    write_dataset(make_dataset(angles=(15, 90), radii=(30,), dt=0.25, periods=1,
                               kinds=("sine_decay",)), tmp_path)
    mlflow_store(tmp_path)
    cmd = [sys.executable, "-m", "pipelines.fit", "families=[linear]", f"paths.root={tmp_path}",
           f"hydra.run.dir={tmp_path / 'outputs'}", "progress=false"]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    counts = []
    for _ in range(2):
        proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        exp = client.get_experiment_by_name("tsm-hysteresis")
        counts.append(len(client.search_runs([exp.experiment_id], max_results=1000)))
    assert counts == [3, 3]  # one parent and two models, then nothing
    assert "nothing new logged" in proc.stdout + proc.stderr
