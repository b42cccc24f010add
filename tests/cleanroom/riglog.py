"""Clean-room writer of raw rig runs in the ``tsm-rig-log/1`` format.

Written from ``../shared/rig-log-format.md`` (the specification) and the seed papers only,
to produce test inputs for an independent ingest/analysis implementation.

What it writes (one *run folder* per run, spec section 1)::

    <dest_dir>/<run_id>/
        manifest.json      format, run_id, rig, started_at, configuration, excitation, channels, notes
        encoder.csv        t_ns,input_counts,output_counts         (10 ms real-time loop)
        loadcell.csv       t_ns,input_mv_per_v,output_mv_per_v     (1 kHz, optional)
        tracker.csv        t_ns,frame,value,confidence             (optional)
        events.csv         t_ns,event,detail                       (optional)

All timestamps are integer nanoseconds on one clock.  Encoder counts are signed
``counter_bits``-bit two's-complement integers that wrap around for real; the reader recovers
position = sign * unwrapped(counts) / counts_per_unit relative to the first sample.
Load-cell readings are raw bridge outputs in mV/V, obtained from tension F (N) by inverting the
manifest calibration ``F = (raw - zero_mv_per_v) * newton_per_mv_per_v``.

Faults are never announced in the run folder (a real rig would not announce them); when
``truth_dir`` is given, a ground-truth JSON per run is written *outside* the source folder.

Only numpy, pandas and the standard library are used.
"""

from __future__ import annotations

import datetime as _dt
import gzip
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

__all__ = [
    "FORMAT",
    "ENCODER_DT_S",
    "LOADCELL_RATE_HZ",
    "STANDARD_CURVE_ANGLES_DEG",
    "STANDARD_RADII_MM",
    "KNOWN_FAULTS",
    "Excitation",
    "simple_tsm_plant",
    "make_excitation",
    "excitation",
    "default_loadcell_calibration",
    "counts_from_position",
    "wrap_counts",
    "unwrap_counts",
    "tension_to_mv_per_v",
    "mv_per_v_to_tension",
    "tip_angle_from_output",
    "write_run_folder",
    "write_clean_source",
    "write_mixed_source",
    "run_id_for",
]

FORMAT = "tsm-rig-log/1"
ENCODER_DT_S = 0.01  # seed 001: 10 ms real-time loop
LOADCELL_RATE_HZ = 1000.0  # spec: loadcell nominally 1 kHz
STANDARD_CURVE_ANGLES_DEG = (15, 30, 45, 60, 75, 90)
STANDARD_RADII_MM = (30, 45, 60, 75)
KNOWN_FAULTS = (
    "stuck_output",
    "stuck_output_quantised",
    "stuck_input",
    "ragged_loadcell_end",
    "loadcell_gap",
    "estop",
)
_NS_PER_S = 1_000_000_000


# ---------------------------------------------------------------------------------------------
# Plant
# ---------------------------------------------------------------------------------------------


def simple_tsm_plant(
    u: Sequence[float] | np.ndarray,
    *,
    clearance: float = 0.4,
    stretch: float = 0.02,
    pretension_n: float = 5.0,
    mu: float = 0.2,
    wrap_angle_deg: float = 90.0,
    spring_rate_n_per_mm: float = 0.05,
    z0: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small lumped tendon-sheath plant from textbook physics.

    Inputs: ``u`` proximal tendon displacement (mm, positive = pull), sampled on any clock.
    F0 = ``pretension_n`` (the follower's constant-force spring), theta = radians(wrap_angle_deg)
    (total angle the sheath turns through), k_s = ``spring_rate_n_per_mm``, c = ``stretch``
    (tendon compliance, mm/N).

    1. Capstan (Euler-Eytelwein) friction: while the tendon slides, the input tension is
       T_out e^{+mu theta} when pulling and T_out e^{-mu theta} when releasing, so a reversal
       changes the input tension by dT = F0 (e^{mu theta} - e^{-mu theta}).

    2. Lost motion (backlash / dead band) of total width ``clearance`` + c dT: the friction
       clearance plus the elastic tendon stretch under the tension swing dT (stretch
       proportional to tension).  With half-width r = (clearance + c dT) / 2, the play operator::

           z[k] = min(u[k] + r, max(u[k] - r, z[k-1])),   z[-1] = z0 (default u[0], relaxed)

    3. Friction state in the dead band, s in [-1, 1] (-1 fully released, +1 fully pulled)::

           s[k] = (u[k] - z[k]) / r          (s = 0 if r == 0)

    4. Output tension from the constant-force spring (with a small residual rate)::

           T_out[k] = F0 + k_s (z[k] - z[-1])

    5. Input tension rises with the pull across the dead band (capstan law at state s)::

           T_in[k] = T_out[k] exp(mu theta s[k])

    6. Output displacement: the slid tendon less its extra stretch under the spring's extra
       tension (so the output never moves backwards while the input is pulled)::

           y[k] = z[k] - c (T_out[k] - F0)

    Returns ``(y, tension_in_n, tension_out_n)``: follower displacement (mm, same direction as
    ``u``) and the two tendon tensions (N).  The input-output loop is about
    ``clearance + stretch * dT`` wide (0.464 mm with the defaults).
    """
    u_arr = np.asarray(u, dtype=float)
    if u_arr.ndim != 1 or u_arr.size == 0:
        raise ValueError("u must be a non-empty 1-D sequence")
    if clearance < 0 or stretch < 0 or pretension_n <= 0:
        raise ValueError("clearance and stretch must be >= 0 and pretension_n > 0")
    theta = math.radians(wrap_angle_deg)
    d_tension = pretension_n * (math.exp(mu * theta) - math.exp(-mu * theta))
    r = (clearance + stretch * d_tension) / 2.0
    z = np.empty_like(u_arr)
    z_prev = float(u_arr[0]) if z0 is None else float(z0)
    z_start = z_prev
    for k, uk in enumerate(u_arr):
        z_prev = min(uk + r, max(uk - r, z_prev))
        z[k] = z_prev
    s = (u_arr - z) / r if r > 0 else np.zeros_like(u_arr)
    t_out = pretension_n + spring_rate_n_per_mm * (z - z_start)
    t_in = t_out * np.exp(mu * theta * s)
    y = z - stretch * (t_out - pretension_n)
    return y, t_in, t_out


def tip_angle_from_output(y_mm: np.ndarray, *, joint_radius_mm: float = 6.0) -> np.ndarray:
    """Tip angle (deg) of a constant-curvature bending section driven by a tendon at distance
    ``joint_radius_mm`` from its neutral axis: theta = delta_L / R (rad)."""
    return np.degrees(np.asarray(y_mm, dtype=float) / joint_radius_mm)


# ---------------------------------------------------------------------------------------------
# Excitations
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Excitation:
    """A sampled excitation and the ``manifest["excitation"]`` block that describes it."""

    t_s: np.ndarray
    u: np.ndarray
    manifest: dict[str, Any] = field(default_factory=dict)


def _time_axis(duration_s: float, dt: float) -> np.ndarray:
    n = int(round(duration_s / dt)) + 1
    return np.arange(n, dtype=float) * dt


def _scaled_periods(periods_per_amplitude: int | None, duration_scale: float) -> int:
    p = 5 if periods_per_amplitude is None else int(periods_per_amplitude)
    if periods_per_amplitude is None and duration_scale != 1.0:
        p = max(1, int(round(5 * duration_scale)))
    if p < 1:
        raise ValueError("periods_per_amplitude must be >= 1")
    return p


def _piecewise_decay(
    amplitudes: Sequence[float], periods: int, slope: float, dwell: float, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Triangle (dwell = 0) or trapezoid with decaying amplitude, starting at 0 going up."""
    if slope <= 0:
        raise ValueError("slope must be > 0")
    bt: list[float] = [0.0]
    bu: list[float] = [0.0]
    for a in amplitudes:
        a = float(a)
        for _ in range(periods):
            for du, hold in ((a, dwell), (-2 * a, dwell), (a, 0.0)):
                bt.append(bt[-1] + abs(du) / slope)
                bu.append(bu[-1] + du)
                if hold > 0:
                    bt.append(bt[-1] + hold)
                    bu.append(bu[-1])
    t = _time_axis(bt[-1], dt)
    return t, np.interp(t, bt, bu)


def make_excitation(
    kind: str,
    dt: float = ENCODER_DT_S,
    *,
    amplitudes_mm: Sequence[float] = (6.0, 4.5, 3.0, 1.5),
    periods_per_amplitude: int | None = None,
    duration_scale: float = 1.0,
    frequency_hz: float | None = None,
    slope_mm_s: float = 6.0,
    dwell_s: float = 1.0,
    amplitude: float = 3.0,
    offset: float = 0.0,
    duration_s: float | None = None,
    velocity_mm_s: float = 0.125,
    stroke_mm: float = 2.0,
    terms: Sequence[Mapping[str, float]] | None = None,
) -> Excitation:
    """Build an excitation of ``kind`` sampled every ``dt`` seconds from t = 0 (inclusive of
    the end point) and the matching manifest ``excitation`` block.

    * ``sine_decay``: u = A_i sin(2 pi f t), A_i in ``amplitudes_mm`` (6, 4.5, 3, 1.5),
      ``periods_per_amplitude`` periods each (5), f = 0.25 Hz -> 80 s (seed 001).
    * ``sine_decay_offset``: as ``sine_decay`` plus ``offset``.
    * ``triangle_decay``: triangle 0 -> A -> -A -> 0 at ``slope_mm_s`` (6 mm/s).
    * ``trapezoid_decay``: as triangle with a ``dwell_s`` hold at each extreme.
    * ``sine``: u = offset + amplitude sin(2 pi f t) (encoder unit); ``duration_s`` default 2
      periods; f default 0.1592 Hz (seed 002).
    * ``ramp``: u = velocity * t up to ``stroke_mm``.
    * ``mixed_sine``: u = sum a sin(2 pi f t + phase); default terms are seed 001 eq. 4.11.

    ``duration_scale`` shortens decaying kinds by scaling the default 5 periods per amplitude
    (rounded, at least 1; 0.2 -> 1 period: sine_decay 16 s, triangle_decay 10 s), keeping the
    physical frequency/slope; it scales ``duration_s`` for ``sine``/``mixed_sine``.
    """
    amps = [float(a) for a in amplitudes_mm]
    if kind in ("sine_decay", "sine_decay_offset"):
        f = 0.25 if frequency_hz is None else float(frequency_hz)
        p = _scaled_periods(periods_per_amplitude, duration_scale)
        seg = p / f
        t = _time_axis(seg * len(amps), dt)
        idx = np.minimum((t / seg + 1e-9).astype(int), len(amps) - 1)
        u = np.asarray(amps)[idx] * np.sin(2 * np.pi * f * t)
        man: dict[str, Any] = {
            "kind": kind,
            "amplitudes_mm": amps,
            "periods_per_amplitude": p,
            "frequency_hz": f,
        }
        if kind == "sine_decay_offset":
            u = u + offset
            man["offset"] = float(offset)
        return Excitation(t, u, man)
    if kind in ("triangle_decay", "trapezoid_decay"):
        p = _scaled_periods(periods_per_amplitude, duration_scale)
        dw = float(dwell_s) if kind == "trapezoid_decay" else 0.0
        t, u = _piecewise_decay(amps, p, float(slope_mm_s), dw, dt)
        man = {
            "kind": kind,
            "amplitudes_mm": amps,
            "periods_per_amplitude": p,
            "slope_mm_s": float(slope_mm_s),
        }
        if kind == "trapezoid_decay":
            man["dwell_s"] = dw
        return Excitation(t, u, man)
    if kind == "sine":
        f = 0.1592 if frequency_hz is None else float(frequency_hz)
        dur = (2.0 / f if duration_s is None else float(duration_s)) * duration_scale
        t = _time_axis(dur, dt)
        u = offset + amplitude * np.sin(2 * np.pi * f * t)
        return Excitation(
            t,
            u,
            {"kind": "sine", "amplitude": float(amplitude), "offset": float(offset), "frequency_hz": f},
        )
    if kind == "ramp":
        if velocity_mm_s <= 0 or stroke_mm <= 0:
            raise ValueError("velocity_mm_s and stroke_mm must be > 0")
        t = _time_axis(stroke_mm / velocity_mm_s, dt)
        u = np.minimum(velocity_mm_s * t, stroke_mm)
        return Excitation(t, u, {"kind": "ramp", "velocity_mm_s": float(velocity_mm_s), "stroke_mm": float(stroke_mm)})
    if kind == "mixed_sine":
        if terms is None:  # seed 001 eq. 4.11 (the -4 term written as +4 with phase pi)
            terms = [
                {"amplitude": 7.0, "frequency_hz": 0.125, "phase_rad": 0.0},
                {"amplitude": 2.0, "frequency_hz": 0.1375, "phase_rad": 0.0},
                {"amplitude": 4.0, "frequency_hz": 0.025, "phase_rad": math.pi},
                {"amplitude": 1.0, "frequency_hz": 0.05625, "phase_rad": 0.0},
            ]
        tl = [{k: float(v) for k, v in term.items()} for term in terms]
        dur = (80.0 if duration_s is None else float(duration_s)) * duration_scale
        t = _time_axis(dur, dt)
        u = np.zeros_like(t)
        for term in tl:
            u += term["amplitude"] * np.sin(2 * np.pi * term["frequency_hz"] * t + term.get("phase_rad", 0.0))
        return Excitation(t, u, {"kind": "mixed_sine", "terms": tl})
    raise ValueError(f"unknown excitation kind {kind!r}")


def excitation(kind: str, dt: float = ENCODER_DT_S, **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(t_s, u)`` of an excitation; see :func:`make_excitation` for kinds and keywords."""
    ex = make_excitation(kind, dt, **kwargs)
    return ex.t_s, ex.u


# ---------------------------------------------------------------------------------------------
# Channel conversions
# ---------------------------------------------------------------------------------------------


def default_loadcell_calibration() -> dict[str, dict[str, float]]:
    """The manifest ``channels.loadcell`` block of the spec's example."""
    return {
        "input": {"newton_per_mv_per_v": 9.81, "zero_mv_per_v": 0.012, "range_n": 20.0},
        "output": {"newton_per_mv_per_v": 9.81, "zero_mv_per_v": -0.004, "range_n": 20.0},
    }


def tension_to_mv_per_v(force_n: np.ndarray, cal: Mapping[str, float]) -> np.ndarray:
    """Inverse of the spec: raw = F / newton_per_mv_per_v + zero_mv_per_v."""
    return np.asarray(force_n, dtype=float) / float(cal["newton_per_mv_per_v"]) + float(cal["zero_mv_per_v"])


def mv_per_v_to_tension(raw: np.ndarray, cal: Mapping[str, float]) -> np.ndarray:
    """Spec: F = (raw - zero_mv_per_v) * newton_per_mv_per_v."""
    return (np.asarray(raw, dtype=float) - float(cal["zero_mv_per_v"])) * float(cal["newton_per_mv_per_v"])


def wrap_counts(counts: np.ndarray, counter_bits: int) -> np.ndarray:
    """Fold unbounded integer counts into a signed two's-complement ``counter_bits`` counter."""
    half = 1 << (counter_bits - 1)
    full = 1 << counter_bits
    c = np.asarray(counts, dtype=np.int64)
    return ((c + half) % full) - half


def unwrap_counts(raw: np.ndarray, counter_bits: int) -> np.ndarray:
    """Reader-side unwrapping (for checks): steps folded into [-2^(b-1), 2^(b-1))."""
    r = np.asarray(raw, dtype=np.int64)
    d = np.diff(r)
    d = wrap_counts(d, counter_bits)
    return np.concatenate([[r[0]], r[0] + np.cumsum(d)])


def counts_from_position(
    pos: np.ndarray, *, counts_per_unit: float, sign: int, counter_bits: int, counter_start: int = 0
) -> np.ndarray:
    """Raw counter values such that sign * unwrapped(counts) / counts_per_unit = pos - pos[0].

    ``counter_start`` is the (unbounded) counter value at the first sample; it is folded into
    the counter range like every other value.
    """
    p = np.asarray(pos, dtype=float)
    if sign not in (1, -1):
        raise ValueError("sign must be +1 or -1")
    rel = np.rint(sign * (p - p[0]) * counts_per_unit).astype(np.int64)
    return wrap_counts(rel + int(counter_start), counter_bits)


def _seconds_to_ns(t_s: np.ndarray, t0_ns: int = 0) -> np.ndarray:
    ns: np.ndarray = np.rint(np.asarray(t_s, dtype=float) * _NS_PER_S).astype(np.int64) + int(t0_ns)
    return ns


# ---------------------------------------------------------------------------------------------
# CSV writing
# ---------------------------------------------------------------------------------------------


def _fmt(values: np.ndarray, spec: str) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    out = np.char.mod(spec, v).astype(object)
    out[np.isnan(v)] = ""
    return out


def _write_csv(path: Path, columns: Mapping[str, np.ndarray | list[str]], gz: bool) -> Path:
    """Comma separated, one header line, '.' decimal point, UTF-8, no index, '\\n' endings."""
    frame = pd.DataFrame({k: pd.Series(v, dtype=object) for k, v in columns.items()})
    text = frame.to_csv(index=False, lineterminator="\n")
    if gz:
        path = path.with_name(path.name + ".gz")
        with gzip.open(path, "wt", encoding="utf-8", newline="") as fh:
            fh.write(text)
    else:
        path.write_text(text, encoding="utf-8", newline="")
    return path


def _int_col(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.int64).astype(str).astype(object)


# ---------------------------------------------------------------------------------------------
# Run folder
# ---------------------------------------------------------------------------------------------


def _parse_faults(faults: Iterable[str]) -> dict[str, float | None]:
    """``"name"`` or ``"name:value"`` (value = periods for the load-cell faults, seconds for estop)."""
    out: dict[str, float | None] = {}
    for f in faults:
        name, _, val = str(f).partition(":")
        name = name.strip()
        if name not in KNOWN_FAULTS:
            raise ValueError(f"unknown fault {f!r}; known: {KNOWN_FAULTS} (use output_delay_s= for delays)")
        out[name] = float(val) if val else None
    return out


def run_id_for(configuration: Mapping[str, Any] | None, kind: str, index: int, rig: str = "tsm-bench") -> str:
    """``phi090_r030_sine_decay_0001`` style id; ``bj_`` prefix for bending-joint, ``phiNA``/``rNA`` if unknown."""
    cfg = configuration or {}
    a, r = cfg.get("curve_angle_deg"), cfg.get("radius_mm")
    pa = f"phi{int(round(a)):03d}" if a is not None else "phiNA"
    pr = f"r{int(round(r)):03d}" if r is not None else "rNA"
    prefix = {"tsm-bench": "", "bending-joint": "bj_"}.get(rig, re.sub(r"[^a-z0-9]+", "", rig.lower()) + "_")
    return f"{prefix}{pa}_{pr}_{kind}_{index:04d}"


def _delay(t: np.ndarray, x: np.ndarray, d: float) -> np.ndarray:
    """Pure transport delay: x_d(t) = x(t - d), holding the first value before t0 + d."""
    if d == 0:
        return np.asarray(x, dtype=float).copy()
    return np.asarray(np.interp(t - d, t, x, left=float(x[0]), right=float(x[-1])), dtype=float)


def write_run_folder(
    dest_dir: str | Path,
    run_id: str,
    t_s: Sequence[float] | np.ndarray,
    u: Sequence[float] | np.ndarray,
    y: Sequence[float] | np.ndarray | None,
    *,
    rig: str = "tsm-bench",
    unit: str = "mm",
    configuration: Mapping[str, Any] | None = None,
    excitation: Mapping[str, Any] | None = None,
    counts_per_unit: float = 10000,
    counter_bits: int = 32,
    input_sign: int = 1,
    output_sign: int = -1,
    counter_start_input: int = 0,
    counter_start_output: int = 0,
    loadcell: tuple[np.ndarray, ...] | None = None,
    loadcell_rate_hz: float | None = LOADCELL_RATE_HZ,
    loadcell_calibration: Mapping[str, Mapping[str, float]] | None = None,
    loadcell_noise_n: float = 0.0,
    tracker: tuple[np.ndarray, np.ndarray, str, str] | None = None,
    tracker_latency_ms: float = 0.0,
    output_on: str | None = None,
    faults: Iterable[str] = (),
    output_delay_s: float = 0.0,
    events: bool = False,
    started_at: str | _dt.datetime = "2026-03-02T10:15:00Z",
    notes: str = "",
    t0_ns: int = 0,
    gzip_files: bool = False,
    seed: int = 0,
    truth_dir: str | Path | None = None,
    strict: bool = True,
) -> Path:
    """Write ``<dest_dir>/<run_id>/`` as a ``tsm-rig-log/1`` run folder and return its path.

    Parameters
    ----------
    t_s, u, y
        Encoder clock (s, from the excitation), input position and output position in ``unit``.
        ``y`` may be ``None`` when the output comes from a tracker.
    rig
        ``tsm-bench`` or ``bending-joint``.  For ``bending-joint`` the output is a tip angle in
        degrees from a tracker: ``output_counts`` is left empty and ``tracker.csv`` is written
        (``channels.tracker`` with ``quantity: tip_angle_deg``, ``source: tracker``); if
        ``tracker`` is not given, ``y`` is taken to be the tip angle (deg) on the encoder clock.
    configuration
        ``{"curve_angle_deg": 90, "radius_mm": 30}`` by default; values may be ``None`` (null).
    excitation
        The manifest ``excitation`` block (``{"kind": "free"}`` if not given).
    counter_start_input, counter_start_output
        Unbounded counter value at the first sample (choose near 2**(bits-1) to force a wrap).
    loadcell
        ``(tension_in_n, tension_out_n)`` on the encoder clock (resampled by linear
        interpolation to ``loadcell_rate_hz``, or kept on the encoder clock if that is ``None``),
        or already sampled at ``loadcell_rate_hz`` (1 kHz) from ``t_s[0]`` to ``t_s[-1]``
        (recognised by its length), or ``(t_s, tension_in_n, tension_out_n)`` on its own clock.
    tracker
        ``(t_s, values, quantity, unit)``; ``quantity`` is ``tip_angle_deg`` or ``output_mm``
        and ``unit`` must match it (``deg``/``mm``; it is not written: the spec's
        ``channels.tracker`` has no unit key).  Confidence is written as 1.
    output_on
        ``encoder`` (default for ``tsm-bench``) or ``tracker`` (default for ``bending-joint``).
        With ``tracker``, ``output_counts`` is empty.  The spec only allows an empty
        ``output_counts`` on ``bending-joint`` rigs, so ``tsm-bench`` + ``tracker`` needs
        ``strict=False``.
    faults
        Any of ``stuck_output``, ``stuck_output_quantised``, ``stuck_input``,
        ``ragged_loadcell_end[:k]`` (k encoder periods, default 3, 1..5),
        ``loadcell_gap[:k]`` (k encoder periods, default 5, 3..8), ``estop[:t_s]``.
    output_delay_s
        Pure transport delay of the output measurement (the channel named by ``output_on``).
    events
        Write ``events.csv`` with ``start``/``stop`` (forced on by the ``estop`` fault).
    truth_dir
        If given, ``<truth_dir>/<run_id>.truth.json`` records the faults exactly as written.
    """
    dest = Path(dest_dir)
    if not re.fullmatch(r"[A-Za-z0-9._-]+", run_id):
        raise ValueError(f"run_id {run_id!r} is not a safe folder name")
    if rig not in ("tsm-bench", "bending-joint") and strict:
        raise ValueError(f"rig {rig!r} is not one the spec names (use strict=False)")
    if output_on is None:
        output_on = "tracker" if rig == "bending-joint" else "encoder"
    if output_on not in ("encoder", "tracker"):
        raise ValueError("output_on must be 'encoder' or 'tracker'")
    if output_on == "tracker" and rig == "tsm-bench" and strict:
        raise ValueError("spec: output_counts may be empty only on bending-joint rigs (use strict=False)")
    if unit not in ("mm", "deg"):
        raise ValueError("unit must be 'mm' or 'deg'")
    t = np.asarray(t_s, dtype=float)
    uu = np.asarray(u, dtype=float)
    if t.ndim != 1 or t.size < 2 or uu.shape != t.shape:
        raise ValueError("t_s and u must be 1-D arrays of the same length (>= 2)")
    if np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be strictly increasing")
    yy = None if y is None else np.asarray(y, dtype=float)
    if yy is not None and yy.shape != t.shape:
        raise ValueError("y must have the same length as t_s")
    if output_on == "encoder" and yy is None:
        raise ValueError("output_on='encoder' needs y")
    if configuration is None:
        configuration = {"curve_angle_deg": 90, "radius_mm": 30}
    if excitation is None:
        excitation = {"kind": "free"}
    fl = _parse_faults(faults)
    rng = np.random.default_rng(seed)
    dt_enc = float(np.median(np.diff(t)))
    t_ns = _seconds_to_ns(t, t0_ns)
    if np.any(np.diff(t_ns) <= 0):
        raise ValueError("t_s too dense for integer nanoseconds")
    truth: dict[str, Any] = {"run_id": run_id, "rig": rig, "faults": {}, "output_delay_s": float(output_delay_s)}

    folder = dest / run_id
    folder.mkdir(parents=True, exist_ok=True)

    # ---- encoder -----------------------------------------------------------------------
    in_counts = counts_from_position(
        uu, counts_per_unit=counts_per_unit, sign=input_sign, counter_bits=counter_bits, counter_start=counter_start_input
    )
    if "stuck_input" in fl:
        in_counts = np.full_like(in_counts, in_counts[0])
        truth["faults"]["stuck_input"] = {"input_counts_value": int(in_counts[0])}
    out_counts: np.ndarray | None = None
    if output_on == "encoder":
        assert yy is not None
        y_meas = _delay(t, yy, float(output_delay_s))
        if "stuck_output_quantised" in fl:
            dy = y_meas - y_meas[0]
            peak = float(np.max(np.abs(dy))) * counts_per_unit
            scale = 0.45 / peak if peak > 0.45 else 1.0
            y_meas = y_meas[0] + dy * scale
            truth["faults"]["stuck_output_quantised"] = {
                "peak_motion_counts": float(np.max(np.abs(y_meas - y_meas[0])) * counts_per_unit),
                "peak_motion_unit": float(np.max(np.abs(y_meas - y_meas[0]))),
            }
        out_counts = counts_from_position(
            y_meas, counts_per_unit=counts_per_unit, sign=output_sign, counter_bits=counter_bits,
            counter_start=counter_start_output,
        )
        if "stuck_output" in fl:
            out_counts = np.full_like(out_counts, out_counts[0])
            truth["faults"]["stuck_output"] = {"output_counts_value": int(out_counts[0])}
    elif "stuck_output" in fl or "stuck_output_quantised" in fl:
        raise ValueError("stuck_output faults need an output encoder (output_on='encoder')")
    enc_cols: dict[str, Any] = {
        "t_ns": _int_col(t_ns),
        "input_counts": _int_col(in_counts),
        "output_counts": _int_col(out_counts) if out_counts is not None else np.array([""] * t.size, dtype=object),
    }
    encoder_path = _write_csv(folder / "encoder.csv", enc_cols, gzip_files)
    truth["encoder"] = {"file": encoder_path.name, "rows": int(t.size), "first_t_ns": int(t_ns[0]), "last_t_ns": int(t_ns[-1])}

    channels: dict[str, Any] = {
        "encoder": {
            "unit": unit,
            "counts_per_unit": counts_per_unit,
            "counter_bits": int(counter_bits),
            "input_sign": int(input_sign),
            "output_sign": int(output_sign),
        }
    }

    # ---- load cells --------------------------------------------------------------------
    if loadcell is not None:
        cal = {k: dict(v) for k, v in (loadcell_calibration or default_loadcell_calibration()).items()}
        if len(loadcell) == 2:
            f_in, f_out = (np.asarray(a, dtype=float) for a in loadcell)
            rate = LOADCELL_RATE_HZ if loadcell_rate_hz is None else float(loadcell_rate_hz)
            n_lc = int(math.floor((t[-1] - t[0]) * rate + 1e-9)) + 1
            t_rate = t[0] + np.arange(n_lc) / rate
            if f_in.shape != f_out.shape:
                raise ValueError("loadcell tensions differ in length")
            if f_in.shape == t.shape:  # on the encoder clock
                if loadcell_rate_hz is None:
                    t_lc = t.copy()
                else:
                    t_lc = t_rate
                    f_in, f_out = np.interp(t_lc, t, f_in), np.interp(t_lc, t, f_out)
            elif f_in.shape == t_rate.shape:  # already at the load-cell rate from t_s[0]
                t_lc = t_rate
            else:
                raise ValueError(
                    f"2-tuple loadcell must have {t.size} (encoder clock) or {n_lc} ({rate:g} Hz) samples"
                )
        elif len(loadcell) == 3:
            t_lc, f_in, f_out = (np.asarray(a, dtype=float) for a in loadcell)
        else:
            raise ValueError("loadcell must be (tension_in, tension_out) or (t_s, tension_in, tension_out)")
        if loadcell_noise_n > 0:
            f_in = f_in + rng.normal(0.0, loadcell_noise_n, f_in.shape)
            f_out = f_out + rng.normal(0.0, loadcell_noise_n, f_out.shape)
        keep = np.ones(t_lc.shape, dtype=bool)
        if "ragged_loadcell_end" in fl:
            k = fl["ragged_loadcell_end"] or 3.0
            cut = t[-1] - k * dt_enc
            keep &= t_lc <= cut + 1e-12
            truth["faults"]["ragged_loadcell_end"] = {"encoder_periods": k}
        if "loadcell_gap" in fl:
            k = fl["loadcell_gap"] or 5.0
            mid = 0.5 * (t[0] + t[-1])
            g0, g1 = mid, mid + k * dt_enc
            keep &= ~((t_lc > g0 + 1e-12) & (t_lc < g1 - 1e-12))
            truth["faults"]["loadcell_gap"] = {
                "encoder_periods": k,
                "missing_from_t_ns": int(_seconds_to_ns(np.array([g0]), t0_ns)[0]),
                "missing_to_t_ns": int(_seconds_to_ns(np.array([g1]), t0_ns)[0]),
            }
        t_lc, f_in, f_out = t_lc[keep], f_in[keep], f_out[keep]
        lc_ns = _seconds_to_ns(t_lc, t0_ns)
        lc_path = _write_csv(
            folder / "loadcell.csv",
            {
                "t_ns": _int_col(lc_ns),
                "input_mv_per_v": _fmt(tension_to_mv_per_v(f_in, cal["input"]), "%.6f"),
                "output_mv_per_v": _fmt(tension_to_mv_per_v(f_out, cal["output"]), "%.6f"),
            },
            gzip_files,
        )
        channels["loadcell"] = cal
        truth["loadcell"] = {"file": lc_path.name, "rows": int(lc_ns.size), "first_t_ns": int(lc_ns[0]), "last_t_ns": int(lc_ns[-1])}
    elif "ragged_loadcell_end" in fl or "loadcell_gap" in fl:
        raise ValueError("load-cell faults need a loadcell")

    # ---- tracker -----------------------------------------------------------------------
    if tracker is None and output_on == "tracker":
        if yy is None:
            raise ValueError("output_on='tracker' needs tracker=(t_s, values, quantity, unit) or y")
        q = "tip_angle_deg" if rig == "bending-joint" else "output_mm"
        tracker = (t, yy, q, "deg" if q == "tip_angle_deg" else "mm")
    if tracker is not None:
        tr_t, tr_v, quantity, tr_unit = tracker
        tr_t = np.asarray(tr_t, dtype=float)
        tr_v = np.asarray(tr_v, dtype=float)
        if quantity not in ("tip_angle_deg", "output_mm"):
            raise ValueError("tracker quantity must be tip_angle_deg or output_mm")
        if tr_unit != quantity.rsplit("_", 1)[1]:
            raise ValueError(f"tracker unit {tr_unit!r} does not match quantity {quantity!r}")
        if output_on == "tracker":
            tr_v = _delay(tr_t, tr_v, float(output_delay_s))
        tr_ns = _seconds_to_ns(tr_t, t0_ns)
        tr_path = _write_csv(
            folder / "tracker.csv",
            {
                "t_ns": _int_col(tr_ns),
                "frame": _int_col(np.arange(tr_ns.size)),
                "value": _fmt(tr_v, "%.6f"),
                "confidence": np.array(["1.0"] * tr_ns.size, dtype=object),
            },
            gzip_files,
        )
        rate = 1.0 / float(np.median(np.diff(tr_t))) if tr_t.size > 1 else 0.0
        channels["tracker"] = {
            "quantity": quantity,
            "source": "tracker",
            "nominal_latency_ms": float(tracker_latency_ms),
            "rate_hz": round(rate, 3),
        }
        truth["tracker"] = {"file": tr_path.name, "rows": int(tr_ns.size)}

    # ---- events ------------------------------------------------------------------------
    if events or "estop" in fl:
        ev_t = [int(t_ns[0])]
        ev_name = ["start"]
        ev_detail = [""]
        if "estop" in fl:
            te = fl["estop"] if fl["estop"] is not None else 0.5 * (t[0] + t[-1])
            ev_t.append(int(_seconds_to_ns(np.array([te]), t0_ns)[0]))
            ev_name.append("estop")
            ev_detail.append("operator pressed emergency stop")
            truth["faults"]["estop"] = {"t_ns": ev_t[-1]}
        ev_t.append(int(t_ns[-1]))
        ev_name.append("stop")
        ev_detail.append("")
        _write_csv(
            folder / "events.csv",
            {"t_ns": _int_col(np.array(ev_t)), "event": np.array(ev_name, dtype=object), "detail": np.array(ev_detail, dtype=object)},
            False,
        )

    # ---- manifest ----------------------------------------------------------------------
    if isinstance(started_at, _dt.datetime):
        started_at = started_at.astimezone(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    manifest = {
        "format": FORMAT,
        "run_id": run_id,
        "rig": rig,
        "started_at": started_at,
        "configuration": {k: configuration.get(k) for k in ("curve_angle_deg", "radius_mm")}
        | {k: v for k, v in configuration.items() if k not in ("curve_angle_deg", "radius_mm")},
        "excitation": dict(excitation),
        "channels": channels,
        "notes": notes,
    }
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")

    if truth_dir is not None:
        td = Path(truth_dir)
        td.mkdir(parents=True, exist_ok=True)
        (td / f"{run_id}.truth.json").write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return folder


# ---------------------------------------------------------------------------------------------
# Sources (folders of runs)
# ---------------------------------------------------------------------------------------------


def _start_time(i: int) -> _dt.datetime:
    return _dt.datetime(2026, 3, 2, 10, 15, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=5 * i)


def write_clean_source(
    dest_dir: str | Path,
    n: int = 3,
    *,
    configuration: Mapping[str, Any] | None = None,
    duration_scale: float = 0.2,
    kinds: Sequence[str] = ("sine_decay", "triangle_decay", "trapezoid_decay"),
    clearance: float | None = None,
    stretch: float = 0.02,
    loadcell_noise_n: float = 0.01,
    seed: int = 0,
    truth_dir: str | Path | None = None,
) -> list[Path]:
    """``n`` ordinary ``tsm-bench`` runs of one configuration, cycling through ``kinds``
    (sine_decay identification, triangle_decay and trapezoid_decay validation), with load cells.

    With the default ``duration_scale=0.2`` (1 period per amplitude, 0.5 s dwell) the runs
    last 16 s, 10 s and 14 s.  ``clearance`` defaults to 0.4 mm scaled by curve angle / 90 deg (more
    friction, more lost motion in a more bent sheath); the wrap angle is the curve angle.
    """
    cfg = dict(configuration or {"curve_angle_deg": 90, "radius_mm": 30})
    angle = cfg.get("curve_angle_deg")
    wrap = float(angle) if angle is not None else 90.0
    c = clearance if clearance is not None else 0.4 * max(wrap, 5.0) / 90.0
    paths = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        ex = make_excitation(kind, duration_scale=duration_scale, dwell_s=0.5)
        y, tin, tout = simple_tsm_plant(ex.u, clearance=c, stretch=stretch, wrap_angle_deg=wrap)
        rid = run_id_for(cfg, kind, i + 1)
        paths.append(
            write_run_folder(
                dest_dir, rid, ex.t_s, ex.u, y, configuration=cfg, excitation=ex.manifest,
                loadcell=(tin, tout), loadcell_noise_n=loadcell_noise_n, events=True,
                started_at=_start_time(i), seed=seed + i, truth_dir=truth_dir,
            )
        )
    return paths


def write_mixed_source(
    dest_dir: str | Path,
    *,
    n_each: int = 2,
    bending_delay_s: float = 0.0,
    duration_scale: float = 0.2,
    bending_input_unit: str = "mm",
    bending_configuration: Mapping[str, Any] | None = None,
    tracker_rate_hz: float = 40.0,
    joint_radius_mm: float = 6.0,
    seed: int = 0,
    truth_dir: str | Path | None = None,
) -> list[Path]:
    """ONE source folder holding runs from two rigs, as two labs' dumps in one folder:

    * ``n_each`` ``tsm-bench`` runs (phi 90 / r 30, alternately sine_decay and triangle_decay,
      output in mm from the follower encoder, with load cells);
    * ``n_each`` ``bending-joint`` runs (``sine`` excitation of the tendon, amplitude 2.5 and
      offset 2.5 mm, 0.1 / 0.2 Hz; output the tip angle in degrees from a ``tracker_rate_hz``
      tracker, ``output_counts`` empty, no load cells), configuration unknown (null) by
      default.  ``bending_delay_s`` delays the tracker (pure transport delay) on these runs only.

    With ``bending_input_unit='deg'`` the bending input is a motor angle (seed 002 style,
    30 sin + 30 deg at 0.1592 Hz) wound on a 5 mm pulley.
    """
    paths: list[Path] = []
    bench_cfg = {"curve_angle_deg": 90, "radius_mm": 30}
    bend_cfg = dict(bending_configuration or {"curve_angle_deg": None, "radius_mm": None})
    idx = 0
    for i in range(n_each):
        kind = ("sine_decay", "triangle_decay")[i % 2]
        ex = make_excitation(kind, duration_scale=duration_scale)
        y, tin, tout = simple_tsm_plant(ex.u, clearance=0.4)
        idx += 1
        paths.append(
            write_run_folder(
                dest_dir, run_id_for(bench_cfg, kind, idx), ex.t_s, ex.u, y, rig="tsm-bench",
                configuration=bench_cfg, excitation=ex.manifest, loadcell=(tin, tout), loadcell_noise_n=0.01,
                started_at=_start_time(idx), seed=seed + idx, truth_dir=truth_dir,
            )
        )
    for i in range(n_each):
        idx += 1
        if bending_input_unit == "deg":
            ex = make_excitation("sine", amplitude=30.0, offset=30.0, frequency_hz=0.1592, duration_s=20.0)
            tendon_mm = np.radians(ex.u) * 5.0
        elif bending_input_unit == "mm":
            ex = make_excitation("sine", amplitude=2.5, offset=2.5, frequency_hz=(0.1, 0.2)[i % 2], duration_s=20.0)
            tendon_mm = ex.u
        else:
            raise ValueError("bending_input_unit must be 'mm' or 'deg'")
        y, _, _ = simple_tsm_plant(tendon_mm, clearance=0.4, z0=float(tendon_mm[0]) - 0.2)
        tip = tip_angle_from_output(y, joint_radius_mm=joint_radius_mm)
        t_tr = np.arange(0.0, ex.t_s[-1] + 1e-9, 1.0 / tracker_rate_hz)
        tip_tr = np.interp(t_tr, ex.t_s, tip)
        paths.append(
            write_run_folder(
                dest_dir, run_id_for(bend_cfg, "sine", idx, rig="bending-joint"), ex.t_s, ex.u, None,
                rig="bending-joint", unit=bending_input_unit, configuration=bend_cfg, excitation=ex.manifest,
                output_sign=1, tracker=(t_tr, tip_tr, "tip_angle_deg", "deg"), output_on="tracker",
                output_delay_s=bending_delay_s, started_at=_start_time(idx), seed=seed + idx, truth_dir=truth_dir,
            )
        )
    return paths
