"""MLflow runs never stay RUNNING after their process is gone; staging folders of dead
processes are removed."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from pipelines import tracking
from pipelines.tracking import HOST_TAG, PID_TAG, Tracker, TrackingSettings
from rig_io.atomic import host_tag
from tests.pipelines.pipeline_data import mlflow_store


def _dead_pid() -> int:
    out = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                         capture_output=True, text=True, check=True).stdout
    return int(out)


def test_runs_of_dead_processes_are_ended_failed_at_the_next_start(tmp_path: Path) -> None:
    mlflow_store(tmp_path)
    tracker = Tracker(TrackingSettings(root=tmp_path))
    dead = tracker.start_run("killed stage", tags={PID_TAG: _dead_pid()})
    live = tracker.start_run("this process")  # owner tags of this (live) process
    other_host = tracker.start_run("elsewhere", tags={HOST_TAG: "0" * 8, PID_TAG: 1})
    untagged = tracker.start_run("old run", tags={PID_TAG: "", HOST_TAG: ""})
    again = Tracker(TrackingSettings(root=tmp_path))
    again.init_store()  # what every stage does when it starts
    status = {r: again.client.get_run(r).info.status
              for r in (dead, live, other_host, untagged)}
    assert status == {dead: "FAILED", live: "RUNNING", other_host: "RUNNING",
                      untagged: "RUNNING"}
    assert again.client.get_run(live).data.tags[HOST_TAG] == host_tag()


def test_a_failing_stage_ends_its_parent_failed(tmp_path: Path) -> None:
    mlflow_store(tmp_path)
    tracker = Tracker(TrackingSettings(root=tmp_path))
    with pytest.raises(RuntimeError):
        with tracking.StageRun(tracker, "fit") as stage:
            raise RuntimeError("stage broke")
    assert stage.parent_id is not None
    assert tracker.client.get_run(stage.parent_id).info.status == "FAILED"


def test_staging_folders_of_dead_processes_are_removed(tmp_path: Path) -> None:
    pid = _dead_pid()
    dead = tmp_path / f"tsm-mlflow-{host_tag()}-{pid}-abc"
    live = tmp_path / f"{tracking.staging_prefix()}def"
    unrelated = tmp_path / "tsm-mlflow-template-2.x.db"
    for d in (dead, live):
        (d / "0").mkdir(parents=True)
    unrelated.write_text("template")
    assert tracking.clean_staging_leftovers(tmp_path) == [dead]
    assert live.is_dir() and unrelated.is_file() and not dead.exists()


@pytest.mark.slow
def test_a_sweep_with_a_failing_job_leaves_no_run_running(tmp_path: Path) -> None:
    import os

    from mlflow import MlflowClient

    from tests.pipelines.pipeline_data import make_dataset, write_dataset

    write_dataset(make_dataset(angles=(15,), radii=(30,), dt=0.25, periods=1,
                               kinds=("sine_decay",)), tmp_path)
    mlflow_store(tmp_path)
    env = {**os.environ, "MPLBACKEND": "Agg"}
    env.pop("TSM_MLFLOW_PARENT_RUN_ID", None)
    proc = subprocess.run(
        [sys.executable, "-m", "pipelines.fit", "-m", "families=[linear]",
         "config.curve_angle_deg=15,33", f"paths.root={tmp_path}", "progress=false",
         f"hydra.sweep.dir={tmp_path}/multirun",  # no 33 deg data: that job fails
         "hydra.launcher.n_jobs=1"],  # the pool's failure path; a second worker adds nothing
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "no configuration matches" in proc.stderr
    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    runs = client.search_runs([exp.experiment_id])
    parent = [r for r in runs if r.data.tags.get("sweep") == "true"]
    assert len(parent) == 1 and parent[0].info.status == "FAILED"
    assert "RUNNING" not in {r.info.status for r in runs}


def test_a_pool_worker_ends_itself_when_its_parent_is_killed() -> None:
    import os
    import signal
    import time

    from rig_io.atomic import pid_alive

    worker = ("import os, sys, time; from pipelines.common import exit_with_parent; "
              "exit_with_parent(int(sys.argv[1]), poll_s=0.05); print('ready', flush=True); "
              "time.sleep(60)")
    parent = ("import os, subprocess, sys, time; "
              f"p = subprocess.Popen([sys.executable, '-c', {worker!r}, str(os.getpid())], "
              "stdout=subprocess.PIPE, text=True); p.stdout.readline(); "
              "print(p.pid, flush=True); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    child = int(proc.stdout.readline())
    assert pid_alive(child)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    while pid_alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not pid_alive(child)
