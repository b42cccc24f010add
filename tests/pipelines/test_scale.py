"""What keeps the stages linear in the number of runs: rows located once per dataset, and
the check that a speed change leaves the results as they were."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.bench_scale import compare
from bench.compare_results import compare_frames
from pipelines import stages
from pipelines.common import read_processed, stage_columns
from rig_io.dataset import read_dataset, write_run_rows
from rig_io.errors import RigIOError
from tests.pipelines.pipeline_data import make_dataset


def test_configuration_rows_are_what_config_rows_returns() -> None:
    data = make_dataset(angles=(15, 90), radii=(30, 75), kinds=("sine_decay",), periods=1)
    shapeless = make_dataset(angles=(15,), radii=(30,), kinds=("sine_decay",), periods=1,
                             rig="catheter")
    shapeless[["curve_angle_deg", "radius_mm"]] = np.nan
    shapeless["run_id"] = "catheter_0001"
    data = pd.concat([shapeless, data], ignore_index=True).sample(frac=1.0, random_state=0)
    located = stages.ConfigurationRows(data)
    configs = stages.configurations(data)
    assert len(configs) == 5
    for config in configs:
        pd.testing.assert_frame_equal(located.rows(config), stages.config_rows(data, config))
    # a value within config_rows' tolerance is still found
    near = stages.Configuration("tsm-bench", 15.0 + 1e-12, 30.0)
    pd.testing.assert_frame_equal(located.rows(near), stages.config_rows(data, near))


def test_compare_results_tolerates_last_bits_not_changes() -> None:
    a = pd.DataFrame({"family": ["gamma", "linear"], "rmse": [0.1, 0.2], "n": [5, 5]})
    b = a.iloc[::-1].reset_index(drop=True)  # rows matched by key, not position
    b["rmse"] = b["rmse"] * (1 + 1e-12)
    assert compare_frames(a, b, ("family",)) == []
    b.loc[0, "rmse"] = 0.25
    assert "rmse: 1 value(s)" in compare_frames(a, b, ("family",))[0]
    b = a.copy()
    b.loc[1, "n"] = 6
    assert compare_frames(a, b, ("family",)) == ["n: 1 value(s) differ"]
    assert compare_frames(a, a.iloc[:1], ("family",)) == ["2 rows vs 1"]


def test_bench_scale_ratios() -> None:
    small = {"stage_s": {"fit": 24.0, "validate": 2.4, "total": 30.0}, "peak_tree_rss_gb": 1.0}
    large = {"stage_s": {"fit": 192.0, "validate": 24.0, "total": 250.0},
             "peak_tree_rss_gb": 1.5}
    out = compare(small, 24, large, 160)
    assert out["stages"]["fit"]["per_config_ratio"] == pytest.approx(1.2)
    assert out["stages"]["validate"]["per_config_ratio"] == pytest.approx(1.5)
    assert out["worst_stage"] == "validate" and not out["stages_within_target"]
    assert out["peak_memory_ratio"] == pytest.approx(1.5) and out["memory_within_target"]


def test_the_stages_read_only_the_columns_they_use(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), kinds=("sine_decay", "triangle_decay"),
                        periods=1)
    for col in ("camera", "tracker", "tension_proxy"):
        data[col] = np.nan
    for run_id, rows in data.groupby("run_id"):
        write_run_rows(tmp_path, rows.reset_index(drop=True), {"run_id": run_id})
    cols = stage_columns({"input": "input", "output": "output"})
    part = read_processed(tmp_path, cols)
    assert list(part.columns) == cols
    pd.testing.assert_frame_equal(part, read_dataset(tmp_path)[cols])
    one = str(data["run_id"].iloc[0])
    pd.testing.assert_frame_equal(read_dataset(tmp_path, runs=[one], columns=cols),
                                  part[part["run_id"] == one].reset_index(drop=True))
    # a signal the schema does not know is left to the stage's check, which names it
    assert list(read_processed(tmp_path, [*cols, "strain"]).columns) == cols
    with pytest.raises(RigIOError, match="strain"):
        read_dataset(tmp_path, columns=["strain"])
