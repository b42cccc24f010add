"""Seed 001, thesis section 4.7 on the tsm-bench: Table 4.2 and Table 4.4.

Each configuration's families are identified on its identification run and their inverses
fed open loop to the bench beside "ours" (the exact Gamma inverse plus an online model-error
estimate) and, for the compensated shapes, a shape-aware model that never saw them; Table
4.4 times the thesis' inversion solvers on the paper's family.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.base import HysteresisError, check_inverse_reach
from hysteresis.compensation import (
    LoopResult,
    StrokeLimits,
    gamma_inverse,
    mixed_sine_profile,
    run_inverse_with_error_correction,
    run_open_loop,
    sine_profile,
    triangle_profile,
)
from hysteresis.shape_aware import ShapeAwareModel
from pipelines.compensation.figures import plot_runs
from pipelines.compensation.models import fit_family, fit_reachable
from pipelines.compensation.result import Outcome
from pipelines.compensation.rig import DT_S, RigBackend, drive, fresh, make_rig, progress
from pipelines.compensation.settings import Seed001Settings, Seed001Timing
from pipelines.compensation.tables import stats_row

log = logging.getLogger(__name__)
PROFILES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "mixed": mixed_sine_profile,
    "sine": sine_profile,
    "triangle": lambda t: triangle_profile(t, periods_per_amplitude=2),
}
#: Steps timed for a Table 4.4 method that ``timing.steps`` does not name.
DEFAULT_TIMED_STEPS = 200
#: A configuration's "champion" model for ``ours`` (curve angle, radius) -> fitted model, when
#: it is taken from the model registry instead of identified here.
Champion = Callable[[float, float], Any]


@dataclass(frozen=True)
class Configuration:
    """One sheath configuration of the experiment; ``full`` runs every profile and family
    (the shapes, and every configuration in the full pass), the quick pass those of
    ``quick``."""

    label: str
    phi: float
    r: float
    full: bool

    def keys(self) -> dict[str, Any]:
        return {"shape": self.label, "curve_angle_deg": self.phi, "radius_mm": self.r}


@dataclass(frozen=True)
class Bench:
    """What every configuration shares: the settings, the plant, the identification input
    and the models that do not depend on the configuration."""

    s: Seed001Settings
    backend: RigBackend
    seed: int
    plots: bool
    u_id_cmd: np.ndarray
    shape_aware: ShapeAwareModel | None = None
    champion: Champion | None = None

    @property
    def stroke(self) -> StrokeLimits:
        return StrokeLimits(*map(float, self.s.stroke))


@dataclass
class Identified:
    """A configuration's rig, its identification record and the models identified on it."""

    rig: Any
    u_id: np.ndarray
    y_id: np.ndarray
    models: dict[str, Any]
    ours: Any = None


@dataclass
class Rows:
    """What the configurations add up to: Table 4.2's rows, Table 4.4's, the fits', plots."""

    table42: list[dict[str, Any]] = field(default_factory=list)
    timing: list[dict[str, Any]] = field(default_factory=list)
    fits: list[dict[str, Any]] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)


def configurations(s: Seed001Settings) -> list[Configuration]:
    """The shapes in full, then (``all_configurations``) every other configuration of the
    grid in the quick or the full pass."""
    out: list[Configuration] = []
    seen: set[tuple[float, float]] = set()
    for label, (phi, r) in s.shapes.items():
        out.append(Configuration(str(label), float(phi), float(r), True))
        seen.add((float(phi), float(r)))
    mode = s.all_configurations
    if mode not in ("none", "quick", "full"):
        raise HysteresisError(f"seed001.all_configurations must be none|quick|full, got {mode!r}")
    if mode == "none":
        return out
    for phi in s.curve_angles_deg:
        for r in s.radii_mm:
            if (float(phi), float(r)) not in seen:
                out.append(Configuration(f"phi{int(phi):03d}_r{int(r):03d}", float(phi),
                                         float(r), mode == "full"))
    return out


def identification_input(s: Seed001Settings, backend: RigBackend) -> np.ndarray:
    """The command every configuration is identified on (``identification``)."""
    ident = s.identification
    _, command = backend.make_excitation(
        ident.kind, dt_s=DT_S, amplitudes_mm=ident.amplitudes_mm,
        periods_per_amplitude=ident.periods_per_amplitude, frequency_hz=ident.frequency_hz)
    return np.asarray(command)


def fit_shape_aware(s: Seed001Settings, backend: RigBackend, u_id_cmd: np.ndarray, *,
                    seed: int, progress_bar: bool) -> tuple[ShapeAwareModel, list[str]]:
    """The shape-aware model of ``shape_aware``, identified on every training configuration
    except the compensated shapes (A, B), which it never sees.

    Each training configuration is driven with the identification excitation and fitted
    through :func:`~pipelines.compensation.models.fit_reachable`; returns the model and the
    labels it was trained on.
    """
    sa = s.shape_aware
    held = {(float(phi), float(r)) for phi, r in s.shapes.values()}
    angles = s.curve_angles_deg if sa.curve_angles_deg is None else sa.curve_angles_deg
    radii = s.radii_mm if sa.radii_mm is None else sa.radii_mm
    train = [(float(phi), float(r)) for phi in angles for r in radii
             if (float(phi), float(r)) not in held]
    models = []
    for phi, r in progress(train, "seed001 shape-aware training", progress_bar):
        rig = make_rig(backend, s.rig, phi, r, effects=s.effects, seed=seed)
        rec = drive(rig, u_id_cmd)
        model, _ = fit_reachable(sa.family, rec.column(s.model_input), rec.column("output"),
                                 sa.params, label=f"seed001 shape-aware {phi:g}/{r:g}")
        models.append(model)
    model = ShapeAwareModel(base_family=sa.family, family_params=dict(sa.params),
                            **dataclasses.asdict(sa.estimator)).fit(train, models)
    return model, [f"{phi:g}/{r:g}" for phi, r in train]


def _fit_families(bench: Bench, conf: Configuration, u_id: np.ndarray, y_id: np.ndarray,
                  rows: Rows) -> dict[str, Any]:
    """Every family of the configuration's pass, fitted on its record; a family that cannot
    fit it is reported and left out."""
    s = bench.s
    models: dict[str, Any] = {}
    for fam in s.families if conf.full else s.quick.families:
        t0 = time.perf_counter()
        try:
            models[fam] = fit_family(fam, u_id, y_id, s.family_params.get(fam) or {})
        except HysteresisError as exc:
            log.warning("seed001 %s: %s failed to fit: %s", conf.label, fam, exc)
            continue
        pred = models[fam].predict(u_id)
        rows.fits.append({**conf.keys(), "family": fam, "fit_s": time.perf_counter() - t0,
                          "fit_rmse": float(np.sqrt(np.mean((pred - y_id) ** 2)))})
    return models


def identify(bench: Bench, conf: Configuration, rows: Rows) -> Identified:
    """Drive the configuration's identification run, fit its families and ours (or take
    ours from the registry)."""
    s = bench.s
    rig = make_rig(bench.backend, s.rig, conf.phi, conf.r, effects=s.effects, seed=bench.seed)
    rec = drive(rig, bench.u_id_cmd)
    ident = Identified(rig, rec.column(s.model_input), rec.column("output"), {})
    ident.models = _fit_families(bench, conf, ident.u_id, ident.y_id, rows)
    if bench.champion is not None:
        ident.ours = bench.champion(conf.phi, conf.r)
    else:
        ident.ours, _ = fit_reachable(s.ours.family, ident.u_id, ident.y_id, s.ours.params,
                                      label=f"seed001 {conf.label} ours")
    return ident


def _family_runs(bench: Bench, conf: Configuration, ident: Identified,
                 yd: np.ndarray) -> dict[str, LoopResult]:
    """Each family's inverse played open loop; one without a usable inverse is skipped."""
    runs: dict[str, LoopResult] = {}
    for fam, model in ident.models.items():
        try:
            u_ff = model.invert(yd)
        except HysteresisError as exc:
            log.warning("seed001 %s: %s has no usable inverse: %s", conf.label, fam, exc)
            continue
        if not np.all(np.isfinite(u_ff)):
            log.warning("seed001 %s: %s inverse is not finite; skipped", conf.label, fam)
            continue
        runs[fam] = run_open_loop(fresh(ident.rig), u_ff, desired=yd, dt_s=DT_S,
                                  stroke=bench.stroke, scheme=fam)
    return runs


def _shape_aware_runs(bench: Bench, conf: Configuration, rig: Any,
                      yd: np.ndarray) -> dict[str, LoopResult]:
    """A model for this shape from the other configurations only (never fitted on it):
    open loop, and with the online model-error estimate of ours."""
    assert bench.shape_aware is not None
    ours = bench.s.ours
    unseen = bench.shape_aware.model_for(conf.phi, conf.r)
    id_range = (float(np.min(bench.u_id_cmd)), float(np.max(bench.u_id_cmd)))
    check_inverse_reach(unseen, identified_range=id_range, desired=yd)
    ff = run_open_loop(fresh(rig), unseen.invert(yd), desired=yd, dt_s=DT_S,
                       stroke=bench.stroke, scheme="shape_aware_ff")
    res = run_inverse_with_error_correction(
        fresh(rig), yd, unseen, dt_s=DT_S, stroke=bench.stroke,
        process_var=float(ours.process_var), meas_var=float(ours.meas_var),
        identified_range=id_range)
    return {"shape_aware_ff": ff, "shape_aware": dataclasses.replace(res, scheme="shape_aware")}


def profile_runs(bench: Bench, conf: Configuration, ident: Identified,
                 yd: np.ndarray) -> dict[str, LoopResult]:
    """Every scheme on one desired profile, in Table 4.2's order."""
    ours = bench.s.ours
    runs = {"none": run_open_loop(fresh(ident.rig), yd, desired=yd, dt_s=DT_S,
                                  stroke=bench.stroke, scheme="none")}
    runs.update(_family_runs(bench, conf, ident, yd))
    runs["ours"] = run_inverse_with_error_correction(
        fresh(ident.rig), yd, ident.ours, dt_s=DT_S, stroke=bench.stroke,
        process_var=float(ours.process_var), meas_var=float(ours.meas_var),
        identified_range=(float(np.min(ident.u_id)), float(np.max(ident.u_id))))
    if bench.shape_aware is not None and conf.full:
        runs.update(_shape_aware_runs(bench, conf, ident.rig, yd))
    return runs


def table44_rows(model: Any, yd: np.ndarray, timing: Seed001Timing, stroke: StrokeLimits,
                 keys: dict[str, Any]) -> list[dict[str, Any]]:
    """Per-step inversion time of Table 4.4's LSQ_Opt solvers and ours on the paper's Gamma."""
    v0 = 0.0
    rows = []
    for method in timing.methods:
        n = int(timing.steps.get(method, DEFAULT_TIMED_STEPS))
        u, times = gamma_inverse(model, yd, method=method, stroke=stroke, v0=v0, max_steps=n)
        # replayed from the state the inverse started from, not the rest state at u[0]
        resid = np.abs(model.predict(u, state=model.initial_state(v0)) - yd[: u.size])
        rows.append({**keys, "method": method, "steps": int(u.size),
                     "mean_ms": 1e3 * float(times.mean()),
                     "median_ms": 1e3 * float(np.median(times)),
                     "max_abs_residual": float(resid.max())})
    return rows


def _profiles(s: Seed001Settings, conf: Configuration) -> dict[str, Any]:
    """Desired profile -> duration (s) of the configuration's pass."""
    if conf.full:
        return dict(s.profiles)
    return {k: v for k, v in s.profiles.items() if k in s.quick.profiles}


def run_configuration(bench: Bench, conf: Configuration, rows: Rows) -> None:
    """Identify one configuration and compensate each of its profiles with every scheme."""
    s = bench.s
    ident = identify(bench, conf, rows)
    for prof, duration in _profiles(s, conf).items():
        yd = PROFILES[prof](np.arange(0.0, float(duration), DT_S))
        keys = {**conf.keys(), "profile": prof}
        runs = profile_runs(bench, conf, ident, yd)
        rows.table42.extend(stats_row(res, **keys) for res in runs.values())
        if conf.full and bench.plots:
            show = {k: v for k, v in runs.items() if k in ("none", s.paper_family, "ours")}
            rows.figures[f"seed001_{conf.label}_{prof}"] = plot_runs(
                f"seed 001 shape {conf.label} ({conf.phi:g} deg, {conf.r:g} mm) - {prof}", show)
        paper = ident.models.get(s.paper_family)
        if conf.full and s.timing.enabled and paper is not None:
            rows.timing.extend(table44_rows(paper, yd, s.timing, bench.stroke, keys))


def table44(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Table 4.4 with each solver's time as a ratio to ours (``exact``) on the same profile."""
    t44 = pd.DataFrame(rows)
    ref = t44[t44["method"] == "exact"].set_index(["shape", "profile"])["mean_ms"]
    t44["ratio_to_ours"] = [
        row.mean_ms / float(ref.get((row.shape, row.profile), math.nan))
        for row in t44.itertuples()
    ]
    return t44


def run_seed001(s: Seed001Settings, backend: RigBackend, *, seed: int, progress_bar: bool,
                plots: bool, champion: Champion | None = None) -> Outcome:
    """Tables ``seed001_table42``, ``seed001_fits`` (and ``seed001_table44``) and the
    shapes' plots; ``champion`` gives ours instead of identifying it (the registry)."""
    configs = configurations(s)
    u_id_cmd = identification_input(s, backend)
    bench = Bench(s, backend, seed, plots, u_id_cmd, champion=champion)
    if s.shape_aware.enabled:
        shape_aware, trained_on = fit_shape_aware(s, backend, u_id_cmd, seed=seed,
                                                  progress_bar=progress_bar)
        log.info("seed001: shape-aware %s trained on %d configurations (%s)",
                 s.shape_aware.family, len(trained_on), ", ".join(trained_on))
        bench = dataclasses.replace(bench, shape_aware=shape_aware)
    rows = Rows()
    for conf in progress(configs, "seed001 configurations", progress_bar):
        run_configuration(bench, conf, rows)
    out = Outcome({"seed001_table42": pd.DataFrame(rows.table42),
                   "seed001_fits": pd.DataFrame(rows.fits)}, rows.figures)
    if rows.timing:
        out.tables["seed001_table44"] = table44(rows.timing)
    return out
