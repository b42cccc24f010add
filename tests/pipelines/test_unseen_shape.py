"""Stage unseen_shape: leave-one-configuration-out of own, nearest and shape-aware models."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hysteresis.gamma import GammaModel
from pipelines.core import fit as fit_stage
from pipelines.core import unseen_shape
from tests.pipelines.pipeline_data import make_dataset, stage_cfg

ANGLES = (15, 30, 45, 60, 75, 90)


def _plant(phi: float, r: float) -> GammaModel:
    """A Gamma_11 plant whose backlash (weight on the wide plays) grows with angle and 1/R."""
    th, k = np.radians(phi), 30.0 / r
    m = GammaModel()
    m.thresholds_ = np.linspace(0.0, 2.0, 11)
    q = np.exp(-np.arange(11) / (0.5 + 2.0 * th * (0.6 + 0.4 * k)))
    m.weights_ = q / q.sum()
    m.offset_ = 0.0
    return m


@pytest.fixture(scope="module")
def fitted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame, pd.DataFrame]:
    root = tmp_path_factory.mktemp("unseen")
    data = make_dataset(angles=ANGLES, radii=(30, 75), kinds=("sine_decay", "triangle_decay"),
                        dt=0.05, periods=1)
    rng = np.random.default_rng(3)
    for rows in data.groupby("run_id").groups.values():
        first = data.loc[rows[0]]
        plant = _plant(float(first["curve_angle_deg"]), float(first["radius_mm"]))
        y = plant.predict(data.loc[rows, "input"].to_numpy())
        data.loc[rows, "output"] = y + 0.01 * rng.normal(size=y.size)
    fits = fit_stage.run(stage_cfg(root), dataset=data)
    return root, data, fits


def _cfg(root: Path, **extra: object) -> dict[str, object]:
    base: dict[str, object] = {
        "fit_excitation": "sine_decay", "eval_excitations": ["triangle_decay"],
        "families": None, "plot": True, "dpi": 40,
        "estimator": {"angle_degree": 3, "curvature_degree": 1, "ridge": 1e-3}}
    return stage_cfg(root, **{**base, **extra})


def test_leave_one_out_table_summary_and_cache(
        fitted: tuple[Path, pd.DataFrame, pd.DataFrame]) -> None:
    root, data, fits = fitted
    result = unseen_shape.run(_cfg(root), dataset=data, fits=fits)
    table = result.table
    assert tuple(table.columns) == unseen_shape.COLUMNS
    assert len(table) == 2 * 12 * 3 and table["rmse"].notna().all()
    assert set(table["predictor"]) == {"own", "nearest", "shape_aware"}
    wide = table.pivot_table(index=["family", "curve_angle_deg", "radius_mm"],
                             columns="predictor", values="rmse")
    gamma = wide.loc["gamma"]
    # the backlash grows smoothly with the shape: the shape-aware Gamma predicts an unseen
    # shape nearly as well as the shape's own model, and far better than the nearest one
    assert gamma["shape_aware"].median() < 1.3 * gamma["own"].median()
    assert gamma["shape_aware"].median() < 0.5 * gamma["nearest"].median()
    assert (gamma["shape_aware"] < gamma["nearest"]).sum() >= 10
    summary = result.summary.set_index("family")
    assert summary.loc["gamma", "configurations"] == 12
    assert summary.loc["gamma", "ratio_shape_aware_to_own"] == pytest.approx(
        gamma["shape_aware"].median() / gamma["own"].median())
    assert result.best_family == "gamma"
    reports = root / "data" / "reports"
    assert (reports / "plots" / "unseen_shape.png").stat().st_size > 1000
    pd.testing.assert_frame_equal(pd.read_parquet(reports / "unseen_shape.parquet"), table)
    metrics = result.mlflow_metrics()
    assert metrics["unseen_shape.gamma.shape_aware_below_nearest"] == float(
        summary.loc["gamma", "shape_aware_below_nearest"])
    again = unseen_shape.run(_cfg(root), dataset=data, fits=fits)
    assert again.cached
    pd.testing.assert_frame_equal(again.table, table)
    other = unseen_shape.run(_cfg(root, estimator={"method": "rbf"}), dataset=data, fits=fits)
    assert not other.cached
    own_rows = table[table["predictor"] == "own"]["rmse"].to_numpy()
    np.testing.assert_allclose(other.table[other.table["predictor"] == "own"]["rmse"], own_rows)


def test_summary_targets() -> None:
    rows = []
    for i in range(24):
        for pred, value in (("own", 1.0), ("nearest", 2.0 if i < 20 else 0.5),
                            ("shape_aware", 1.1)):
            rows.append({"family": "gamma", "curve_angle_deg": float(i), "radius_mm": 30.0,
                         "predictor": pred, "rmse": value})
    summary = unseen_shape.summarise(pd.DataFrame(rows)).iloc[0]
    assert summary["shape_aware_below_nearest"] == 20 and summary["meets_targets"]
    rows[-1 - 3 * 4]["rmse"] = 3.0  # one configuration more where nearest wins
    summary = unseen_shape.summarise(pd.DataFrame(rows)).iloc[0]
    assert summary["shape_aware_below_nearest"] == 19 and not summary["meets_targets"]


def test_too_few_configurations_are_skipped(
        fitted: tuple[Path, pd.DataFrame, pd.DataFrame], tmp_path: Path) -> None:
    _, data, fits = fitted
    cfg = _cfg(tmp_path, config={"rig": None, "curve_angle_deg": [15, 90], "radius_mm": 30})
    result = unseen_shape.run(cfg, dataset=data, fits=fits)
    assert result.table.empty and result.best_family is None


def test_the_report_shows_the_summary(fitted: tuple[Path, pd.DataFrame, pd.DataFrame]) -> None:
    from pipelines.core import report as report_stage
    from pipelines.core import validate as validate_stage

    root, data, fits = fitted
    unseen_shape.run(_cfg(root), dataset=data, fits=fits)
    validate_stage.run(stage_cfg(root, heldout=["triangle_decay"]), dataset=data, fits=fits)
    rcfg = stage_cfg(root, fit_excitation="sine_decay", metric="rmse", formats=["md"],
                     plots={"per_configuration": False, "dpi": 30, "max_points": 200})
    first = report_stage.run(rcfg)
    md = (root / "data" / "reports" / "report.md").read_text()
    assert "Shapes no model was fitted on" in md and "plots/unseen_shape.png" in md
    summary = pd.read_csv(root / "data" / "reports" / "unseen_shape_summary.csv")
    assert f"{summary['median_shape_aware'].iloc[0]:.3g}" in md
    # a changed unseen-shape summary redraws the report (it is part of the report's key)
    assert report_stage.run(rcfg).cached
    unseen_shape.run(_cfg(root, families=["gamma"]), dataset=data, fits=fits)
    again = report_stage.run(rcfg)
    assert not again.cached and again.key != first.key


def test_closed_form_folds_equal_refitting_every_fold(
        fitted: tuple[Path, pd.DataFrame, pd.DataFrame], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    _, data, fits = fitted
    fast = unseen_shape.run(_cfg(tmp_path / "fast", plot=False), dataset=data, fits=fits)
    solved: list[int] = []

    def refit_every_fold(shapes: object, models: list[object], **params: object) -> list[None]:
        solved.append(len(models))
        return [None] * len(models)

    monkeypatch.setattr(unseen_shape, "leave_one_out_models", refit_every_fold)
    slow = unseen_shape.run(_cfg(tmp_path / "slow", plot=False), dataset=data, fits=fits)
    assert solved == [12, 12]  # one regression per family, not one per fold
    pd.testing.assert_frame_equal(fast.table, slow.table, check_exact=False, rtol=1e-7)
