"""A small ``make pipeline`` end to end: virtual rig -> ingest -> fit -> validate -> report ->
MLflow, on two configurations; then a second run with nothing changed recomputes nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from mlflow import MlflowClient
from mlflow.entities import ViewType

from pipelines.run_all import compose_stage, run_pipeline
from tests.pipelines.pipeline_data import mlflow_store, small_pipeline


def _check_first_outputs(reports: Path) -> pd.DataFrame:
    """The tables, report and timings of the first run; returns its metrics."""
    metrics = pd.read_parquet(reports / "metrics.parquet")
    # 2 families x 2 configurations x (fit + 4 held-out excitations, two evaluation-only)
    assert len(metrics) == 20
    assert set(metrics["eval_excitation"]) == {"sine_decay", "triangle_decay",
                                               "trapezoid_decay", "mixed_sine", "band_random"}
    assert (metrics["sse"] > 0).all() and metrics["rmse"].notna().all()
    # on the virtual rig hysteresis matters: Gamma beats the linear baseline held out, most
    # clearly at the large curve angle
    held = metrics[metrics["split"] == "heldout"].groupby(
        ["curve_angle_deg", "family"])["rmse"].mean()
    assert held[(90.0, "gamma")] < 0.5 * held[(90.0, "linear")]
    gamma = pd.read_parquet(reports / "gamma_weights.parquet")
    assert list(gamma["curve_angle_deg"]) == [15.0, 90.0]
    # the default Gamma's weights are non-negative (conf/family/gamma.yaml)
    q = gamma[[c for c in gamma.columns if c.startswith("q") and c[1:].isdigit()]]
    assert q.shape[1] == 11 and (q.fillna(0.0) >= 0).all().all()
    assert (gamma["weights_sum"] > 0).all() and (gamma["sse"] > 0).all()
    md = (reports / "report.md").read_text()
    assert "plots/elementary_tsm-bench_phi090_r030.png" in md
    general = pd.read_csv(reports / "generalisation.csv")
    assert len(general) == 2 * 4 and (general["configurations"] == 2).all()
    assert "Held-out / in-sample rmse" in md
    timing = json.loads((reports / "pipeline_timing.json").read_text())
    assert {"generate", "ingest", "fit", "validate", "unseen_shape", "report", "tracking",
            "total"} <= set(timing)
    # two configurations: too few to leave one out (needs 3), so an empty table, no error
    assert pd.read_parquet(reports / "unseen_shape.parquet").empty

    return metrics


def test_small_pipeline_end_to_end_and_incremental_rerun(tmp_path: Path) -> None:
    mlflow_store(tmp_path)
    cfg = compose_stage("pipeline", small_pipeline(tmp_path))
    first = run_pipeline(cfg)
    assert first.generate_report is not None and len(first.generate_report["written"]) == 10
    assert first.ingest_report is not None and first.ingest_report["n_rejected"] == 0
    reports = tmp_path / "data" / "reports"
    metrics = _check_first_outputs(reports)

    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    runs = client.search_runs([exp.experiment_id])
    parent = client.get_run(first.parent_run_id)
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parent.info.run_id]
    assert len(runs) == 5 and len(children) == 4
    assert parent.data.tags["complete"] == "true" and parent.info.status == "FINISHED"
    assert "stage_seconds.fit" in parent.data.metrics
    arts = {a.path for a in client.list_artifacts(parent.info.run_id, "report")}
    assert "report/report.md" in arts and "report/report.html" in arts
    child = children[0]
    assert child.data.tags["dataset_hash"] == parent.data.tags["dataset_hash"]
    assert {a.path for a in client.list_artifacts(child.info.run_id, "plots")} >= {
        f"plots/config_{child.data.tags['configuration']}.png"}

    second = run_pipeline(cfg)
    assert second.up_to_date
    assert second.fits is not None and second.fits["cached"].all()
    assert second.report is not None and second.report.cached
    # nothing changed: nothing new is logged (no pointer run, no copies)
    assert second.parent_run_id is None
    assert len(client.search_runs([exp.experiment_id])) == 5
    assert len(client.search_runs([exp.experiment_id], run_view_type=ViewType.ALL)) == 5
    # only the report is made anew: one parent run holds it and points at the models' run
    (reports / "report.html").unlink()
    third = run_pipeline(cfg)
    assert third.report is not None and not third.report.cached
    pointer = client.get_run(third.parent_run_id)
    assert pointer.data.tags["same_as"] == first.parent_run_id
    assert pointer.data.tags["dataset_hash"] == parent.data.tags["dataset_hash"]
    assert len(client.search_runs([exp.experiment_id])) == 6
    pd.testing.assert_frame_equal(pd.read_parquet(reports / "metrics.parquet"), metrics)
