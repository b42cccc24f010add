"""Virtual rig physics: loop growth with curve angle, the radius effect, realistic loop size
(a Gamma fit leaves an SSE of the order of seed 001 Table 4.1), step == whole trajectory,
reproducibility."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pandas as pd
import pytest

from rig_io.virtual import VirtualRig, make_excitation, simulate_run
from rig_io.virtual.effects import EffectStrengths
from rig_io.virtual.model import build_chain, params_with

SINE = {"kind": "sine_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
        "periods_per_amplitude": 5, "frequency_hz": 0.25}
NO_NOISE = {"camera": False}


@cache
def _truth(phi: float, r: float, seed: int = 0) -> pd.DataFrame:
    run = simulate_run(curve_angle_deg=phi, radius_mm=r, excitation=SINE, seed=seed,
                       sensors=NO_NOISE)
    return run.extras["truth"]


def loop_area(phi: float, r: float) -> float:
    """Area of the input-output loops of the 4.5 mm block (periods 7-9 of the sine)."""
    tr = _truth(phi, r)
    t = tr["t_s"].to_numpy()
    sel = (t >= 24.0) & (t < 36.0)  # three whole periods at 4.5 mm, away from transients
    x, y = tr["input_mm"].to_numpy()[sel], tr["output_mm"].to_numpy()[sel]
    return abs(float(np.sum(x[:-1] * np.diff(y) - y[:-1] * np.diff(x)))) / 2.0 / 3.0


def play(v: np.ndarray, p: float) -> np.ndarray:
    """Seed 001 eq. 4.8, zero initial state."""
    w = np.zeros_like(v)
    for k in range(1, v.size):
        prev = w[k - 1]
        if prev > v[k]:
            w[k] = v[k]
        elif v[k] > prev + p:
            w[k] = v[k] - p
        else:
            w[k] = prev
    return w


def gamma_sse(x: np.ndarray, y: np.ndarray) -> float:
    """Eq. 4.10: least squares for Q with sum(Q) = 1, thresholds 0, 0.2, ..., 2.0 mm."""
    a = np.stack([play(x, p) for p in np.arange(11) * 0.2], axis=1)
    n = a.shape[1]
    kkt = np.block([[2 * a.T @ a, np.ones((n, 1))], [np.ones((1, n)), np.zeros((1, 1))]])
    q = np.linalg.solve(kkt, np.concatenate([2 * a.T @ y, [1.0]]))[:n]
    res = a @ q - y
    return float(res @ res)


def test_tendon_is_discretised_into_at_least_50_elements() -> None:
    chain = build_chain(rig="tsm-bench", curve_angle_deg=90, radius_mm=30, params=params_with(None),
                        effects=EffectStrengths())
    assert chain.n_segments >= 50
    # The arc nodes carry the wrap: their turning angles sum to more than phi (wedging) and
    # the lost motion coefficient exists only where the path turns.
    assert chain.theta[chain.arc_nodes].sum() > math.radians(90)
    assert np.all(chain.coef[chain.arc_nodes, 1] > 0)
    assert chain.coef[0, 1] == 0.0


def test_loop_width_grows_with_curve_angle() -> None:
    areas = [loop_area(phi, 45) for phi in (15, 45, 90)]
    assert areas[0] < areas[1] < areas[2]
    assert areas[2] > 1.8 * areas[0]


def test_radius_matters_at_90_deg_and_hardly_at_15_deg() -> None:
    rel90 = loop_area(90, 30) / loop_area(90, 75) - 1.0
    rel15 = loop_area(15, 30) / loop_area(15, 75) - 1.0
    assert rel90 > 0.10, rel90  # smaller radius, fatter loop at large curve angle
    assert abs(rel15) < 0.04, rel15
    assert rel90 > 4 * abs(rel15)


def test_output_lag_has_seed_001_magnitude() -> None:
    tr = _truth(90, 30)
    lag = (tr["input_mm"] - tr["output_mm"]).to_numpy()
    # Up to ~1-2 mm of lost motion at 90 deg / 30 mm; the output follows, it does not vanish.
    assert 1.0 < np.ptp(lag) < 2.5
    assert tr["output_mm"].max() > 4.0


def test_tensions_follow_the_capstan_relation() -> None:
    tr90, tr15 = _truth(90, 30), _truth(15, 30)
    t_out = tr90["tension_out_n"].to_numpy()
    # The follower's constant-force spring: the output tension stays near the pretension.
    assert np.all(np.abs(t_out - 4.0) < 0.5)
    # Pulling needs more input tension the more the sheath wraps; releasing gives less.
    assert tr90["tension_in_n"].max() > tr15["tension_in_n"].max() + 1.0
    assert tr90["tension_in_n"].min() < tr15["tension_in_n"].min() - 0.5
    # Capstan: T_in/T_out while pulling is at least exp(mu * phi) at 90 deg.
    assert tr90["tension_in_n"].max() / 4.15 > math.exp(0.2 * math.pi / 2)


@pytest.mark.parametrize(("phi", "r"), [(90, 30), (15, 30)])
def test_gamma_fit_leaves_an_sse_of_table_4_1s_order(phi: float, r: float) -> None:
    # Table 4.1: 26-61 over the 80 s sine at 100 Hz (mm^2). "Tens", not ~0 nor thousands.
    run = simulate_run(curve_angle_deg=phi, radius_mm=r, excitation=SINE, seed=1)
    enc = run.encoder
    cpu = run.manifest["channels"]["encoder"]["counts_per_unit"]
    x = (enc["input_counts"] - enc["input_counts"].iloc[0]).to_numpy(float) / cpu
    y = -(enc["output_counts"].astype("int64") - int(enc["output_counts"].iloc[0])).to_numpy(
        float) / cpu
    assert x.size == 8001
    sse = gamma_sse(x, y)
    assert 5.0 < sse < 200.0, sse


def test_step_interface_equals_whole_trajectory() -> None:
    exc = {"kind": "triangle_decay", "amplitudes_mm": [3.0, 1.5], "periods_per_amplitude": 1,
           "slope_mm_s": 6.0}
    effects = {"time_delay": 1.0, "drift": 1.0, "dead_zone": 0.5}
    run = simulate_run(curve_angle_deg=60, radius_mm=45, excitation=exc, seed=5,
                       effects=effects)
    truth = run.extras["truth"]
    rig = VirtualRig(curve_angle_deg=60, radius_mm=45, seed=5, effects=effects)
    rows = [rig.reset()]
    for c in truth["command"].to_numpy()[:-1]:
        rows.append(rig.step(float(c)))
    got = pd.DataFrame(rows)
    np.testing.assert_allclose(got["t_s"], truth["t_s"], atol=1e-12)
    for key, col in (("true_input_mm", "input_mm"), ("true_output_mm", "output_mm"),
                     ("true_tension_in_n", "tension_in_n"),
                     ("true_tension_out_n", "tension_out_n")):
        np.testing.assert_allclose(got[key], truth[col], rtol=0, atol=1e-12, err_msg=key)
    # The measured output of the step interface is the encoder's (delay and drift included).
    enc = run.encoder
    y_enc = -(enc["output_counts"].astype("int64") - int(enc["output_counts"].iloc[0])) / 1e4
    np.testing.assert_allclose(got["output"] - got["output"].iloc[0], y_enc, atol=1.5e-4)
    x_enc = (enc["input_counts"] - enc["input_counts"].iloc[0]) / 1e4
    np.testing.assert_allclose(got["input"], x_enc, atol=1.5e-4)
    # reset() starts over: the same command gives the same reading.
    first = rig.reset()
    assert first["true_tension_in_n"] == rows[0]["true_tension_in_n"]
    assert rig.step(1.0) == pytest.approx(VirtualRig(curve_angle_deg=60, radius_mm=45, seed=5,
                                                     effects=effects).step(1.0))


@pytest.mark.parametrize("rig_name, sensors", [("tsm-bench", None),
                                               ("bending-joint", {"input_unit": "deg"})])
def test_step_many_returns_exactly_the_readings_of_step_by_step(
        rig_name: str, sensors: dict[str, str] | None) -> None:
    # delay and drift make the readings depend on the kept history; the chunks are uneven so
    # that a chunk boundary falls everywhere in the servo and history windows
    effects = {"time_delay": 1.0, "drift": 1.0, "rate_dependence": 1.0}
    cmd = 40.0 * np.sin(np.linspace(0.0, 6.0 * np.pi, 700)) if sensors else \
        3.0 * np.sin(np.linspace(0.0, 6.0 * np.pi, 700))

    def make() -> VirtualRig:
        return VirtualRig(rig=rig_name, curve_angle_deg=75, radius_mm=30, seed=9,
                          effects=effects, sensors=sensors)

    one, many = make(), make()
    assert one.reset() == many.reset()
    expected = [one.step(float(c)) for c in cmd]
    got: list[dict[str, float]] = []
    for chunk in np.split(cmd, [1, 4, 97, 98, 350, 651]):
        got.extend(many.step_many(chunk))
    assert got == expected  # every key, bit for bit
    assert many.step(0.5) == one.step(0.5)  # and the state both leave behind is the same
    with pytest.raises(ValueError, match="finite"):
        many.step_many([0.0, float("nan")])
    # past the size limit: refused before the physics runs, the rig's state untouched
    with pytest.raises(ValueError, match="split the sequence"):
        many.step_many(np.zeros(VirtualRig.MAX_TICKS_PER_CALL + 1))
    assert many.step(0.25) == one.step(0.25)


def test_bending_joint_step_reports_tip_angle_and_degree_commands() -> None:
    rig = VirtualRig(rig="bending-joint", curve_angle_deg=45, radius_mm=45,
                     sensors={"input_unit": "deg"})
    rig.reset()
    out = {}
    for _ in range(200):  # 2 s at 90 deg of motor angle = 7.85 mm of pull on a 5 mm pulley
        out = rig.step(90.0)
    assert out["input"] == pytest.approx(90.0, abs=0.01)
    assert out["true_input_mm"] == pytest.approx(math.radians(90) * 5.0, abs=1e-3)
    assert 20.0 < out["tip_angle_deg"] < 115.0
    assert out["true_tip_angle_deg"] == pytest.approx(
        math.degrees(2 * out["true_output_mm"] / 8.0), abs=1e-9)


def test_same_seed_same_run_other_seed_other_noise() -> None:
    exc = {"kind": "sine", "amplitude": 2.0, "offset": 0.0, "frequency_hz": 0.5,
           "duration_s": 4.0}
    a = simulate_run(curve_angle_deg=30, radius_mm=60, excitation=exc, seed=11)
    b = simulate_run(curve_angle_deg=30, radius_mm=60, excitation=exc, seed=11)
    c = simulate_run(curve_angle_deg=30, radius_mm=60, excitation=exc, seed=12)
    assert a.manifest == b.manifest
    for name, frame in a.streams().items():
        pd.testing.assert_frame_equal(frame, b.streams()[name])
    assert not a.loadcell.equals(c.loadcell)  # type: ignore[union-attr]
    assert a.manifest["channels"]["loadcell"] != c.manifest["channels"]["loadcell"]


def test_excitations_have_the_papers_shapes() -> None:
    t, y = make_excitation("sine_decay", **{k: v for k, v in SINE.items() if k != "kind"})
    assert t[-1] == pytest.approx(80.0) and np.diff(t).max() == pytest.approx(0.01)
    assert y.max() == pytest.approx(6.0, abs=1e-3) and y[-1] == pytest.approx(0.0, abs=1e-9)
    assert np.abs(y[t > 60]).max() == pytest.approx(1.5, abs=1e-3)
    t, y = make_excitation("triangle_decay", amplitudes_mm=[6.0], periods_per_amplitude=1,
                           slope_mm_s=6.0)
    assert t[-1] == pytest.approx(4.0) and np.abs(np.diff(y) / 0.01).max() == pytest.approx(6.0)
    t, y = make_excitation("trapezoid_decay", amplitudes_mm=[3.0], periods_per_amplitude=1,
                           slope_mm_s=6.0, dwell_s=0.5)
    assert t[-1] == pytest.approx(3.0) and np.sum(np.isclose(y, 3.0)) >= 50
    with pytest.raises(ValueError, match="missing parameter"):
        make_excitation("sine_decay", amplitudes_mm=[1.0])
    with pytest.raises(ValueError, match="unknown excitation kind"):
        make_excitation("square")
