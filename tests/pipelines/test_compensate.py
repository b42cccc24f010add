"""The compensate stage end to end on stand-in plants (a RigBackend swapped in for the rig)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from hysteresis import make_family
from hysteresis.coleman_hodgdon import ColemanHodgdonModel
from hysteresis.compensation import sine_profile
from pipelines import compensate, schemas
from pipelines.compensation import experiments
from pipelines.compensation.models import fit_reachable
from pipelines.compensation.rig import RigBackend, drive
from pipelines.compensation.seed001 import fit_shape_aware
from pipelines.compensation.settings import CompensateConfig, Seed001Settings
from pipelines.compensation.tables import table42_wide
from tests.pipelines.pipeline_data import mlflow_store

CONF = Path(__file__).resolve().parents[2] / "conf"


class StandInRig:
    """tsm-bench: backlash in mm; bending joint: backlash in deg (motor-angle input) or the
    Coleman-Hodgdon law of seed 000 in tendon pull (mm) plus a slow drift (the model error
    the UKF of seed 000 is there to estimate)."""

    def __init__(self, *, rig: str, curve_angle_deg: float, radius_mm: float,
                 effects: Any = None, seed: int = 0, sensors: Any = None) -> None:
        self.rig = rig
        self.deg = bool(sensors and sensors.get("input_unit") == "deg")
        self.play = (0.3 + curve_angle_deg / 90.0) * (8.0 if self.deg else 1.0)
        self.ch = ColemanHodgdonModel.from_params(0.95, -0.92, 18.53, origin=(0.0, 50.0),
                                                  scheme="euler")
        self.rng = np.random.default_rng(seed)
        self.reset()

    def reset(self) -> dict[str, float]:
        self.w, self.y, self.t = 0.0, 0.0, 0.0
        self.ch_state: dict[str, float] | None = None
        return {"t_s": 0.0}

    def step(self, command: float) -> dict[str, float]:
        self.t += 0.01
        out = {"t_s": self.t, "command": command, "input": command}
        if self.rig == "bending-joint" and not self.deg:
            alpha, self.ch_state = self.ch.step(command, self.ch_state)
            y = alpha + 10.0 * math.sin(0.3 * self.t)  # a slow error no CH model has
        else:
            self.w = min(command, max(command - self.play, self.w))
            self.y += 0.25 * (0.95 * self.w - self.y)
            y = self.y
        noise = 0.002 * float(self.rng.standard_normal())
        out["output"] = y + noise
        out["tip_angle_deg"] = y + noise
        return out


def stand_in_excitation(kind: str, *, dt_s: float = 0.01, **params: Any) -> tuple[Any, Any]:
    assert kind == "sine_decay"
    n = len(params["amplitudes_mm"]) * params["periods_per_amplitude"] / params["frequency_hz"]
    t = np.arange(0.0, n, dt_s)
    return t, sine_profile(t, amplitudes=params["amplitudes_mm"],
                           periods_per_amplitude=params["periods_per_amplitude"],
                           frequency_hz=params["frequency_hz"])


BACKEND = RigBackend(make_rig=StandInRig, make_excitation=stand_in_excitation)


def _cfg(tmp_path: Path, *overrides: str) -> Any:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose("compensate", overrides=[
            "experiment=compensation_quick", f"paths.root={tmp_path}", "progress=false",
            *overrides])


def test_quick_run_writes_every_table_report_and_plot(tmp_path: Path) -> None:
    settings = schemas.settings(CompensateConfig, _cfg(tmp_path, "tracking=off"))
    result = experiments.run(settings, backend=BACKEND)
    assert not [p for p in tmp_path.rglob("*") if p.is_file()]  # the core writes nothing
    files = compensate.write(result, settings)
    assert all(p.is_file() for p in files) and files == compensate.output_files(result, settings)
    tables = result.tables
    out = tmp_path / "data" / "reports" / "compensation"
    for name in ("seed001_table42", "seed001_table44", "seed001_fits", "seed002_table1",
                 "seed000_estimation", "seed000_tracking", "seed000_reference"):
        back = pd.read_parquet(out / f"{name}.parquet")
        pd.testing.assert_frame_equal(back, tables[name].reset_index(drop=True),
                                      check_dtype=False)
    t42 = tables["seed001_table42"]
    assert set(t42["scheme"]) >= {"none", "gamma", "bouc_wen", "ours"}
    assert (t42["command_travel"] > 0).all()
    assert set(t42["shape"]) == {"A", "B"} and set(t42["profile"]) == {"mixed", "sine", "triangle"}
    # Ours removes >= 90 % of the RMSE on the stand-in bench for every profile and shape.
    for (_, _), g in t42.groupby(["shape", "profile"]):
        by = g.set_index("scheme")["rmse"]
        assert by["ours"] < 0.1 * by["none"]
        # a model that never saw shapes A and B (trained on 15-75 deg) compensates them too
        assert by["shape_aware"] < 0.15 * by["none"]
        assert by["shape_aware_ff"] < 0.5 * by["none"]
    wide = table42_wide(t42, ["A", "B"], ["none", "gamma", "ours"])
    assert list(wide.columns[:2]) == ["type", "statistic"] and len(wide) == 3 * 5
    t44 = tables["seed001_table44"]
    assert set(t44["method"]) == {"exact", "bounded", "nelder-mead", "slsqp", "interior-point"}
    assert np.allclose(t44.loc[t44["method"] == "exact", "ratio_to_ours"], 1.0)
    t1 = tables["seed002_table1"]
    assert set(t1["scheme"]) == {"none", "vision_feedback", "bouc_wen_ff", "ours"}
    mean = t1.groupby("scheme")["rmse"].mean()
    assert mean["vision_feedback"] < mean["none"] and mean["ours"] < mean["none"]
    t5 = tables["seed000_tracking"].set_index("scheme")
    assert t5.loc["ame_pd", "abs_err"] < t5.loc["pd", "abs_err"]
    assert t5.loc["ours", "abs_err"] <= t5.loc["pd", "abs_err"]
    est = tables["seed000_estimation"]
    # the UKF removes > 65 % of the reference's error: the reference is fitted the paper's way
    # (B < 0) on 0-2 mm of a plant with a slow error no Coleman-Hodgdon model has
    assert (est["abs_err_ratio"] < 0.35).all()
    report = (tmp_path / "data" / "reports" / "compensation.md").read_text()
    for heading in ("Table 4.2", "Table 4.4", "Table I", "Table 5", "Headline numbers",
                    "never saw them"):
        assert heading in report
    assert list((out / "plots").glob("seed001_A_mixed.png"))
    assert not list(out.rglob("*.tmp*"))  # atomic writes leave no temporaries


def test_run_logs_tables_and_metrics_to_mlflow(tmp_path: Path) -> None:
    mlflow_store(tmp_path)  # an initialised store: the migrations are not what is tested
    cfg = _cfg(tmp_path, "tracking=local", "plots=false", "seed001.enabled=false",
               "seed002.enabled=false")
    compensate.stage(cfg, backend=BACKEND)
    from mlflow import MlflowClient

    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    runs = client.search_runs([exp.experiment_id], filter_string="tags.stage = 'compensate'")
    child = [r for r in runs if r.data.tags.get("kind") == "experiment"]
    assert len(child) == 1
    metrics = child[0].data.metrics
    assert math.isfinite(metrics["seed000.ame_pd.abs_err_reduction_vs_pd_pct"])
    arts = [a.path for a in client.list_artifacts(child[0].info.run_id, "tables")]
    assert "tables/seed000_tracking.json" in arts


def test_bad_configuration_mode_is_named(tmp_path: Path) -> None:
    cfg = _cfg(tmp_path, "tracking=off", "seed001.all_configurations=some")
    with pytest.raises(Exception, match="all_configurations must be none|quick|full"):
        compensate.stage(cfg, backend=BACKEND)


def test_a_registry_setting_needs_the_champions_given_to_the_core(tmp_path: Path) -> None:
    settings = schemas.settings(CompensateConfig, _cfg(tmp_path, "tracking=off",
                                                       "seed001.ours.registry=tsm"))
    with pytest.raises(ValueError, match="seed001.ours.registry is set"):
        experiments.run(settings, backend=BACKEND)
    assert compensate.champion_loader(settings) is not None
    settings.seed001.enabled = False
    assert compensate.champion_loader(settings) is None


def test_an_unreachable_fit_is_refitted_with_narrower_plays() -> None:
    t = np.arange(0.0, 20.0, 0.01)
    u = 1.0 + np.sin(0.5 * t) * np.minimum(1.0, t / 5.0)  # inputs 0..2
    y = 10.0 * np.clip(u - 0.2, 0.0, None)
    params = {"constraint": "free", "fit_offset": True, "n_operators": 11, "max_threshold": 3.0}
    model, note = fit_reachable("gamma", u, y, params, label="test")
    assert "thresholds up to 3 reach" in note and "refitted with max_threshold=" in note
    assert model.thresholds_.max() <= 0.75 * float(np.ptp(u)) + 1e-12
    assert model.weights_.sum() > 0
    ok, none = fit_reachable("gamma", u, y, {**params, "max_threshold": 1.0}, label="test")
    assert none == "" and ok.thresholds_.max() == 1.0



def test_a_default_fit_whose_plays_reach_the_span_is_refitted_for_the_inverse() -> None:
    """A lag of a good fraction of a period makes the default Gamma widths reach the whole
    input span (best for prediction); for an inverse that fit is refused and narrowed."""
    t = np.arange(0.0, 80.0, 0.01)
    u = 28.0 * np.sin(2 * np.pi * 0.1 * t + 0.5) + 30.0
    y = 0.9 * 28.0 * np.sin(2 * np.pi * 0.1 * (t - 0.9) + 0.5) + 30.0
    assert make_family("gamma").fit(u, y).thresholds_.max() >= np.ptp(u) * (1 - 1e-9)
    model, note = fit_reachable("gamma", u, y, {}, label="lagged")
    assert "reach the identification range" in note and "refitted with max_threshold=" in note
    assert model.thresholds_.max() <= 0.75 * float(np.ptp(u)) + 1e-9

def test_quick_seed000_ours_is_not_worse_than_pd_on_the_virtual_rig(tmp_path: Path) -> None:
    cfg = _cfg(tmp_path, "tracking=off", "plots=false", "seed001.enabled=false",
               "seed002.enabled=false")
    t5 = compensate.stage(cfg).tables["seed000_tracking"].set_index("scheme")
    # the quick experiment identifies on 0..2 mm with plays configured up to 3 mm: refused,
    # refitted narrower, and then it tracks far better than PD (not 4x worse)
    assert "refitted with max_threshold" in t5.loc["ours", "note"]
    assert t5.loc["ours", "abs_err"] < 0.5 * t5.loc["pd", "abs_err"]


def test_shape_aware_model_is_trained_without_the_compensated_shapes() -> None:
    cfg = {"rig": "tsm-bench", "shapes": {"A": [90, 30], "B": [60, 60]},
           "curve_angles_deg": [30, 60, 90], "radii_mm": [30, 60], "model_input": "command",
           "shape_aware": {"family": "gamma", "params": {"constraint": "free",
                                                        "fit_offset": True, "max_threshold": 2.0},
                           "estimator": {"angle_degree": 2, "curvature_degree": 1}}}
    s1 = schemas.settings(Seed001Settings, cfg)  # the seed001 node run() passes
    _, u = stand_in_excitation("sine_decay", amplitudes_mm=[3.0, 1.5], periods_per_amplitude=2,
                               frequency_hz=0.5)
    sa, trained = fit_shape_aware(s1, BACKEND, u, seed=0, progress_bar=False)
    assert trained == ["30/30", "30/60", "60/30", "90/60"]
    assert sa.shapes_.tolist() == [[30, 30], [30, 60], [60, 30], [90, 60]]
    # the stand-in's backlash grows with the angle: the model for shape A (never driven)
    # reproduces that rig's response to the identification input closely
    rig = StandInRig(rig="tsm-bench", curve_angle_deg=90, radius_mm=30)
    y = drive(rig, u).column("output")
    err = sa.predict(u, curve_angle_deg=90.0, radius_mm=30.0) - y
    assert np.sqrt(np.mean(err**2)) < 0.1 * np.sqrt(np.mean(y**2))
