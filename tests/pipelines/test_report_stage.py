"""Stage report: Table 4.1 equivalent, leaderboard, plots and the static report."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hysteresis.gamma import GammaModel
from hysteresis.play import play_matrix
from pipelines import stages
from pipelines.core import fit as fit_stage
from pipelines.core import report as report_stage
from pipelines.core import validate as validate_stage
from tests.pipelines.pipeline_data import make_dataset, stage_cfg

Q_TRUE = np.array([0.1, 0.3, 0.0, 0.2, 0.15, 0.05, 0.0, 0.1, 0.05, 0.03, 0.02])


def _gamma_dataset() -> pd.DataFrame:
    """Two configurations whose output is exactly a known Gamma_11 (weights sum to 1)."""
    data = make_dataset(angles=(45, 90), radii=(30,), dt=0.05)
    truth = GammaModel()
    truth.thresholds_ = np.linspace(0.0, 2.0, 11)
    truth.offset_ = 0.0
    for phi, q in ((45.0, Q_TRUE), (90.0, Q_TRUE[::-1])):
        truth.weights_ = q / q.sum()
        for run_id in data.loc[data["curve_angle_deg"] == phi, "run_id"].unique():
            hit = data["run_id"] == run_id
            data.loc[hit, "output"] = truth.predict(data.loc[hit, "input"].to_numpy())
    return data


def test_table41_equivalent_recovers_known_weights_and_report_is_complete(
        tmp_path: Path) -> None:
    data = _gamma_dataset()
    cfg = stage_cfg(tmp_path, families=["linear", "gamma"],
                    heldout=["triangle_decay", "trapezoid_decay"])
    fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run(cfg, dataset=data)
    rcfg = {**cfg, "exemplary": {"rig": "tsm-bench", "curve_angle_deg": 90, "radius_mm": 30},
            "fit_excitation": "sine_decay", "metric": "rmse",
            "plots": {"per_configuration": True, "dpi": 40, "max_points": 500},
            "formats": ["md", "html"]}
    result = report_stage.run(rcfg)
    assert not result.cached
    reports = tmp_path / "data/reports"
    table = pd.read_parquet(reports / "gamma_weights.parquet")
    assert list(table["curve_angle_deg"]) == [45.0, 90.0]
    q_cols = [f"q{i}" for i in range(1, 12)]
    np.testing.assert_allclose(table.loc[0, q_cols].to_numpy(float), Q_TRUE / Q_TRUE.sum(),
                               atol=1e-8)
    np.testing.assert_allclose(table.loc[1, q_cols].to_numpy(float),
                               Q_TRUE[::-1] / Q_TRUE.sum(), atol=1e-8)
    np.testing.assert_allclose(table["weights_sum"], 1.0, atol=1e-12)
    assert (table["sse"] < 1e-12).all()  # the exact model leaves no error
    np.testing.assert_allclose(table.loc[0, "thresholds"], np.linspace(0, 2, 11))
    # leaderboard: gamma (exact) beats linear everywhere
    board = pd.read_parquet(reports / "leaderboard.parquet")
    assert (board[board["family"] == "gamma"]["rank"] == 1).all()
    assert (board[board["family"] == "linear"]["rank"] == 2).all()
    # plots and the documents
    names = {p.name for p in (reports / "plots").iterdir()}
    assert {"config_tsm-bench_phi045_r030.png", "config_tsm-bench_phi090_r030.png",
            "elementary_tsm-bench_phi090_r030.png", "heatmap_heldout_rmse.png",
            "heatmap_fit_sse.png", "lines_heldout_rmse.png"} <= names
    md = (reports / "report.md").read_text()
    for fig in names:
        assert f"plots/{fig}" in md  # every figure is linked from the report
    assert "Table 4.1 equivalent" in md and "Leaderboard" in md
    html = (reports / "report.html").read_text()
    assert html.startswith("<!doctype html>") and "elementary_tsm-bench_phi090_r030.png" in html
    # read first: the headline; rendered Markdown; a unit in every table's header;
    # thumbnails of every configuration; weights rounded to what they mean
    assert '<p class="headline" id="headline"><strong>gamma wins 2 of 2 configurations' in html
    assert "`" not in html and "**" not in html
    for table in re.findall(r"<thead>(.*?)</thead>", html):
        assert re.search(r"<th>[^<]*\[[^<\]]+\]</th>", table), table
        for head in re.findall(r"<th>([^<]*)</th>", table):
            if any(w in head for w in ("rmse", "sse", "error")):
                assert "[" in head, head
    assert html.count('<figure class="thumb">') == 2
    # (this dataset's index names no units: "?" says so rather than guessing mm)
    assert "q1 [?/?]" in html and "curve angle [deg]" in html
    assert set(result.config_plots) == {"tsm-bench_phi045_r030", "tsm-bench_phi090_r030"}
    # nothing changed: nothing redrawn
    mtime = (reports / "report.md").stat().st_mtime_ns
    again = report_stage.run(rcfg)
    assert again.cached and (reports / "report.md").stat().st_mtime_ns == mtime
    assert len(metrics) == 2 * 2 * 3


def test_leaderboard_ranks_by_mean_heldout_metric() -> None:
    rows = []
    for fam, fit_rmse, held in (("a", 0.1, (0.5, 0.7)), ("b", 0.3, (0.4, 0.4)),
                                ("c", 0.2, (0.4, 0.4))):
        base = {"family": fam, "rig": "r", "curve_angle_deg": 90.0, "radius_mm": 30.0,
                "fit_excitation": "sine_decay", "n": 10, "sse": 1.0, "mse": 0.1,
                "std_error": 0.1, "mean_error": 0.0, "error_range": 1.0,
                "mean_abs_error": 0.1, "var_error": 0.01}
        rows.append({**base, "eval_excitation": "sine_decay", "split": "fit", "rmse": fit_rmse})
        rows.append({**base, "eval_excitation": "tri", "split": "heldout", "rmse": held[0]})
        rows.append({**base, "eval_excitation": "trap", "split": "heldout", "rmse": held[1]})
    board = stages.leaderboard(stages.metrics_frame(rows))
    ranks = dict(zip(board["family"], board["rank"], strict=True))
    assert ranks == {"b": 1, "c": 1, "a": 3}  # ties share the better rank
    assert board.set_index("family").loc["a", "heldout_rmse"] == pytest.approx(0.6)
    summary = stages.family_summary(board)
    assert summary.set_index("family").loc["b", "wins"] == 1
    with pytest.raises(stages.PipelineError, match="unknown metric"):
        stages.leaderboard(stages.metrics_frame(rows), metric="r2")


def test_play_operator_matches_seed001_definition() -> None:
    # p = 1: output stays until the input is more than p above it, follows v - p up,
    # and follows the input down when the input falls below it (eq. 4.8).
    u = np.array([0.0, 0.5, 1.0, 2.0, 3.0, 2.5, 1.0, 0.0, 1.5])
    w = play_matrix(u, np.array([1.0]), np.zeros(1))[0][:, 0]
    np.testing.assert_allclose(w, [0, 0, 0, 1, 2, 2, 1, 0, 0.5])
    model = GammaModel(n_operators=3, max_threshold=1.0)
    np.testing.assert_allclose(model.design_matrix(u),
                               play_matrix(u, np.array([0.0, 0.5, 1.0]), np.zeros(3))[0])


def test_report_without_metrics_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(stages.PipelineError, match="metrics.parquet"):
        report_stage.run(stage_cfg(tmp_path))
    assert json.dumps(stage_cfg(tmp_path))  # plain JSON-able config


def test_generalisation_table_is_the_held_out_over_in_sample_ratio() -> None:
    rows = []
    for fam, fit_rmse, factor in (("gamma", 0.1, 1.0), ("bouc_wen", 0.2, 1.5)):
        for i, phi in enumerate((15.0, 45.0, 90.0)):
            base = {"family": fam, "rig": "tsm-bench", "curve_angle_deg": phi,
                    "radius_mm": 30.0, "fit_excitation": "sine_decay", "n": 10}
            scale = 1.0 + i  # the configurations differ; the ratio is per configuration
            rows.append({**base, "eval_excitation": "sine_decay", "split": "fit",
                         "rmse": fit_rmse * scale})
            rows.append({**base, "eval_excitation": "band_random", "split": "heldout",
                         "rmse": fit_rmse * scale * factor * (1.0 + 0.1 * i)})
    table = report_stage.generalisation_table(stages.metrics_frame(rows),
                                              fit_excitation="sine_decay")
    assert list(table["family"]) == ["bouc_wen", "gamma"]
    assert (table["eval_excitation"] == "band_random").all()
    assert (table["configurations"] == 3).all()
    np.testing.assert_allclose(table["median_ratio"], [1.5 * 1.1, 1.1])
    np.testing.assert_allclose(table["min_ratio"], [1.5, 1.0])
    np.testing.assert_allclose(table["max_ratio"], [1.5 * 1.2, 1.2])
    np.testing.assert_allclose(table["median_fit_rmse"], [0.4, 0.2])
    empty = report_stage.generalisation_table(stages.metrics_frame(rows),
                                              fit_excitation="triangle_decay")
    assert empty.empty and "median_ratio" in empty.columns
