"""Synchronisation: every stream of a run onto one time base, the encoder loop.

- Load cells (1 kHz) are averaged over each encoder tick (a boxcar, so 1 kHz noise does not
  alias) and so resampled onto the encoder's time stamps.
- Trackers are interpolated linearly onto the encoder's time stamps.
- Camera frames are stamped when processed, so they lag the motion. The latency is estimated by
  cross-correlation against the tracker (same quantity) or else the output encoder where one
  exists, otherwise the manifest's ``nominal_latency_ms`` is used; which one is recorded.
  Frames are then moved back by the latency and smoothed and up-sampled with a Kalman filter
  (filterpy; constant-velocity model with white-noise acceleration, as seed 002 smooths
  30 Hz vision), followed by a Rauch-Tung-Striebel smoother: the filter runs at the frame
  times and the smoothed position/velocity are joined by cubic Hermite pieces, which is the
  exact smoothed mean of that model between frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicHermiteSpline

from rig_io.calibrate import PhysicalRun
from rig_io.errors import RigIOError

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class SyncOptions:
    """Knobs of synchronisation (``conf/ingest.yaml`` -> ``sync``)."""

    #: Largest camera latency searched (ms): cross-correlation of the frames against the tracker or
    #: encoder.
    max_latency_ms: float = 300.0
    #: Step between the latencies tried (ms); the best is refined by a parabola through the peak.
    latency_step_ms: float = 1.0
    #: Below this |correlation| the estimate is not trusted and the manifest's nominal latency
    #: is used.
    min_correlation: float = 0.8
    #: Kalman process noise: white-acceleration spectral density as a multiple of the
    #: variance of the camera signal (units^2 / s^3 per unit variance).
    process_noise_scale: float = 5.0
    #: Measurement noise variance; ``None`` estimates it from the frames (second differences).
    measurement_var: float | None = None
    #: ``filterpy`` (the reference) or ``numba`` (the same equations compiled, fast; tested to
    #: agree to 1e-12).
    kalman_backend: str = "numba"


@dataclass
class SyncedRun:
    """All channels on the encoder time base (``t_s`` from the first encoder sample)."""

    t_s: FloatArray
    channels: dict[str, FloatArray]
    info: dict[str, Any] = field(default_factory=dict)


def resample_boxcar(t_src: npt.NDArray[np.int64], v_src: FloatArray,
                    t_dst: npt.NDArray[np.int64]) -> FloatArray:
    """Mean of the source samples within half a destination period of each destination time.

    Destination times outside the source's span are NaN; a window that holds no source sample
    (a slower source) falls back to linear interpolation.
    """
    out = np.full(t_dst.size, np.nan)
    ok = np.isfinite(v_src)
    t_src, v_src = t_src[ok], v_src[ok]
    if t_src.size == 0 or t_dst.size == 0:
        return out
    half = np.diff(t_dst).astype(float) / 2.0
    lo_edge = t_dst - np.concatenate([[half[0] if half.size else 0.0], half])
    hi_edge = t_dst + np.concatenate([half, [half[-1] if half.size else 0.0]])
    lo = np.searchsorted(t_src, lo_edge, side="left")
    hi = np.searchsorted(t_src, hi_edge, side="left")
    csum = np.concatenate([[0.0], np.cumsum(v_src)])
    count = hi - lo
    has = count > 0
    out[has] = (csum[hi[has]] - csum[lo[has]]) / count[has]
    missing = ~has
    if missing.any():
        out[missing] = np.interp(t_dst[missing], t_src, v_src, left=np.nan, right=np.nan)
    inside = (t_dst >= t_src[0]) & (t_dst <= t_src[-1])
    out[~inside] = np.nan
    return out


def interp_stream(t_src: npt.NDArray[np.int64] | FloatArray, v_src: FloatArray,
                  t_dst: npt.NDArray[np.int64] | FloatArray) -> FloatArray:
    """Linear interpolation of the finite source samples; NaN outside their span."""
    ok = np.isfinite(v_src)
    if ok.sum() < 2:
        return np.full(np.shape(t_dst), np.nan)
    out: FloatArray = np.interp(np.asarray(t_dst, dtype=float),
                                np.asarray(t_src, dtype=float)[ok], v_src[ok],
                                left=np.nan, right=np.nan)
    return out


def confident_frames(frame: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(t_ns as float, value, confidence) of the measured frames (confidence > 0, a value)."""
    t = frame["t_ns"].to_numpy(dtype=float)
    v = frame["value"].to_numpy(dtype=float)
    c = frame["confidence"].to_numpy(dtype=float)
    ok = np.isfinite(v) & np.isfinite(c) & (c > 0)
    return t[ok], v[ok], c[ok]


def estimate_latency(t_frames_s: FloatArray, values: FloatArray, t_ref_s: FloatArray,
                     ref: FloatArray, *, max_latency_s: float,
                     step_s: float) -> tuple[float, float]:
    """Latency (s) maximising |Pearson correlation| of frames against the delayed reference.

    A frame stamped at ``t`` shows the reference at ``t - latency``. Returns the latency
    (refined by a parabola through the peak) and the peak's |correlation|.
    """
    ok = np.isfinite(ref)
    t_ref_s, ref = t_ref_s[ok], ref[ok]
    v = values - values.mean()

    def score(lags: FloatArray) -> FloatArray:
        corr = np.full(lags.size, np.nan)
        for i, lag in enumerate(lags):
            r = np.interp(t_frames_s - lag, t_ref_s, ref, left=np.nan, right=np.nan)
            m = np.isfinite(r)
            if m.sum() < 10:
                continue
            a, b = v[m] - v[m].mean(), r[m] - r[m].mean()
            den = np.sqrt(np.dot(a, a) * np.dot(b, b))
            corr[i] = abs(np.dot(a, b) / den) if den > 0 else np.nan
        return corr

    # Coarse pass every 10 steps, then every step around the best coarse lag.
    coarse = np.arange(0.0, max_latency_s + step_s / 2, 10 * step_s)
    c_corr = score(coarse)
    if not np.isfinite(c_corr).any():
        return float("nan"), float("nan")
    best = float(coarse[int(np.nanargmax(c_corr))])
    lags = np.arange(max(0.0, best - 10 * step_s), min(max_latency_s, best + 10 * step_s)
                     + step_s / 2, step_s)
    corr = score(lags)
    if not np.isfinite(corr).any():
        return float("nan"), float("nan")
    k = int(np.nanargmax(corr))
    lag = float(lags[k])
    if 0 < k < lags.size - 1 and np.isfinite(corr[k - 1]) and np.isfinite(corr[k + 1]):
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            lag += float(0.5 * (y0 - y2) / den) * step_s
    return lag, float(corr[k])


def kalman_upsample(t_frames_s: FloatArray, values: FloatArray, confidence: FloatArray,
                    t_grid_s: FloatArray, *, process_noise_scale: float = 5.0,
                    measurement_var: float | None = None,
                    backend: str = "filterpy") -> FloatArray:
    """Kalman filter + RTS smoother over the frames, evaluated on ``t_grid_s``.

    Constant-velocity state [value, rate]; a frame's measurement variance is the base
    variance divided by its confidence. Before the first and after the last frame the value
    is held (no extrapolation of the rate).
    """
    n = t_frames_s.size
    if n == 0:
        return np.full(t_grid_s.size, np.nan)
    if n == 1:
        return np.full(t_grid_s.size, float(values[0]))
    if measurement_var is None:
        # White measurement noise dominates second differences of a smooth signal.
        d2 = np.diff(values, 2)
        mad = float(np.median(np.abs(d2 - np.median(d2)))) * 1.4826
        measurement_var = max((mad**2) / 6.0, 1e-12)
    q = process_noise_scale * max(float(np.var(values)), 1e-12)
    dts = np.diff(t_frames_s, prepend=t_frames_s[0])
    r = measurement_var / np.clip(confidence, 1e-3, 1.0)
    if backend == "filterpy":
        pos, vel = _kalman_filterpy(values, dts, r, q, measurement_var)
    elif backend == "numba":
        pos, vel = _kalman_numba(np.ascontiguousarray(values, dtype=np.float64),
                                 np.ascontiguousarray(dts, dtype=np.float64),
                                 np.ascontiguousarray(r, dtype=np.float64),
                                 float(q), float(measurement_var))
    else:
        raise ValueError(f"unknown Kalman backend {backend!r} (filterpy or numba)")
    spline = CubicHermiteSpline(t_frames_s, pos, vel, extrapolate=False)
    out = np.asarray(spline(t_grid_s), dtype=float)
    out[t_grid_s < t_frames_s[0]] = pos[0]
    out[t_grid_s > t_frames_s[-1]] = pos[-1]
    return out


def _kalman_filterpy(values: FloatArray, dts: FloatArray, r: FloatArray, q: float,
                     r0: float) -> tuple[FloatArray, FloatArray]:
    from filterpy.kalman import KalmanFilter  # imported here: it pulls in scipy.stats (1 s)

    kf = KalmanFilter(dim_x=2, dim_z=1)
    kf.x = np.array([[values[0]], [0.0]])
    kf.P = np.diag([r0, q])
    kf.H = np.array([[1.0, 0.0]])
    # Continuous white-noise acceleration of spectral density q, integrated over dt.
    Qs = [q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]]) for dt in dts]
    Fs = [np.array([[1.0, dt], [0.0, 1.0]]) for dt in dts]
    Rs = [np.array([[ri]]) for ri in r]
    zs = [np.array([[z]]) for z in values]
    means, covs, _, _ = kf.batch_filter(zs, Fs=Fs, Qs=Qs, Rs=Rs)
    xs, _, _, _ = kf.rts_smoother(means, covs, Fs=Fs, Qs=Qs)
    return xs[:, 0, 0], xs[:, 1, 0]


@numba.njit(cache=True)  # type: ignore[untyped-decorator,misc,unused-ignore]
def _kalman_numba(z: FloatArray, dts: FloatArray, r: FloatArray, q: float,
                  r0: float) -> tuple[FloatArray, FloatArray]:
    """filterpy's predict/update + RTS smoother, written out for the 2-state model."""
    xm, pm = _kalman_forward(z, dts, r, q, r0)
    return _rts_backward(xm, pm, dts, q)


@numba.njit(cache=True)  # type: ignore[untyped-decorator,misc,unused-ignore]
def _kalman_forward(z: FloatArray, dts: FloatArray, r: FloatArray, q: float,
                    r0: float) -> tuple[FloatArray, FloatArray]:
    """The filter pass: (state means, covariances) after each update."""
    n = z.size
    xm = np.empty((n, 2))
    pm = np.empty((n, 2, 2))
    xp = np.empty((n, 2))
    pp = np.empty((n, 2, 2))
    x0, x1 = z[0], 0.0
    p00, p01, p11 = r0, 0.0, q
    for k in range(n):
        dt = dts[k]
        # predict
        x0 = x0 + dt * x1
        a00 = p00 + dt * (p01 + p01) + dt * dt * p11 + q * dt**3 / 3.0
        a01 = p01 + dt * p11 + q * dt**2 / 2.0
        a11 = p11 + q * dt
        p00, p01, p11 = a00, a01, a11
        xp[k, 0], xp[k, 1] = x0, x1
        pp[k, 0, 0], pp[k, 0, 1], pp[k, 1, 0], pp[k, 1, 1] = p00, p01, p01, p11
        # update
        s = p00 + r[k]
        k0, k1 = p00 / s, p01 / s
        y = z[k] - x0
        x0, x1 = x0 + k0 * y, x1 + k1 * y
        # Joseph form, as filterpy
        b00 = (1 - k0) * (1 - k0) * p00 + k0 * k0 * r[k]
        b01 = (1 - k0) * (p01 - k1 * p00) + k0 * k1 * r[k]
        b11 = p11 - 2 * k1 * p01 + k1 * k1 * p00 + k1 * k1 * r[k]
        p00, p01, p11 = b00, b01, b11
        xm[k, 0], xm[k, 1] = x0, x1
        pm[k, 0, 0], pm[k, 0, 1], pm[k, 1, 0], pm[k, 1, 1] = p00, p01, p01, p11
    return xm, pm


@numba.njit(cache=True)  # type: ignore[untyped-decorator,misc,unused-ignore]
def _rts_backward(xm: FloatArray, pm: FloatArray, dts: FloatArray,
                  q: float) -> tuple[FloatArray, FloatArray]:
    """The RTS smoother pass over the filter's means and covariances: (position, speed)."""
    n = xm.shape[0]
    xs = xm.copy()
    ps = pm.copy()
    for k in range(n - 2, -1, -1):
        dt = dts[k + 1]
        # predicted covariance of k+1 from k (as filterpy's rts_smoother recomputes it)
        c00 = pm[k, 0, 0] + dt * 2 * pm[k, 0, 1] + dt * dt * pm[k, 1, 1] \
            + q * dt**3 / 3.0
        c01 = pm[k, 0, 1] + dt * pm[k, 1, 1] + q * dt**2 / 2.0
        c11 = pm[k, 1, 1] + q * dt
        det = c00 * c11 - c01 * c01
        i00, i01, i11 = c11 / det, -c01 / det, c00 / det
        # P F^T
        f00 = pm[k, 0, 0] + dt * pm[k, 0, 1]
        f01 = pm[k, 0, 1]
        f10 = pm[k, 0, 1] + dt * pm[k, 1, 1]
        f11 = pm[k, 1, 1]
        g00 = f00 * i00 + f01 * i01
        g01 = f00 * i01 + f01 * i11
        g10 = f10 * i00 + f11 * i01
        g11 = f10 * i01 + f11 * i11
        px0 = xm[k, 0] + dt * xm[k, 1]
        px1 = xm[k, 1]
        d0, d1 = xs[k + 1, 0] - px0, xs[k + 1, 1] - px1
        xs[k, 0] = xm[k, 0] + g00 * d0 + g01 * d1
        xs[k, 1] = xm[k, 1] + g10 * d0 + g11 * d1
        e00, e01 = ps[k + 1, 0, 0] - c00, ps[k + 1, 0, 1] - c01
        e11 = ps[k + 1, 1, 1] - c11
        # P_s = P + G (Ps' - Pp) G^T
        h00 = g00 * e00 + g01 * e01
        h01 = g00 * e01 + g01 * e11
        h10 = g10 * e00 + g11 * e01
        h11 = g10 * e01 + g11 * e11
        ps[k, 0, 0] = pm[k, 0, 0] + h00 * g00 + h01 * g01
        ps[k, 0, 1] = pm[k, 0, 1] + h00 * g10 + h01 * g11
        ps[k, 1, 0] = ps[k, 0, 1]
        ps[k, 1, 1] = pm[k, 1, 1] + h10 * g10 + h11 * g11
    return xs[:, 0].copy(), xs[:, 1].copy()


def synchronise(run: PhysicalRun, options: SyncOptions | None = None) -> SyncedRun:
    """Put every channel of ``run`` on its encoder time base; see the module docstring."""
    opt = options or SyncOptions()
    enc = run.encoder
    t_ns = enc["t_ns"].to_numpy(dtype=np.int64)
    t0 = int(t_ns[0])
    t_s = (t_ns - t0).astype(float) / 1e9
    ch: dict[str, FloatArray] = {
        "input": enc["input"].to_numpy(dtype=float),
        "output_encoder": enc["output"].to_numpy(dtype=float),
    }
    info: dict[str, Any] = {"t0_ns": t0}
    if run.loadcell is not None:
        tl = run.loadcell["t_ns"].to_numpy(dtype=np.int64)
        for col in ("tension_in_n", "tension_out_n", "tension_proxy"):
            if col in run.loadcell:  # the proxy: an uncalibrated cell's raw mV/V
                ch[col] = resample_boxcar(tl, run.loadcell[col].to_numpy(dtype=float), t_ns)
    for name, arr in run.extra.items():
        ch[name] = np.asarray(arr, dtype=float)
    if run.tracker is not None:
        tt, vt, _ = confident_frames(run.tracker)
        ch["tracker"] = interp_stream(tt, vt, t_ns.astype(float))
    if run.camera is not None:
        ch["camera"], camera_info = _camera_channel(run, ch, t_ns, t_s, opt)
        info.update(camera_info)
    return SyncedRun(t_s=t_s, channels=ch, info=info)


def _camera_channel(run: PhysicalRun, ch: dict[str, FloatArray], t_ns: np.ndarray,
                    t_s: FloatArray, opt: SyncOptions) -> tuple[FloatArray, dict[str, Any]]:
    """The camera's confident frames, latency-corrected and Kalman-smoothed onto the encoder
    time base, and what was found about its latency."""
    assert run.camera is not None
    t0 = int(t_ns[0])
    tc, vc, cc = confident_frames(run.camera)
    if tc.size == 0:
        raise RigIOError("no confident camera frame", run=run.run_id, file=run.file("camera"))
    # Frames on another clock would be held constant over the whole run by the smoother.
    t_end = float(t_ns[-1])
    slack = opt.max_latency_ms * 1e6
    if not np.any((tc >= t0) & (tc <= t_end + slack)):
        raise RigIOError(f"no confident camera frame within the encoder's span "
                         f"(frames t={tc[0] / 1e9:.3f}..{tc[-1] / 1e9:.3f} s, encoder "
                         f"t={t0 / 1e9:.3f}..{t_end / 1e9:.3f} s)", run=run.run_id,
                         file=run.file("camera"))
    tcs = (tc - t0) / 1e9
    latency_s, method, corr = _camera_latency(run, ch, tcs, vc, t_s, opt)
    smooth = kalman_upsample(tcs - latency_s, vc, cc, t_s,
                             process_noise_scale=opt.process_noise_scale,
                             measurement_var=opt.measurement_var,
                             backend=opt.kalman_backend)
    info = dict(camera_latency_ms=latency_s * 1e3, camera_latency_method=method,
                camera_latency_correlation=None if not np.isfinite(corr) else corr,
                camera_frames_used=int(tc.size), camera_frames=int(len(run.camera)))
    return smooth, info


def _camera_latency(run: PhysicalRun, ch: dict[str, FloatArray], tcs: FloatArray,
                    vc: FloatArray, t_s: FloatArray, opt: SyncOptions
                    ) -> tuple[float, str, float]:
    """(latency in s, how it was found, correlation): cross-correlation with the tracker or
    the output encoder where that is confident, else the manifest's nominal latency."""
    cam = run.manifest.get("channels", {}).get("camera") or {}
    nominal_ms = cam.get("nominal_latency_ms")
    latency_s, method, corr = float("nan"), "nominal", float("nan")
    reference = None
    if "tracker" in ch and np.isfinite(ch["tracker"]).sum() > 10:
        reference = ("tracker", ch["tracker"])
    elif np.isfinite(ch["output_encoder"]).sum() > 10:
        reference = ("output_encoder", ch["output_encoder"])
    if reference is not None and tcs.size >= 20:
        lat, corr = estimate_latency(tcs, vc, t_s, reference[1],
                                     max_latency_s=opt.max_latency_ms / 1e3,
                                     step_s=opt.latency_step_ms / 1e3)
        if np.isfinite(lat) and corr >= opt.min_correlation:
            latency_s, method = lat, f"cross_correlation:{reference[0]}"
    if method == "nominal":
        if nominal_ms is None:
            latency_s, method = 0.0, "none"
        else:
            latency_s = float(nominal_ms) / 1e3
    return latency_s, method, corr
