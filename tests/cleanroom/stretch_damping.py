"""Clean-room generator: a tendon-sheath plant with capstan friction, one hidden effect per source.

What it makes
-------------
Ten ``tsm-rig-log/1`` sources (one folder each, opaque names ``sd-<hex>``) of the same
``tsm-bench`` mechanism (configuration curve angle 90 deg, radius 30 mm), and a ground-truth file
``stretch_damping_truth.json`` beside them that maps each folder name to its hidden effect:

=================  ====================  ===========================================  ==========
effect             form                  what it does (noise-free, before zeroing)     sizes
=================  ====================  ===========================================  ==========
tendon_stretch     linear_input          the sheath sees u - c (T_in - T_in(0))        0.3 / 0.8 mm
tendon_stretch     quadratic_input       the sheath sees u - c (T_in^2 - T_in(0)^2)    0.3 / 0.8 mm
rate_dependence    viscous               y -= b v_in                                   0.1 / 0.3 mm
rate_dependence    nonlinear_damping     y -= b sign(v_in) |v_in / v_ref|^0.5          0.1 / 0.3 mm
none               (clean)               nothing; one source from rest, one at speed    0
=================  ====================  ===========================================  ==========

Stretch sizes are the series spring's own stretch s(T) = c T (or c T^2, from zero tension) at the
largest input tension of the identification run (c solved so that it is exact on that run, with
the effect in the loop); the formula's T_in(0) terms only zero it at the first sample, and the
truth also gives the swing s(max T_in) - s(min T_in) and the value from the first sample.
Damping sizes are the term's peak at the identification run's top speed
v_ref = 2 pi 0.25 Hz 6 mm = 9.42 mm/s (weak / strong).

Each source holds three runs of 80 s, all starting upwards from u = 0:

* ``phi090_r030_sine_decay_0001``: identification, decaying sine 6 / 4.5 / 3 / 1.5 mm, five
  periods each at 0.25 Hz (top speed 9.42 mm/s);
* ``phi090_r030_triangle_decay_0002``: held out, decaying triangle at 6 mm/s, eight periods per
  amplitude (80 s);
* ``phi090_r030_trapezoid_decay_0003``: held out, decaying trapezoid at 5 mm/s with 0.5 s dwells
  at each extreme, five periods per amplitude (80 s).

Nine sources start *at speed*: the log begins as the input passes its mid-stroke going up at
full speed, with the mechanism in the state it has when it has been cycling (it came up from
-6 mm).  One clean source starts *from rest*: the tendon is uniformly pre-tensioned (relaxed),
the input stands still for 1.0 s, then the same excitations begin (those runs last 81 s; the
manifest's ``notes`` and an ``events.csv`` ``note`` say when the motion starts).

Recording (through ``riglog.py``'s writer): encoder at 100 Hz (input and distal output, 10000
counts/mm, 32-bit, input sign +1, output sign -1 as in the spec's example, positions relative to
the first sample); load cells at 1 kHz (input tension T_in and output tension T_out, raw mV/V with
the spec's example calibration, noise sd 0.02 N); ``events.csv`` with start/stop.  Output noise:
Gaussian, sd 0.01 mm, added to the distal position after the effect and before the encoder
zeroing; the input is noise-free (quantised to 1e-4 mm).

Physics of the plant (textbook tendon-sheath mechanics)
-------------------------------------------------------
A tendon of total axial stiffness k runs through a sheath that turns through theta (the
configuration's curve angle).  It is discretised into N = 24 elastic segments (stiffness N k
each) joined at N - 1 contact nodes inside the sheath; each node carries the wrap angle
dtheta = theta / (N - 1) and Coulomb capstan (Euler-Eytelwein) friction: across node j the
tension ratio T_j / T_{j+1} stays in [exp(-mu dtheta), exp(mu dtheta)]; the node sticks inside
that band and slides (in the direction of the input's motion) at its edge.  Over the whole
sheath this is the friction-limited elastic element T_out = T_in exp(-mu theta sign(v)) while the
whole tendon slides, stick otherwise, with the stick zone and its tension profile remembered
(hysteresis).  The distal end is a mass-free follower held by a return spring,
T_out = F0 + k_r y (y = distal displacement, mm, positive = pulled); the input is the proximal
displacement u (mm) and T_in the tension of the first segment.  The motion is quasi-static:
at each sample the contact nodes 1..m slide (m found from the proximal end: sliding spreads from
the input), the rest keep their positions; the tensions along the sliding zone are the capstan
geometric series and the equilibrium is solved in closed form.  The solution is exact for a
monotone input between samples; the plant is solved at 1 kHz.

Parameters: N = 24, k = 2.0 N/mm, mu = 0.35, theta = 90 deg, F0 = pretension = 5 N,
k_r = 0.4 N/mm.  Loop: about 1.4 mm wide in the input (1.2 mm in the output) at +-6 mm, i.e.
about 12 % of the 12 mm stroke; output gain about 0.79; T_in 1.8-11.5 N, T_out 3.1-6.6 N.

Hidden effects: the tendon stretch is an extra spring in series ahead of the sheath (the
proximal tendon stretch s(T_in) = c T_in or c T_in^2); the sheath's input is x = u - s(T_in),
solved together with the plant at every sample (closed form: linear or quadratic in T_in).
The damping terms are applied to the output reading only (the load cells keep the clean plant's
tensions), so that each source's one hidden effect is the named one.  The ground truth's oracle
runs the noise-free plant with and without the effect on the held-out runs, zeroes both at the
first encoder sample as the reader does, and gives the RMS (and peak) of the difference in units
of the output noise sd.

API: ``write_all(root, seed=0) -> dict`` (the truth), ``write_source(root, effect, form,
strength, seed=0)`` (one source folder; returns ``(folder_name, truth_entry)``), and the CLI
``python tests/cleanroom/stretch_damping.py OUT_DIR [--seed N]``.  ``riglog.py`` is imported by
file path: ``CLEANROOM_RIGLOG`` names it (a file, or the folder holding it), else the copy beside
this file.

Written from: the rig-log specification (``../shared/rig-log-format.md``), the seeds' README
(``../shared/seeds/README.md``), this folder's ``README.md`` and ``riglog.py``, and textbook
physics (capstan / Euler-Eytelwein friction, a discretised tendon with Coulomb contact nodes,
series springs, viscous and power-law damping).  The project's implementation, tests and docs
were not read.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import functools
import hashlib
import importlib.util
import json
import math
import os
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

__all__ = [
    "PLANT",
    "OUTPUT_NOISE_SD_MM",
    "LOADCELL_NOISE_SD_N",
    "EFFECTS",
    "SOURCES",
    "TendonSheath",
    "simulate",
    "write_source",
    "write_all",
    "main",
]

TRUTH_FILE = "stretch_damping_truth.json"
OUTPUT_NOISE_SD_MM = 0.01
LOADCELL_NOISE_SD_N = 0.02
REST_LEAD_IN_S = 1.0
PLANT_RATE_HZ = 1000.0
ENCODER_DECIMATION = 10  # 1 kHz plant -> 100 Hz encoder
CONFIGURATION = {"curve_angle_deg": 90, "radius_mm": 30}
PREROLL_MM = 6.0  # an at-speed log starts after the input came up from -6 mm

# (effect, form) -> size for (weak, strong), in mm
EFFECTS: dict[tuple[str, str], dict[str, float]] = {
    ("tendon_stretch", "linear_input"): {"weak": 0.3, "strong": 0.8},
    ("tendon_stretch", "quadratic_input"): {"weak": 0.3, "strong": 0.8},
    ("rate_dependence", "viscous"): {"weak": 0.1, "strong": 0.3},
    ("rate_dependence", "nonlinear_damping"): {"weak": 0.1, "strong": 0.3},
}
DAMPING_EXPONENT = 0.5

# the ten sources: (effect, form, strength, starts_at_speed)
SOURCES: tuple[tuple[str, str | None, str | None, bool], ...] = (
    ("none", None, None, False),
    ("none", None, None, True),
    *((e, f, s, True) for (e, f) in EFFECTS for s in ("weak", "strong")),
)

# the three runs of a source: (kind, role, make_excitation keywords)
RUNS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("sine_decay", "identification", {"frequency_hz": 0.25, "periods_per_amplitude": 5}),
    ("triangle_decay", "held_out", {"slope_mm_s": 6.0, "periods_per_amplitude": 8}),
    ("trapezoid_decay", "held_out", {"slope_mm_s": 5.0, "dwell_s": 0.5, "periods_per_amplitude": 5}),
)
AMPLITUDES_MM = (6.0, 4.5, 3.0, 1.5)


# ---------------------------------------------------------------------------------------------
# riglog.py, by file path
# ---------------------------------------------------------------------------------------------


def _load_riglog() -> ModuleType:
    env = os.environ.get("CLEANROOM_RIGLOG")
    path = Path(env) if env else Path(__file__).resolve().with_name("riglog.py")
    if path.is_dir():
        path = path / "riglog.py"
    name = "_cleanroom_riglog_for_stretch_damping"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load riglog.py from {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses look their module up while the class is built
    spec.loader.exec_module(mod)
    return mod


riglog = _load_riglog()


# ---------------------------------------------------------------------------------------------
# Plant
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TendonSheath:
    """Discretised tendon in a sheath with capstan (Coulomb) friction at its contact nodes."""

    n_segments: int = 24
    tendon_stiffness_n_per_mm: float = 2.0  # whole tendon, k
    mu: float = 0.35
    wrap_angle_deg: float = 90.0  # theta, the configuration's curve angle
    pretension_n: float = 5.0  # F0: return spring force (and uniform tension) at rest
    return_spring_n_per_mm: float = 0.4  # k_r


PLANT = TendonSheath()


def _stretch_of(form: str | None, c: float, tension: float) -> float:
    if form is None:
        return 0.0
    if form == "linear_input":
        return c * tension
    if form == "quadratic_input":
        return c * tension * tension
    raise ValueError(f"unknown stretch form {form!r}")


def _input_tension(form: str | None, c: float, a: float, b: float, u_abs: float) -> float:
    """Solve T = a + b x with x = u_abs - s(T) (the sheath's input behind the series stretch)."""
    if form is None or c == 0.0:
        return a + b * u_abs
    if form == "linear_input":
        return (a + b * u_abs) / (1.0 + b * c)
    q = c * b  # c b T^2 + T - (a + b u) = 0, the positive root
    disc = 1.0 + 4.0 * q * (a + b * u_abs)
    if disc < 0.0:  # no tension balances it: this stick/slide split is not the solution
        return math.nan
    return 2.0 * (a + b * u_abs) / (1.0 + math.sqrt(disc))


def simulate(
    u: np.ndarray,
    *,
    plant: TendonSheath = PLANT,
    stretch_form: str | None = None,
    stretch_c: float = 0.0,
    preroll: tuple[float, ...] = (),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quasi-static response to the input travel ``u`` (mm, relative to the relaxed position).

    The plant starts relaxed (uniform tension F0, every node at 0), is driven through the
    ``preroll`` input values (each a monotone move from the last), then through ``u``.  With a
    stretch form, the sheath's input is x = u - s(T_in) + s(F0) (the relaxed state is the zero).
    Returns ``(y, T_in, T_out)``: distal displacement (mm) and the two tensions (N).
    """
    n = int(plant.n_segments)
    ks = n * plant.tendon_stiffness_n_per_mm
    t0 = plant.pretension_n
    kr = plant.return_spring_n_per_mm
    krs = kr / ks
    dth = math.radians(plant.wrap_angle_deg) / (n - 1)
    tabs = {}
    for d in (1, -1):
        r = math.exp(-d * plant.mu * dth)  # T_{j+1} = r T_j across a node sliding in direction d
        rp = r ** np.arange(n + 1, dtype=float)
        s = np.concatenate([[0.0], np.cumsum(rp)])  # s[m] = sum_{j<m} r^j
        tabs[d] = (r, rp, s, rp.tolist(), s.tolist())
    idx = np.arange(n + 1, dtype=float)
    w = np.zeros(n + 1)  # node positions: w[0] sheath input x, w[n] distal output y
    tension = np.full(n + 2, t0)  # tension[j]: segment j (between nodes j-1 and j), j = 1..n
    offset = _stretch_of(stretch_form, stretch_c, t0)
    m_cur, d_cur, u_cur = 0, 0, offset  # sliding nodes, direction and input of the last move

    def step(u_abs: float) -> None:
        nonlocal m_cur, d_cur, u_cur
        du = u_abs - u_cur
        if du == 0.0:
            return
        d = 1 if du > 0.0 else -1
        r, rp, _, rpl, sl = tabs[d]
        m = m_cur if d == d_cur else 0
        while True:
            if m < n - 1:  # nodes 1..m slide, node m+1 sticks
                den = rpl[m] + sl[m]
                a = (t0 * (1 + m) - ks * w[m + 1]) / den
                b = ks / den
                t1 = _input_tension(stretch_form, stretch_c, a, b, u_abs)
                if d * (t1 * rpl[m] * r - tension[m + 2]) <= 1e-12:
                    break
                m += 1
            else:  # the whole sheath slides: the distal spring moves
                den = rpl[n - 1] + krs * sl[n]
                a = (t0 + krs * n * t0) / den
                b = kr / den
                t1 = _input_tension(stretch_form, stretch_c, a, b, u_abs)
                if not t1 > 0.0:
                    raise ValueError(f"tendon goes slack (T_in = {t1}) at input {u_abs - offset:.3f} mm")
                break
        x = (t1 - a) / b
        w[0] = x
        last = m + 1 if m < n - 1 else n  # segments 1..last carry the capstan series
        tension[1:last + 1] = t1 * rp[:last]
        top = m if m < n - 1 else n
        if top > 0:
            w[1:top + 1] = x - (np.cumsum(tension[1:top + 1]) - t0 * idx[1:top + 1]) / ks
        m_cur, d_cur, u_cur = m, d, u_abs

    for p in preroll:
        step(float(p) + offset)
    uu = np.asarray(u, dtype=float)
    y = np.empty(uu.size)
    t_in = np.empty(uu.size)
    t_out = np.empty(uu.size)
    for i, ui in enumerate(uu.tolist()):
        step(ui + offset)
        y[i] = w[n]
        t_in[i] = tension[1]
        t_out[i] = tension[n]
    return y, t_in, t_out


# ---------------------------------------------------------------------------------------------
# Excitations and runs
# ---------------------------------------------------------------------------------------------


@functools.cache
def _excitation(kind: str, starts_at_speed: bool, rate_hz: float = PLANT_RATE_HZ) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """``(t_s, u, manifest block)`` sampled at ``rate_hz``; from rest: a lead-in hold at u = 0."""
    kw = dict(next(k for (kk, _, k) in RUNS if kk == kind))
    ex = riglog.make_excitation(kind, 1.0 / rate_hz, amplitudes_mm=AMPLITUDES_MM, **kw)
    t, u = ex.t_s, ex.u
    if not starts_at_speed:
        n_hold = int(round(REST_LEAD_IN_S * rate_hz))
        u = np.concatenate([np.zeros(n_hold), u])
        t = np.arange(u.size, dtype=float) / rate_hz
    t.setflags(write=False)
    u.setflags(write=False)
    return t, u, dict(ex.manifest)


def _preroll(starts_at_speed: bool) -> tuple[float, ...]:
    return (-PREROLL_MM,) if starts_at_speed else ()


@functools.cache
def _clean_run(kind: str, starts_at_speed: bool, rate_hz: float = PLANT_RATE_HZ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    _, u, _ = _excitation(kind, starts_at_speed, rate_hz)
    out = simulate(u, preroll=_preroll(starts_at_speed))
    for a in out:
        a.setflags(write=False)
    return out


def _speed(u: np.ndarray, rate_hz: float = PLANT_RATE_HZ) -> np.ndarray:
    return np.asarray(np.gradient(u, 1.0 / rate_hz), dtype=float)


def _top_speed_identification() -> float:
    _, u, _ = _excitation("sine_decay", True)
    return float(np.max(np.abs(_speed(u))))


def _stretch_coefficient(form: str, size_mm: float, starts_at_speed: bool) -> float:
    """c such that the series spring's stretch at the identification run's largest input tension,
    s(max T_in) = c max T_in (or c max T_in^2), is ``size_mm``, with the effect in the loop
    (fixed point on the 100 Hz identification run)."""
    rate = PLANT_RATE_HZ / ENCODER_DECIMATION
    _, u, _ = _excitation("sine_decay", starts_at_speed, rate)
    _, t_in, _ = _clean_run("sine_decay", starts_at_speed, rate)
    c = size_mm / _stretch_of(form, 1.0, float(t_in.max()))
    for _ in range(30):
        _, t_in, _ = simulate(u, stretch_form=form, stretch_c=c, preroll=_preroll(starts_at_speed))
        got = _stretch_of(form, c, float(t_in.max()))
        c_new = c * size_mm / got
        if abs(c_new - c) <= 1e-10 * c:
            return c_new
        c = c_new
    return c


@dataclass(frozen=True)
class _Effect:
    effect: str
    form: str | None
    strength: str | None
    size_mm: float
    coefficient: float  # c (mm/N or mm/N^2) or b (s, or mm for the power law)
    coefficient_unit: str
    v_ref_mm_s: float | None = None
    exponent: float | None = None


def _make_effect(effect: str, form: str | None, strength: str | None, starts_at_speed: bool) -> _Effect:
    if effect == "none":
        return _Effect("none", None, None, 0.0, 0.0, "")
    try:
        size = EFFECTS[(effect, str(form))][str(strength)]
    except KeyError:
        raise ValueError(
            f"unknown effect/form/strength {effect!r}/{form!r}/{strength!r}; known: "
            f"{sorted(EFFECTS)} x weak/strong, or effect 'none'"
        ) from None
    if effect == "tendon_stretch":
        c = _stretch_coefficient(str(form), size, starts_at_speed)
        return _Effect(effect, form, strength, size, c, "mm/N" if form == "linear_input" else "mm/N^2")
    v_top = _top_speed_identification()
    if form == "viscous":
        return _Effect(effect, form, strength, size, size / v_top, "s", v_ref_mm_s=v_top, exponent=1.0)
    return _Effect(effect, form, strength, size, size, "mm", v_ref_mm_s=v_top, exponent=DAMPING_EXPONENT)


def _run_with_effect(eff: _Effect, kind: str, starts_at_speed: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free (y, T_in, T_out) at 1 kHz with the source's effect."""
    _, u, _ = _excitation(kind, starts_at_speed)
    if eff.effect == "tendon_stretch":
        return simulate(u, stretch_form=eff.form, stretch_c=eff.coefficient, preroll=_preroll(starts_at_speed))
    y, t_in, t_out = (np.array(a) for a in _clean_run(kind, starts_at_speed))
    if eff.effect == "rate_dependence":
        v = _speed(u)
        if eff.form == "viscous":
            y = y - eff.coefficient * v
        else:
            assert eff.v_ref_mm_s is not None and eff.exponent is not None
            y = y - eff.coefficient * np.sign(v) * np.abs(v / eff.v_ref_mm_s) ** eff.exponent
    return y, t_in, t_out


def _oracle_stats(y_eff: np.ndarray, y_clean: np.ndarray) -> dict[str, float]:
    """Effect's contribution on the encoder clock, both zeroed at the first sample, in noise sd."""
    ye = y_eff[::ENCODER_DECIMATION]
    yc = y_clean[::ENCODER_DECIMATION]
    diff = (ye - ye[0]) - (yc - yc[0])
    return {
        "rms_sd": float(np.sqrt(np.mean(diff**2)) / OUTPUT_NOISE_SD_MM),
        "peak_sd": float(np.max(np.abs(diff)) / OUTPUT_NOISE_SD_MM),
        "rms_sd_demeaned": float(np.std(diff) / OUTPUT_NOISE_SD_MM),
    }


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _folder_name(effect: str, form: str | None, strength: str | None, starts_at_speed: bool, seed: int) -> str:
    key = f"stretch_damping/{effect}/{form}/{strength}/{'speed' if starts_at_speed else 'rest'}/{seed}"
    return "sd-" + hashlib.sha1(key.encode("utf-8")).hexdigest()[:10]


def _write_events(folder: Path, t_ns_end: int, motion_ns: int | None) -> None:
    rows = ["t_ns,event,detail", "0,start,"]
    if motion_ns is not None:
        rows.append(f"{motion_ns},note,motion starts")
    rows.append(f"{t_ns_end},stop,")
    (folder / "events.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


def write_source(
    root: str | Path,
    effect: str,
    form: str | None,
    strength: str | None,
    seed: int = 0,
    *,
    starts_at_speed: bool = True,
) -> tuple[str, dict[str, Any]]:
    """Write one source folder under ``root`` and return ``(folder_name, truth_entry)``; the entry
    is also merged into ``root/stretch_damping_truth.json``.

    ``effect`` is ``tendon_stretch`` (form ``linear_input`` / ``quadratic_input``),
    ``rate_dependence`` (``viscous`` / ``nonlinear_damping``) or ``none`` (form and strength
    ``None``); ``strength`` is ``weak`` or ``strong``.  Clean sources may start from rest
    (``starts_at_speed=False``).
    """
    eff = _make_effect(effect, form, strength, starts_at_speed)
    name = _folder_name(eff.effect, eff.form, eff.strength, starts_at_speed, seed)
    src = Path(root) / name
    src.mkdir(parents=True, exist_ok=True)
    src_index = int(hashlib.sha1(name.encode("utf-8")).hexdigest()[:8], 16)
    runs: list[dict[str, Any]] = []
    held_sq: list[np.ndarray] = []
    for i, (kind, role, _) in enumerate(RUNS):
        t1k, u1k, man = _excitation(kind, starts_at_speed)
        y1k, tin1k, tout1k = _run_with_effect(eff, kind, starts_at_speed)
        yc1k = _clean_run(kind, starts_at_speed)[0]
        rng = np.random.default_rng([int(seed), src_index, i])
        t = t1k[::ENCODER_DECIMATION]
        u = u1k[::ENCODER_DECIMATION]
        y = y1k[::ENCODER_DECIMATION] + rng.normal(0.0, OUTPUT_NOISE_SD_MM, t.size)
        run_id = riglog.run_id_for(CONFIGURATION, kind, i + 1)
        notes = "" if starts_at_speed else f"input at rest for {REST_LEAD_IN_S:g} s before the excitation starts"
        started = _dt.datetime(2026, 3, 2, 10, 15, tzinfo=_dt.timezone.utc) + _dt.timedelta(minutes=5 * i)
        folder = riglog.write_run_folder(
            src, run_id, t, u, y, configuration=CONFIGURATION, excitation=man,
            loadcell=(tin1k, tout1k), loadcell_noise_n=LOADCELL_NOISE_SD_N, events=True,
            started_at=started, notes=notes, seed=int(rng.integers(2**31)),
        )
        _write_events(folder, int(round(t[-1] * 1e9)), None if starts_at_speed else int(round(REST_LEAD_IN_S * 1e9)))
        v = _speed(u1k)
        ora = _oracle_stats(y1k, yc1k)
        info: dict[str, Any] = {
            "run_id": run_id, "kind": kind, "role": role, "duration_s": float(t[-1]),
            "input_speed_at_t0_mm_s": float(v[0]), "top_speed_mm_s": float(np.max(np.abs(v))),
            "t_in_range_n": [float(tin1k.min()), float(tin1k.max())],
            "t_out_range_n": [float(tout1k.min()), float(tout1k.max())],
            "oracle": ora,
        }
        if eff.effect == "tendon_stretch":
            s_max, s_min, s_0 = (_stretch_of(eff.form, eff.coefficient, float(x)) for x in (tin1k.max(), tin1k.min(), tin1k[0]))
            info["stretch_at_largest_tension_mm"] = s_max
            info["stretch_swing_mm"] = s_max - s_min
            info["stretch_at_largest_tension_from_first_sample_mm"] = s_max - s_0
        elif eff.effect == "rate_dependence":
            info["term_peak_mm"] = float(np.max(np.abs(y1k - yc1k)))
        runs.append(info)
        if role == "held_out":
            ye, yc = y1k[::ENCODER_DECIMATION], yc1k[::ENCODER_DECIMATION]
            held_sq.append(((ye - ye[0]) - (yc - yc[0])) ** 2)
    pooled = np.concatenate(held_sq)
    held = [r for r in runs if r["role"] == "held_out"]
    truth = {
        "effect": eff.effect,
        "form": eff.form,
        "strength": eff.strength,
        "size": eff.size_mm,
        "size_unit": "mm",
        "size_meaning": {
            "tendon_stretch": "the series spring's stretch s(T) = c T (or c T^2) at the identification "
            "run's largest input tension (from zero tension; see runs[].stretch_* for the swing and "
            "the value from the first sample)",
            "rate_dependence": "peak of the damping term at the identification run's top speed",
            "none": "no effect",
        }[eff.effect],
        "coefficient": eff.coefficient,
        "coefficient_unit": eff.coefficient_unit,
        "law": {
            "tendon_stretch": "sheath input = u - c (T_in - T_in(0))" if eff.form == "linear_input"
            else "sheath input = u - c (T_in^2 - T_in(0)^2)",
            "rate_dependence": "y -= b v_in" if eff.form == "viscous" else "y -= b sign(v_in) |v_in / v_ref|^a",
            "none": "",
        }[eff.effect],
        "v_ref_mm_s": eff.v_ref_mm_s,
        "exponent": eff.exponent,
        "starts_at_speed": starts_at_speed,
        "start": "at speed, mechanism as if cycling (came up from -6 mm)" if starts_at_speed
        else f"from rest: relaxed (uniform {PLANT.pretension_n:g} N), input still for {REST_LEAD_IN_S:g} s",
        "seed": int(seed),
        "identification_run": runs[0]["run_id"],
        "held_out_runs": [r["run_id"] for r in held],
        "oracle": {
            "what": "RMS of the effect's contribution to the output on the held-out runs (noise-free "
            "plant with minus without the effect, both zeroed at the first encoder sample), in output noise sd",
            "noise_sd_mm": OUTPUT_NOISE_SD_MM,
            "heldout_rms_sd": float(np.sqrt(np.mean(pooled)) / OUTPUT_NOISE_SD_MM),
            "heldout_peak_sd": float(max(r["oracle"]["peak_sd"] for r in held)),
            "identification_rms_sd": runs[0]["oracle"]["rms_sd"],
        },
        "runs": runs,
        "plant": {"model": "discretised tendon in a sheath, capstan Coulomb friction at contact nodes, distal return spring", **asdict(PLANT)},
        "configuration": dict(CONFIGURATION),
        "loadcell_noise_sd_n": LOADCELL_NOISE_SD_N,
    }
    _merge_truth(Path(root), {name: truth})
    return name, truth


def _merge_truth(root: Path, entries: dict[str, Any], *, fresh: bool = False) -> None:
    path = root / TRUTH_FILE
    old: dict[str, Any] = {}
    if path.exists() and not fresh:
        old = json.loads(path.read_text(encoding="utf-8"))
    old.update(entries)
    path.write_text(json.dumps(old, indent=2) + "\n", encoding="utf-8")


def write_all(root: str | Path, seed: int = 0) -> dict[str, Any]:
    """Write the ten sources under ``root`` and ``root/stretch_damping_truth.json``; return the
    truth: folder name -> {effect, form, strength, size, starts_at_speed, oracle, runs, ...}."""
    out = Path(root)
    out.mkdir(parents=True, exist_ok=True)
    truth: dict[str, Any] = {}
    for effect, form, strength, at_speed in SOURCES:
        name, entry = write_source(out, effect, form, strength, seed, starts_at_speed=at_speed)
        truth[name] = entry
    _merge_truth(out, truth, fresh=True)  # exactly this set's sources
    return truth


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("out_dir", help="folder to write the sources and the truth file into")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    truth = write_all(args.out_dir, seed=args.seed)
    for name, e in truth.items():
        print(
            f"{name}  effect={e['effect']:<15} form={e['form'] or '-':<17} strength={e['strength'] or '-':<6} "
            f"size={e['size']:.2f} mm  starts_at_speed={str(e['starts_at_speed']):<5}  "
            f"held-out rms={e['oracle']['heldout_rms_sd']:.2f} sd"
        )
    print(f"truth: {Path(args.out_dir) / TRUTH_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
