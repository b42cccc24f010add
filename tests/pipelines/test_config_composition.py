"""Every stage config composes (with overrides) through hydra.compose."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from pipelines import fit as fit_stage
from pipelines.common import CONF_DIR, Paths, to_container
from pipelines.run_all import stage_config

STAGES = ("fit", "validate", "report", "pipeline")


def _compose(name: str, overrides: list[str] | None = None, *, hydra_cfg: bool = False):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name=name, overrides=overrides or [],
                       return_hydra_config=hydra_cfg)


@pytest.mark.parametrize("name", STAGES)
def test_each_stage_composes_with_paths_and_tracking(name: str) -> None:
    cfg = _compose(name, ["paths.root=/tmp/somewhere"])
    plain = to_container(cfg)
    paths = Paths.from_config(plain["paths"])
    assert paths.processed == Path("/tmp/somewhere/data/processed/virtual")
    assert paths.reports == Path("/tmp/somewhere/data/reports")
    assert plain["tracking"]["enabled"] is True and plain["tracking"]["uri"] is None


@pytest.mark.parametrize("name", ("fit", "validate", "report"))
def test_stage_uses_joblib_launcher_and_mlflow_callback(name: str) -> None:
    cfg = _compose(name, hydra_cfg=True)
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("JoblibLauncher")
    assert launcher.n_jobs == 2
    assert cfg.hydra.callbacks.mlflow_parent._target_ == "pipelines.tracking.MlflowSweepCallback"


def test_fit_family_group_selects_one_family_and_its_overrides() -> None:
    cfg = _compose("fit", ["family=gamma", "family.n_operators=21",
                           "config.curve_angle_deg=90", "config.radius_mm=[30,45]"])
    plain = to_container(cfg)
    assert plain["family"]["_target_"] == "hysteresis.gamma.GammaModel"
    specs = fit_stage.family_specs(plain)
    assert [s.name for s in specs] == ["gamma"]
    model = specs[0].build(specs[0].config)
    assert model.n_operators == 21
    assert plain["config"] == {"rig": None, "curve_angle_deg": 90, "radius_mm": [30, 45]}


def test_fit_without_family_fits_every_registered_family() -> None:
    import hysteresis

    plain = to_container(_compose("fit", ["+family_overrides.gamma.n_operators=7"]))
    assert "family" not in plain or plain["family"] is None
    specs = fit_stage.family_specs(plain)
    assert [s.name for s in specs] == hysteresis.family_names()
    gamma = next(s for s in specs if s.name == "gamma")
    assert gamma.config["n_operators"] == 7
    for spec in specs:  # every config instantiates the registered class
        assert type(spec.build(spec.config)).family == spec.name


def test_tracking_server_and_off_groups(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://mlflow.lab:5000")
    server = to_container(_compose("fit", ["tracking=server"]))["tracking"]
    assert server["uri"] == "http://mlflow.lab:5000"
    off = to_container(_compose("pipeline", ["tracking=off"]))["tracking"]
    assert off["enabled"] is False


def test_experiments_compose_into_the_pipeline() -> None:
    quick = to_container(_compose("pipeline", ["+experiment=quick"]))
    assert quick["config"]["curve_angle_deg"] == [15, 90]
    cross = to_container(_compose("pipeline", ["+experiment=cross_excitation"]))
    assert cross["cross"] is True
    assert set(cross["fit_excitations"]) == {"sine_decay", "triangle_decay", "trapezoid_decay"}


def test_pipeline_forwards_shared_values_to_each_stage(tmp_path: Path) -> None:
    pipeline = to_container(_compose("pipeline", [
        f"paths.root={tmp_path}", "config.curve_angle_deg=45", "n_jobs=1",
        "heldout=[triangle_decay]", "overrides.fit=['families=[linear]']"]))
    fit_cfg = stage_config("fit", pipeline)
    assert fit_cfg["families"] == ["linear"]
    assert fit_cfg["config"]["curve_angle_deg"] == 45 and fit_cfg["n_jobs"] == 1
    assert Paths.from_config(fit_cfg["paths"]).root == tmp_path
    val_cfg = stage_config("validate", pipeline)
    assert val_cfg["heldout"] == ["triangle_decay"]
    rep_cfg = stage_config("report", pipeline)
    assert rep_cfg["fit_excitation"] == "sine_decay"
    ing = OmegaConf.create(stage_config("report", pipeline))
    assert ing.paths.reports == str(tmp_path / "data" / "reports")


def test_discrepancy_workflow_is_a_typed_node_with_its_defaults_in_one_place() -> None:
    from dataclasses import asdict

    from hydra.errors import ConfigCompositionException

    from hysteresis.discrepancy.workflow import WorkflowSettings
    from pipelines.discrepancy import DiscrepancyError, workflow_settings

    plain = to_container(_compose("discrepancy", ["workflow.max_effects=2"]))
    defaults = asdict(WorkflowSettings())
    assert set(plain["workflow"]) == set(defaults)
    settings = workflow_settings(plain["workflow"], progress=True)
    assert settings == WorkflowSettings(max_effects=2, progress=True)
    for bad in ("workflow.max_efects=2", "workflow.max_effects=two"):
        with pytest.raises(ConfigCompositionException):
            _compose("discrepancy", [bad])
    # a forced addition composes, and the stage refuses it
    forced = to_container(_compose("discrepancy", ["+workflow.max_efects=2"]))["workflow"]
    with pytest.raises(DiscrepancyError, match=r"unknown workflow setting\(s\) \['max_efects'\]"):
        workflow_settings(forced)
