"""Typed configuration nodes (Hydra structured configs).

The own settings of each pipeline stage (:data:`STAGE_SCHEMAS`) are a dataclass here, so
their defaults and types are written once: ``conf/<stage>.yaml`` puts the stage's schema first
in its defaults list (``- fit_schema``) and holds only interpolations (``out: ${paths.raw}``)
and the config groups, and a misspelt or mistyped override (``n_jobz=1``, ``n_jobs=two``)
fails when the config is composed instead of being ignored. A setting whose meaning lives in
a dataclass of the library is typed as that dataclass (``sync``:
:class:`rig_io.synchronise.SyncOptions`, the discrepancy workflow's knobs:
:class:`WorkflowSettings`).

Config groups (``paths``, ``tracking``, ``family``, ``rig``, ``campaign``, ...) stay groups:
their fields are typed ``Any``. A stage's Hydra-free ``run(cfg)`` passes its plain config
through :func:`with_defaults`, so a hand-written config gets the same defaults and checks.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from hysteresis.discrepancy.workflow import WorkflowSettings
from rig_io.limits import ReadLimits
from rig_io.synchronise import SyncOptions

#: Config group of the discrepancy workflow's knobs (``conf/discrepancy.yaml``:
#: ``- workflow_schema@workflow: workflow``).
WORKFLOW_GROUP = "workflow_schema"

#: Kinds scored as held out by default (validate's ``heldout``, unseen_shape's
#: ``eval_excitations``). mixed_sine and band_random are evaluation-only: the campaign records
#: them, no model is identified on them (docs/pipeline.md, "Held-out excitations").
HELDOUT_EXCITATIONS = ("triangle_decay", "trapezoid_decay", "mixed_sine", "band_random")


@dataclass
class ConfigurationSelection:
    """Which configurations a stage works on: each field null = every one in the dataset,
    a value or a list narrows it (``config.curve_angle_deg=[15,90]``)."""

    rig: Any = None
    curve_angle_deg: Any = None
    radius_mm: Any = None


@dataclass
class Signals:
    """Dataset columns used as model input u and output y."""

    input: str = "input"
    output: str = "output"


@dataclass
class GenerateConfig:
    """``conf/generate.yaml``: the virtual rig writes a campaign of raw runs."""

    paths: Any = MISSING
    #: Groups conf/rig/, conf/campaign/ and conf/effects/ (the strength of each effect).
    rig: Any = MISSING
    campaign: Any = MISSING
    effects: Any = MISSING
    #: The campaign's folder (``${paths.raw}``).
    out: str = MISSING
    #: folder (tsm-rig-log/1 run folders) | rosbag1 (.bag) | sqlite3 (rosbag2 .db3) |
    #: mcap (rosbag2 .mcap)
    format: str = "folder"
    #: Run folders only: write the streams as .csv.gz.
    compress: bool = False
    #: Parallel worker processes (joblib/loky); 1 = in this process.
    n_jobs: int = 2
    #: Rewrite a run whose id exists with a different spec (otherwise an error: raw runs are
    #: never rewritten; one with the same spec is always left alone).
    overwrite: bool = False
    progress: bool = True


@dataclass
class IngestConfig:
    """``conf/ingest.yaml``: raw runs -> validated parquet dataset."""

    paths: Any = MISSING
    #: Group conf/importer/: a foreign-log mapping; null = tsm-rig-log/1 runs only.
    importer: Any = None
    #: Raw runs (``${paths.raw}``): a folder of runs, or one run folder or bag.
    source: str = MISSING
    #: The processed dataset (``${paths.processed}``).
    out: str = MISSING
    #: Reprocess every run even when its source files, ingest version and options are
    #: unchanged.
    force: bool = False
    #: Drop outputs of runs that are no longer in the source (or are now rejected). Never
    #: applied when ``source`` is one run, and a missing or empty source, or one whose runs
    #: are all rejected, is refused.
    prune: bool = True
    progress: bool = True
    #: Synchronisation: camera latency search, Kalman filter (each knob's meaning is in
    #: SyncOptions; ``sync.max_latency_ms=500``).
    sync: SyncOptions = field(default_factory=SyncOptions)
    #: Read limits in MB: a run beyond one is rejected with the limit named, before it is
    #: read (FIFOs, devices and symlinks out of a run folder are always refused). 40 MB keeps
    #: one run's ingest under 1 GB of memory; raise ``limits.max_file_mb`` for longer runs.
    limits: ReadLimits = field(default_factory=ReadLimits)


@dataclass
class TrackedStageConfig:
    """What fit, validate, unseen_shape and report share."""

    paths: Any = MISSING
    #: Group conf/tracking/ (MLflow).
    tracking: Any = MISSING
    #: Parallel worker processes (joblib). Inside a multirun job the launcher already uses
    #: the cores: the stage then runs in one.
    n_jobs: int = 2
    #: false = recompute everything even when the content hashes say nothing changed.
    cache: bool = True


@dataclass
class IdentificationConfig(TrackedStageConfig):
    """Fit and validate: which configurations, and which data identifies (one rule for both,
    docs/pipeline.md "Which run identifies")."""

    config: ConfigurationSelection = field(default_factory=ConfigurationSelection)
    #: Identification excitation(s). Several = one model per excitation (cross-excitation
    #: matrix).
    fit_excitations: list[str] = field(default_factory=lambda: ["sine_decay"])
    #: Which run identifies, where a configuration has several runs of that excitation (run
    #: ids; one per configuration and excitation). Empty: each configuration must have exactly
    #: one, else the stage stops and names the candidates (never a silent pick).
    fit_runs: list[str] = field(default_factory=list)
    #: A configuration recorded in one run only (and no run of the fit excitations): its head
    #: identifies, this last fraction is held out as excitation ``<kind>.tail``.
    single_run_heldout_fraction: float = 0.3
    signals: Signals = field(default_factory=Signals)
    progress: bool = True


@dataclass
class FitConfig(IdentificationConfig):
    """``conf/fit.yaml``: identify every model family on every configuration."""

    #: Group conf/family/: null = every family in ``families``; ``family=gamma`` selects one
    #: family and lets its hyper-parameters be overridden (``family.n_operators=21``).
    family: Any = None
    #: Families fitted when no ``family`` is selected: ``all`` (hysteresis.family_names())
    #: or a list.
    families: Any = "all"
    #: In the all-families mode: per-family hyper-parameter overrides, added with ``+``:
    #: ``+family_overrides.gamma.n_operators=21``.
    family_overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class ValidateConfig(IdentificationConfig):
    """``conf/validate.yaml``: every fitted model predicts the runs of its configuration."""

    #: Kinds scored as held out besides the identification record.
    heldout: list[str] = field(default_factory=lambda: list(HELDOUT_EXCITATIONS))
    #: true = the full cross-excitation matrix (each model on every excitation present).
    cross: bool = False


@dataclass
class ShapeAwareEstimator:
    """Hyper-parameters of :class:`hysteresis.shape_aware.ShapeAwareModel`, with its defaults:
    features theta (curve angle, rad) and kappa = 1/R; ridge regression on
    theta^0..angle_degree x kappa^0..curvature_degree (``method: poly``) or a thin-plate
    spline (``method: rbf``)."""

    method: str = "poly"
    angle_degree: int = 3
    curvature_degree: int = 1
    ridge: float = 1.0e-3
    rbf_smoothing: float = 0.0


@dataclass
class UnseenShapeConfig(TrackedStageConfig):
    """``conf/unseen_shape.yaml``: leave-one-configuration-out over every configuration."""

    config: ConfigurationSelection = field(default_factory=ConfigurationSelection)
    #: The models scored are those identified on this excitation (the fit stage's files).
    fit_excitation: str = "sine_decay"
    #: Runs each predictor is scored on (pooled RMSE); empty = every kind but fit_excitation.
    eval_excitations: list[str] = field(default_factory=lambda: list(HELDOUT_EXCITATIONS))
    #: null = every family with fitted models.
    families: list[str] | None = None
    estimator: ShapeAwareEstimator = field(default_factory=ShapeAwareEstimator)
    signals: Signals = field(default_factory=Signals)
    plot: bool = True
    dpi: int = 72


@dataclass
class ExemplaryShape:
    """The configuration the report shows in detail (seed 001 presents phi = 90 deg,
    r = 30 mm); when the data lacks it, the largest angle with the smallest radius."""

    rig: str | None = "tsm-bench"
    curve_angle_deg: float | None = 90.0
    radius_mm: float | None = 30.0


@dataclass
class ReportPlots:
    """The report's figures."""

    #: One figure per configuration (all families overlaid).
    per_configuration: bool = True
    dpi: int = 72
    #: Time series are thinned to this many points per line.
    max_points: int = 1500


@dataclass
class ReportConfig(TrackedStageConfig):
    """``conf/report.yaml``: tables, leaderboard, plots and the static report."""

    exemplary: ExemplaryShape = field(default_factory=ExemplaryShape)
    #: Identification excitation whose models are reported.
    fit_excitation: str = "sine_decay"
    #: Ranking metric of the leaderboard (mean over the held-out excitations).
    metric: str = "rmse"
    plots: ReportPlots = field(default_factory=ReportPlots)
    #: md and/or html.
    formats: list[str] = field(default_factory=lambda: ["md", "html"])


#: Stage name -> its schema, stored as ``<stage>_schema`` (first in ``conf/<stage>.yaml``).
STAGE_SCHEMAS: dict[str, type[Any]] = {
    "generate": GenerateConfig,
    "ingest": IngestConfig,
    "fit": FitConfig,
    "validate": ValidateConfig,
    "unseen_shape": UnseenShapeConfig,
    "report": ReportConfig,
}


def _writable(node: DictConfig) -> None:
    """Clear the read-only flag a frozen library dataclass (SyncOptions, ReadLimits) puts on
    its node: the config's copy must take overrides; the library objects stay frozen."""
    OmegaConf.set_readonly(node, None)
    for key in node:
        child = node._get_node(str(key))
        if isinstance(child, DictConfig):
            _writable(child)


def schema_node(schema: type[Any]) -> DictConfig:
    """``schema`` as a typed OmegaConf node holding its defaults (struct: unknown keys fail)."""
    node = OmegaConf.structured(schema)
    assert isinstance(node, DictConfig)
    _writable(node)
    return node


def with_defaults(schema: type[Any], cfg: Mapping[str, Any]) -> dict[str, Any]:
    """``cfg`` merged over ``schema``'s defaults and checked against its types, as a plain dict.

    What a stage's Hydra-free ``run`` works on: a composed config comes back unchanged, a
    hand-written one (tests, ``run_all``) gets every setting it leaves out. Keys the schema
    does not know are kept, so one plain config may serve several stages; group nodes left
    unset (``paths`` ...) are left out. A mistyped value raises
    :class:`omegaconf.errors.ValidationError` (a ``ValueError``) naming the key.
    """
    node = schema_node(schema)
    OmegaConf.set_struct(node, False)
    node.merge_with(dict(cfg))
    unset = {str(k) for k in node if OmegaConf.is_missing(node, str(k))}
    plain = OmegaConf.to_container(node, resolve=True)
    assert isinstance(plain, dict)
    return {str(k): v for k, v in plain.items() if str(k) not in unset}


def register() -> None:
    """Store every schema node in Hydra's ConfigStore (idempotent)."""
    store = ConfigStore.instance()
    store.store(group=WORKFLOW_GROUP, name="workflow", node=WorkflowSettings)
    for stage, schema in STAGE_SCHEMAS.items():
        store.store(name=f"{stage}_schema", node=schema_node(schema))
