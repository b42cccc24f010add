"""Every stage config composes (with overrides) through hydra.compose."""

from __future__ import annotations

import dataclasses
import tempfile
from dataclasses import asdict
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from pipelines.common import CONF_DIR, Paths, to_container
from pipelines.core import fit as fit_stage
from pipelines.run_all import EXTERNAL_STAGES, OWN_STAGES, stage_config

#: An absolute root elsewhere (composition only: nothing is written there).
ELSEWHERE = Path(tempfile.gettempdir(), "somewhere")

STAGES = ("fit", "validate", "report", "pipeline")


def _compose(name: str, overrides: list[str] | None = None, *, hydra_cfg: bool = False):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name=name, overrides=overrides or [],
                       return_hydra_config=hydra_cfg)


@pytest.mark.parametrize("name", STAGES)
def test_each_stage_composes_with_paths_and_tracking(name: str) -> None:
    cfg = _compose(name, [f"paths.root={ELSEWHERE}"])
    plain = to_container(cfg)
    paths = Paths.from_config(plain["paths"])
    assert paths.processed == ELSEWHERE / "data/processed/virtual"
    assert paths.reports == ELSEWHERE / "data/reports"
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
    assert fit_cfg.families == ["linear"]
    assert fit_cfg.config.curve_angle_deg == 45 and fit_cfg.n_jobs == 1
    assert Paths.from_config(fit_cfg.paths).root == tmp_path
    val_cfg = stage_config("validate", pipeline)
    assert val_cfg.heldout == ["triangle_decay"]
    rep_cfg = stage_config("report", pipeline)
    assert rep_cfg.fit_excitation == "sine_decay"
    ing = OmegaConf.structured(stage_config("report", pipeline))
    assert ing.paths.reports == str(tmp_path / "data" / "reports")


def test_discrepancy_workflow_is_a_typed_node_with_its_defaults_in_one_place() -> None:
    from dataclasses import asdict

    from hydra.errors import ConfigCompositionException

    from hysteresis.discrepancy.workflow import WorkflowSettings
    from pipelines.discrepancy import DiscrepancyError, settings, workflow_settings

    plain = to_container(_compose("discrepancy", ["workflow.max_effects=2", "progress=true"]))
    defaults = asdict(WorkflowSettings())
    assert set(plain["workflow"]) == set(defaults)
    typed = settings(plain)
    assert typed.workflow == WorkflowSettings(max_effects=2, candidates=list(defaults[
        "candidates"]))  # a list in the config; the workflow's own tuple below
    assert workflow_settings(typed) == WorkflowSettings(max_effects=2, progress=True, workers=0)
    for bad in ("workflow.max_efects=2", "workflow.max_effects=two"):
        with pytest.raises(ConfigCompositionException):
            _compose("discrepancy", [bad])
    # a forced addition composes, and the stage refuses it
    forced = to_container(_compose("discrepancy", ["+workflow.max_efects=2"]))
    with pytest.raises(DiscrepancyError, match=r"^workflow.max_efects: Key 'max_efects' not in"):
        settings(forced)


#: Per converted stage: an override with a misspelt key and one with a mistyped value.
BAD_OVERRIDES = {
    "generate": ("compres=true", "n_jobs=two"),
    "ingest": ("sync.max_latncy_ms=500", "prune=sometimes"),
    "fit": ("fit_excitation=[sine_decay]", "single_run_heldout_fraction=a_third"),
    "validate": ("held_out=[triangle_decay]", "cross=sometimes"),
    "unseen_shape": ("estimator.methd=rbf", "dpi=high"),
    "report": ("plots.max_point=500", "plots.dpi=[72]"),
    "discrepancy": ("max_base=3", "base_check=sometimes"),
    "discrepancy_study": ("pairs_selectd=[a]", "seed=three"),
    "compensate": ("seed001.profilez=8", "seed002.trials=two"),
    "pipeline": ("stage=[fit]", "overrides.fit=families"),
}


def _schema_defaults(stage: str) -> dict[str, object]:
    """The stage schema's own settings with their dataclass defaults (groups left out), as
    plain values (a tuple default, WorkflowSettings.candidates, as the list a config holds)."""
    from dataclasses import fields

    from pipelines.schemas import STAGE_SCHEMAS, schema_node

    schema = STAGE_SCHEMAS[stage]
    groups = {"paths", "tracking", "rig", "campaign", "effects", "importer", "family"}
    node = schema_node(schema)
    values = OmegaConf.to_container(node)
    assert isinstance(values, dict)
    return {f.name: values[f.name] for f in fields(schema)
            if f.name not in groups and not OmegaConf.is_missing(node, f.name)}


def test_every_stage_has_a_schema() -> None:
    from pipelines.schemas import STAGE_SCHEMAS

    assert set(STAGE_SCHEMAS) == set(BAD_OVERRIDES)


@pytest.mark.parametrize("stage", sorted(BAD_OVERRIDES))
def test_stage_defaults_come_from_its_schema(stage: str) -> None:
    plain = to_container(_compose(stage))
    defaults = _schema_defaults(stage)
    assert defaults and {k: plain[k] for k in defaults} == defaults
    # the YAML holds no setting of its own but interpolations (out: ${paths.raw} ...)
    own = OmegaConf.load(CONF_DIR / f"{stage}.yaml")
    for key in own:
        if key not in ("defaults", "hydra"):
            assert OmegaConf.is_interpolation(own, str(key)), f"{stage}.yaml sets {key}"


@pytest.mark.parametrize("stage", sorted(BAD_OVERRIDES))
def test_stage_rejects_a_misspelt_or_mistyped_override(stage: str) -> None:
    from hydra.errors import ConfigCompositionException

    misspelt, mistyped = BAD_OVERRIDES[stage]
    for bad in (misspelt, mistyped):
        with pytest.raises(ConfigCompositionException):
            _compose(stage, [bad])


def test_typed_overrides_reach_the_stage() -> None:
    ingest = to_container(_compose("ingest", ["sync.max_latency_ms=500",
                                              "limits.max_file_mb=200"]))
    assert ingest["sync"]["max_latency_ms"] == 500.0
    assert ingest["limits"]["max_file_mb"] == 200.0
    unseen = to_container(_compose("unseen_shape", ["families=[gamma]", "estimator.method=rbf"]))
    assert unseen["families"] == ["gamma"] and unseen["estimator"]["method"] == "rbf"
    report = to_container(_compose("report", ["plots.per_configuration=false", "formats=[md]"]))
    assert report["plots"]["per_configuration"] is False and report["formats"] == ["md"]


def test_a_hand_written_stage_config_gets_the_schema_defaults_and_checks() -> None:
    from dataclasses import asdict

    from omegaconf.errors import ValidationError

    from pipelines.schemas import ConfigurationSelection, FitConfig, ReportConfig, settings

    cfg = settings(FitConfig, {"paths": {"root": "x"}, "config": {"radius_mm": 30},
                               "heldout": []})
    assert cfg.config == ConfigurationSelection(rig=None, curve_angle_deg=None, radius_mm=30)
    assert cfg.fit_excitations == ["sine_decay"] and cfg.families == "all"
    assert cfg.paths == {"root": "x"} and not hasattr(cfg, "heldout")  # validate's key
    assert cfg.tracking is None  # a group left unset
    assert asdict(settings(ReportConfig, {"plots": {"dpi": 30}}).plots) == {
        "per_configuration": True, "dpi": 30, "max_points": 1500}
    with pytest.raises(ValidationError, match="n_jobs"):
        settings(FitConfig, {"n_jobs": "two"})


def test_unseen_shape_estimator_defaults_are_the_models() -> None:
    import inspect
    from dataclasses import asdict

    from hysteresis.shape_aware import ShapeAwareModel
    from pipelines.schemas import ShapeAwareEstimator

    params = inspect.signature(ShapeAwareModel.__init__).parameters
    assert asdict(ShapeAwareEstimator()) == {
        k: params[k].default for k in asdict(ShapeAwareEstimator())}


@pytest.mark.parametrize("experiment", ["quick", "cross_excitation", "gamma_only",
                                        "bending_joint"])
def test_pipeline_experiments_compose_every_stage(experiment: str, tmp_path: Path) -> None:
    from pipelines.run_all import OWN_STAGES, compose_stage, stage_overrides

    pipeline = to_container(_compose("pipeline", [f"+experiment={experiment}",
                                                  f"paths.root={tmp_path}"]))
    for stage in ("generate", "ingest"):
        assert compose_stage(stage, stage_overrides(stage, pipeline)).out
    for stage in OWN_STAGES:
        cfg = stage_config(stage, pipeline)
        assert set(_schema_defaults(stage)) <= set(asdict(cfg))
    if experiment == "gamma_only":
        assert stage_config("fit", pipeline).families == ["gamma"]
    if experiment == "bending_joint":
        generate = compose_stage("generate", stage_overrides("generate", pipeline))
        assert generate.effects["time_delay"] == 12.0


@pytest.mark.parametrize("experiment", ["compensation_default", "compensation_quick",
                                        "compensation_full"])
def test_compensation_experiments_compose_and_validate(experiment: str) -> None:
    from hydra.errors import ConfigCompositionException

    from pipelines import schemas

    cfg = _compose("compensate", [f"experiment={experiment}", f"paths.root={ELSEWHERE}"])
    # the composed config is the schema's node: merging it into the schema (struct) changes
    # nothing, and the typed settings of a plain copy come back equal to it
    typed = OmegaConf.merge(schemas.schema_node(schemas.CompensateConfig), cfg)
    assert OmegaConf.to_container(typed, resolve=True) == to_container(cfg)
    plain = to_container(cfg)
    assert dataclasses.asdict(schemas.settings(schemas.CompensateConfig, plain)) == plain
    assert plain["out_dir"] == str(ELSEWHERE / "data/reports/compensation")
    defaults = _schema_defaults("compensate")
    s1, s2, s0 = plain["seed001"], plain["seed002"], plain["seed000"]
    if experiment == "compensation_default":
        assert {k: plain[k] for k in defaults} == defaults
    elif experiment == "compensation_quick":
        assert s1["all_configurations"] == "none" and s1["families"] == ["gamma", "bouc_wen"]
        assert s1["shape_aware"]["curve_angles_deg"] == [15, 45, 75]
        assert s1["timing"]["steps"]["exact"] == 100 and s2["trials"] == 1
        # the list of cases replaces the default four (a mapping would have merged into them)
        assert s2["cases"] == [{"name": "case1", "curve_angle_deg": 90.0, "radius_mm": 30.0}]
        # a nested node set in part keeps the schema's other values
        assert s0["tracking"] == {**defaults["seed000"]["tracking"], "duration_s": 20.0}
        assert s0["ga"] == {"maxiter": 10, "popsize": 8, "max_samples": 400}
    else:
        assert s1["all_configurations"] == "full" and s2["trials"] == 5
        assert [c["name"] for c in s2["cases"]] == ["case1", "case2", "case3", "case4"]
        assert {**s1, "all_configurations": "quick"} == defaults["seed001"]
    for bad in ("seed001.profilez=8", "seed000.tracking.kpp=0.1", "seed001.ours.registri=tsm",
                "seed002.trials=two", "seed001.shape_aware.enabled=sometimes",
                "seed000.segments=[0,3]", "seed002.camera.rate_hz=fast",
                "seed002.cases=[{name:c,curve_angle_deg:steep,radius_mm:30}]"):
        with pytest.raises(ConfigCompositionException):
            _compose("compensate", [f"experiment={experiment}", bad])


def test_a_hand_written_compensation_config_gets_the_schema_defaults_and_checks() -> None:
    from dataclasses import asdict

    from omegaconf.errors import ValidationError

    from pipelines.registry import ALIAS
    from pipelines.schemas import CompensateConfig, settings

    cfg = settings(CompensateConfig, {"out_dir": "x", "report": "r.md",
                                      "seed001": {"shapes": {"A": [90, 30]}},
                                      "seed000": {"tracking": {"kp": 0.1}}})
    assert cfg.seed001.shapes == {"A": [90, 30]}  # a free mapping replaces the default
    assert cfg.seed001.all_configurations == "quick" and cfg.seed002.trials == 2
    assert cfg.seed000.tracking.kp == 0.1 and cfg.seed000.tracking.kd == 0.05
    assert asdict(cfg.seed000.camera) == {"rate_hz": 30.0, "latency_s": 0.0, "noise_std": 0.2}
    assert cfg.seed001.ours.registry_alias == ALIAS
    with pytest.raises(ValidationError, match="trials"):
        settings(CompensateConfig, {"out_dir": "x", "report": "r.md",
                                    "seed002": {"trials": "two"}})


#: The discrepancy stage, its study and the whole pipeline: config name -> (schema, settings
#: the composed config holds besides the groups, a mistyped value for a hand-written config).
ENTRY_POINTS = {
    "discrepancy": ("DiscrepancyConfig", {"max_bases": 2, "analysis_rate_hz": 25.0},
                    {"base_misfit_factor": "large"}),
    "discrepancy_study": ("DiscrepancyStudyConfig", {"seed": 3, "rate_hz": 20.0},
                          {"n_jobs": "two"}),
    "pipeline": ("PipelineConfig", {"n_jobs": 2, "stages": [*EXTERNAL_STAGES, *OWN_STAGES]},
                 {"overrides": {"fit": "families=[linear]"}}),
}


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_entry_point_config_validates_against_its_schema(name: str) -> None:
    from omegaconf.errors import ValidationError

    from pipelines import schemas

    schema = getattr(schemas, ENTRY_POINTS[name][0])
    assert schemas.STAGE_SCHEMAS[name] is schema
    cfg = _compose(name, [f"paths.root={ELSEWHERE}"])
    # the composed config is the schema's node: merging it into the schema (struct: an unknown
    # key would fail) changes nothing, and the typed settings of a plain copy come back equal
    typed = OmegaConf.merge(schemas.schema_node(schema), cfg)
    assert OmegaConf.to_container(typed, resolve=True) == to_container(cfg)
    plain = to_container(cfg)
    assert dataclasses.asdict(schemas.settings(schema, plain)) == plain
    settings, mistyped = ENTRY_POINTS[name][1], ENTRY_POINTS[name][2]
    assert {k: plain[k] for k in settings} == settings
    with pytest.raises(ValidationError, match=next(iter(mistyped))):
        schemas.settings(schema, {**plain, **mistyped})


@pytest.mark.parametrize(("name", "bad"), [
    ("discrepancy", "auto_familes.gamma={}"), ("discrepancy", "workflow.pair_pool=[3]"),
    ("discrepancy", "analysis_rate_hz=fast"), ("discrepancy", "identify_excitations=sine"),
    ("discrepancy_study", "combinations.pair_selected=[b]"),
    ("discrepancy_study", "effects_selected=drift"),
    ("pipeline", "overrides.fitt=[]"), ("pipeline", "signals.inputs=x"),
    ("pipeline", "cross=sometimes"), ("pipeline", "config.radius=30"),
])
def test_entry_point_rejects_a_misspelt_or_mistyped_override(name: str, bad: str) -> None:
    from hydra.errors import ConfigCompositionException

    with pytest.raises(ConfigCompositionException):
        _compose(name, [bad])


def test_entry_point_overrides_reach_their_settings() -> None:
    disc = to_container(_compose("discrepancy", [
        "base_family=gamma", "+base_params={constraint: free, fit_offset: true}",
        "analysis_rate_hz=null", "workflow.max_effects=2"]))
    assert disc["base_params"] == {"constraint": "free", "fit_offset": True}
    assert disc["analysis_rate_hz"] is None and disc["workflow"]["max_effects"] == 2
    study = to_container(_compose("discrepancy_study", [
        "effects_selected=[drift]", "strengths.drift=[1,2]", "+pairs.f=[[60,30],[60,75]]",
        "pairs_selected=[f]", "+workflow.physical_evidence=false"]))
    assert study["effects_selected"] == ["drift"] and study["strengths"]["drift"] == [1, 2]
    assert study["pairs"]["f"] == [[60, 30], [60, 75]] and study["pairs_selected"] == ["f"]
    assert study["workflow"] == {"physical_evidence": False}
    pipeline = to_container(_compose("pipeline", ["stages=[fit,validate]", "n_jobs=1"]))
    assert pipeline["stages"] == ["fit", "validate"] and pipeline["n_jobs"] == 1


def test_a_hand_written_mapping_replaces_the_default_mapping_whole() -> None:
    from dataclasses import asdict

    from pipelines.schemas import DiscrepancyConfig, DiscrepancyStudyConfig, Signals, settings

    study = settings(DiscrepancyStudyConfig, {"out": "x", "combinations": {"strengths": {}},
                                              "strengths": {"drift": [1.0]}})
    # combinations is a typed node: its own free mapping is replaced, its other field kept
    assert asdict(study.combinations) == {"strengths": {}, "pairs_selected": ["a"]}
    assert study.strengths == {"drift": [1.0]}
    assert study.pairs_selected == ["a", "b", "c", "d", "e"] and study.workflow == {}
    disc = settings(DiscrepancyConfig, {"source": "s", "report": "r.json",
                                        "auto_families": {"gamma": {}},
                                        "signals": {"input": "u"},
                                        "workflow": {"max_effects": 2}})
    assert disc.auto_families == {"gamma": {}}
    # typed nodes still merge field by field
    assert disc.signals == Signals(input="u", output="output")
    assert disc.workflow.max_effects == 2 and disc.workflow.noise_factor == 2.0
    assert disc.importer is None


def test_a_hand_written_pipeline_config_forwards_the_schema_defaults(tmp_path: Path) -> None:
    from pipelines.schemas import ValidateConfig

    composed = to_container(_compose("pipeline", [f"paths.root={tmp_path}", "tracking=off"]))
    pipeline = {"paths": composed["paths"], "tracking": composed["tracking"],
                "overrides": {"fit": ["families=[linear]"]}}
    fit_cfg = stage_config("fit", pipeline)
    assert fit_cfg.families == ["linear"]
    assert fit_cfg.fit_excitations == ValidateConfig().fit_excitations
    val_cfg = stage_config("validate", pipeline)
    assert val_cfg.heldout == ValidateConfig().heldout and val_cfg.cross is False
    unseen = stage_config("unseen_shape", pipeline)
    assert unseen.fit_excitation == "sine_decay"
    assert unseen.eval_excitations == ValidateConfig().heldout
