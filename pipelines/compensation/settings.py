"""Typed settings of the compensation experiments (``conf/compensate.yaml``).

:class:`CompensateConfig` is the stage's schema; ``seed001``, ``seed002`` and ``seed000`` are one
typed node per experiment, and each experiment is handed only its own node. Each field's
default and meaning is written here once (``python -m pipelines.compensate --help`` prints
them); :mod:`pipelines.schemas` re-exports these classes and registers the schema with Hydra.
A ``dict[str, Any]`` field is a free mapping whose keys are the user's (shape labels, family
names, solver names): it is read as the mapping it is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING

from pipelines.shape_aware_settings import ShapeAwareEstimator


@dataclass
class CompensationOurs:
    """"Ours" (``<seed>.ours``): the exact Gamma inverse plus an online estimate of the model's
    error, a scalar random walk tracked by a Kalman filter on the measured output."""

    #: The family identified (its inverse drives the rig) and its parameters.
    family: str = "gamma"
    #: Parameters of ``family`` (its keyword arguments, e.g. n_operators); empty = the family's
    #: defaults.
    params: dict[str, Any] = field(default_factory=dict)
    #: The error estimate's random-walk variance per tick (or camera frame).
    process_var: float = 1.0e-2
    #: Variance of each measurement of the output in that Kalman filter (output unit squared).
    meas_var: float = 1.0


@dataclass
class Seed001Ours(CompensationOurs):
    """Seed 001's ``ours``: identified on each shape's sine_decay run, or taken from the model
    registry."""

    #: Parameters of ``family``: free weights with an output offset, 21 plays up to 4 mm.
    params: dict[str, Any] = field(default_factory=lambda: {
        "constraint": "free", "fit_offset": True, "n_operators": 21, "max_threshold": 4.0})
    #: A registered-model prefix (e.g. tsm, after `make pipeline`) = use each shape's
    #: registered champion (models:/<prefix>.tsm-bench_phi090_r030@champion, from the
    #: `tracking` store) instead of identifying `family` on the shape's sine_decay run.
    registry: str | None = None
    #: The registered model's alias loaded (pipelines.registry.ALIAS).
    registry_alias: str = "champion"
    #: Per-tick error estimate on the output encoder. 1e-3 tracks a little better (RMSE 0.049
    #: vs 0.060 mm, shape A mixed) but follows the follower's vibration: ~1.5x the command
    #: travel.
    process_var: float = 3.0e-4
    #: Measurement variance of the output encoder (mm^2).
    meas_var: float = 1.0e-2


@dataclass
class Seed001Quick:
    """What a configuration of the ``quick`` pass runs."""

    #: Desired profiles (names from seed001's ``profiles``) run on a quick-pass configuration.
    profiles: list[str] = field(default_factory=lambda: ["mixed"])
    #: Families a quick-pass configuration identifies and inverts.
    families: list[str] = field(default_factory=lambda: ["gamma"])


@dataclass
class Seed001Identification:
    """Each configuration's identification run (the virtual rig's excitation ``kind`` and its
    parameters)."""

    #: The virtual rig's excitation kind (rig_io.virtual.excitations) taking the parameters below:
    #: sine_decay.
    kind: str = "sine_decay"
    #: Command amplitudes (mm of pull), in this order.
    amplitudes_mm: list[float] = field(default_factory=lambda: [6.0, 4.5, 3.0, 1.5])
    #: Periods run at each amplitude.
    periods_per_amplitude: int = 5
    #: Frequency of every period (Hz).
    frequency_hz: float = 0.25


@dataclass
class Seed001ShapeAware:
    """Shapes A and B compensated by a model that never saw them: the family's parameters
    regressed on wrap angle and curvature over the other configurations' fits
    (hysteresis.shape_aware; docs/unseen-shape.md). Schemes ``shape_aware_ff`` (its inverse,
    open loop) and ``shape_aware`` (+ the online model-error estimate of ``ours``)."""

    #: Train the shape-aware model and run its two schemes on the shapes.
    enabled: bool = True
    #: The family whose parameters are regressed on the shape.
    family: str = "gamma"
    #: Parameters of ``family`` for each training configuration's fit.
    params: dict[str, Any] = field(default_factory=lambda: {
        "constraint": "free", "fit_offset": True, "n_operators": 21, "max_threshold": 4.0})
    estimator: ShapeAwareEstimator = field(default_factory=ShapeAwareEstimator)
    #: Training grid (minus the shapes): null = seed001's curve_angles_deg x radii_mm.
    curve_angles_deg: list[int | float] | None = None
    #: Training radii (mm); null = seed001's radii_mm.
    radii_mm: list[int | float] | None = None


@dataclass
class Seed001Timing:
    """Table 4.4: per-step inversion time of the solvers on each full shape's paper family."""

    #: Time the solvers on the paper_family model of each full-pass configuration.
    enabled: bool = True
    #: Solvers timed (hysteresis.compensation.gamma_inverse methods); ``exact`` is ours, the
    #: reference of the time ratios.
    methods: list[str] = field(default_factory=lambda: [
        "exact", "bounded", "nelder-mead", "slsqp", "interior-point"])
    #: Steps timed per method (a prefix of each profile); a method without an entry: 200.
    steps: dict[str, Any] = field(default_factory=lambda: {
        "exact": 3000, "bounded": 400, "nelder-mead": 150, "slsqp": 200, "interior-point": 40})


@dataclass
class Seed001Settings:
    """``seed001``: thesis section 4.7 on the tsm-bench (Table 4.2, Table 4.4)."""

    #: Run seed 001.
    enabled: bool = True
    #: The virtual rig (the tsm-bench: command and output in mm).
    rig: str = "tsm-bench"
    #: Seed 001 section 4.7's shapes: label -> [curve angle deg, radius mm].
    shapes: dict[str, Any] = field(default_factory=lambda: {"A": [90, 30], "B": [60, 60]})
    #: Other configurations: none | quick (profiles/families of ``quick``) | full (as the
    #: shapes).
    all_configurations: str = "quick"
    #: Curve angles of the configuration grid (deg): the other configurations and the shape-aware
    #: training grid.
    curve_angles_deg: list[int | float] = field(
        default_factory=lambda: [15, 30, 45, 60, 75, 90])
    #: Radii of that grid (mm).
    radii_mm: list[int | float] = field(default_factory=lambda: [30, 45, 60, 75])
    quick: Seed001Quick = field(default_factory=Seed001Quick)
    #: Desired output profiles and their durations (s): eq. 4.11, the decaying sinusoid, a
    #: 6 mm/s triangle (the thesis' records are 30, 80 and 20 s long).
    profiles: dict[str, Any] = field(default_factory=lambda: {
        "mixed": 30.0, "sine": 80.0, "triangle": 20.0})
    identification: Seed001Identification = field(default_factory=Seed001Identification)
    #: Model input: ``command`` (the set-point the compensator controls) or ``input`` (the
    #: encoder).
    model_input: str = "command"
    #: Families identified on each full-pass configuration; their inverses are played open loop
    #: beside ours (Table 4.2).
    families: list[str] = field(default_factory=lambda: [
        "linear", "gamma", "preisach", "bouc_wen", "coleman_hodgdon"])
    #: Per-family parameters (family -> parameters).
    family_params: dict[str, Any] = field(default_factory=dict)
    #: The thesis' "with compensation" column.
    paper_family: str = "gamma"
    #: Command limits [low, high] (mm of pull): every command is clipped into them.
    stroke: list[float] = field(default_factory=lambda: [-15.0, 15.0])
    #: The virtual rig's effects (effect -> strength); empty = the rig's own.
    effects: dict[str, Any] = field(default_factory=dict)
    ours: Seed001Ours = field(default_factory=Seed001Ours)
    shape_aware: Seed001ShapeAware = field(default_factory=Seed001ShapeAware)
    timing: Seed001Timing = field(default_factory=Seed001Timing)


@dataclass
class CompensationCamera:
    """The camera (``CameraModel``): frames every 1/rate_hz s, ``latency_s`` late, with Gaussian
    noise ``noise_std``; rate_hz null (seed 000 only) = every tick, no latency, no noise."""

    #: Frame rate (Hz); null = every tick, no latency, no noise (seed 000 only).
    rate_hz: float | None = 30.0
    #: Delay of each frame (s).
    latency_s: float = 0.045
    #: Standard deviation of the Gaussian noise on each frame, in the output's unit (deg of tip
    #: angle).
    noise_std: float = 1.0


@dataclass
class Seed002Calibration:
    """The Bouc-Wen calibration motion: amplitude sin(2 pi f t) + offset (deg)."""

    #: Amplitude of the calibration command (deg of motor angle).
    amplitude: float = 30.0
    #: Its offset (deg of motor angle).
    offset: float = 30.0
    #: Its frequency (Hz).
    frequency_hz: float = 0.1592
    #: Its length (s).
    duration_s: float = 31.4


@dataclass
class Seed002Feedback:
    """The vision-feedback scheme's gains."""

    #: Integrator gain per camera frame (the correction adds gain x each frame's error), in [0, 2).
    gain: float = 0.3
    #: Proportional gain on the latest frame's error (0 = integrator only).
    kp: float = 0.0


@dataclass
class Seed002Case:
    """One of ViO-Com's hysteresis cases: a sheath shape."""

    name: str = MISSING
    curve_angle_deg: float = MISSING
    radius_mm: float = MISSING


@dataclass
class Seed002Settings:
    """``seed002``: ViO-Com Table I on the bending joint (vision feedback vs Bouc-Wen
    feed-forward vs ours)."""

    #: Run seed 002.
    enabled: bool = True
    #: The virtual rig (a bending joint: the output is its tip angle).
    rig: str = "bending-joint"
    #: The rig's sensor set-up (rig_io.virtual.sensors.SensorConfig fields); input_unit deg = the
    #: command is the motor angle.
    sensors: dict[str, Any] = field(default_factory=lambda: {"input_unit": "deg"})
    #: The rig reading scored as the true tip angle (deg) and seen by the camera.
    tracker_key: str = "tip_angle_deg"
    #: Four hysteresis cases = four sheath shapes (largest hysteresis first). A list, so that
    #: an experiment giving fewer cases replaces these rather than adding to them.
    cases: list[Seed002Case] = field(default_factory=lambda: [
        Seed002Case(f"case{i}", phi, r)
        for i, (phi, r) in enumerate(((90, 30), (75, 45), (45, 60), (15, 75)), start=1)])
    calibration: Seed002Calibration = field(default_factory=Seed002Calibration)
    #: Desired tip-angle motions: amplitude sin(omega t) + offset (deg).
    amplitude: float = 30.0
    #: Their offset (deg).
    offset: float = 30.0
    #: Periodic motions' frequencies (rad/s).
    omegas: list[float] = field(default_factory=lambda: [0.25, 0.5, 1.0])
    #: Also the non-periodic motion (N-P).
    non_periodic: bool = True
    #: Length of each motion after the lead-in (s).
    duration_s: float = 30.0
    #: From rest to the motion's start, not scored.
    lead_in_s: float = 3.0
    #: Trials per case, each with its own rig and camera noise and its own calibration.
    trials: int = 2
    #: Command limits [low, high] (deg of motor angle): every command is clipped into them.
    stroke: list[float] = field(default_factory=lambda: [-30.0, 120.0])
    camera: CompensationCamera = field(default_factory=CompensationCamera)
    feedback: Seed002Feedback = field(default_factory=Seed002Feedback)
    #: Parameters of the Bouc-Wen model calibrated on the camera's view; empty = its defaults.
    bouc_wen_params: dict[str, Any] = field(default_factory=dict)
    #: Bouc-Wen's inverse method (eq. 4).
    bouc_wen_inverse: str = "feedforward"
    #: The virtual rig's effects (effect -> strength); empty = the rig's own.
    effects: dict[str, Any] = field(default_factory=dict)
    #: Error estimate per camera frame: a slow random walk (K ~ 0.1) - faster gains pass more
    #: camera noise and latency than they remove (tuned on case 1, seed 17).
    ours: CompensationOurs = field(default_factory=lambda: CompensationOurs(params={
        "constraint": "free", "fit_offset": True, "n_operators": 21, "max_threshold": 20.0}))


@dataclass
class Seed000GA:
    """The genetic algorithm identifying the Coleman-Hodgdon reference (eq. 26)."""

    #: Differential-evolution generations, at most.
    maxiter: int = 60
    #: Population size per parameter (scipy's differential_evolution).
    popsize: int = 15
    #: The GA fits a stride-decimated record of at most this many samples.
    max_samples: int = 1500


@dataclass
class Seed000UKF:
    """The UKF's initial covariance, process and measurement noise (eq. 29)."""

    #: Initial covariance of the state [tip angle, model error f_h], as its diagonal.
    P0: list[float] = field(default_factory=lambda: [10.0, 10.0])
    #: Process noise of [tip angle, model error f_h], as its diagonal.
    Q: list[float] = field(default_factory=lambda: [5.0, 15.0])
    #: Measurement noise variance of the camera's tip angle (deg^2).
    R: float = 1.0e-4


@dataclass
class Seed000Tracking:
    """Eq. 32's tracking: PD / AME-PD gains (kp, kd, kc), control every n ticks, the pull at
    rest l0; eq. 32 starts at 30 deg: a lead-in from rest (not scored) brings the joint
    there."""

    #: Length of eq. 32's target after the lead-in (s).
    duration_s: float = 100.0
    #: Proportional gain of the PD law (eq. 21): pull velocity (mm/s) per deg of tracking error.
    kp: float = 0.02
    #: Derivative gain of the PD law (eq. 21).
    kd: float = 0.05
    #: AME-PD's gain on the error the UKF predicts one control period ahead (eq. 24-25); plain PD
    #: runs with 0.
    kc: float = 0.06
    #: The controller runs every this many 10 ms ticks.
    control_every: int = 3
    #: Pull at rest (mm): where every scheme's pull starts.
    l0: float = 0.0
    #: Smooth move from rest to the target's start (s), not scored.
    lead_in_s: float = 10.0


@dataclass
class Seed000Settings:
    """``seed000``: Tables 2-5 on the bending joint (Coleman-Hodgdon reference by GA, UKF active
    estimation per stroke segment, PD vs AME-PD tracking eq. 32)."""

    #: Run seed 000.
    enabled: bool = True
    #: The virtual rig (a bending joint: the output is its tip angle).
    rig: str = "bending-joint"
    #: The rig's sensor set-up (rig_io.virtual.sensors.SensorConfig fields); empty = the rig's own.
    sensors: dict[str, Any] = field(default_factory=dict)
    #: [curve angle deg, radius mm].
    configuration: list[int | float] = field(default_factory=lambda: [90, 45])
    #: The rig reading used as the tip angle (deg): what the camera sees and the schemes track.
    angle_key: str = "tip_angle_deg"
    #: Pull speed over each stroke segment (mm/s).
    velocity_mm_s: float = 0.125
    #: Stroke segments [lo, hi] (mm of pull).
    segments: list[list[float]] = field(default_factory=lambda: [
        [0.0, 3.0], [3.0, 6.0], [0.0, 6.0]])
    ga: Seed000GA = field(default_factory=Seed000GA)
    ukf: Seed000UKF = field(default_factory=Seed000UKF)
    #: Pull limits [low, high] (mm): every command is clipped into them.
    stroke: list[float] = field(default_factory=lambda: [0.0, 20.0])
    camera: CompensationCamera = field(
        default_factory=lambda: CompensationCamera(latency_s=0.0, noise_std=0.2))
    tracking: Seed000Tracking = field(default_factory=Seed000Tracking)
    #: The virtual rig's effects (effect -> strength); empty = the rig's own.
    effects: dict[str, Any] = field(default_factory=dict)
    #: A slow error estimate: faster ones dither the pull across the backlash on camera noise
    #: (command travel 1177 mm at 1e-2 vs 53 mm here) and track worse.
    ours: CompensationOurs = field(default_factory=lambda: CompensationOurs(
        params={"constraint": "free", "fit_offset": True, "n_operators": 21,
                "max_threshold": 3.0},
        process_var=1.0e-4, meas_var=4.0e-2))


@dataclass
class CompensateConfig:
    """``conf/compensate.yaml``: the papers' compensation experiments on the virtual rig
    (docs/compensation.md). Its defaults are the default experiment
    (``conf/experiment/compensation_default.yaml``); ``compensation_quick`` and
    ``compensation_full`` override them."""

    #: Group conf/paths/: the project's data folders (``out_dir`` and ``report`` are under its
    #: reports folder).
    paths: Any = MISSING
    #: Group conf/tracking/ (MLflow; also the store of ``seed001.ours.registry``).
    tracking: Any = MISSING
    #: Tables and plots (``${paths.reports}/compensation``).
    out_dir: str = MISSING
    #: The report section (``${paths.reports}/compensation.md``).
    report: str = MISSING
    #: Seed of the rigs' and cameras' noise (each seed002 trial derives its own) and of seed000's
    #: GA.
    seed: int = 0
    #: Write the experiments' figures (``<out_dir>/plots/``).
    plots: bool = True
    #: Progress bars (tqdm, on stderr) over configurations, cases and segments.
    progress: bool = True
    seed001: Seed001Settings = field(default_factory=Seed001Settings)
    seed002: Seed002Settings = field(default_factory=Seed002Settings)
    seed000: Seed000Settings = field(default_factory=Seed000Settings)
