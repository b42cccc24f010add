"""Seed 000, Tables 2-5 on the bending joint: the Coleman-Hodgdon reference identified by a
genetic algorithm, the UKF's active estimation of its error per stroke segment, and PD vs
AME-PD (and ours) tracking eq. 32."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.coleman_hodgdon import ColemanHodgdonModel
from hysteresis.compensation import (
    CameraModel,
    LoopResult,
    StrokeLimits,
    camera_frames,
    estimate_model_error,
    run_ame_pd,
    run_inverse_with_error_correction,
    seed000_target,
    segment_statistics,
    with_lead_in,
)
from pipelines.compensation.figures import plot_reference_model, plot_runs
from pipelines.compensation.models import fit_reachable
from pipelines.compensation.result import Outcome
from pipelines.compensation.rig import DT_S, RigBackend, drive, fresh, make_rig, progress
from pipelines.compensation.settings import Seed000Settings
from pipelines.compensation.tables import command_travel

Record = tuple[np.ndarray, np.ndarray]  # (pull mm, tip angle deg)


@dataclass
class Segments:
    """The stroke segments' records: ``measured`` from each segment's start, ``full`` from
    rest, by segment name (``[lo,hi]``); ``widest`` names the widest."""

    measured: dict[str, Record]
    full: dict[str, Record]

    @property
    def widest(self) -> str:
        return max(self.measured, key=lambda k: float(np.ptp(self.measured[k][0])))


def segment_pull(lo: float, hi: float, v: float, approach_s: float = 2.0) -> tuple[np.ndarray, int]:
    """Pull trajectory: approach ``lo`` from 0, dwell, then ``lo -> hi -> lo`` at ``v`` mm/s.
    Returns the trajectory and the index where the measured segment starts."""
    pre = np.linspace(0.0, lo, max(2, int(round(max(lo / max(v * 8, 1e-9), approach_s) / DT_S))))
    dwell = np.full(int(round(approach_s / DT_S)), lo)
    up = np.arange(lo, hi, v * DT_S)
    seg = np.concatenate([up, [hi], up[::-1]])
    return np.concatenate([pre, dwell, seg]), pre.size + dwell.size


def record_segments(s: Seed000Settings, rig: Any, *, progress_bar: bool) -> Segments:
    """Drive each stroke segment of ``segments`` at ``velocity_mm_s`` and record the tip."""
    out = Segments({}, {})
    for lo, hi in progress([tuple(seg) for seg in s.segments], "seed000 segments",
                           progress_bar):
        pull, start = segment_pull(float(lo), float(hi), float(s.velocity_mm_s))
        angle = drive(rig, pull).column(s.angle_key)
        name = f"[{lo:g},{hi:g}]"
        out.measured[name] = (pull[start:], angle[start:])
        out.full[name] = (pull, angle)
    return out


def reference_model(s: Seed000Settings, record: Record, *, seed: int) -> ColemanHodgdonModel:
    """The paper's form: GA (B < 0) and the explicit step of eq. 16 the UKF predicts with."""
    ga = s.ga
    return ColemanHodgdonModel(method="ga", scheme="euler", seed=seed,
                               fit_max_samples=int(ga.max_samples), maxiter=int(ga.maxiter),
                               popsize=int(ga.popsize)).fit(*record)


def ukf_settings(s: Seed000Settings) -> dict[str, Any]:
    """The UKF's keyword arguments (eq. 29)."""
    return {"P0": tuple(s.ukf.P0), "Q": tuple(s.ukf.Q), "R": float(s.ukf.R)}


def estimation_rows(s: Seed000Settings, ref: ColemanHodgdonModel, segments: Segments,
                    cam: CameraModel) -> list[dict[str, Any]]:
    """Tables 2-4: per segment, the reference's error and the UKF estimate's."""
    rows = []
    for name, (pull, alpha) in segments.measured.items():
        # The estimator sees the 30 Hz camera; both estimates are scored against the tracker.
        frames = camera_frames(alpha, cam, dt_s=DT_S)
        model, est, _ = estimate_model_error(ref, pull, frames, dt_s=DT_S,
                                             alpha0=float(alpha[0]), **ukf_settings(s))
        m, e = segment_statistics(alpha, model), segment_statistics(alpha, est)
        rows.append({"segment": name, "abs_err_model": m["abs_err"], "var_model": m["var"],
                     "abs_err_estm": e["abs_err"], "var_estm": e["var"],
                     "abs_err_ratio": e["abs_err"] / m["abs_err"],
                     "var_ratio": e["var"] / m["var"]})
    return rows


def tracking_runs(s: Seed000Settings, rig: Any, ref: ColemanHodgdonModel, id_record: Record,
                  cam: CameraModel) -> tuple[dict[str, LoopResult], str]:
    """PD vs AME-PD vs ours on alpha_d(t) = -50 cos(pi t / 50) + 80 (eq. 32), after a lead-in
    from rest. Ours is the Gamma operator identified on ``id_record`` (the widest segment's
    whole record, from rest); returns the runs and the note of its fit."""
    tr = s.tracking
    t = np.arange(0.0, float(tr.duration_s), DT_S)
    rest = float(rig.reset().get(s.angle_key, 0.0))
    yd = with_lead_in(seed000_target(t), start=rest, lead_s=float(tr.lead_in_s), dt_s=DT_S)
    stroke = StrokeLimits(*map(float, s.stroke))
    common = dict(dt_s=DT_S, kp=float(tr.kp), kd=float(tr.kd), stroke=stroke, camera=cam,
                  control_every=int(tr.control_every), output_key=s.angle_key,
                  l0=float(tr.l0))
    runs = {
        "pd": run_ame_pd(fresh(rig), yd, None, kc=0.0, **common),  # type: ignore[arg-type]
        "ame_pd": run_ame_pd(fresh(rig), yd, ref, kc=float(tr.kc), ukf_kw=ukf_settings(s),
                             **common),  # type: ignore[arg-type]
    }
    pull_id, angle_id = id_record
    ours_model, note = fit_reachable(s.ours.family, pull_id, angle_id, s.ours.params,
                                     label="seed000 ours")
    runs["ours"] = run_inverse_with_error_correction(
        fresh(rig), yd, ours_model, camera=cam, stroke=stroke, output_key=s.angle_key,
        process_var=float(s.ours.process_var), meas_var=float(s.ours.meas_var),
        v0=float(tr.l0), identified_range=(float(np.min(pull_id)), float(np.max(pull_id))))
    return runs, note


def tracking_rows(runs: dict[str, LoopResult], *, lead_s: float,
                  note: str) -> list[dict[str, Any]]:
    """Table 5: each scheme's error after the lead-in; ``note`` says how ours was fitted."""
    rows = []
    for res in runs.values():
        st = res.statistics(skip_s=lead_s)
        rows.append({"scheme": res.scheme, "abs_err": st["mean_abs_error"],
                     "var": st["var_error"], "rmse": st["rmse"],
                     "command_travel": command_travel(res),
                     "note": note if res.scheme == "ours" else ""})
    return rows


def run_seed000(s: Seed000Settings, backend: RigBackend, *, seed: int, progress_bar: bool,
                plots: bool) -> Outcome:
    """Tables ``seed000_reference``, ``seed000_estimation``, ``seed000_tracking`` and their
    plots."""
    phi, r = map(float, s.configuration)
    rig = make_rig(backend, s.rig, phi, r, effects=s.effects, seed=seed, sensors=s.sensors)
    cam = CameraModel(rate_hz=s.camera.rate_hz, latency_s=float(s.camera.latency_s),
                      noise_std=float(s.camera.noise_std), seed=seed)
    segments = record_segments(s, rig, progress_bar=progress_bar)
    # GA identification of the reference model (eq. 26) on the widest segment.
    widest = segments.widest
    ref = reference_model(s, segments.measured[widest], seed=seed)
    est_rows = estimation_rows(s, ref, segments, cam)
    runs, note = tracking_runs(s, rig, ref, segments.full[widest], cam)
    out = Outcome()
    if plots:
        out.figures["seed000_tracking"] = plot_runs("seed 000 eq. 32 tracking", runs)
        out.figures["seed000_reference_model"] = plot_reference_model(ref, segments.measured)
    ref_row = pd.DataFrame([{"A": ref.A_, "B": ref.B_, "C": ref.C_, "O_l": ref.origin_u_,
                             "O_alpha": ref.origin_y_, "identified_on": widest}])
    lead = float(s.tracking.lead_in_s)
    out.tables.update({"seed000_reference": ref_row,
                       "seed000_estimation": pd.DataFrame(est_rows),
                       "seed000_tracking": pd.DataFrame(tracking_rows(runs, lead_s=lead,
                                                                      note=note))})
    return out
