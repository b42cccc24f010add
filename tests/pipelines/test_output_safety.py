"""No write escapes its output folder; a wrong source never deletes processed data; a
damaged processed file is detected and redone."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from pipelines import artifacts
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from pipelines.core.generate import GenerateError, campaign_specs, run_generate
from pipelines.ingest import run_ingest
from rig_io.dataset import read_dataset, read_runs, run_file
from rig_io.errors import RigIOError
from rig_io.folder import write_run_folder
from rig_io.synthetic import make_raw_run
from tests.pipelines.pipeline_data import make_dataset, stage_cfg


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


def _raw_run(src: Path, name: str, *, seed: int = 1, **manifest: object) -> Path:
    folder = write_run_folder(make_raw_run(name, duration_s=4.0, seed=seed), src)
    if manifest:
        doc = json.loads((folder / "manifest.json").read_text())
        doc.update(manifest)
        (folder / "manifest.json").write_text(json.dumps(doc))
    return folder


@pytest.mark.parametrize("bad_id", ["../../escape", "/escape_abs", "sub/dir"])
def test_ingest_never_writes_a_run_id_outside_out(tmp_path: Path, bad_id: str) -> None:
    area = tmp_path / "area"
    src, out = area / "raw", area / "deep" / "out"
    _raw_run(src, "good", seed=1)
    _raw_run(src, "evil", seed=2, run_id=bad_id.replace("/tmp", str(tmp_path)))
    before = _files(tmp_path)
    report = run_ingest(src, out, progress=False)
    assert [a["run_id"] for a in report["accepted"]] == ["good"]
    assert report["n_rejected"] == 1
    reason = report["rejected"][0]["reason"]
    assert "run" in reason and ("unsafe" in reason or "run_id" in reason), reason
    new = _files(tmp_path) - before
    assert new and all(out in p.parents for p in new), sorted(new)
    assert set(read_dataset(out)["run_id"]) == {"good"}


def test_run_file_and_read_dataset_refuse_ids_that_are_not_plain_names(tmp_path: Path) -> None:
    for bad in ("../x", "/abs", "sub/dir", ".."):
        with pytest.raises(RigIOError, match="unsafe run_id"):
            run_file(tmp_path, bad)
    (tmp_path / "samples" / "sub").mkdir(parents=True)
    pd.DataFrame({"a": [1]}).to_parquet(tmp_path / "samples" / "sub" / "dir.parquet")
    with pytest.raises(RigIOError, match="subfolders"):  # never silently left out
        read_dataset(tmp_path)


def test_a_rig_name_with_dotdot_never_makes_fit_or_validate_write_outside_root(
        tmp_path: Path) -> None:
    root = tmp_path / "proj"
    data = make_dataset(angles=(15,), radii=(30,), dt=0.1, rig="../x")
    cfg = stage_cfg(root, families=["linear"])
    with pytest.raises(RigIOError, match="unsafe path component '../x_phi015_r030"):
        fit_stage.run(cfg, dataset=data)
    with pytest.raises(RigIOError, match="unsafe path component"):
        artifacts.prediction_path(root, _config("../x"))
    assert all(root in p.parents for p in _files(tmp_path))


def _config(rig: str) -> object:
    from pipelines.stages import Configuration

    return Configuration(rig, 15.0, 30.0)


def test_generate_refuses_a_run_id_that_leaves_out(tmp_path: Path) -> None:
    spec = campaign_specs(curve_angles_deg=[15], radii_mm=[30])[0]
    spec["run_id"] = "../../escape"
    with pytest.raises(GenerateError, match="unsafe path component '../../escape'"):
        run_generate([spec], tmp_path / "a" / "out", n_jobs=1, progress=False)
    assert _files(tmp_path) == set()


# --------------------------------------------------------------------------------------
# a wrong source is refused and never prunes
# --------------------------------------------------------------------------------------


@pytest.fixture
def ingested(tmp_path: Path) -> tuple[Path, Path, dict[Path, bytes]]:
    src, out = tmp_path / "raw", tmp_path / "out"
    for i in range(2):
        _raw_run(src, f"run{i}", seed=i + 1)
    run_ingest(src, out, progress=False)
    return src, out, {p: p.read_bytes() for p in _files(out)}


def _unchanged(out: Path, before: dict[Path, bytes]) -> bool:
    return {p: p.read_bytes() for p in _files(out)} == before


def test_missing_empty_or_all_rejected_sources_are_refused_and_prune_nothing(
        tmp_path: Path, ingested: tuple[Path, Path, dict[Path, bytes]]) -> None:
    _, out, before = ingested
    with pytest.raises(RigIOError, match="source does not exist"):
        run_ingest(tmp_path / "nowhere", out, progress=False)
    (tmp_path / "empty").mkdir()
    with pytest.raises(RigIOError, match="no raw run found"):
        run_ingest(tmp_path / "empty", out, progress=False)
    bad = tmp_path / "bad"
    _raw_run(bad, "broken", seed=5)
    (bad / "broken" / "manifest.json").write_text("{not json")
    report = run_ingest(bad, out, progress=False)
    assert report["n_rejected"] == 1 and report["removed"] == []
    assert "all 1 run(s) of the source were rejected" in report["refused"]
    before.pop(out / "ingest_report.json")  # the report of this refused ingest
    assert {p: p.read_bytes() for p in _files(out) if p.name != "ingest_report.json"} == before
    assert set(read_dataset(out)["run_id"]) == {"run0", "run1"}


def test_the_hydra_entry_point_exits_non_zero_on_an_empty_source(
        tmp_path: Path, ingested: tuple[Path, Path, dict[Path, bytes]]) -> None:
    import subprocess
    import sys

    _, out, before = ingested
    (tmp_path / "empty").mkdir()
    proc = subprocess.run([sys.executable, "-m", "pipelines.ingest", f"source={tmp_path}/empty",
                           f"out={out}", "progress=false",
                           f"hydra.run.dir={tmp_path}/hydra"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "no raw run found" in proc.stderr
    assert _unchanged(out, before)


def test_one_run_folder_as_source_is_ingested_alone_and_prunes_nothing(
        ingested: tuple[Path, Path, dict[Path, bytes]]) -> None:
    src, out, _ = ingested
    _raw_run(src, "run_new", seed=9)
    report = run_ingest(src / "run_new", out, progress=False)
    assert [(a["run_id"], a["status"]) for a in report["accepted"]] == [("run_new", "processed")]
    assert report["removed"] == []
    assert set(read_runs(out)) == {"run0", "run1", "run_new"}
    assert set(read_dataset(out)["run_id"]) == {"run0", "run1", "run_new"}
    # the same run, from its parent folder, is the same cache entry: not processed again
    again = run_ingest(src, out, progress=False)
    assert {a["run_id"]: a["status"] for a in again["accepted"]} == {
        "run0": "unchanged", "run1": "unchanged", "run_new": "unchanged"}


def test_a_truncated_processed_file_is_detected_and_processed_again(
        ingested: tuple[Path, Path, dict[Path, bytes]]) -> None:
    src, out, before = ingested
    victim = run_file(out, "run0")
    victim.write_bytes(victim.read_bytes()[: victim.stat().st_size // 2])
    report = run_ingest(src, out, progress=False)
    assert {a["run_id"]: a["status"] for a in report["accepted"]} == {
        "run0": "processed", "run1": "unchanged"}
    assert victim.read_bytes() == before[victim]


def test_a_truncated_report_output_is_redrawn_not_trusted(tmp_path: Path) -> None:
    from pipelines.core import report as report_stage

    data = make_dataset(angles=(90,), radii=(30,), dt=0.1)
    cfg = stage_cfg(tmp_path, families=["linear", "gamma"])
    fit_stage.run(cfg, dataset=data)
    validate_stage.run(cfg, dataset=data)
    rcfg = {**cfg, "exemplary": {"rig": "tsm-bench", "curve_angle_deg": 90, "radius_mm": 30},
            "fit_excitation": "sine_decay", "metric": "rmse",
            "plots": {"per_configuration": True, "dpi": 30, "max_points": 200},
            "formats": ["md"]}
    assert not report_stage.run(rcfg).cached
    assert report_stage.run(rcfg).cached
    plot = tmp_path / "data/reports/plots/config_tsm-bench_phi090_r030.png"
    whole = plot.read_bytes()
    plot.write_bytes(whole[: len(whole) // 3])  # e.g. a disk that filled up
    again = report_stage.run(rcfg)
    assert not again.cached and plot.read_bytes() == whole
