"""Compensation schemes against the real virtual rig (``rig_io.virtual.VirtualRig``), short runs."""

from __future__ import annotations

import numpy as np
import pytest

from hysteresis import make_family
from hysteresis.coleman_hodgdon import ColemanHodgdonModel
from hysteresis.compensation import (
    CameraModel,
    StrokeLimits,
    mixed_sine_profile,
    reduction,
    run_ame_pd,
    run_inverse_with_error_correction,
    run_open_loop,
    run_vision_feedback,
    seed000_target,
    seed002_motion,
    sine_profile,
)
from rig_io import virtual

DT = 0.01


def _fresh(rig: object) -> object:
    rig.reset()  # type: ignore[attr-defined]
    return rig.step  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def bench() -> object:
    return virtual.VirtualRig(rig="tsm-bench", curve_angle_deg=90, radius_mm=30, seed=3)


def test_gamma_inverse_and_ours_on_the_virtual_bench(bench: object) -> None:
    # Identification: the decaying sinusoid, one period per amplitude (16 s).
    t_id = np.arange(0.0, 16.0, DT)
    u_id = sine_profile(t_id, periods_per_amplitude=1)
    y_id = run_open_loop(_fresh(bench), u_id, desired=u_id).output  # type: ignore[arg-type]
    paper = make_family("gamma").fit(u_id, y_id)
    ours = make_family("gamma", constraint="free", fit_offset=True, n_operators=21,
                       max_threshold=4.0).fit(u_id, y_id)
    yd = 0.5 * mixed_sine_profile(np.arange(0.0, 10.0, DT))
    stroke = StrokeLimits(-15.0, 15.0)
    none = run_open_loop(_fresh(bench), yd, desired=yd, stroke=stroke)  # type: ignore[arg-type]
    ff = run_open_loop(_fresh(bench), paper.invert(yd), desired=yd,  # type: ignore[arg-type]
                       stroke=stroke)
    mine = run_inverse_with_error_correction(_fresh(bench), yd, ours,  # type: ignore[arg-type]
                                             stroke=stroke)
    s0, s1, s2 = none.statistics(), ff.statistics(), mine.statistics()
    assert reduction(s0["std_error"], s1["std_error"]) > 75.0  # thesis: 80-90 %
    assert reduction(s0["rmse"], s2["rmse"]) > 90.0  # our target
    assert stroke.contains(mine.command) and stroke.contains(ff.command)


def test_open_loop_plays_a_known_command_in_one_call_with_the_same_readings(
        bench: object) -> None:
    class Batched:  # a step function that can also take the whole command at once
        def __init__(self, rig: object) -> None:
            self.rig, self.calls = rig, 0

        def __call__(self, command: float) -> object:
            return self.rig.step(command)  # type: ignore[attr-defined]

        def many(self, commands: np.ndarray) -> object:
            self.calls += 1
            return self.rig.step_many(commands)  # type: ignore[attr-defined]

    u = sine_profile(np.arange(0.0, 4.0, DT), periods_per_amplitude=1)
    stroke = StrokeLimits(-2.0, 2.0)  # clips: the clipped command is what is played
    tick = run_open_loop(_fresh(bench), u, desired=u, stroke=stroke)  # type: ignore[arg-type]
    bench.reset()  # type: ignore[attr-defined]
    batched = Batched(bench)
    once = run_open_loop(batched, u, desired=u, stroke=stroke)  # type: ignore[arg-type]
    assert batched.calls == 1
    np.testing.assert_array_equal(once.command, tick.command)
    np.testing.assert_array_equal(once.output, tick.output)


def test_vision_feedback_is_stable_on_the_virtual_bending_joint() -> None:
    rig = virtual.VirtualRig(rig="bending-joint", curve_angle_deg=60, radius_mm=45, seed=1,
                             sensors={"input_unit": "deg"})
    t = np.arange(0.0, 20.0, DT)
    yd = seed002_motion(t, omega_rad_s=1.0, amplitude=10.0, offset=10.0)
    cam = CameraModel(rate_hz=30.0, latency_s=0.045, noise_std=0.5, seed=1)
    none = run_open_loop(_fresh(rig), yd, desired=yd, output_key="tip_angle_deg")  # type: ignore[arg-type]
    fb = run_vision_feedback(_fresh(rig), yd, camera=cam, gain=0.3,  # type: ignore[arg-type]
                             output_key="tip_angle_deg", stroke=StrokeLimits(-30.0, 120.0))
    e = np.abs(fb.error())
    assert np.all(np.isfinite(e))
    assert e[t > 12.0].max() <= 1.2 * e[(t > 4.0) & (t < 12.0)].max()  # no growing oscillation
    assert reduction(none.statistics(skip_s=4.0)["rmse"], fb.statistics(skip_s=4.0)["rmse"]) > 60


def test_pd_and_ame_pd_are_stable_on_the_virtual_bending_joint() -> None:
    rig = virtual.VirtualRig(rig="bending-joint", curve_angle_deg=90, radius_mm=45, seed=2)
    pull = np.concatenate([np.arange(0.0, 6.0, 0.5 * DT), np.arange(6.0, 0.0, -0.5 * DT)])
    angle = run_open_loop(_fresh(rig), pull, desired=pull,  # type: ignore[arg-type]
                          output_key="tip_angle_deg").output
    ref = ColemanHodgdonModel(method="ga", scheme="euler", maxiter=25,
                              popsize=10).fit(pull[::4], angle[::4])
    t = np.arange(0.0, 60.0, DT)
    yd = seed000_target(t)
    yd = np.concatenate([np.linspace(0.0, yd[0], 500), yd])  # 5 s lead-in from rest
    kw = dict(kp=0.02, kd=0.05, control_every=3, output_key="tip_angle_deg",
              stroke=StrokeLimits(0.0, 20.0),
              camera=CameraModel(rate_hz=30.0, latency_s=0.0, noise_std=0.2))
    pd = run_ame_pd(_fresh(rig), yd, None, kc=0.0, **kw)  # type: ignore[arg-type]
    ame = run_ame_pd(_fresh(rig), yd, ref, kc=0.06, **kw)  # type: ignore[arg-type]
    for r in (pd, ame):
        e = r.error()[500:]
        assert np.all(np.isfinite(e)) and np.max(np.abs(e)) < 30.0
        assert 0.0 <= r.command.min() and r.command.max() <= 20.0
    s_pd, s_ame = pd.statistics(skip_s=5.0), ame.statistics(skip_s=5.0)
    assert reduction(s_pd["mean_abs_error"], s_ame["mean_abs_error"]) > 50.0  # paper: 73 %
