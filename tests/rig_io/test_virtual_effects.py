"""Each named effect changes the runs in its own signature, and nothing else (same seed, so the
runs differ by the effect only)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pandas as pd
import pytest

from rig_io.virtual import EFFECT_NAMES, simulate_run, standard_campaign
from rig_io.virtual.effects import DRIFT_MM, DRIFT_TAU_S, EffectStrengths

SHORT = {"kind": "sine_decay", "amplitudes_mm": [6.0, 3.0], "periods_per_amplitude": 2,
         "frequency_hz": 0.25}


def _sine(f: float) -> dict[str, object]:
    return {"kind": "sine", "amplitude": 3.0, "offset": 0.0, "frequency_hz": f,
            "duration_s": 2.0 / f}


@cache
def run(effect: str | None = None, strength: float = 1.0, exc: str = "short"):  # type: ignore[no-untyped-def]
    excitation = SHORT if exc == "short" else _sine(float(exc))
    effects = {effect: strength} if effect else None
    return simulate_run(curve_angle_deg=60, radius_mm=45, excitation=excitation, seed=3,
                        effects=effects)


def truth(effect: str | None = None, exc: str = "short") -> pd.DataFrame:
    return run(effect, exc=exc).extras["truth"]


def measured_output(r) -> np.ndarray:  # type: ignore[no-untyped-def]
    enc = r.encoder
    return -(enc["output_counts"].astype("int64") - int(enc["output_counts"].iloc[0])).to_numpy(
        float) / 1e4


def lag_width(tr: pd.DataFrame) -> float:
    return float(np.ptp((tr["input_mm"] - tr["output_mm"]).to_numpy()))


def loop_area(tr: pd.DataFrame) -> float:
    x, y = tr["input_mm"].to_numpy(), tr["output_mm"].to_numpy()
    return abs(float(np.sum(x[:-1] * np.diff(y) - y[:-1] * np.diff(x)))) / 2.0


def assert_same(a: pd.Series, b: pd.Series, what: str) -> None:
    np.testing.assert_allclose(a.to_numpy(), b.to_numpy(), rtol=0, atol=1e-12, err_msg=what)


def test_effect_vocabulary_and_validation() -> None:
    assert EFFECT_NAMES == ("rate_dependence", "tendon_elongation", "time_delay", "drift",
                            "asymmetry", "saturation", "dead_zone")
    assert EffectStrengths.from_mapping(None).active() == []
    with pytest.raises(ValueError, match="unknown effect"):
        EffectStrengths.from_mapping({"hysteresis": 1.0})
    with pytest.raises(ValueError, match=">= 0"):
        EffectStrengths.from_mapping({"drift": -1.0})
    # The standard campaign has every effect off.
    assert all(not spec["effects"] for spec in standard_campaign(0))
    assert run().extras["effects"] == dict.fromkeys(EFFECT_NAMES, 0.0)
    assert run("drift").extras["effects"]["drift"] == 1.0
    assert "drift" in run("drift").manifest["notes"]


@pytest.mark.parametrize("effect", ["time_delay", "drift"])
def test_measurement_effects_leave_the_mechanics_alone(effect: str) -> None:
    base, eff = truth(), truth(effect)
    for col in ("input_mm", "tension_in_n", "tension_out_n"):
        assert_same(eff[col], base[col], col)
    pd.testing.assert_frame_equal(run(effect).loadcell, run().loadcell)


def test_time_delay_shifts_the_measured_output_by_its_latency() -> None:
    base, eff = run(), run("time_delay")
    assert_same(eff.extras["truth"]["output_mm"], base.extras["truth"]["output_mm"], "truth")
    y0, y1 = measured_output(base), measured_output(eff)
    # The delayed output is the undelayed one 50 ms (5 samples) later.
    np.testing.assert_allclose(y1[5:], y0[:-5], atol=2e-4)
    lags = range(0, 11)
    err = [float(np.mean((y1[k:] - y0[: y0.size - k]) ** 2)) for k in lags]
    assert int(np.argmin(err)) == 5
    # Without the effect the encoder reads the truth.
    np.testing.assert_allclose(y0, base.extras["truth"]["output_mm"], atol=1e-4)


def test_drift_is_a_slow_offset_independent_of_the_input() -> None:
    base, eff = truth(), truth("drift")
    t = base["t_s"].to_numpy()
    expected = DRIFT_MM * (1.0 - np.exp(-t / DRIFT_TAU_S))
    np.testing.assert_allclose(eff["output_mm"] - base["output_mm"], expected, atol=1e-12)
    np.testing.assert_allclose(measured_output(run("drift")) - measured_output(run()), expected,
                               atol=2e-4)


@pytest.mark.parametrize("effect", ["rate_dependence", "tendon_elongation", "asymmetry",
                                    "saturation", "dead_zone"])
def test_mechanical_effects_keep_the_commanded_input(effect: str) -> None:
    # The carriage (input encoder) follows the same commands; only the tendon side changes.
    assert_same(truth(effect)["input_mm"], truth()["input_mm"], "input")
    assert not np.allclose(truth(effect)["output_mm"], truth()["output_mm"], atol=1e-3)


def test_rate_dependence_widens_loops_with_speed_only() -> None:
    slow0, fast0 = loop_area(truth(exc="0.05")), loop_area(truth(exc="0.8"))
    slow1, fast1 = (loop_area(truth("rate_dependence", exc="0.05")),
                    loop_area(truth("rate_dependence", exc="0.8")))
    # The rig without the effect is rate independent (quasi-static Coulomb friction)...
    assert abs(fast0 / slow0 - 1.0) < 0.05
    # ... with it, faster sliding means more friction and a fatter loop.
    assert fast1 / slow1 > 1.1
    assert fast1 / fast0 > slow1 / slow0


def test_rate_dependent_friction_follows_the_sliding_speed_not_the_servo_lurches() -> None:
    # A 10 ms set-point step makes the carriage lurch (fast, then nearly still) inside every
    # tick. Friction follows the speed through the contact's memory (friction_memory_s), so a
    # 6 mm/s slide reads the nominal law 1 + tanh(6 / 10) = 1.54 x the rate-free friction in
    # the load cells (ln(T_in / T_out) = mu x turning while the tendon slides). Without the
    # memory the friction relaxes to the nearly-still end of every tick and reads much less.
    ramp = {"kind": "ramp", "velocity_mm_s": 6.0, "stroke_mm": 6.0}

    def reading(effects: dict[str, float] | None, memory: float = 0.02) -> float:
        fine = simulate_run(curve_angle_deg=90, radius_mm=30, excitation=ramp, seed=3,
                            effects=effects, params={"friction_memory_s": memory,
                                                     "friction_texture": 0.0}
                            ).extras["truth_fine"]
        t, x = fine["t_s"].to_numpy(), fine["input_mm"].to_numpy()
        ratio = np.log(fine["tension_in_n"].to_numpy() / fine["tension_out_n"].to_numpy())
        return float(np.mean(ratio[(t > 0.6) & (x > 2.0) & (x < 5.0)]))

    free = reading(None)
    assert reading({"rate_dependence": 1.0}) / free == pytest.approx(1 + np.tanh(0.6), rel=0.03)
    assert reading({"rate_dependence": 1.0}, memory=0.0) / free < 1.4


def test_tendon_elongation_adds_load_dependent_lag_at_unchanged_tension() -> None:
    base, eff = truth(), truth("tendon_elongation")
    # Tension is set by friction and the follower spring, not by the tendon's compliance.
    assert eff["tension_in_n"].max() == pytest.approx(base["tension_in_n"].max(), rel=0.02)
    assert eff["tension_in_n"].min() == pytest.approx(base["tension_in_n"].min(), rel=0.02)
    extra_lag = (eff["input_mm"] - eff["output_mm"]) - (base["input_mm"] - base["output_mm"])
    # More lag where the tendon is loaded harder (pulling), and a wider loop overall.
    assert np.corrcoef(extra_lag, base["tension_in_n"])[0, 1] > 0.6
    assert lag_width(eff) > lag_width(base) + 0.05


def test_asymmetry_shifts_the_loop_but_hardly_changes_its_width() -> None:
    base, eff = truth(), truth("asymmetry")
    # More friction pulling, less releasing: input tension rises on both branches.
    assert eff["tension_in_n"].max() > base["tension_in_n"].max() + 0.3
    assert eff["tension_in_n"].min() > base["tension_in_n"].min() + 0.2
    mean_lag0 = float(np.mean(base["input_mm"] - base["output_mm"]))
    mean_lag1 = float(np.mean(eff["input_mm"] - eff["output_mm"]))
    assert abs(mean_lag1 - mean_lag0) > 0.08
    assert lag_width(eff) == pytest.approx(lag_width(base), rel=0.15)


def test_saturation_clips_the_output_at_the_end_of_stroke() -> None:
    base, eff = truth(), truth("saturation")
    stop = 6.0 * (1 - 0.3)
    vib = 0.25  # the follower's vibration rides on top of the stop
    assert base["output_mm"].max() > stop + 0.3
    assert eff["output_mm"].max() < stop + vib
    # Identical until the follower first reaches the stop...
    first = int(np.argmax(base["output_mm"].to_numpy() > stop - vib))
    assert first > 0
    np.testing.assert_allclose(eff["output_mm"][:first], base["output_mm"][:first], atol=1e-12)
    # ... then the tendon is pulled against the stop: more input tension there.
    assert eff["tension_in_n"].max() > base["tension_in_n"].max() + 0.5


def test_dead_zone_adds_lost_motion_at_reversals() -> None:
    base, eff = truth(), truth("dead_zone")
    extra = lag_width(eff) - lag_width(base)
    assert 0.25 < extra < 0.55  # the 0.4 mm actuator-side backlash
    # The follower and tension pause after each reversal: same peaks, later.
    assert eff["output_mm"].max() == pytest.approx(base["output_mm"].max() - 0.2, abs=0.1)
