"""The virtual rig writes exactly the format: manifest, streams, sensors that decode to the truth,
run folders and bags of the same run carrying the same data, the standard campaign."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rig_io.bag import read_bag, write_bag
from rig_io.calibrate import calibrate_raw_run
from rig_io.folder import check_raw_run, read_run_folder, write_run_folder
from rig_io.run import STREAM_COLUMNS
from rig_io.virtual import simulate_run, standard_campaign

EXAMPLE_MANIFEST = {  # rig-log-format.md section 1 (the keys the example shows)
    "format", "run_id", "rig", "started_at", "configuration", "excitation", "channels", "notes"}
SHORT = {"kind": "sine_decay", "amplitudes_mm": [6.0, 3.0], "periods_per_amplitude": 1,
         "frequency_hz": 0.5}


@pytest.fixture(scope="module")
def bench_run():  # type: ignore[no-untyped-def]
    return simulate_run(curve_angle_deg=90, radius_mm=30, excitation=SHORT, seed=4,
                        run_id="phi090_r030_sine_decay_0001",
                        sensors={"counter_start": "near_wrap", "tracker": True})


def test_standard_campaign_is_120_reproducible_specs() -> None:
    specs = standard_campaign(0)
    assert len(specs) == 120
    ids = [s["run_id"] for s in specs]
    assert len(set(ids)) == 120
    assert all(re.fullmatch(r"phi\d{3}_r\d{3}_((sine|triangle|trapezoid)_decay|mixed_sine|"
                            r"band_random)_\d{4}", i) for i in ids)
    assert ids[0] == "phi015_r030_sine_decay_0001"
    assert ids[-1] == "phi090_r075_band_random_0120"
    kinds = [s["excitation"]["kind"] for s in specs[:5]]
    assert kinds == ["sine_decay", "triangle_decay", "trapezoid_decay", "mixed_sine",
                     "band_random"]
    configs = {(s["curve_angle_deg"], s["radius_mm"]) for s in specs}
    assert configs == {(p, r) for p in (15, 30, 45, 60, 75, 90) for r in (30, 45, 60, 75)}
    sine = [s for s in specs if s["excitation"]["kind"] == "sine_decay"]
    assert sine[0]["excitation"] == {"kind": "sine_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                                     "periods_per_amplitude": 5, "frequency_hz": 0.25}
    tri = [s for s in specs if s["excitation"]["kind"] == "triangle_decay"][0]
    assert tri["excitation"]["slope_mm_s"] == 6.0
    assert standard_campaign(0) == specs
    seeds1 = [s["seed"] for s in standard_campaign(1)]
    assert seeds1 != [s["seed"] for s in specs] and len(set(seeds1)) == 120


def test_manifest_has_the_formats_shape(bench_run) -> None:  # type: ignore[no-untyped-def]
    m = bench_run.manifest
    assert set(m) == EXAMPLE_MANIFEST
    assert m["format"] == "tsm-rig-log/1" and m["rig"] == "tsm-bench"
    assert m["configuration"] == {"curve_angle_deg": 90, "radius_mm": 30}
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", m["started_at"])
    assert m["excitation"] == SHORT
    ch = m["channels"]
    assert ch["encoder"] == {"unit": "mm", "counts_per_unit": 10000, "counter_bits": 32,
                             "input_sign": 1, "output_sign": -1}
    for side in ("input", "output"):
        assert set(ch["loadcell"][side]) == {"newton_per_mv_per_v", "zero_mv_per_v", "range_n"}
    assert ch["camera"] == {"quantity": "output_mm", "source": "camera",
                            "nominal_latency_ms": 45, "rate_hz": 30}
    assert ch["tracker"]["source"] == "tracker"
    json.dumps(m)  # plain JSON
    for name, frame in bench_run.streams().items():
        assert tuple(frame.columns) == STREAM_COLUMNS[name], name
    check_raw_run(bench_run)  # the format's value checks (timestamps, gaps, saturation, ...)


def test_sensors_decode_to_the_truth(bench_run) -> None:  # type: ignore[no-untyped-def]
    truth = bench_run.extras["truth"]
    enc = bench_run.encoder
    assert enc["t_ns"].dtype == np.int64 and np.all(np.diff(enc["t_ns"]) == 10_000_000)
    counts = enc["input_counts"].to_numpy(np.int64)
    assert counts.min() >= -(2**31) and counts.max() < 2**31
    # near_wrap: the 32-bit counter wraps during the run, and unwraps to the truth.
    assert np.any(np.abs(np.diff(counts)) > 2**31)
    phys = calibrate_raw_run(bench_run)
    np.testing.assert_allclose(phys.encoder["input"], truth["input_mm"], atol=1e-4)
    np.testing.assert_allclose(phys.encoder["output"], truth["output_mm"], atol=1e-4)
    # Load cells: 1 kHz, offset removed by the manifest's zero, noise of a few mN.
    lc = bench_run.loadcell
    assert len(lc) == 10 * (len(enc) - 1) + 1
    fine = bench_run.extras["truth_fine"]
    err = phys.loadcell["tension_in_n"].to_numpy() - fine["tension_in_n"].to_numpy()
    assert 0.002 < np.std(err) < 0.02 and abs(np.mean(err)) < 0.002
    # Camera: ~30 Hz, late by about its latency, dropped and unconfident frames, noisy.
    cam = bench_run.camera
    dur = enc["t_ns"].iloc[-1] / 1e9
    assert 0.9 * 30 * dur < len(cam) < 30 * dur
    assert np.all(np.diff(cam["frame"]) >= 1)
    bad = cam["confidence"] == 0
    assert cam.loc[bad, "value"].isna().all() and cam.loc[~bad, "value"].notna().all()
    assert cam["confidence"].between(0, 1).all()
    good = cam[~bad]
    lat = bench_run.extras["camera_latency_s"]
    t = good["t_ns"].to_numpy() / 1e9
    on_time = np.interp(t, truth["t_s"], truth["output_mm"])
    late = np.interp(t - lat, truth["t_s"], truth["output_mm"])
    assert np.mean((good["value"] - late) ** 2) < 0.5 * np.mean((good["value"] - on_time) ** 2)
    assert list(bench_run.events["event"]) == ["start", "stop"]


def test_folder_and_bags_of_the_same_run_carry_the_same_data(bench_run, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    path = write_run_folder(bench_run, tmp_path / "runs")
    back = read_run_folder(path)
    assert back.manifest == bench_run.manifest
    for name, frame in bench_run.streams().items():
        got = back.streams()[name]
        for col in frame.columns:
            a, b = frame[col].to_numpy(), got[col].to_numpy()
            if a.dtype.kind == "f":
                np.testing.assert_allclose(b.astype(float), a, rtol=0, atol=1e-9,
                                           err_msg=f"{name}.{col}")
            else:
                assert list(a) == list(b), f"{name}.{col}"
    ref = calibrate_raw_run(back)
    for storage, target in (("rosbag1", "run.bag"), ("mcap", "run_mcap"),
                            ("sqlite3", "run_db3")):
        bag = read_bag(write_bag(bench_run, tmp_path / target, storage=storage))  # type: ignore[arg-type]
        assert bag.manifest == bench_run.manifest
        for stream, cols in (("encoder", ["t_ns", "input", "output"]),
                             ("loadcell", ["t_ns", "tension_in_n", "tension_out_n"]),
                             ("camera", ["t_ns", "value", "confidence"]),
                             ("tracker", ["t_ns", "value", "confidence"])):
            np.testing.assert_allclose(getattr(bag, stream)[cols].to_numpy(float),
                                       getattr(ref, stream)[cols].to_numpy(float), rtol=1e-12,
                                       atol=1e-12, err_msg=f"{storage} {stream}")


def test_bending_joint_run(tmp_path: Path) -> None:
    exc = {"kind": "sine", "amplitude": 90.0, "offset": 90.0, "frequency_hz": 0.25,
           "duration_s": 8.0}
    run = simulate_run(rig="bending-joint", curve_angle_deg=60, radius_mm=45, excitation=exc,
                       seed=2, sensors={"input_unit": "deg"})
    m = run.manifest
    assert m["rig"] == "bending-joint" and m["channels"]["encoder"]["unit"] == "deg"
    assert m["channels"]["camera"]["quantity"] == "tip_angle_deg"
    assert m["channels"]["tracker"]["source"] == "tracker"
    assert run.encoder["output_counts"].isna().all()  # no distal encoder
    truth = run.extras["truth"]
    # seed 000 eq. 6-7: alpha = 2 dl / D; the section never bends past straight.
    np.testing.assert_allclose(truth["tip_angle_deg"], np.degrees(2 * truth["output_mm"] / 8.0))
    assert truth["tip_angle_deg"].min() > -2.0 and truth["tip_angle_deg"].max() > 40.0
    tr = run.tracker
    np.testing.assert_allclose(tr["value"], np.interp(tr["t_ns"] / 1e9 - 0.008, truth["t_s"],
                                                      truth["tip_angle_deg"]), atol=1.0)
    back = read_run_folder(write_run_folder(run, tmp_path))
    assert back.encoder["output_counts"].isna().all()
    phys = calibrate_raw_run(back)
    np.testing.assert_allclose(phys.encoder["input"],
                               np.degrees(truth["input_mm"] / 5.0), atol=2e-3)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"rig": "robot"}, "unknown rig"),
    ({"effects": {"stiction": 1.0}}, "unknown effect"),
    ({"effects": {"drift": float("nan")}}, "finite"),
    ({"excitation": {"kind": "sine"}}, "missing parameter"),
    ({"excitation": {"amplitude": 1.0}}, "'kind'"),
    ({"sensors": {"camera_fps": 60}}, "unknown sensor option"),
    ({"params": {"mu_static": 0.3}}, "unknown rig parameter"),
    ({"radius_mm": -5.0}, "radius_mm"),
    ({"seed": -1}, "seed"),
])
def test_bad_input_is_a_clear_error(kwargs: dict[str, object], match: str) -> None:
    spec: dict[str, object] = {"curve_angle_deg": 30, "radius_mm": 45, "excitation": SHORT}
    spec.update(kwargs)
    with pytest.raises(ValueError, match=match):
        simulate_run(**spec)  # type: ignore[arg-type]


def test_loadcell_saturates_at_its_range() -> None:
    run = simulate_run(curve_angle_deg=90, radius_mm=30, excitation=SHORT, seed=1,
                       sensors={"loadcell_range_n": 5.0})
    cell = run.manifest["channels"]["loadcell"]["input"]
    force = (run.loadcell["input_mv_per_v"] - cell["zero_mv_per_v"]) * cell["newton_per_mv_per_v"]
    assert force.max() == pytest.approx(5.0, abs=1e-4)
    assert run.extras["truth_fine"]["tension_in_n"].max() > 6.0
    with pytest.raises(Exception, match="saturated"):
        check_raw_run(run)


def test_truth_frame_is_on_the_encoder_clock(bench_run) -> None:  # type: ignore[no-untyped-def]
    truth = bench_run.extras["truth"]
    assert isinstance(truth, pd.DataFrame)
    assert list(truth.columns) == ["t_s", "command", "input_mm", "output_mm", "tension_in_n",
                                   "tension_out_n"]
    np.testing.assert_array_equal(np.rint(truth["t_s"] * 1e9).astype(np.int64),
                                  bench_run.encoder["t_ns"])


def test_large_seeds_and_default_run_id() -> None:
    exc = {"kind": "ramp", "velocity_mm_s": 2.0, "stroke_mm": 1.0, "dwell_s": 0.1}
    run = simulate_run(curve_angle_deg=45, radius_mm=60, excitation=exc, seed=4_000_000_000)
    assert run.run_id == "phi045_r060_ramp_4000000000"
    assert run.manifest["started_at"].startswith("2026-")
    assert run.manifest["excitation"] == {"kind": "ramp", **{k: v for k, v in exc.items()}}
