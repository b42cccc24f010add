"""The silent paths of a user's own data, each now loud or right: runs marked held out are
scored as held out whatever their excitation is called, nothing held out is said loudly, a
champion judged in-sample says so, a shapeless configuration has a readable name, and the
plots and tables carry the data's units."""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd
import pytest

from pipelines import plots, registry, stages
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from pipelines.core.report import with_units
from tests.pipelines.pipeline_data import make_dataset, stage_cfg, write_dataset


def _two_runs_one_kind() -> pd.DataFrame:
    """One shape, two sine_decay runs: the first identifies, the second is held out."""
    data = make_dataset(angles=(90,), radii=(30,), kinds=("sine_decay",), dt=0.2)
    second = data.copy()
    second["run_id"] = second["run_id"].astype(str) + "_b"
    return pd.concat([data, second], ignore_index=True)


def test_a_run_marked_held_out_is_scored_held_out_even_where_its_kind_identifies() -> None:
    data = _two_runs_one_kind()
    first, second = sorted(data["run_id"].astype(str).unique())
    plan = stages.identification_plan(data, fit_excitations=["sine_decay"], heldout=[],
                                      roles={first: "identification", second: "held_out"})
    assert "sine_decay.heldout" in plan.heldout
    kinds = plan.dataset.groupby("run_id")["excitation"].first()
    assert kinds[first] == "sine_decay" and kinds[second] == "sine_decay.heldout"
    assert plan.marked == frozenset({first})


def test_nothing_held_out_is_said_loudly_and_the_champion_is_tagged_in_sample(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    data = make_dataset(angles=(90,), radii=(30,), kinds=("sine_decay",), dt=0.2)
    write_dataset(data, tmp_path)
    cfg = stage_cfg(tmp_path, heldout=["triangle_decay"])
    fits = fit_stage.run(cfg)
    with caplog.at_level(logging.WARNING):
        metrics, _ = validate_stage.run(cfg, fits=fits)
    assert set(metrics["split"]) == {"fit"}
    assert any("NOTHING HELD OUT WAS SCORED" in r.getMessage() for r in caplog.records)
    champs = registry.choose_champions(fits, metrics)
    assert list(champs["score_split"]) == ["fit"]
    assert "insample.rmse" in champs and "heldout.rmse" not in champs


def test_a_held_out_score_outranks_an_in_sample_one() -> None:
    fits = pd.DataFrame([
        {"family": f, "rig": "r", "curve_angle_deg": None, "radius_mm": None,
         "fit_excitation": "s", "key": f, "model_json": "{}", "error": None}
        for f in ("a", "b")])
    metrics = pd.DataFrame([
        {"family": "a", "rig": "r", "curve_angle_deg": None, "radius_mm": None,
         "fit_excitation": "s", "eval_excitation": "s", "split": "fit", "rmse": 0.1},
        {"family": "b", "rig": "r", "curve_angle_deg": None, "radius_mm": None,
         "fit_excitation": "s", "eval_excitation": "s", "split": "fit", "rmse": 0.5},
        {"family": "b", "rig": "r", "curve_angle_deg": None, "radius_mm": None,
         "fit_excitation": "s", "eval_excitation": "h", "split": "heldout", "rmse": 0.9}])
    champ = registry.choose_champions(fits, metrics)
    assert list(champ["family"]) == ["b"] and list(champ["score_split"]) == ["heldout"]


def test_a_shapeless_configuration_is_named_by_its_rig() -> None:
    assert stages.Configuration("bending-joint", None, None).label == "bending-joint"
    assert stages.Configuration("tsm-bench", 90.0, 30.0).label == "tsm-bench_phi090_r030"
    assert not stages.Configuration("bending-joint", None, None).has_shape


def test_units_reach_the_plot_axes_and_the_table_headers(tmp_path: Path) -> None:
    preds = pd.DataFrame({"family": "gamma", "fit_excitation": "s", "eval_excitation": "s",
                          "run_id": "r1", "t_s": [0.0, 0.1, 0.2], "input": [0.0, 1.0, 0.5],
                          "output": [30.0, 40.0, 35.0], "predicted": [30.0, 39.0, 36.0]})
    import matplotlib.pyplot as plt

    seen: list[str] = []
    real = plt.Axes.set_ylabel

    def spy(self: plt.Axes, label: str, *a: object, **k: object) -> object:
        seen.append(label)
        return real(self, label, *a, **k)

    plt.Axes.set_ylabel = spy  # type: ignore[method-assign]
    try:
        plots.configuration_figure(preds, tmp_path / "f.png", title="t", fit_excitation="s",
                                   units=("mm", "deg"))
    finally:
        plt.Axes.set_ylabel = real  # type: ignore[method-assign]
    # every y axis in the output's unit: the signal and its residual
    assert "output [deg]" in seen and "residual [deg]" in seen
    assert all(s in ("output [deg]", "residual [deg]") for s in seen)
    headers = with_units(pd.DataFrame(columns=["family", "median_heldout_rmse", "sse",
                                               "median_ratio"]), "deg").columns
    assert list(headers) == ["family", "median_heldout_rmse [deg]", "sse [deg^2]",
                             "median_ratio"]


def test_the_documented_mapping_template_is_a_valid_mapping() -> None:
    from rig_io.importer import file_settings, load_mapping, manifest_for
    from tests.conftest import REPO

    mapping = load_mapping(REPO / "docs" / "importer-template.yaml")
    assert file_settings(mapping, "train_1.csv")["excitation"]["role"] == "identification"
    assert manifest_for(mapping, "test_1.csv")["excitation"]["role"] == "held_out"
