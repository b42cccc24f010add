"""MLflow glue: store initialisation, retries, consistent keys, parent/child runs, and the
up-to-date short cut of run_all."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import mlflow
import pytest
from mlflow import MlflowClient

from pipelines import tracking
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from tests.pipelines.pipeline_data import make_dataset, mlflow_store, stage_cfg


def test_flatten_gives_dotted_string_params() -> None:
    flat = tracking.flatten({"a": {"b": 1, "c": [1, 2]}, "d": None,
                             "e": [{"x": 1.5}], "f": "s"})
    assert flat == {"a.b": "1", "a.c": "[1, 2]", "d": "null", "e.0.x": "1.5", "f": "s"}


def test_retry_survives_a_locked_database_and_not_other_errors() -> None:
    calls = {"n": 0}

    def flaky() -> str:
        calls["n"] += 1
        if calls["n"] < 3:
            raise sqlite3.OperationalError("database is locked")
        return "ok"

    assert tracking.retry(flaky) == "ok" and calls["n"] == 3

    def broken() -> None:
        calls["n"] += 1
        raise ValueError("bad param")

    calls["n"] = 0
    with pytest.raises(ValueError):
        tracking.retry(broken)
    assert calls["n"] == 1


def test_settings_default_to_local_sqlite_store_and_artifacts(tmp_path: Path) -> None:
    s = tracking.settings_from_config({"enabled": True, "uri": None}, root=tmp_path)
    assert s.tracking_uri == f"sqlite:///{tmp_path}/mlflow.db"
    assert s.artifact_uri == (tmp_path / "mlartifacts").as_uri()
    server = tracking.settings_from_config({"uri": "http://h:5000"}, root=tmp_path)
    assert server.tracking_uri == "http://h:5000" and server.artifact_uri is None


def test_child_runs_carry_params_metrics_tags_and_artifacts(tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.2)
    cfg = stage_cfg(tmp_path, heldout=["triangle_decay", "trapezoid_decay"])
    fits = fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run(cfg, dataset=data)
    mlflow_store(tmp_path)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    tracker.init_store()
    tracker.init_store()  # idempotent
    parent = tracker.start_run("pipeline", tags={"kind": "parent"})
    hydra_dir = tmp_path / ".hydra"
    hydra_dir.mkdir()
    (hydra_dir / "config.yaml").write_text("a: 1\n")
    ids = tracking.log_model_runs(tracker, parent, fits=fits, metrics=metrics,
                                  base_params=tracking.flatten({"config": cfg["config"]}),
                                  tags={"dataset_hash": "abc"}, hydra_dir=hydra_dir)
    tracker.end_run(parent)
    assert len(ids) == 4
    children = tracker.child_runs(parent)
    assert sorted(r.info.run_id for r in children) == sorted(ids)
    keys = None
    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    for run in children:
        tags = run.data.tags
        assert tags["dataset_hash"] == "abc" and tags["git_commit"]
        assert tags["family"] in {"linear", "gamma"}
        assert tags["curve_angle_deg"] in {"15", "90"} and tags["radius_mm"] == "30"
        assert run.data.params["family.name"] == tags["family"]
        assert run.data.params["config.curve_angle_deg"] == "null"
        # the same metric keys in every child run (MLflow compare charts them side by side)
        run_keys = {k for k in run.data.metrics if "." in k}
        keys = run_keys if keys is None else keys
        assert run_keys == keys
        assert {"fit.sse", "heldout.rmse", "eval.triangle_decay.rmse",
                "eval.trapezoid_decay.std_error"} <= run_keys
        # the identification record is fit.* only, not repeated as eval.<its excitation>.*
        assert not any(k.startswith(f"eval.{tags['fit_excitation']}.") for k in run_keys)
        # a short name the runs table shows whole, and a description saying what it is
        angle = tags["curve_angle_deg"]
        assert run.info.run_name == f"{tags['family']} {angle}°/30 mm"
        note = tags["mlflow.note.content"]
        assert note.startswith(f"{tags['family']} model of rig tsm-bench (curve angle {angle} "
                               "deg, bend radius 30 mm), identified on sine_decay")
        assert "Held-out RMSE" in note
        arts = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {"model", "metrics.json", ".hydra"} <= arts
        model_json = client.download_artifacts(run.info.run_id, "model/model.json",
                                               str(tmp_path / "dl" / run.info.run_id))
        assert json.loads(Path(model_json).read_text())["family"] == tags["family"]
        assert json.loads(tags["mlflow.loggedArtifacts"]) == [{"path": "metrics.json",
                                                               "type": "table"}]
        row = metrics[(metrics["family"] == tags["family"])
                      & (metrics["curve_angle_deg"] == float(tags["curve_angle_deg"]))
                      & (metrics["split"] == "fit")].iloc[0]
        assert run.data.metrics["fit.sse"] == pytest.approx(row["sse"])
    # MLflow's table API reads the per-run tables back (what the UI's table view uses)
    # (load_table searches through the fluent API, i.e. the global tracking URI)
    mlflow.set_tracking_uri(tracker.settings.tracking_uri)
    try:
        table = client.load_table(tracker.experiment_id, "metrics.json", run_ids=ids)
    finally:
        mlflow.set_tracking_uri(None)
    assert len(table) == len(metrics) and set(table["split"]) == {"fit", "heldout"}


def test_stage_run_attaches_to_an_inherited_parent(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    mlflow_store(tmp_path)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    with tracking.StageRun(tracker, "fit") as own:
        assert own.parent_id is not None
    assert tracker.client.get_run(own.parent_id).info.status == "FINISHED"
    monkeypatch.setenv(tracking.PARENT_ENV, own.parent_id)
    with tracking.StageRun(tracker, "validate") as inherited:
        assert inherited.parent_id == own.parent_id
    monkeypatch.delenv(tracking.PARENT_ENV)
    (tmp_path / tracking.PARENT_FILE).write_text("from-file")
    assert tracking.inherited_parent(tmp_path) == "from-file"
    off = tracking.Tracker(tracking.settings_from_config({"enabled": False}, root=tmp_path))
    with tracking.StageRun(off, "fit") as nothing:
        assert nothing.parent_id is None
