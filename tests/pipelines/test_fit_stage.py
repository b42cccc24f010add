"""Stage fit: every family x configuration, model files, content-hash caching, failures."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hysteresis.base import HysteresisModel
from pipelines import artifacts, stages
from pipelines.core import fit as fit_stage
from pipelines.stages import FamilySpec, PipelineError
from tests.pipelines.pipeline_data import make_dataset, stage_cfg, write_dataset


def _linear_dataset() -> pd.DataFrame:
    """y = g u + c exactly, with a different (g, c) per configuration."""
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.1, noise=0.0)
    gain = np.where(data["curve_angle_deg"] == 15, 0.9, 0.7)
    data["output"] = gain * data["input"] + 0.25
    return data


def test_fits_every_family_on_every_configuration_and_recovers_known_gain(
        tmp_path: Path) -> None:
    data = _linear_dataset()
    fits = fit_stage.run(stage_cfg(tmp_path), dataset=data)
    assert len(fits) == 2 * 2  # 2 families x 2 configurations
    assert set(fits["family"]) == {"linear", "gamma"}
    assert fits["error"].isna().all() and not fits["cached"].any()
    lin = fits[fits["family"] == "linear"].set_index("curve_angle_deg")
    for phi, gain in ((15.0, 0.9), (90.0, 0.7)):
        model = HysteresisModel.from_json(lin.loc[phi, "model_json"])
        assert model.gain_ == pytest.approx(gain, abs=1e-9)
        assert model.offset_ == pytest.approx(0.25, abs=1e-9)
    files = sorted((tmp_path / "data/interim/models").rglob("*.json"))
    assert [f.relative_to(tmp_path / "data/interim/models").as_posix() for f in files] == [
        "gamma/tsm-bench_phi015_r030__sine_decay.json",
        "gamma/tsm-bench_phi090_r030__sine_decay.json",
        "linear/tsm-bench_phi015_r030__sine_decay.json",
        "linear/tsm-bench_phi090_r030__sine_decay.json",
    ]
    record = json.loads(files[0].read_text())
    assert record["family"] == "gamma" and record["fit_run_ids"] == "phi015_r030_sine_decay_0001"
    # the saved model round-trips and predicts what the fitted one predicts
    model = HysteresisModel.from_dict(record["model"])
    u = data[data["run_id"] == "phi015_r030_sine_decay_0001"]["input"].to_numpy()
    direct = HysteresisModel.from_json(fits.iloc[1]["model_json"]).predict(u)
    np.testing.assert_array_equal(model.predict(u), direct)


def test_unchanged_inputs_are_not_refitted_and_a_changed_run_is(tmp_path: Path) -> None:
    data = _linear_dataset()
    first = fit_stage.run(stage_cfg(tmp_path), dataset=data)
    mtimes = {p: p.stat().st_mtime_ns for p in (tmp_path / "data/interim").rglob("*.json")}
    second = fit_stage.run(stage_cfg(tmp_path), dataset=data)
    assert second["cached"].all()
    assert list(second["key"]) == list(first["key"])
    assert {p: p.stat().st_mtime_ns for p in mtimes} == mtimes  # nothing rewritten
    changed = data.copy()
    hit = changed["run_id"] == "phi090_r030_sine_decay_0001"
    changed.loc[hit, "output"] = changed.loc[hit, "output"] + 0.01
    third = fit_stage.run(stage_cfg(tmp_path), dataset=changed)
    refit = third[~third["cached"]]
    assert set(refit["curve_angle_deg"]) == {90.0} and len(refit) == 2
    # a hyper-parameter change refits that family only
    fourth = fit_stage.run(stage_cfg(tmp_path, family_overrides={"gamma": {"n_operators": 5}}),
                           dataset=changed)
    assert set(fourth[~fourth["cached"]]["family"]) == {"gamma"}
    assert fit_stage.run(stage_cfg(tmp_path, cache=False), dataset=changed)["cached"].sum() == 0


def test_configuration_and_family_selection(tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 45, 90), radii=(30, 75), dt=0.2)
    cfg = stage_cfg(tmp_path, families=["linear"],
               config={"rig": None, "curve_angle_deg": [15, 90], "radius_mm": 75})
    fits = fit_stage.run(cfg, dataset=data)
    assert sorted(zip(fits["curve_angle_deg"], fits["radius_mm"], strict=True)) == [
        (15.0, 75.0), (90.0, 75.0)]
    with pytest.raises(PipelineError, match="no configuration matches"):
        fit_stage.run(stage_cfg(tmp_path, config={"curve_angle_deg": 33}), dataset=data)
    with pytest.raises(PipelineError, match="lacks column"):
        fit_stage.run(stage_cfg(tmp_path), dataset=data.drop(columns=["output"]))
    with pytest.raises(PipelineError, match="nothing to fit"):
        fit_stage.run(stage_cfg(tmp_path, fit_excitations=["ramp"]), dataset=data)


class _Broken(HysteresisModel):
    family = "broken-test"

    def fit(self, u: Any, y: Any, **_: Any) -> _Broken:
        raise ValueError("cannot identify")


def _build_broken(_: Any) -> HysteresisModel:
    return _Broken()


def test_a_failing_fit_is_recorded_not_raised(tmp_path: Path) -> None:
    data = make_dataset(angles=(15,), radii=(30,), dt=0.2)
    good = fit_stage.family_specs({"families": ["linear"]})[0]
    bad = FamilySpec("broken", {"_target_": "x.Broken"}, _build_broken, "v1")
    tasks = stages.plan_fits(data, [good, bad], stages.configurations(data),
                             fit_excitations=["sine_decay"])
    fits = stages.fit_models(tasks)
    row = fits.set_index("family").loc["broken"]
    assert row["error"] == "ValueError: cannot identify" and pd.isna(row["model_json"])
    assert pd.isna(fits.set_index("family").loc["linear", "error"])
    paths = artifacts.save_models(fits, tmp_path / "models")
    loaded = artifacts.load_models(tmp_path / "models")
    assert len(paths) == 2 and set(loaded["family"]) == {"linear", "broken"}
    assert loaded.set_index("family").loc["broken", "error"] == "ValueError: cannot identify"


def test_parallel_fits_equal_serial_fits(tmp_path: Path) -> None:
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.2)
    specs = fit_stage.family_specs({"families": ["linear", "gamma"]})
    tasks = stages.plan_fits(data, specs, stages.configurations(data),
                             fit_excitations=["sine_decay"])
    serial = stages.fit_models(tasks)
    parallel = stages.fit_models(tasks, runner=fit_stage.joblib_runner(2, progress=False))
    assert list(parallel["key"]) == list(serial["key"])
    # the same models, to rounding: worker processes may run their BLAS with another thread
    # count than this one, which can move last bits
    u = data.loc[data["excitation"] == "triangle_decay", "input"].to_numpy()[:300]
    for a, b in zip(parallel["model_json"], serial["model_json"], strict=True):
        pa, pb = stages.load_model(str(a)).predict(u), stages.load_model(str(b)).predict(u)
        np.testing.assert_allclose(pa, pb, rtol=1e-9, atol=1e-12 * float(np.ptp(pb)))


def test_reads_the_processed_dataset_from_disk(tmp_path: Path) -> None:
    write_dataset(make_dataset(angles=(15,), radii=(30,), dt=0.2), tmp_path)
    fits = fit_stage.run(stage_cfg(tmp_path, families=["linear"]))
    assert len(fits) == 1 and fits["error"].isna().all()


def _with_second_sine_decay_run(data: pd.DataFrame) -> pd.DataFrame:
    """The dataset plus a copy of each configuration's sine_decay run under a new id."""
    extra = data[data["excitation"] == "sine_decay"].copy()
    extra["run_id"] = extra["run_id"].astype(str) + "_repeat"
    extra["output"] = extra["output"] * 1.1  # a different record, so a different model
    return pd.concat([data, extra], ignore_index=True)


def test_several_candidate_runs_stop_the_fit_and_name_the_option() -> None:
    data = _with_second_sine_decay_run(make_dataset(angles=(15,), radii=(30,), dt=0.2))
    spec = fit_stage.family_specs({"families": ["linear"]})
    with pytest.raises(PipelineError, match=r"2 runs could identify .*fit_runs=\["):
        stages.plan_fits(data, spec, stages.configurations(data),
                         fit_excitations=["sine_decay"])


def test_fit_runs_chooses_the_identification_run_and_the_row_records_it() -> None:
    data = _with_second_sine_decay_run(make_dataset(angles=(15,), radii=(30,), dt=0.2))
    spec = fit_stage.family_specs({"families": ["linear"]})
    repeat = next(r for r in data["run_id"].unique() if str(r).endswith("_repeat"))
    tasks = stages.plan_fits(data, spec, stages.configurations(data),
                             fit_excitations=["sine_decay"], fit_runs=[repeat])
    fits = stages.fit_models(tasks)
    assert list(fits["fit_run_ids"]) == [repeat]
    original = repeat.removesuffix("_repeat")
    other = stages.fit_models(stages.plan_fits(data, spec, stages.configurations(data),
                                               fit_excitations=["sine_decay"],
                                               fit_runs=[original]))
    assert list(other["fit_run_ids"]) == [original]
    assert other["model_json"].iloc[0] != fits["model_json"].iloc[0]
    # naming both fits one parameter set on both runs, each from its own start
    both = stages.fit_models(stages.plan_fits(data, spec, stages.configurations(data),
                                              fit_excitations=["sine_decay"],
                                              fit_runs=[repeat, original]))
    assert sorted(both["fit_run_ids"].iloc[0].split(",")) == sorted([repeat, original])
    assert int(both["n_samples"].iloc[0]) == int(fits["n_samples"].iloc[0]) + int(
        other["n_samples"].iloc[0])
    assert both["model_json"].iloc[0] not in (fits["model_json"].iloc[0],
                                              other["model_json"].iloc[0])
    # two candidates and none named: refused, with the ways to decide
    with pytest.raises(PipelineError, match="fitted jointly"):
        stages.plan_fits(data, spec, stages.configurations(data),
                         fit_excitations=["sine_decay"])
