"""Typed configuration nodes (Hydra structured configs).

The own settings of each pipeline stage, of the discrepancy stage and study, of the
compensation experiments and of the whole-pipeline entry point ``run_all``
(:data:`STAGE_SCHEMAS`) are a dataclass here, so their defaults and types are written once:
``conf/<stage>.yaml`` puts the stage's schema first in its defaults list (``- fit_schema``)
and holds only interpolations (``out: ${paths.raw}``) and the config groups, and a misspelt
or mistyped override (``n_jobz=1``, ``n_jobs=two``) fails when the config is composed instead
of being ignored. A setting whose meaning lives in a dataclass of the library is typed as that
dataclass (``sync``: :class:`rig_io.synchronise.SyncOptions`, the discrepancy workflow's
knobs: :class:`WorkflowSettings`). A free mapping (``auto_families``, the study's
``strengths``) is a ``dict[str, Any]`` field: its keys are the user's, and a value given for
it replaces the default mapping whole (:func:`settings`).

Config groups (``paths``, ``tracking``, ``family``, ``rig``, ``campaign``, ...) stay groups:
their fields are typed ``Any``. A stage's Hydra-free core converts its config once with
:func:`settings` (a composed config and a hand-written mapping alike get the same defaults
and checks) and reads attributes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from hysteresis.discrepancy.workflow import WorkflowSettings

# The compensation stage's settings live beside its experiments (and the shape-aware
# estimator's in a leaf both stages import); re-exported so that every schema is reachable here.
from pipelines.compensation.settings import CompensateConfig as CompensateConfig
from pipelines.compensation.settings import CompensationCamera as CompensationCamera
from pipelines.compensation.settings import CompensationOurs as CompensationOurs
from pipelines.compensation.settings import Seed000GA as Seed000GA
from pipelines.compensation.settings import Seed000Settings as Seed000Settings
from pipelines.compensation.settings import Seed000Tracking as Seed000Tracking
from pipelines.compensation.settings import Seed000UKF as Seed000UKF
from pipelines.compensation.settings import Seed001Identification as Seed001Identification
from pipelines.compensation.settings import Seed001Ours as Seed001Ours
from pipelines.compensation.settings import Seed001Quick as Seed001Quick
from pipelines.compensation.settings import Seed001Settings as Seed001Settings
from pipelines.compensation.settings import Seed001ShapeAware as Seed001ShapeAware
from pipelines.compensation.settings import Seed001Timing as Seed001Timing
from pipelines.compensation.settings import Seed002Calibration as Seed002Calibration
from pipelines.compensation.settings import Seed002Case as Seed002Case
from pipelines.compensation.settings import Seed002Feedback as Seed002Feedback
from pipelines.compensation.settings import Seed002Settings as Seed002Settings
from pipelines.shape_aware_settings import ShapeAwareEstimator as ShapeAwareEstimator
from rig_io.limits import ReadLimits
from rig_io.synchronise import SyncOptions

#: Config group of the discrepancy workflow's knobs (``conf/discrepancy.yaml``:
#: ``- workflow_schema@workflow: workflow``).
WORKFLOW_GROUP = "workflow_schema"
T = TypeVar("T")

#: Kinds scored as held out by default (validate's ``heldout``, unseen_shape's
#: ``eval_excitations``). mixed_sine and band_random are evaluation-only: the campaign records
#: them, no model is identified on them (docs/pipeline.md, "Held-out excitations").
HELDOUT_EXCITATIONS = ("triangle_decay", "trapezoid_decay", "mixed_sine", "band_random")


@dataclass
class ConfigurationSelection:
    """Which configurations a stage works on: each field null = every one in the dataset,
    a value or a list narrows it (``config.curve_angle_deg=[15,90]``)."""

    #: Rig(s) worked on (the dataset's ``rig`` column, e.g. tsm-bench).
    rig: Any = None
    #: Sheath curve angle(s) worked on, deg.
    curve_angle_deg: Any = None
    #: Sheath curve radius (or radii) worked on, mm.
    radius_mm: Any = None


@dataclass
class Signals:
    """Dataset columns used as model input u and output y."""

    #: Processed-dataset column read as the model input u (``input``: mm of pull or deg of motor
    #: angle; ``input_norm``: scaled to [-1, 1]).
    input: str = "input"
    #: Processed-dataset column read as the model output y (``output`` or ``output_norm``).
    output: str = "output"


@dataclass
class GenerateConfig:
    """``conf/generate.yaml``: the virtual rig writes a campaign of raw runs."""

    #: Group conf/paths/: the project's data folders (``out`` is its raw folder).
    paths: Any = MISSING
    #: Group conf/rig/: the virtual rig simulated (its name, physical parameters and sensors).
    rig: Any = MISSING
    #: Group conf/campaign/: the runs written (seed, curve angles x radii, excitations).
    campaign: Any = MISSING
    #: Group conf/effects/: the strength of each physical effect (0 = off, 1 = nominal;
    #: docs/virtual-rig.md).
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
    #: A progress bar (tqdm, on stderr) over the runs written.
    progress: bool = True


@dataclass
class IngestConfig:
    """``conf/ingest.yaml``: raw runs -> validated parquet dataset."""

    #: Group conf/paths/: the project's data folders (``source`` and ``out`` are its raw and
    #: processed folders).
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
    #: A progress bar (tqdm, on stderr) over the runs ingested.
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

    #: Group conf/paths/: the project's data folders (processed, models, predictions, reports) the
    #: stage reads and writes.
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
    #: A held-out run recorded after others of its configuration (manifest ``started_at``)
    #: may start where they left the mechanism, and a relative encoder zeroes the output
    #: there: ``chained`` judges it from the state the earlier runs' input left (its output
    #: moved to its own zero), ``separate`` from the start the base takes from the record,
    #: ``auto`` joins them from the first round where the model as it stands predicts them
    #: 10 % better (report: run_history).
    history: str = "auto"
    signals: Signals = field(default_factory=Signals)
    #: Progress bars (tqdm, on stderr) while models are fitted or scored; false = none (fit then
    #: logs each finished model).
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
    #: Per-run limit of the fit: the most samples one identification run may have; a longer
    #: one stops the stage before any fit, naming the run, its size and this setting. The
    #: standard campaign's records have ~8 000 samples; the limit keeps a 10 kHz record of
    #: 10 million samples (a fit of it passed 5 GB) from exhausting the machine's memory.
    max_samples: int = 2_000_000


@dataclass
class ValidateConfig(IdentificationConfig):
    """``conf/validate.yaml``: every fitted model predicts the runs of its configuration."""

    #: Kinds scored as held out besides the identification record.
    heldout: list[str] = field(default_factory=lambda: list(HELDOUT_EXCITATIONS))
    #: true = the full cross-excitation matrix (each model on every excitation present).
    cross: bool = False


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
    #: Write ``${paths.reports}/plots/unseen_shape.png`` (per family, each configuration's RMSE
    #: under the three predictors).
    plot: bool = True
    #: Resolution of that figure (dots per inch).
    dpi: int = 72


@dataclass
class ExemplaryShape:
    """The configuration the report shows in detail (seed 001 presents phi = 90 deg,
    r = 30 mm); when the data lacks it, the largest angle with the smallest radius."""

    #: Its rig (the dataset's ``rig`` column).
    rig: str | None = "tsm-bench"
    #: Its curve angle, deg (null: a configuration recorded without one).
    curve_angle_deg: float | None = 90.0
    #: Its curve radius, mm (null: a configuration recorded without one).
    radius_mm: float | None = 30.0


@dataclass
class ReportPlots:
    """The report's figures."""

    #: One figure per configuration (all families overlaid).
    per_configuration: bool = True
    #: Resolution of the report's figures (dots per inch).
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


@dataclass
class DiscrepancyConfig:
    """``conf/discrepancy.yaml``: what is the model missing? The source is ingested into a
    temporary folder, the base family is fitted per configuration on the identification
    excitation and judged on the held-out ones; locate -> name -> add -> show repeats until no
    candidate beats the noise (docs/discrepancy.md)."""

    paths: Any = MISSING
    #: Group conf/tracking/ (MLflow).
    tracking: Any = MISSING
    #: Group conf/importer/: a foreign-log mapping; null = tsm-rig-log/1 runs and bags.
    importer: Any = None
    #: Raw runs or bags (``${paths.raw}``): a folder of runs, or one run folder or bag.
    source: str = MISSING
    #: The report JSON (``${paths.reports}/discrepancy.json``), written atomically; its plots
    #: go beside it (``<report stem>_plots/``).
    report: str = MISSING
    #: Base family: a registered family name (gamma, preisach, bouc_wen, coleman_hodgdon,
    #: linear), a local one (play_sum, affine), or ``auto`` = the family of ``auto_families``
    #: with the lowest held-out RMSE on this source (the best standard family). As a base,
    #: gamma is the thesis' physical form (sum-to-one, no offset, widest play 1/6 of the
    #: input's range) so it cannot absorb the effects searched for, with every run's start
    #: taken from the record; base_params override it.
    base_family: str = "auto"
    #: Parameters of the base family (``'+base_params={constraint: free, fit_offset: true}'``;
    #: hysteresis.discrepancy.workflow.BASE_DEFAULTS).
    base_params: dict[str, Any] = field(default_factory=dict)
    #: The families ``auto`` ranks (and a given base is checked against): label -> parameters
    #: (``family:`` names the family when the label does not).
    auto_families: dict[str, Any] = field(default_factory=lambda: {
        "gamma": {},
        "gamma_free": {"family": "gamma", "constraint": "free", "fit_offset": True},
        "preisach": {},
        "bouc_wen": {},
        "coleman_hodgdon": {},
        # plays whose widths follow the output tension (a follower whose load grows with its
        # travel); ranked only on runs with output load cells, and only where it predicts 20 %
        # better than every family above
        "gamma_tension": {},
    })
    #: auto: the workflow runs on the best plain family and, while its answer (clean or not)
    #: is not explained to within base_retry_factor x the noise floor, on the next best (up to
    #: max_bases); the base whose model with its terms predicts the held-out runs best is kept
    #: (a later one must beat the first by workflow.min_relative_gain, and where the first
    #: found nothing, reach base_retry_factor x the noise floor: a base tried after a clean
    #: answer stops after its first round unless one term alone comes within twice that).
    #: The report's bases_tried lists them.
    max_bases: int = 2
    base_retry_factor: float = 1.5
    #: With a base family given (not auto): also score the auto_families plain and check the
    #: base against the best of them (report: base_misfit; the headline says so): the effects
    #: named on a base that cannot take the loop's shape may stand in for its misfit.
    base_check: bool = True
    base_misfit_factor: float = 1.5
    #: A base that fits base_misfit_factor x worse plain, or whose answer is not within
    #: base_retry_factor x the noise floor, does not answer alone: auto runs too, and answers
    #: when its base is another family whose model with its terms predicts the held-out runs
    #: workflow.min_relative_gain better, or better at all where the given base's terms leave
    #: it worse than the best family plain (report: given_base keeps the given base's
    #: answer). false: the given base's answer, flagged when even with its terms it fits
    #: base_misfit_factor x worse than the best family plain.
    base_misfit_fallback: bool = True
    #: Excitation kinds used for identification when a run's manifest does not say its role
    #: (``excitation.role``); every other run is held out.
    identify_excitations: list[str] = field(default_factory=lambda: ["sine_decay"])
    #: A configuration recorded in one run only: its head identifies and this last fraction of
    #: it is held out (the report's run_choice says so). Configurations with several runs use
    #: roles.
    single_run_heldout_fraction: float = 0.3
    #: A held-out run recorded after others of its configuration (manifest ``started_at``)
    #: may start where they left the mechanism, and a relative encoder zeroes the output
    #: there: ``chained`` judges it from the state the earlier runs' input left (its output
    #: moved to its own zero), ``separate`` from the start the base takes from the record,
    #: ``auto`` joins them from the first round where the model as it stands predicts them
    #: 10 % better (report: run_history).
    history: str = "auto"
    signals: Signals = field(default_factory=Signals)
    #: Analyse at this rate (moving-average decimation; null = the dataset's own rate).
    analysis_rate_hz: float | None = 25.0
    #: The workflow's knobs: :class:`WorkflowSettings` holds their defaults and what each
    #: means. The main ones: candidates, max_effects, min_relative_gain (a term must remove
    #: this fraction of the held-out RMSE), max_delta_bic, min_runs_improved, noise_factor
    #: (stop this close to the noise floor), physical_evidence (friction candidates must show
    #: in the load cells), pair_search and pair_pool (when no single term clears the bar,
    #: pairs with a member among the best pair_pool singles), joint_retune, clean_factor
    #: (no_missing_effect only within this multiple of the noise floor; beyond it,
    #: unexplained), compare_forms (a named effect's other forms judged on the held-out
    #: runs: a better one taken, the ties reported as not separable). Override as
    #: ``workflow.<knob>=<value>``; its ``progress`` and ``workers`` follow the stage's.
    workflow: WorkflowSettings = field(default_factory=WorkflowSettings)
    #: Processes that score the candidates, forked from the stage's (0: one per core this
    #: process may use; 1: all in the stage's process). Sets ``workflow.workers``; the answer
    #: does not depend on it.
    workers: int = 0
    #: Seed 000 evidence: fit Coleman-Hodgdon + the active-modelling UKF on each
    #: identification record and regress its model-error estimate f_h on the winning term
    #: (SINDy-style).
    ukf_evidence: bool = False
    #: Before/after plots beside the report.
    plots: bool = True
    progress: bool = True


@dataclass
class StudyExpectation:
    """What one single-effect case of the study must show (``expect`` of the study)."""

    effect: str = MISSING
    strength: float = MISSING
    pair: str = MISSING
    #: ``halved``: named first and the held-out RMSE at least halved in every configuration
    #: of the pair; ``named``: named first; ``clean``: no effect named.
    outcome: str = "halved"
    #: With ``named``: the pooled held-out RMSE the first term removes, at least (0..1).
    min_reduction: float = 0.0


@dataclass
class StudyCombinations:
    """Two effects hidden at once (``combinations`` of the study)."""

    #: One strength per effect, where each alone is named first; every pair of these effects
    #: is a case. Given, it replaces the default mapping whole; empty
    #: (``combinations.strengths={}``) = no two-effect cases.
    strengths: dict[str, Any] = field(default_factory=lambda: {
        "rate_dependence": 1.0,
        "tendon_elongation": 8.0,
        "time_delay": 1.0,
        "drift": 2.0,
        "asymmetry": 2.0,
        "saturation": 1.0,
        "dead_zone": 1.0,
    })
    #: The configuration pairs (of the study's ``pairs``) the two-effect cases run on.
    pairs_selected: list[str] = field(default_factory=lambda: ["a"])


def _study_expectations() -> list[StudyExpectation]:
    halved = [("time_delay", 1.0, "a"), ("saturation", 1.0, "a"), ("dead_zone", 1.0, "e"),
              ("rate_dependence", 1.0, "e"), ("rate_dependence", 1.5, "a"), ("drift", 2.0, "a"),
              ("asymmetry", 2.0, "a"), ("tendon_elongation", 12.0, "e")]
    return [*(StudyExpectation(e, s, p) for e, s, p in halved),
            # the stretch goes with the tension squared: on pair a it is named from 2 and
            # removes half the error only from 8 (in the 90 deg configuration)
            StudyExpectation("tendon_elongation", 8.0, "a", "named", 0.5),
            StudyExpectation("tendon_elongation", 2.0, "a", "named", 0.2),
            StudyExpectation("tendon_elongation", 1.0, "a", "clean")]


@dataclass
class DiscrepancyStudyConfig:
    """``conf/discrepancy_study.yaml``: detection limits of the discrepancy workflow. Each case
    hides one effect at one strength in virtual-rig runs of a configuration pair (seed 001's
    excitations; the sine identifies, triangle and trapezoid are held out) and records what the
    workflow names and how much held-out error it removes."""

    paths: Any = MISSING
    #: Group conf/tracking/ (MLflow).
    tracking: Any = MISSING
    #: Path stem of the outputs (``${paths.reports}/discrepancy_study``): <out>.json (every
    #: case) and <out>.md (the table).
    out: str = MISSING
    #: Effects to study (null = every effect under ``strengths``).
    effects_selected: list[str] | None = None
    #: Strengths per effect (1 = the rig's nominal size, docs/virtual-rig.md).
    strengths: dict[str, Any] = field(default_factory=lambda: {
        "rate_dependence": [0.5, 1.0, 1.5, 2.0],
        "tendon_elongation": [1.0, 2.0, 4.0, 8.0, 12.0],
        "time_delay": [0.5, 1.0, 2.0],
        "drift": [0.5, 1.0, 2.0],
        "asymmetry": [0.5, 1.0, 2.0],
        "saturation": [0.5, 1.0, 2.0],
        "dead_zone": [0.5, 1.0, 2.0],
    })
    #: Configuration pairs [curve_angle_deg, radius_mm]. ``a`` is the pair the workflow was
    #: built on; ``b`` and ``c`` were first looked at in this study; ``d`` (tight radius) and
    #: ``e`` (one wrap, two radii) are the high-tension pairs. More: ``'+pairs.f=[[60,30],
    #: [60,75]]'``.
    pairs: dict[str, Any] = field(default_factory=lambda: {
        "a": [[90, 30], [45, 60]],
        "b": [[60, 45], [30, 75]],
        "c": [[75, 30], [15, 60]],
        "d": [[90, 30], [75, 30]],
        "e": [[90, 45], [90, 60]],
    })
    #: The pairs studied (null or empty = every pair in ``pairs``).
    pairs_selected: list[str] | None = field(
        default_factory=lambda: ["a", "b", "c", "d", "e"])
    #: Two effects at once: every pair of the effects under ``combinations.strengths`` (one
    #: strength each) on the configuration pairs of ``combinations.pairs_selected``.
    combinations: StudyCombinations = field(default_factory=StudyCombinations)
    #: What the study must show, checked after its tables are written (a shortfall fails the
    #: stage, naming each case): every clean case answers no effect, every two-effect
    #: combination names both effects and its terms remove at least
    #: ``expect_combination_reduction`` of the pooled held-out RMSE, and each single-effect
    #: case listed here shows its outcome (a case the selection left out is not checked).
    #: ``expect=[]`` keeps only the clean and combination checks.
    expect: list[StudyExpectation] = field(default_factory=_study_expectations)
    expect_combination_reduction: float = 0.4
    #: Seed of the virtual rig's runs.
    seed: int = 3
    #: The runs are analysed at this rate (Hz; moving-average decimation).
    rate_hz: float = 20.0
    base_family: str = "gamma"
    #: Workflow settings (:class:`WorkflowSettings` fields, added with ``+``:
    #: ``+workflow.physical_evidence=false`` judges on the output fit alone, no load-cell
    #: evidence); empty = its defaults. An unknown knob stops the study before any case runs.
    workflow: dict[str, Any] = field(default_factory=dict)
    #: Parallel worker processes (joblib).
    n_jobs: int = 2
    progress: bool = True


@dataclass
class StageOverrides:
    """Extra Hydra overrides per stage of ``run_all`` (lists of "key=value"), e.g.
    ``"overrides.fit=['+family_overrides.bouc_wen.n_starts=2']"`` (each element quoted)."""

    #: Overrides of generate (conf/generate.yaml), applied after the pipeline's paths.
    generate: list[str] = field(default_factory=list)
    #: Overrides of ingest (conf/ingest.yaml), applied after the pipeline's paths; with your own
    #: data its source and importer win.
    ingest: list[str] = field(default_factory=list)
    #: Overrides of fit (conf/fit.yaml); the settings the pipeline shares with fit (config, signals,
    #: n_jobs, ...) replace theirs.
    fit: list[str] = field(default_factory=list)
    #: Overrides of validate (conf/validate.yaml); the settings the pipeline shares with validate
    #: (heldout, cross, ...) replace theirs.
    validate: list[str] = field(default_factory=list)
    #: Overrides of unseen_shape (conf/unseen_shape.yaml); the settings the pipeline shares with it
    #: (config, held-out kinds, ...) replace theirs.
    unseen_shape: list[str] = field(default_factory=list)
    #: Overrides of report (conf/report.yaml); the pipeline's paths, tracking, n_jobs, cache and
    #: identification excitation replace theirs.
    report: list[str] = field(default_factory=list)


@dataclass
class PipelineConfig(ValidateConfig):
    """``conf/pipeline.yaml`` (``make pipeline`` = ``python -m pipelines.run_all``): generate ->
    ingest -> fit -> validate -> unseen_shape -> report under one MLflow parent run.

    The settings it shares with the stages are validate's (:class:`ValidateConfig`, the same
    defaults): ``run_all.stage_config`` forwards config, fit_excitations, fit_runs,
    single_run_heldout_fraction, signals, n_jobs and cache to fit and validate, heldout and
    cross to validate, config, signals, n_jobs, cache and the held-out kinds to unseen_shape,
    n_jobs and cache to report, progress to fit and validate (generate and ingest keep their
    own, set through ``overrides``)."""

    #: The stages run, in this order (any subset of the default). With your own data
    #: (``importer`` or ``source`` set) ``generate`` is left out.
    stages: list[str] = field(default_factory=lambda: [
        "generate", "ingest", "fit", "validate", "unseen_shape", "report"])
    #: Group conf/importer/: your own logs through a mapping (``importer=tendon_catheter``);
    #: null = the virtual campaign (or tsm-rig-log/1 runs given as ``source``). The data
    #: folders are then named after it: data/processed/<name>, data/reports/<name>, ...
    importer: Any = None
    #: Your own raw runs or logs (a folder), read in place and never written; null = the
    #: virtual campaign under ``paths.raw``.
    source: str | None = None
    overrides: StageOverrides = field(default_factory=StageOverrides)


#: Config name -> its schema, stored as ``<name>_schema`` (first in ``conf/<name>.yaml``).
STAGE_SCHEMAS: dict[str, type[Any]] = {
    "generate": GenerateConfig,
    "ingest": IngestConfig,
    "fit": FitConfig,
    "validate": ValidateConfig,
    "unseen_shape": UnseenShapeConfig,
    "report": ReportConfig,
    "discrepancy": DiscrepancyConfig,
    "discrepancy_study": DiscrepancyStudyConfig,
    "compensate": CompensateConfig,
    "pipeline": PipelineConfig,
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


def settings(schema: type[T], cfg: Any) -> T:
    """A stage's typed settings: ``cfg`` (a composed DictConfig, a hand-written mapping or
    already a ``schema`` instance) merged over ``schema``'s defaults, checked against its
    types and converted once with ``OmegaConf.to_object``.

    Keys ``schema`` does not know are dropped here (one plain config may serve several
    stages; the composed config was already checked by Hydra and the command-line guard).
    Group fields typed ``Any`` (``paths``, ``tracking``) stay plain dicts, None when not
    given. A mistyped value
    raises :class:`omegaconf.errors.ValidationError` (a ``ValueError``) naming the key.
    """
    if isinstance(cfg, schema):
        return cfg
    if isinstance(cfg, DictConfig):
        plain = OmegaConf.to_container(cfg, resolve=True)
        assert isinstance(plain, dict)
        cfg = plain
    node = schema_node(schema)
    names = {f.name for f in dataclasses.fields(schema)}  # type: ignore[arg-type]
    known = {k: v for k, v in dict(cfg).items() if k in names}
    _clear_given_mappings(node, known)
    node.merge_with(known)
    for key in names:
        child = node._get_node(key)
        if OmegaConf.is_missing(node, key) and child is not None \
                and child._metadata.ref_type is Any:
            node[key] = None  # a group not given (``tracking`` in a test): None, not a crash
    OmegaConf.resolve(node)
    obj = OmegaConf.to_object(node)
    assert isinstance(obj, schema)
    return obj


def _clear_given_mappings(node: DictConfig, cfg: Mapping[str, Any]) -> None:
    """Empty each free mapping (a ``dict[str, Any]`` field) of ``node`` that ``cfg`` gives,
    so the merge puts the given mapping in its place instead of adding its keys to the
    default's; typed nodes are searched for them."""
    for key, value in cfg.items():
        if not isinstance(key, str) or key not in node or not isinstance(value, Mapping):
            continue
        child = node._get_node(key)
        if not isinstance(child, DictConfig) or child._is_none() or child._is_missing():
            continue
        if child._metadata.object_type in (None, dict):
            node[key] = {}
        else:
            _clear_given_mappings(child, value)


def _subfolder(name: Any) -> str:
    """``/<name>`` for a non-empty name, else nothing: ``data/reports${tsm_subfolder:x}``."""
    return f"/{name}" if name not in (None, "") else ""


def register() -> None:
    """Store every schema node in Hydra's ConfigStore and the config resolvers (idempotent)."""
    if not OmegaConf.has_resolver("tsm_subfolder"):
        OmegaConf.register_new_resolver("tsm_subfolder", _subfolder)
    store = ConfigStore.instance()
    store.store(group=WORKFLOW_GROUP, name="workflow", node=WorkflowSettings)
    for stage, schema in STAGE_SCHEMAS.items():
        store.store(name=f"{stage}_schema", node=schema_node(schema))
