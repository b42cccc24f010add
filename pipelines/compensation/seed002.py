"""Seed 002, ViO-Com Table I on the bending joint: no compensation, vision feedback, Bouc-Wen
feed-forward (calibrated on the 30 Hz camera estimate) and ours, scored against the tracker."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hysteresis.compensation import (
    CameraModel,
    LoopResult,
    StrokeLimits,
    camera_frames,
    run_inverse_with_error_correction,
    run_open_loop,
    run_vision_feedback,
    seed002_motion,
    with_lead_in,
)
from pipelines.compensation.figures import plot_runs
from pipelines.compensation.models import fit_family, fit_reachable
from pipelines.compensation.result import Outcome
from pipelines.compensation.rig import DT_S, RigBackend, drive, fresh, make_rig, progress
from pipelines.compensation.settings import Seed002Case, Seed002Settings
from pipelines.compensation.tables import stats_row

#: The motions plotted (trial 0 of each case).
PLOTTED = ("P(0.5)", "N-P")


@dataclass
class Trial:
    """One case's trial: its camera, rig, the two calibrated models and the rest angle."""

    case: Seed002Case
    number: int
    camera: CameraModel
    rig: Any
    bouc_wen: Any
    ours: Any
    rest: float

    def keys(self, signal: str) -> dict[str, Any]:
        return {"case": self.case.name, "curve_angle_deg": float(self.case.curve_angle_deg),
                "radius_mm": float(self.case.radius_mm), "signal": signal, "trial": self.number}


def camera_estimate(rec_t: np.ndarray, truth: np.ndarray, cam: CameraModel) -> np.ndarray:
    """The calibration's camera angle on the 100 Hz grid: the 30 Hz noisy frames at their
    (nominal-latency-corrected) stamps, linearly interpolated (the paper Kalman-smooths them)."""
    frames = camera_frames(truth, cam, dt_s=DT_S)
    ok = np.isfinite(frames)
    return np.asarray(np.interp(rec_t, rec_t[ok], frames[ok]), dtype=np.float64)


def calibration_motion(s: Seed002Settings) -> tuple[np.ndarray, np.ndarray]:
    """``(t, command)`` of the Bouc-Wen calibration: amplitude sin(2 pi f t) + offset."""
    cal = s.calibration
    t_cal = np.arange(0.0, float(cal.duration_s), DT_S)
    u_cal = seed002_motion(t_cal, omega_rad_s=2 * math.pi * float(cal.frequency_hz),
                           amplitude=float(cal.amplitude), offset=float(cal.offset))
    return t_cal, u_cal


def signals(s: Seed002Settings) -> dict[str, float | None]:
    """Motion label -> omega (rad/s); ``N-P`` (None) is the non-periodic motion."""
    out: dict[str, float | None] = {f"P({w:g})": float(w) for w in s.omegas}
    if s.non_periodic:
        out["N-P"] = None
    return out


def calibrate(s: Seed002Settings, backend: RigBackend, case: Seed002Case, number: int, *,
              seed: int) -> Trial:
    """A fresh rig and camera for one trial, both models calibrated on the camera's view of
    the calibration motion."""
    rseed = seed + 1000 * number + 17
    cam = s.camera
    camera = CameraModel(rate_hz=float(cam.rate_hz),  # type: ignore[arg-type]
                         latency_s=float(cam.latency_s), noise_std=float(cam.noise_std),
                         seed=rseed)
    rig = make_rig(backend, s.rig, float(case.curve_angle_deg), float(case.radius_mm),
                   effects=s.effects, seed=rseed, sensors=s.sensors)
    t_cal, u_cal = calibration_motion(s)
    rec = drive(rig, u_cal)
    y_cam = camera_estimate(t_cal, rec.column(s.tracker_key), camera)
    bw = fit_family("bouc_wen", u_cal, y_cam, dict(s.bouc_wen_params))
    ours, _ = fit_reachable(s.ours.family, u_cal, y_cam, s.ours.params,
                            label=f"seed002 {case.name} ours")
    rest = float(rig.reset().get(s.tracker_key, 0.0))
    return Trial(case, number, camera, rig, bw, ours, rest)


def motion_runs(s: Seed002Settings, trial: Trial, yd: np.ndarray) -> dict[str, LoopResult]:
    """The four schemes on one desired motion, in Table I's order."""
    stroke = StrokeLimits(*map(float, s.stroke))
    key = s.tracker_key
    runs: dict[str, LoopResult] = {
        "none": run_open_loop(fresh(trial.rig), yd, desired=yd, stroke=stroke, scheme="none",
                              output_key=key),
        "vision_feedback": run_vision_feedback(
            fresh(trial.rig), yd, camera=trial.camera, gain=float(s.feedback.gain),
            kp=float(s.feedback.kp), stroke=stroke, output_key=key),
    }
    u_bw = trial.bouc_wen.invert(yd, method=s.bouc_wen_inverse)
    runs["bouc_wen_ff"] = run_open_loop(fresh(trial.rig), u_bw, desired=yd, stroke=stroke,
                                        scheme="bouc_wen_ff", output_key=key)
    runs["ours"] = run_inverse_with_error_correction(
        fresh(trial.rig), yd, trial.ours, camera=trial.camera, stroke=stroke, output_key=key,
        process_var=float(s.ours.process_var), meas_var=float(s.ours.meas_var))
    return runs


def run_trial(s: Seed002Settings, trial: Trial, out: Outcome,
              rows: list[dict[str, Any]], *, plots: bool) -> None:
    """Every motion of one trial: Table I's rows (and the plotted motions' figures)."""
    t = np.arange(0.0, float(s.duration_s), DT_S)
    lead = float(s.lead_in_s)
    case = trial.case
    for sig, omega in signals(s).items():
        yd = with_lead_in(seed002_motion(t, omega_rad_s=omega, amplitude=float(s.amplitude),
                                         offset=float(s.offset)),
                          start=trial.rest, lead_s=lead, dt_s=DT_S)
        runs = motion_runs(s, trial, yd)
        rows.extend(stats_row(res, skip_s=lead, **trial.keys(sig)) for res in runs.values())
        if trial.number == 0 and plots and sig in PLOTTED:
            name = f"seed002_{case.name}_{sig.replace('(', '').replace(')', '')}"
            out.figures[name] = plot_runs(
                f"seed 002 {case.name} ({float(case.curve_angle_deg)} deg, "
                f"{float(case.radius_mm)} mm) - {sig}", runs)


def run_seed002(s: Seed002Settings, backend: RigBackend, *, seed: int, progress_bar: bool,
                plots: bool) -> Outcome:
    """Table ``seed002_table1`` (every case x trial x motion x scheme) and its plots."""
    out = Outcome()
    rows: list[dict[str, Any]] = []
    jobs = [(case, number) for case in s.cases for number in range(int(s.trials))]
    for case, number in progress(jobs, "seed002 cases x trials", progress_bar):
        run_trial(s, calibrate(s, backend, case, number, seed=seed), out, rows, plots=plots)
    out.tables["seed002_table1"] = pd.DataFrame(rows)
    return out
