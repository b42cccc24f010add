"""Lineage: each model run logs the processed datasets it was fitted and scored on (name,
digest, raw source, run ids and raw hashes); changed raw data is a different dataset."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
from mlflow import MlflowClient

from pipelines import lineage, tracking
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from tests.pipelines.pipeline_data import make_dataset, mlflow_store, stage_cfg


def _write_ingest_layout(frame: pd.DataFrame, root: Path, raw_hashes: dict[str, str]) -> Path:
    """The ingest's layout: ``samples/<run_id>.parquet`` and ``runs.json`` with raw hashes."""
    out = root / "data" / "processed" / "virtual"
    (out / "samples").mkdir(parents=True, exist_ok=True)
    runs = {}
    for run_id, rows in frame.groupby("run_id"):
        rows.reset_index(drop=True).to_parquet(out / "samples" / f"{run_id}.parquet",
                                               index=False)
        runs[str(run_id)] = {"source_hash": raw_hashes[str(run_id)],
                             "source_path": str(root / "data" / "raw" / "virtual" / str(run_id))}
    (out / "runs.json").write_text(json.dumps({"schema_version": "1", "runs": runs}))
    return out


def _inputs(client: MlflowClient, run_id: str) -> dict[str, tuple[str, str, dict[str, str]]]:
    """context -> (dataset name, digest, input tags) of one run."""
    run = client.get_run(run_id)
    out = {}
    for di in run.inputs.dataset_inputs:
        tags = {t.key: t.value for t in di.tags}
        out[tags[lineage.CONTEXT_TAG]] = (di.dataset.name, di.dataset.digest, tags)
    return out


def test_model_runs_log_training_and_validation_datasets_and_raw_changes_show(
        tmp_path: Path) -> None:
    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    raw = {str(r): f"raw{i:04d}" for i, r in enumerate(sorted(data["run_id"].unique()))}
    processed = _write_ingest_layout(data, tmp_path, raw)
    cfg = stage_cfg(tmp_path, families=["linear"],
                    heldout=["triangle_decay", "trapezoid_decay"])
    fits = fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run(cfg, dataset=data)
    mlflow_store(tmp_path)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    parent = tracker.start_run("pipeline", tags={"kind": "parent"})

    def log_once() -> str:
        ids = tracking.log_model_runs(tracker, parent, fits=fits, metrics=metrics,
                                      base_params={}, tags={})
        assert lineage.log_model_inputs(tracker, ids, fits, metrics, processed=processed) == 2
        return ids[0]

    first = log_once()
    client = MlflowClient(tracker.settings.tracking_uri)
    got = _inputs(client, first)
    assert set(got) == {"training", "validation"}
    name, digest, tags = got["training"]
    sine = "phi090_r030_sine_decay_0001"
    assert name == "tsm-bench_phi090_r030:sine_decay" and len(digest) == 16
    assert tags["run_ids"] == sine and tags["raw_hashes"] == f"{sine}={raw[sine]}"
    vname, vdigest, vtags = got["validation"]
    assert vname == "tsm-bench_phi090_r030:trapezoid_decay+triangle_decay"
    assert vtags["run_ids"].split(",") == ["phi090_r030_trapezoid_decay_0001",
                                           "phi090_r030_triangle_decay_0001"]
    # the UI's runs table reads inputs from search_runs: the Dataset column is filled
    listed = tracker.child_runs(parent)[0]
    assert {d.dataset.name for d in listed.inputs.dataset_inputs} == {name, vname}
    source = json.loads(client.get_run(first).inputs.dataset_inputs[0].dataset.source)
    assert source["uri"].startswith(str(tmp_path / "data" / "raw" / "virtual"))

    # the same data logged again: the same datasets (same names and digests)
    again = _inputs(client, log_once())
    assert again["training"][:2] == (name, digest)
    assert again["validation"][:2] == (vname, vdigest)

    # the raw identification run changes (re-recorded): same name, a new digest, and the
    # held-out data it did not touch keeps its digest
    changed = data.copy()
    mask = changed["run_id"] == sine
    changed.loc[mask, "output"] = changed.loc[mask, "output"] + 0.01
    _write_ingest_layout(changed, tmp_path, {**raw, sine: "raw-rerecorded"})
    after = _inputs(client, log_once())
    assert after["training"][0] == name and after["training"][1] != digest
    assert after["training"][2]["raw_hashes"] == f"{sine}=raw-rerecorded"
    assert after["validation"][:2] == (vname, vdigest)
    tracker.end_run(parent)

    # a validate stage's own run: per configuration, its training and validation data
    stage = tracker.start_run("validate", tags={"kind": "parent"})
    assert lineage.log_stage_inputs(tracker, stage, metrics, processed=processed) == 2
    staged = _inputs(client, stage)
    assert staged["training"][:2] == after["training"][:2]
    assert staged["validation"][:2] == (vname, vdigest)
    tracker.end_run(stage)


def test_fit_only_runs_log_their_training_data_and_dataset_layout_without_runs_json(
        tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.2, kinds=("sine_decay",))
    cfg = stage_cfg(tmp_path, families=["linear"])
    fits = fit_stage.run(cfg, dataset=data)
    runs = lineage.run_lineage(tmp_path / "nowhere", data)
    assert len(runs) == 2 and {r.raw_hash for r in runs.values()} == {"unknown"}
    one = lineage.run_lineage(tmp_path / "nowhere", data, labels={"tsm-bench_phi015_r030"})
    assert list(one) == ["phi015_r030_sine_decay_0001"]
    # rows, not files, are hashed here: different data, different hash
    other = lineage.run_lineage(tmp_path / "nowhere", make_dataset(
        angles=(15, 90), radii=(30,), dt=0.2, kinds=("sine_decay",), seed=1))
    assert all(other[k].processed_hash != runs[k].processed_hash for k in runs)
    mlflow_store(tmp_path)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    parent = tracker.start_run("fit", tags={"kind": "parent"})
    ids = tracking.log_model_runs(tracker, parent, fits=fits, metrics=None, base_params={},
                                  tags={})
    n = lineage.log_model_inputs(tracker, ids, fits, None, processed=tmp_path / "nowhere",
                                 dataset=data)
    assert n == 2
    client = MlflowClient(tracker.settings.tracking_uri)
    names = sorted(_inputs(client, i)["training"][0] for i in ids)
    assert names == ["tsm-bench_phi015_r030:sine_decay", "tsm-bench_phi090_r030:sine_decay"]


def test_whole_dataset_source_and_measured_inputs_and_their_count(tmp_path: Path) -> None:
    """The inputs of the runs that read data but fit no model (pipeline parent, discrepancy,
    compensation): each names its data with a digest that follows the data, and
    ``python -m pipelines.lineage`` counts the runs that log one."""
    from pipelines.common import dataset_hash

    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    ids = sorted(data["run_id"].unique())
    processed = _write_ingest_layout(data, tmp_path, {r: "a" * 64 for r in ids})
    whole = lineage.processed_input(processed, context="evaluation")
    assert whole.dataset.digest == dataset_hash(processed)
    assert whole.dataset.name == "virtual:all runs"
    index = {r: {"source_hash": "a" * 64, "excitation": {"name": "sine_decay"}} for r in ids}
    src = lineage.source_input(tmp_path / "raw", index, context="analysis")
    again = lineage.source_input(tmp_path / "raw", {**index, ids[0]: {"source_hash": "b" * 64}},
                                 context="analysis")
    assert src.dataset.name == f"raw:{len(ids)} runs"
    assert src.dataset.digest != again.dataset.digest  # a re-recorded run is other data
    assert json.loads(src.dataset.profile)["excitations"] == ["sine_decay"]
    tables = {"t": pd.DataFrame({"rmse": [0.1, 0.2]})}
    measured = lineage.measured_input("compensation:seed001", tables, source="rig",
                                      context="evaluation")
    other = lineage.measured_input("compensation:seed001",
                                   {"t": pd.DataFrame({"rmse": [0.1, 0.3]})}, source="rig",
                                   context="evaluation")
    assert measured.dataset.digest != other.dataset.digest

    mlflow_store(tmp_path)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=tmp_path))
    runs = [tracker.start_run(f"r{i}") for i in range(4)]
    lineage.log_input(tracker, runs[:1], whole)
    lineage.log_input(tracker, [runs[1], None], src)
    lineage.log_input(tracker, runs[2:3], measured)
    for run_id in runs:
        tracker.end_run(run_id)
    assert lineage.input_coverage(tracker.client, [tracker.experiment_id]) == (3, 4)
    assert lineage.main(["--store", tracker.settings.tracking_uri, "--min", "75"]) == 0
    assert lineage.main(["--store", tracker.settings.tracking_uri, "--min", "95"]) == 1
