"""Pure ingest transforms: resampling, latency by cross-correlation, Kalman up-sampling,
normalisation, and the schema at both edges."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from rig_io.calibrate import calibrate_raw_run
from rig_io.errors import RigIOError
from rig_io.normalise import normalise
from rig_io.process import process_run
from rig_io.schema import validate
from rig_io.synchronise import (
    SyncOptions,
    estimate_latency,
    kalman_upsample,
    resample_boxcar,
    synchronise,
)
from rig_io.synthetic import make_raw_run


def test_boxcar_resample_averages_each_tick() -> None:
    t_src = np.arange(0, 1_000_000_000, 1_000_000, dtype=np.int64)  # 1 kHz
    v = np.where((t_src // 1_000_000) % 2 == 0, 1.0, 3.0)  # 500 Hz square wave, mean 2
    t_dst = np.arange(10_000_000, 990_000_000, 10_000_000, dtype=np.int64)
    out = resample_boxcar(t_src, v, t_dst)
    np.testing.assert_allclose(out, 2.0, atol=0.11)  # plain interpolation would give 1 or 3
    assert np.isnan(resample_boxcar(t_src, v, np.array([2_000_000_000], dtype=np.int64)))[0]


@pytest.mark.parametrize("latency_ms", [20.0, 45.0, 83.0])
def test_camera_latency_recovered_by_cross_correlation(latency_ms: float) -> None:
    run = make_raw_run("lat", duration_s=20.0, camera_latency_ms=latency_ms, seed=3)
    synced = synchronise(calibrate_raw_run(run))
    assert synced.info["camera_latency_method"] == "cross_correlation:output_encoder"
    assert synced.info["camera_latency_ms"] == pytest.approx(latency_ms, abs=2.0)


def test_latency_falls_back_to_nominal_without_reference() -> None:
    run = make_raw_run("nom", duration_s=10.0, with_output_encoder=False, camera_latency_ms=70)
    synced = synchronise(calibrate_raw_run(run))
    assert synced.info["camera_latency_method"] == "nominal"
    assert synced.info["camera_latency_ms"] == pytest.approx(70.0)
    # With a tracker the estimate comes from it instead.
    run = make_raw_run("trk", duration_s=10.0, with_output_encoder=False, with_tracker=True,
                       camera_latency_ms=70)
    synced = synchronise(calibrate_raw_run(run))
    assert synced.info["camera_latency_method"] == "cross_correlation:tracker"
    assert synced.info["camera_latency_ms"] == pytest.approx(70.0, abs=2.0)


def test_estimate_latency_on_a_known_shift() -> None:
    t_ref = np.arange(0, 30, 0.01)
    ref = np.sin(2 * np.pi * 0.3 * t_ref) + 0.3 * np.sin(2 * np.pi * 1.1 * t_ref)
    t_f = np.arange(0.5, 29, 1 / 30)
    frames = np.interp(t_f - 0.0617, t_ref, ref)
    lag, corr = estimate_latency(t_f, frames, t_ref, ref, max_latency_s=0.3, step_s=0.001)
    assert lag == pytest.approx(0.0617, abs=5e-4) and corr > 0.999


def test_kalman_numba_equals_filterpy_and_reduces_noise() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.02, 0.05, 600))
    truth = np.sin(t)
    z = truth + 0.05 * rng.standard_normal(t.size)
    conf = rng.uniform(0.3, 1.0, t.size)
    grid = np.arange(t[0], t[-1], 0.01)
    a = kalman_upsample(t, z, conf, grid, backend="filterpy")
    b = kalman_upsample(t, z, conf, grid, backend="numba")
    np.testing.assert_allclose(b, a, atol=1e-12)
    err_kf = np.sqrt(np.mean((b - np.sin(grid)) ** 2))
    err_raw = np.sqrt(np.mean((np.interp(grid, t, z) - np.sin(grid)) ** 2))
    assert err_kf < 0.6 * err_raw
    with pytest.raises(ValueError, match="unknown Kalman backend"):
        kalman_upsample(t, z, conf, grid, backend="magic")


def test_camera_channel_is_closer_to_truth_than_raw_frames() -> None:
    run = make_raw_run("cam", duration_s=20.0, camera_latency_ms=45.0, seed=9)
    frame, info = process_run(calibrate_raw_run(run), sync=SyncOptions())
    truth = run.extras["true_output"]
    cam = frame["camera"].to_numpy()
    rmse = np.sqrt(np.mean((cam - truth) ** 2))  # the camera column keeps absolute values
    c = run.camera
    ok = c["confidence"] > 0
    raw = c["value"][ok].to_numpy()
    tc = c["t_ns"][ok].to_numpy() / 1e9 - 0.045
    raw_rmse = np.sqrt(np.mean((raw - np.interp(tc, np.arange(truth.size) * 0.01, truth)) ** 2))
    assert rmse < 0.7 * raw_rmse


def test_normalise_offsets_and_amplitude() -> None:
    u = np.array([2.0, 3.0, 6.0, -2.0, 2.0])
    y = np.array([10.0, 10.5, 12.0, 9.0, 10.0])
    n = normalise(u, y)
    np.testing.assert_allclose(n["input"], [0, 1, 4, -4, 0])
    np.testing.assert_allclose(n["input_norm"], [0, 0.25, 1, -1, 0])
    np.testing.assert_allclose(n["output_norm"], [0, 0.125, 0.5, -0.25, 0])
    assert n["input_offset"] == 2.0 and n["output_offset"] == 10.0


def test_process_run_rejects_a_still_input() -> None:
    run = make_raw_run("still", duration_s=2.0, amplitude=0.0, with_camera=False)
    with pytest.raises(RigIOError, match="never moves"):
        process_run(calibrate_raw_run(run))


def test_schema_catches_bad_rows() -> None:
    frame, _ = process_run(calibrate_raw_run(make_raw_run("s", duration_s=2.0)))
    validate(frame, where="write")
    broken = frame.copy()
    broken.loc[5, "t_s"] = broken.loc[4, "t_s"]
    with pytest.raises(RigIOError, match="write edge.*t_s must increase"):
        validate(broken, where="write", run="s")
    broken = frame.copy()
    broken.loc[3, "output"] = np.nan
    with pytest.raises(RigIOError, match="output"):
        validate(broken, where="read")
    with pytest.raises(RigIOError, match="extra"):
        validate(frame.assign(extra=1.0), where="read")
    assert isinstance(frame, pd.DataFrame)
