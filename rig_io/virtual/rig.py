"""The virtual rig: step-by-step (:class:`VirtualRig`) and whole-trajectory (:func:`simulate_run`).

Both drive the same numba kernel (:func:`rig_io.virtual.physics.run_ticks`) with the same
random streams, so stepping through a trajectory reproduces ``simulate_run`` exactly.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.signal import lfilter

from rig_io.run import FORMAT, RawRun
from rig_io.virtual import physics as ph
from rig_io.virtual import sensors as sn
from rig_io.virtual.effects import EffectStrengths
from rig_io.virtual.excitations import make_excitation, manifest_excitation
from rig_io.virtual.model import (
    RIG_NAMES,
    TSMParams,
    build_chain,
    params_with,
    tip_angle_deg,
)

FloatArray = npt.NDArray[np.float64]
_EPOCH = datetime(2026, 3, 2, 10, 15, tzinfo=UTC)


def _number(x: float) -> int | float:
    """Manifest numbers: integers where they are whole (``90`` not ``90.0``)."""
    return int(x) if float(x).is_integer() else float(x)


class _Streams:
    """The run's random streams, one per purpose (adding one never shifts the others)."""

    def __init__(self, seed: int) -> None:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        ss = np.random.SeedSequence(int(seed))
        texture, vibration, sensors, step_noise = ss.spawn(4)
        self.texture = np.random.default_rng(texture)
        self.vibration = np.random.default_rng(vibration)
        self.sensors = np.random.default_rng(sensors)
        self.step_noise = np.random.default_rng(step_noise)


def _texture(params: TSMParams, rng: np.random.Generator, k: int = 4) -> FloatArray:
    eps = params.friction_texture
    if eps <= 0.0:
        return np.zeros((0, 3))
    lo, hi = params.texture_wavelength_mm
    lam = rng.uniform(lo, hi, k)
    amp = rng.uniform(0.5, 1.0, k)
    amp *= eps / math.sqrt(float(np.sum(amp**2)) / 2.0)  # RMS of the sum of sines = eps
    return np.ascontiguousarray(np.stack([amp, 2 * np.pi / lam, rng.uniform(0, 2 * np.pi, k)],
                                         axis=1))


class _Vibration:
    """AR(1) vibration of the follower carriage, drawn chunk by chunk (same numbers either way)."""

    def __init__(self, params: TSMParams, rng: np.random.Generator) -> None:
        self.rng = rng
        dt = params.physics_dt_s
        self.a = math.exp(-dt / params.follower_vibration_tau_s)
        self.b = params.follower_vibration_mm * math.sqrt(1.0 - self.a**2)
        self.zi = np.zeros(1)
        self.on = params.follower_vibration_mm > 0.0

    def draw(self, n: int) -> FloatArray:
        if not self.on:
            return np.zeros(n)
        e = self.rng.standard_normal(n)
        y, self.zi = lfilter([self.b], [1.0, -self.a], e, zi=self.zi)
        return np.asarray(y)


class _Core:
    """Physics state of one rig (shared by the step and whole-trajectory interfaces)."""

    def __init__(self, *, rig: str, curve_angle_deg: float, radius_mm: float,
                 effects: dict[str, float] | None, seed: int, sensors: dict[str, Any] | None,
                 params: dict[str, Any] | None) -> None:
        if rig not in RIG_NAMES:
            raise ValueError(f"unknown rig {rig!r}; expected one of {RIG_NAMES}")
        self.rig = rig
        self.curve_angle_deg = float(curve_angle_deg)
        self.radius_mm = float(radius_mm)
        self.effects = EffectStrengths.from_mapping(effects)
        self.params = params_with(params)
        self.sensor_cfg = sn.SensorConfig.from_mapping(sensors)
        if self.sensor_cfg.input_unit == "deg" and rig != "bending-joint":
            raise ValueError("sensors.input_unit='deg' (motor angle) needs rig='bending-joint'")
        self.seed = int(seed)
        self.chain = build_chain(rig=rig, curve_angle_deg=curve_angle_deg, radius_mm=radius_mm,
                                 params=self.params, effects=self.effects)
        c = self.chain
        sv = np.zeros_like(c.tens0)
        s0 = ph._fill(c.tens0, sv, c.coef, c.p[ph.P_TREF], c.p[ph.P_TC], c.p[ph.P_TS])
        # The input end sits at 0: the follower starts where the rest profile leaves it.
        self.u_out0 = -float(s0)
        self.sv0 = sv
        # Stops relative to the start; a bending section cannot bend past straight (its rest).
        c.p[ph.P_STOP] += self.u_out0
        c.p[ph.P_STOP_LO] = self.u_out0 if rig == "bending-joint" else (
            c.p[ph.P_STOP_LO] + self.u_out0)
        dt_ratio = self.params.control_dt_s / self.params.physics_dt_s
        self.n_sub = int(round(dt_ratio))
        if self.n_sub < 1 or abs(self.n_sub - dt_ratio) > 1e-9:
            raise ValueError("control_dt_s must be a whole multiple of physics_dt_s")
        self.reset()

    def reset(self) -> None:
        c = self.chain
        self.streams = _Streams(self.seed)
        self.texture = _texture(self.params, self.streams.texture)
        self.vibration = _Vibration(self.params, self.streams.vibration)
        self.tens = c.tens0.copy()
        self.sv = self.sv0.copy()
        self.work = np.zeros_like(self.tens)
        self.wsv = np.zeros_like(self.tens)
        self.state = np.array([0.0, 0.0, 0.0, self.u_out0, 0.0, 0.0])
        self.ticks = 0

    def command_to_mm(self, command: FloatArray) -> FloatArray:
        if self.sensor_cfg.input_unit == "deg":
            return np.radians(command) * self.params.pulley_radius_mm
        return np.asarray(command, dtype=float)

    def run(self, commands_mm: FloatArray) -> FloatArray:
        """Advance len(commands) ticks; return rows (carriage, follower, T_in, T_out) at 1 kHz
        with the follower's vibration added."""
        cmds = np.ascontiguousarray(commands_mm, dtype=np.float64)
        rec = np.zeros((cmds.shape[0] * self.n_sub, 4))
        c = self.chain
        ph.run_ticks(cmds, self.n_sub, self.state, self.tens, self.sv, self.work, self.wsv,
                     c.theta, c.cont, c.coef, c.p, self.texture, rec)
        rec[:, 1] += self.vibration.draw(rec.shape[0])
        rec[:, 1] -= self.u_out0  # follower displacement from its start
        self.ticks += cmds.shape[0]
        return rec

    def initial_row(self) -> FloatArray:
        return np.array([0.0, 0.0, self.tens[0], self.tens[-1]])

    # --- measurement-side effects -------------------------------------------------------
    def measured_output(self, t_s: FloatArray, t_fine: FloatArray, y_fine: FloatArray
                        ) -> FloatArray:
        """Output as measured at ``t_s``: delayed by ``time_delay``, offset by ``drift``."""
        d = self.effects.delay_s()
        y = np.interp(t_s - d, t_fine, y_fine, left=y_fine[0]) if d > 0 else np.interp(
            t_s, t_fine, y_fine)
        if self.effects.drift > 0.0:
            y = y + np.array([self.effects.drift_mm(float(t)) for t in t_s])
        return y

    def output_quantity(self, y_mm: FloatArray) -> FloatArray:
        """The rig's output quantity: follower mm (bench) or tip angle deg (bending joint)."""
        if self.rig == "bending-joint":
            return tip_angle_deg(y_mm, self.params)
        return y_mm


def _truth_output(core: _Core, t: FloatArray, t_fine: FloatArray, y_fine: FloatArray
                  ) -> FloatArray:
    """True output including the drift (a physical creep), without the measurement delay."""
    y = np.interp(t, t_fine, y_fine)
    if core.effects.drift > 0.0:
        y = y + np.array([core.effects.drift_mm(float(tt)) for tt in t])
    return y


class VirtualRig:
    """Closed-loop interface: one :meth:`step` = one 10 ms control tick (1 kHz physics inside).

    >>> rig = VirtualRig(curve_angle_deg=90, radius_mm=30)
    >>> first = rig.reset(); reading = rig.step(1.0)   # command 1 mm of pull
    """

    dt_s = 0.01
    #: Most ticks one :meth:`step_many` call takes: its readings cost about 1 kB a tick, so
    #: this is about 360 MB (an hour at 100 Hz); a longer sequence goes in several calls.
    MAX_TICKS_PER_CALL = 360_000

    def __init__(self, *, rig: str = "tsm-bench", curve_angle_deg: float, radius_mm: float,
                 effects: dict[str, float] | None = None, seed: int = 0,
                 sensors: dict[str, Any] | None = None,
                 params: dict[str, Any] | None = None) -> None:
        self._core = _Core(rig=rig, curve_angle_deg=curve_angle_deg, radius_mm=radius_mm,
                           effects=effects, seed=seed, sensors=sensors, params=params)
        self.dt_s = self._core.params.control_dt_s
        self.rig = rig
        self.reset()

    @property
    def effects(self) -> dict[str, float]:
        return self._core.effects.as_dict()

    def reset(self) -> dict[str, float]:
        """Back to the rest state of t=0 (same random streams); returns the t=0 reading."""
        core = self._core
        core.reset()
        row = core.initial_row()
        self._t_fine: FloatArray = np.zeros(1)
        self._y_fine: FloatArray = np.zeros(1)
        self._cmd = 0.0
        return self._readings(np.zeros(1), row[None, :], np.zeros(1), self._t_fine,
                              self._y_fine)[0]

    def step(self, command: float) -> dict[str, float]:
        """Hold ``command`` (mm of pull, or deg of motor angle) for one tick; read the sensors."""
        return self.step_many(np.array([command], dtype=np.float64))[0]

    def step_many(self, commands: npt.ArrayLike) -> list[dict[str, float]]:
        """Hold each of ``commands`` for one tick, in order; the readings :meth:`step` would
        return one by one (the same numbers), for a command sequence known in advance: one
        physics call instead of one per tick, as an open-loop or identification run needs."""
        cmds = np.asarray(commands, dtype=np.float64).ravel()
        if cmds.size == 0:
            return []
        if cmds.size > self.MAX_TICKS_PER_CALL:
            raise ValueError(f"{cmds.size} commands in one call; step_many takes at most "
                             f"{self.MAX_TICKS_PER_CALL} (an hour of ticks): split the sequence")
        if not np.all(np.isfinite(cmds)):
            bad = cmds[~np.isfinite(cmds)][0]
            raise ValueError(f"command must be finite, got {bad!r}")
        core = self._core
        ticks0 = core.ticks
        rec = core.run(core.command_to_mm(cmds))
        dt = core.params.physics_dt_s
        k0 = ticks0 * core.n_sub
        t_fine = np.concatenate([self._t_fine, (k0 + 1 + np.arange(rec.shape[0])) * dt])
        y_fine = np.concatenate([self._y_fine, rec[:, 1]])
        # Keep only what the delay can still reach.
        keep = int(core.effects.delay_s() / dt) + 2 * core.n_sub + 2
        self._t_fine, self._y_fine = ((t_fine[-keep:], y_fine[-keep:])
                                      if t_fine.shape[0] > 4 * keep else (t_fine, y_fine))
        self._cmd = float(cmds[-1])
        t: FloatArray = (ticks0 + 1 + np.arange(cmds.size, dtype=np.float64)) * self.dt_s
        return self._readings(t, rec[core.n_sub - 1::core.n_sub], cmds, t_fine, y_fine)

    def _readings(self, t: FloatArray, rows: FloatArray, cmds: FloatArray, tf: FloatArray,
                  yf: FloatArray) -> list[dict[str, float]]:
        """The sensor readings at times ``t`` of the physics rows ``rows`` (one per tick)."""
        core = self._core
        cfg = core.sensor_cfg
        y_meas = core.measured_output(t, tf, yf)
        y_true = _truth_output(core, t, tf, yf)
        x_mm = rows[:, 0]
        q = 1.0 / cfg.counts_per_mm
        npm = cfg.newton_per_mv_per_v
        noise_n = cfg.loadcell_noise_mv_per_v * npm
        rng_n = cfg.loadcell_range_n
        # one (input, output) load-cell noise pair per tick, in tick order
        noise = core.streams.step_noise.normal(0, noise_n, size=(t.shape[0], 2))
        cols: dict[str, FloatArray] = {"t_s": t, "command": cmds}
        if cfg.input_unit == "deg":
            qd = 1.0 / cfg.counts_per_deg
            cols["input"] = np.round(np.degrees(x_mm / core.params.pulley_radius_mm) / qd) * qd
        else:
            cols["input"] = np.round(x_mm / q) * q
        if self.rig == "bending-joint":
            ang_meas = np.asarray(core.output_quantity(y_meas), dtype=np.float64)
            cols["output"] = ang_meas
            cols["tip_angle_deg"] = ang_meas
        else:
            cols["output"] = np.round(y_meas / q) * q
        cols["tension_in_n"] = np.clip(rows[:, 2] + noise[:, 0], -rng_n, rng_n)
        cols["tension_out_n"] = np.clip(rows[:, 3] + noise[:, 1], -rng_n, rng_n)
        cols["true_input_mm"] = x_mm
        cols["true_output_mm"] = y_true
        cols["true_tension_in_n"] = rows[:, 2]
        cols["true_tension_out_n"] = rows[:, 3]
        if self.rig == "bending-joint":
            cols["true_tip_angle_deg"] = np.asarray(core.output_quantity(y_true),
                                                    dtype=np.float64)
        keys = list(cols)
        return [dict(zip(keys, vals, strict=True))
                for vals in zip(*(cols[k].tolist() for k in keys), strict=True)]


def _run_id(curve: float, radius: float, kind: str, index: int) -> str:
    return f"phi{int(round(curve)):03d}_r{int(round(radius)):03d}_{kind}_{index:04d}"


def _encoder_stream(core: _Core, rig: str, n: int, t_enc: FloatArray, x_true: FloatArray,
                    y_meas: FloatArray) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The encoder stream (100 Hz counters) and the manifest's channel blocks started with it.

    Draws from the sensor stream in the order the rig's loggers always have (input counter
    start, then output), so a seed gives the same run."""
    cfg = core.sensor_cfg
    rng = core.streams.sensors
    if cfg.input_unit == "deg":
        unit, cpu = "deg", cfg.counts_per_deg
        x_unit = np.degrees(x_true / core.params.pulley_radius_mm)
    else:
        unit, cpu = "mm", cfg.counts_per_mm
        x_unit = x_true
    travel = int(np.ptp(x_unit) * cpu) + 1
    in_counts = sn.encoder_counts(x_unit, sn.counter_start(cfg, rng, travel), cpu, 1)
    out_start = sn.counter_start(cfg, rng, int(np.ptp(y_meas) * cfg.counts_per_mm) + 1)
    t_ns = np.rint(t_enc * 1e9).astype(np.int64)
    if rig == "bending-joint":
        out_counts = pd.array([pd.NA] * n, dtype="Int64")
    else:
        out_counts = pd.array(sn.encoder_counts(y_meas, out_start, cfg.counts_per_mm,
                                                cfg.output_sign), dtype="Int64")
    encoder = pd.DataFrame({"t_ns": t_ns, "input_counts": in_counts,
                            "output_counts": out_counts})

    channels: dict[str, Any] = {
        "encoder": {"unit": unit, "counts_per_unit": _number(cpu), "counter_bits": 32,
                    "input_sign": 1, "output_sign": cfg.output_sign},
    }
    return encoder, channels


def _loadcell_stream(core: _Core, fine: np.ndarray, t_fine: FloatArray,
                     channels: dict[str, Any]) -> pd.DataFrame | None:
    """The load-cell stream (1 kHz raw mV/V of both cells), its calibration added to
    ``channels``; None on a rig without load cells."""
    cfg = core.sensor_cfg
    rng = core.streams.sensors
    loadcell = None
    if cfg.loadcell:
        step = int(round(1.0 / (cfg.loadcell_rate_hz * core.params.physics_dt_s)))
        idx = np.arange(0, fine.shape[0], max(step, 1))
        zeros = np.round(rng.normal(0.0, cfg.loadcell_zero_sd_mv_per_v, 2), 4)
        loadcell = pd.DataFrame({
            "t_ns": np.rint(t_fine[idx] * 1e9).astype(np.int64),
            "input_mv_per_v": sn.loadcell_raw(fine[idx, 2], float(zeros[0]), cfg, rng),
            "output_mv_per_v": sn.loadcell_raw(fine[idx, 3], float(zeros[1]), cfg, rng),
        })
        channels["loadcell"] = {
            side: {"newton_per_mv_per_v": cfg.newton_per_mv_per_v,
                   "zero_mv_per_v": float(z), "range_n": cfg.loadcell_range_n}
            for side, z in zip(("input", "output"), zeros, strict=True)}
    return loadcell


def simulate_run(*, rig: str = "tsm-bench", curve_angle_deg: float, radius_mm: float,
                 excitation: dict[str, Any], effects: dict[str, float] | None = None,
                 seed: int = 0, run_id: str | None = None, sensors: dict[str, Any] | None = None,
                 params: dict[str, Any] | None = None, started_at: str | None = None) -> RawRun:
    """Run one excitation on one configuration; return the raw run the rig's loggers write.

    ``excitation`` is the manifest's excitation block (``kind`` + parameters). Ground truth
    (``truth`` DataFrame, effects, parameters, true camera latency) is in ``RawRun.extras``.
    """
    if not isinstance(excitation, dict) or "kind" not in excitation:
        raise ValueError("excitation must be a dict with a 'kind' key")
    kind = str(excitation["kind"])
    exc_params = {k: v for k, v in excitation.items() if k != "kind"}
    core = _Core(rig=rig, curve_angle_deg=curve_angle_deg, radius_mm=radius_mm,
                 effects=effects, seed=seed, sensors=sensors, params=params)
    cfg = core.sensor_cfg
    dt_ctrl = core.params.control_dt_s
    t_cmd, command = make_excitation(kind, dt_s=dt_ctrl, **exc_params)
    n = t_cmd.shape[0]
    # Sample k of the encoder is the state at t_k, before set-point k is applied.
    first = core.initial_row()
    rec = core.run(core.command_to_mm(command[:-1]))
    fine = np.vstack([first, rec])
    t_fine: FloatArray = np.asarray(np.arange(fine.shape[0]) * core.params.physics_dt_s,
                                    dtype=np.float64)
    enc_idx = np.arange(n) * core.n_sub
    t_enc = t_cmd
    x_true = fine[enc_idx, 0]
    y_true = _truth_output(core, t_enc, t_fine, fine[:, 1])
    y_meas = core.measured_output(t_enc, t_fine, fine[:, 1])
    rng = core.streams.sensors

    encoder, channels = _encoder_stream(core, rig, n, t_enc, x_true, y_meas)
    loadcell = _loadcell_stream(core, fine, t_fine, channels)
    # --- camera / tracker ----------------------------------------------------------------
    t_end = float(t_enc[-1])
    bending = rig == "bending-joint"
    quantity = "tip_angle_deg" if bending else "output_mm"

    def true_quantity(tc: FloatArray) -> FloatArray:
        return np.asarray(core.output_quantity(_truth_output(core, tc, t_fine, fine[:, 1])))

    def seen_quantity(tc: FloatArray) -> FloatArray:
        # The vision system sees the same (possibly late, drifting) output as the encoder.
        return np.asarray(core.output_quantity(core.measured_output(tc, t_fine, fine[:, 1])))

    camera = None
    latency = max(0.0, (cfg.camera_latency_ms + rng.normal(0.0, cfg.camera_latency_sd_ms))
                  / 1000.0)
    if cfg.camera:
        camera = sn.vision_frames(
            t_end, seen_quantity, rate_hz=cfg.camera_rate_hz, latency_s=latency,
            jitter_s=cfg.camera_jitter_ms / 1000.0, drop_rate=cfg.camera_drop_rate,
            unconfident_rate=cfg.camera_unconfident_rate,
            noise=cfg.camera_noise_deg if bending else cfg.camera_noise_mm, rng=rng)
        channels["camera"] = {"quantity": quantity, "source": "camera",
                              "nominal_latency_ms": _number(cfg.camera_latency_ms),
                              "rate_hz": _number(cfg.camera_rate_hz)}
    tracker = None
    if cfg.tracker or (cfg.tracker is None and bending):
        tracker = sn.vision_frames(
            t_end, seen_quantity, rate_hz=cfg.tracker_rate_hz,
            latency_s=cfg.tracker_latency_ms / 1000.0, jitter_s=0.0005, drop_rate=0.0,
            unconfident_rate=0.0,
            noise=cfg.tracker_noise_deg if bending else cfg.tracker_noise_mm, rng=rng,
            confident=True)
        channels["tracker"] = {"quantity": quantity, "source": "tracker",
                               "nominal_latency_ms": _number(cfg.tracker_latency_ms),
                               "rate_hz": _number(cfg.tracker_rate_hz)}
    events = pd.DataFrame({"t_ns": np.array([0, int(encoder["t_ns"].iloc[-1])],
                                            dtype=np.int64),
                           "event": ["start", "stop"], "detail": ["", ""]})

    rid = run_id if run_id is not None else _run_id(curve_angle_deg, radius_mm, kind, seed)
    if started_at is None:
        # A plausible, reproducible start time (seeds can be large: keep within a year).
        minutes = 5 * (int(seed) % 100_000)
        started_at = (_EPOCH + timedelta(minutes=minutes)).strftime("%Y-%m-%dT%H:%M:%SZ")
    active = core.effects.active()
    manifest: dict[str, Any] = {
        "format": FORMAT,
        "run_id": rid,
        "rig": rig,
        "started_at": started_at,
        "configuration": {"curve_angle_deg": _number(curve_angle_deg),
                          "radius_mm": _number(radius_mm)},
        "excitation": manifest_excitation(kind, exc_params),
        "channels": channels,
        "notes": (f"virtual rig, seed {int(seed)}"
                  + (f", effects: {', '.join(active)}" if active else "")),
    }
    truth = pd.DataFrame({"t_s": t_enc, "command": command, "input_mm": x_true,
                          "output_mm": y_true, "tension_in_n": fine[enc_idx, 2],
                          "tension_out_n": fine[enc_idx, 3]})
    if bending:
        truth["tip_angle_deg"] = tip_angle_deg(y_true, core.params)
    extras = {"truth": truth, "effects": core.effects.as_dict(), "seed": int(seed),
              "params": core.params.to_dict(), "camera_latency_s": latency,
              "truth_fine": pd.DataFrame({"t_s": t_fine, "input_mm": fine[:, 0],
                                          "output_mm": fine[:, 1],
                                          "tension_in_n": fine[:, 2],
                                          "tension_out_n": fine[:, 3]})}
    return RawRun(manifest=manifest, encoder=encoder, loadcell=loadcell, camera=camera,
                  tracker=tracker, events=events, extras=extras)
