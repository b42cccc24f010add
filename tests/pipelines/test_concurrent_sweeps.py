"""Two sweeps started at the same moment on a fresh store: separate sweep folders, separate
parents, one schema migration (serialised by the store lock), no RUNNING run left.

The sweeps run their jobs in-process (Hydra's basic launcher): what races here is the sweeps'
own start (folder, parent run, schema), which every launcher shares; the joblib pool's jobs
landing under one parent are checked by test_sweep, and each pool worker here would only add
another import of the whole stack."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from mlflow import MlflowClient

from tests.pipelines.pipeline_data import make_dataset, write_dataset


@pytest.mark.slow
def test_two_sweeps_started_together_never_share_a_folder_or_race_the_store(
        tmp_path: Path) -> None:
    write_dataset(make_dataset(angles=(15, 30, 60, 90), radii=(30,), dt=0.25, periods=1,
                               kinds=("sine_decay",)), tmp_path)
    assert not (tmp_path / "mlflow.db").exists()  # both processes find no store
    # two sweeps over different shapes (a sweep identical to one already logged logs nothing)
    cmds = [[sys.executable, "-m", "pipelines.fit", "-m", "families=[linear]",
             f"config.curve_angle_deg={angles}", f"paths.root={tmp_path}", "progress=false",
             "hydra/launcher=basic"] for angles in ("15,90", "30,60")]
    env = {**os.environ, "HYDRA_FULL_ERROR": "1", "MPLBACKEND": "Agg"}
    for var in ("TSM_MLFLOW_PARENT_RUN_ID", "TSM_SWEEP_ID"):
        env.pop(var, None)
    procs = [subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for cmd in cmds]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err[-3000:]
    sweeps = sorted(p.parent for p in (tmp_path / "multirun").rglob("mlflow_parent_run_id"))
    assert len(sweeps) == 2  # one folder each, even when started in the same second
    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    runs = client.search_runs([exp.experiment_id], max_results=100)
    parents = {r.info.run_id for r in runs if r.data.tags.get("kind") == "parent"}
    assert parents == {(s / "mlflow_parent_run_id").read_text() for s in sweeps}
    for sweep in sweeps:
        parent = (sweep / "mlflow_parent_run_id").read_text()
        mine = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent]
        assert len(mine) == 2  # both jobs of this sweep, none of the other
        assert sorted(d.name for d in sweep.iterdir() if d.is_dir()) == ["0", "1"]
    assert {r.info.status for r in runs} == {"FINISHED"}
