"""Stage validate: the metrics table (columns, splits, formulas against hand-computed values),
the cross-excitation matrix, predictions files and caching."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipelines import stages
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from tests.pipelines.pipeline_data import make_dataset, stage_cfg

EXPECTED_COLUMNS = [
    "family", "rig", "curve_angle_deg", "radius_mm", "fit_excitation", "eval_excitation",
    "split", "n", "sse", "mse", "rmse", "std_error", "mean_error", "error_range",
    "mean_abs_error", "var_error",
]


def _run(run_id: str, kind: str, u: list[float], y: list[float]) -> pd.DataFrame:
    return pd.DataFrame({
        "run_id": run_id, "rig": "tsm-bench", "curve_angle_deg": 60.0, "radius_mm": 45.0,
        "excitation": kind, "t_s": 0.01 * np.arange(len(u)), "input": u, "output": y,
    })


def _hand_dataset() -> pd.DataFrame:
    # off any grid: an exact fit to a record on a grid (a quantised output) is refused
    u = 3.0 * np.sin(np.linspace(0.1, 6.0, 50))
    return pd.concat([
        _run("a_sine", "sine_decay", list(u), list(u)),             # identity: gain 1, offset 0
        _run("b_tri", "triangle_decay", [0, 1, 2], [1, 0, 4]),        # e = [1, -1, 2]
        _run("c_trap1", "trapezoid_decay", [0.5, 1.5], [1.5, 2.5]),   # e = [1, 1]
        _run("c_trap2", "trapezoid_decay", [2.0, 3.0], [1.0, 2.0]),   # e = [-1, -1]
    ], ignore_index=True)


def test_metrics_match_hand_computed_values(tmp_path: Path) -> None:
    data = _hand_dataset()
    fit_stage.run(stage_cfg(tmp_path, families=["linear"]), dataset=data)
    metrics, errors = validate_stage.run(stage_cfg(tmp_path, heldout=["triangle_decay",
                                                                 "trapezoid_decay"]),
                                         dataset=data)
    assert errors == []
    assert list(metrics.columns) == EXPECTED_COLUMNS
    rows = metrics.set_index("eval_excitation")
    assert list(metrics["split"]) == ["fit", "heldout", "heldout"]
    fit = rows.loc["sine_decay"]
    assert fit["n"] == 50 and fit["sse"] == pytest.approx(0.0, abs=1e-20)
    tri = rows.loc["triangle_decay"]  # e = [1, -1, 2]
    assert tri["n"] == 3
    assert tri["sse"] == pytest.approx(6.0)
    assert tri["mse"] == pytest.approx(2.0)
    assert tri["rmse"] == pytest.approx(math.sqrt(2.0))
    assert tri["mean_error"] == pytest.approx(2 / 3)
    assert tri["std_error"] == pytest.approx(math.sqrt((42 / 9) / 2))  # S_{n-1}
    assert tri["error_range"] == pytest.approx(3.0)
    assert tri["mean_abs_error"] == pytest.approx(4 / 3)
    assert tri["var_error"] == pytest.approx(42 / 27)  # 1/N variance (seed 000 eq. 28)
    trap = rows.loc["trapezoid_decay"]  # two runs pooled: e = [1, 1, -1, -1]
    assert trap["n"] == 4 and trap["sse"] == pytest.approx(4.0)
    assert trap["mean_error"] == pytest.approx(0.0, abs=1e-12)
    assert trap["std_error"] == pytest.approx(math.sqrt(4 / 3))
    assert trap["var_error"] == pytest.approx(1.0)
    assert trap["error_range"] == pytest.approx(2.0)
    # the written tables hold the same rows
    on_disk = pd.read_parquet(tmp_path / "data/reports/metrics.parquet")
    pd.testing.assert_frame_equal(on_disk, metrics)
    csv = pd.read_csv(tmp_path / "data/reports/metrics.csv")
    assert list(csv.columns) == EXPECTED_COLUMNS and len(csv) == 3


def test_every_family_configuration_and_excitation_gets_a_row(tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 90), radii=(30, 75), dt=0.2)
    fit_stage.run(stage_cfg(tmp_path), dataset=data)  # linear + gamma
    metrics, _ = validate_stage.run(stage_cfg(tmp_path, heldout=["triangle_decay",
                                                            "trapezoid_decay"]), dataset=data)
    assert len(metrics) == 2 * 4 * 3
    per_model = metrics.groupby(["family", "curve_angle_deg", "radius_mm"]).size()
    assert (per_model == 3).all()
    assert (metrics[metrics["split"] == "fit"]["eval_excitation"] == "sine_decay").all()
    assert metrics[["sse", "rmse", "std_error"]].notna().all().all()
    assert (metrics["sse"] > 0).all()
    preds = pd.read_parquet(tmp_path / "data/interim/predictions/tsm-bench_phi090_r030.parquet")
    assert set(preds.columns) == set(stages.PREDICTION_COLUMNS)
    assert set(preds["family"].astype(str)) == {"linear", "gamma"}


def test_cross_excitation_matrix(tmp_path: Path) -> None:
    data = make_dataset(angles=(45,), radii=(60,), dt=0.2)
    kinds = ["sine_decay", "triangle_decay", "trapezoid_decay"]
    cfg = stage_cfg(tmp_path, families=["linear"], fit_excitations=kinds)
    fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run({**cfg, "heldout": [], "cross": True}, dataset=data)
    assert len(metrics) == 9
    pairs = set(zip(metrics["fit_excitation"], metrics["eval_excitation"], strict=True))
    assert pairs == {(a, b) for a in kinds for b in kinds}
    assert ((metrics["fit_excitation"] == metrics["eval_excitation"])
            == (metrics["split"] == "fit")).all()
    # the report shows the matrix (mean RMSE, identification x evaluation excitation)
    from pipelines.core import report as report_stage

    report_stage.run({**cfg, "fit_excitation": "sine_decay", "plots": {"dpi": 30}})
    md = (tmp_path / "data/reports/report.md").read_text()
    assert "Cross-excitation matrix" in md
    assert "| linear | triangle_decay |" in md
    # without cross only the identification excitation itself is evaluated
    only_fit, _ = validate_stage.run({**cfg, "heldout": [], "cross": False}, dataset=data)
    assert (only_fit["split"] == "fit").all() and len(only_fit) == 3


def test_unchanged_configurations_are_read_back_not_recomputed(tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.2)
    cfg = stage_cfg(tmp_path, families=["linear"], heldout=["triangle_decay"])
    fit_stage.run(cfg, dataset=data)
    first, _ = validate_stage.run(cfg, dataset=data)
    pred_dir = tmp_path / "data/interim/predictions"
    before = {p.name: p.stat().st_mtime_ns for p in pred_dir.iterdir()}
    second, _ = validate_stage.run(cfg, dataset=data)
    pd.testing.assert_frame_equal(first, second)
    assert {p.name: p.stat().st_mtime_ns for p in pred_dir.iterdir()} == before
    # another held-out list is another key: recomputed
    third, _ = validate_stage.run({**cfg, "heldout": ["trapezoid_decay"]}, dataset=data)
    assert set(third["eval_excitation"]) == {"sine_decay", "trapezoid_decay"}


def test_no_models_is_a_clear_error(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), dt=0.2)
    with pytest.raises(stages.PipelineError, match="no fitted model"):
        validate_stage.run(stage_cfg(tmp_path), dataset=data)
