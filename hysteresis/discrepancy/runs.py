"""The arrays of one run as the discrepancy analysis sees them (no files, no pandas needed)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from hysteresis.base import HysteresisError, as_1d
from hysteresis.discrepancy._ops import FloatArray, direction, velocity
from hysteresis.roles import (
    HELDOUT,
    IDENTIFICATION,
    check_heldout_fraction,
    split_note,
    tail_start,
)

ROLES = (IDENTIFICATION, HELDOUT)


@dataclass(eq=False)
class RunData:
    """One run: time, input, measured output, optional tensions (input/output end), and labels.

    ``config`` is the configuration key (e.g. ``{"curve_angle_deg": 90, "radius_mm": 30}``);
    runs with equal ``config`` share one fitted model. ``role`` says whether the run is used to
    identify (``identification``) or to judge (``heldout``).
    """

    run_id: str
    t: FloatArray
    u: FloatArray
    y: FloatArray
    tension: FloatArray | None = None
    tension_out: FloatArray | None = None
    config: dict[str, Any] = field(default_factory=dict)
    excitation: str = ""
    role: str = "identification"
    #: Sample indices where a new record starts (runs concatenated by :func:`concat_runs`).
    starts: tuple[int, ...] = (0,)
    #: When the recording began, for a run that is a later segment of a record (time since
    #: the start keeps counting from there: a creep does not restart mid-record).
    record_start_s: float | None = None
    #: For a later segment judged on its own: the whole record and where the segment starts in
    #: it. A model predicts the whole record and keeps the segment, so the segment is judged
    #: from the state the earlier input left (the input is known; no output before is used).
    whole: RunData | None = field(default=None, repr=False, compare=False)
    offset: int = 0
    #: The output's zero is this run's own first sample (a relative encoder: tsm-rig-log/1
    #: positions are relative to each run's first sample), not the zero of ``whole``: a model
    #: predicting the whole record predicts the change from the run's first sample.
    rezeroed: bool = False
    #: When the recording started (POSIX seconds, from the manifest), or None: which run was
    #: recorded just before which (:func:`chain_records`).
    started_at: float | None = None

    def __post_init__(self) -> None:
        self.t = as_1d(self.t, f"{self.run_id}: t")
        self.u = as_1d(self.u, f"{self.run_id}: input")
        self.y = as_1d(self.y, f"{self.run_id}: output")
        if not (self.t.size == self.u.size == self.y.size):
            raise HysteresisError(
                f"run {self.run_id}: t, input and output differ in length "
                f"({self.t.size}, {self.u.size}, {self.y.size})"
            )
        if self.t.size < 20:
            raise HysteresisError(f"run {self.run_id}: only {self.t.size} samples (need >= 20)")
        if np.any(np.diff(self.t) <= 0):
            raise HysteresisError(f"run {self.run_id}: time is not strictly increasing")
        if self.tension is not None:
            self.tension = as_1d(self.tension, f"{self.run_id}: tension")
            if self.tension.size != self.t.size:
                raise HysteresisError(f"run {self.run_id}: tension length differs from t")
        if self.tension_out is not None:
            self.tension_out = as_1d(self.tension_out, f"{self.run_id}: tension_out")
            if self.tension_out.size != self.t.size:
                raise HysteresisError(f"run {self.run_id}: tension_out length differs from t")
        if self.role not in ROLES:
            raise HysteresisError(
                f"run {self.run_id}: role must be one of {ROLES}, got {self.role!r}")

    @property
    def n(self) -> int:
        return int(self.t.size)

    def segment(self, start: int, stop: int, *, role: str, suffix: str,
                keep_history: bool = False) -> RunData:
        """Samples ``start:stop`` as a run of its own (``<run_id>:<suffix>``), time kept.
        ``keep_history``: the segment remembers the record (``whole``, ``offset``), so models
        predict it after the input before it."""
        def cut(x: FloatArray | None) -> FloatArray | None:
            return None if x is None else x[start:stop].copy()

        return RunData(run_id=f"{self.run_id}:{suffix}", t=self.t[start:stop].copy(),
                       u=self.u[start:stop].copy(), y=self.y[start:stop].copy(),
                       tension=cut(self.tension), tension_out=cut(self.tension_out),
                       config=dict(self.config), excitation=self.excitation, role=role,
                       record_start_s=(self.record_start_s if self.record_start_s is not None
                                       else float(self.t[0])),
                       whole=self if keep_history and start > 0 else None,
                       offset=start if keep_history else 0)

    @cached_property
    def dt(self) -> float:
        """Median sample interval, s (a term's low-pass filter asks for it at every refit)."""
        return float(np.median(np.diff(self.t)))

    @property
    def config_key(self) -> str:
        if not self.config:
            return "default"
        return ",".join(f"{k}={self.config[k]}" for k in sorted(self.config))

    @cached_property
    def ts(self) -> FloatArray:
        """Time since the start of the run (of each concatenated record), s."""
        out = np.empty(self.n)
        edges = [*self.starts, self.n]
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            origin = self.record_start_s if a == 0 and self.record_start_s is not None \
                else self.t[a]
            out[a:b] = self.t[a:b] - origin
        return out

    @cached_property
    def v(self) -> FloatArray:
        """Smoothed input velocity."""
        return velocity(self.t, self.u)

    @cached_property
    def v_eps(self) -> float:
        """Speed below which the input counts as still (2 % of the 99th-percentile speed)."""
        return max(0.02 * float(np.percentile(np.abs(self.v), 99)), 1e-12)

    @cached_property
    def s(self) -> FloatArray:
        """Direction of the last motion (+1 loading, -1 unloading; held through dwells)."""
        return direction(self.v, eps=self.v_eps)

    @cached_property
    def pull_sign(self) -> float:
        """+1 when a larger input pulls the tendon (the input tension rises with it), -1 when
        it releases it; +1 without an input tension."""
        if self.tension is None:
            return 1.0
        return -1.0 if float(np.cov(self.u, self.tension)[0, 1]) < 0.0 else 1.0

    def decimated(self, factor: int) -> RunData:
        """Every ``factor``-th sample after a moving-average anti-alias filter; a sample whose
        share of the record holds an input reversal keeps the raw input and output of the
        reversal instead (:func:`turning_samples`)."""
        if factor <= 1:
            return self
        from hysteresis.discrepancy._ops import smooth

        turn = turning_samples(self.u, factor)
        at_turn = turn >= 0

        def dec(x: FloatArray) -> FloatArray:
            return np.asarray(smooth(x, factor)[::factor], dtype=np.float64)

        def dec_kept(x: FloatArray) -> FloatArray:
            out = dec(x)
            out[at_turn] = x[turn[at_turn]]
            return out

        return RunData(
            run_id=self.run_id, t=self.t[::factor].copy(), u=dec_kept(self.u),
            y=dec_kept(self.y),
            tension=None if self.tension is None else dec(self.tension),
            tension_out=None if self.tension_out is None else dec(self.tension_out),
            config=dict(self.config), excitation=self.excitation, role=self.role,
            starts=tuple(sorted({int(np.ceil(s / factor)) for s in self.starts})),
            record_start_s=self.record_start_s, started_at=self.started_at,
        )


def turning_samples(u: FloatArray, factor: int) -> npt.NDArray[np.intp]:
    """Per sample kept by a decimation by ``factor`` (raw index ``k factor``): the raw index of
    an input reversal within its share of the record (``[k f - f // 2, k f - f // 2 + f)``,
    each raw sample in exactly one share), or -1.

    Why: a hysteresis plant's memory is set by the extremes of the input it saw. A moving
    average shaves a sharp reversal (a triangle's corner: by about one raw step's travel), so
    a play operator driven by the averaged input holds a lower state for the whole of the next
    stroke, and the averaged output, taken through the plant's nonlinearity, is not the plant's
    output for the averaged input. On a clean play-sum plant sampled at 100 Hz and analysed at
    25 Hz this left 4x the held-out error of the full rate (13.5 um against 3.4 um on a
    triangle); keeping the reversal's own raw input and output leaves 3.2 um.

    A reversal is an extreme of the share that stands out from the input one share before and
    one after by more than three times the input's own noise (robust, from its second
    differences): a still or slowly turning input (a dwell, the top of a slow sine) keeps the
    average, which is the better estimate there."""
    n, f = u.size, int(factor)
    keep = np.arange(0, n, f)
    lo = np.clip(keep - f // 2, 0, n - 1)
    idx = np.minimum(lo[:, None] + np.arange(f)[None, :], n - 1)
    seg = u[idx]
    left = u[np.maximum(lo - f, 0)]
    right = u[np.minimum(lo + 2 * f - 1, n - 1)]
    rows = np.arange(keep.size)
    j_hi, j_lo = seg.argmax(axis=1), seg.argmin(axis=1)
    rise = seg[rows, j_hi] - np.maximum(left, right)
    fall = np.minimum(left, right) - seg[rows, j_lo]
    d2 = np.diff(u, 2)
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0) if n > 3 \
        else 0.0
    pick = idx[rows, np.where(rise >= fall, j_hi, j_lo)]
    turn = np.maximum(rise, fall) > 3.0 * noise
    return np.where(turn, pick, -1).astype(np.intp)


def describe_mix(groups: Mapping[tuple[str, ...], Sequence[str]],
                 fields: Sequence[str]) -> str | None:
    """``None`` when every run falls in one group, else one sentence naming what differs
    and each group with its runs, for a refusal: ``source mixes rigs: tsm-bench (2 runs,
    output mm) and bending-joint (2 runs, output deg); analyse each group apart: ...``.

    ``groups`` maps a key (rig first, then the output's unit and quantity, as many as
    ``fields`` names) to its run ids."""
    if len(groups) <= 1:
        return None
    keys = list(groups)
    differs = [name for i, name in enumerate(fields) if len({k[i] for k in keys}) > 1]

    def label(key: tuple[str, ...]) -> str:
        n = len(groups[key])
        extra = ", ".join(f"output {v}" if i == 1 else str(v)
                          for i, v in enumerate(key) if i > 0 and v)
        return f"{key[0]} ({n} run{'s' if n != 1 else ''}{', ' + extra if extra else ''})"

    def runs_of(key: tuple[str, ...]) -> str:
        ids = list(groups[key])
        more = f" and {len(ids) - 4} more" if len(ids) > 4 else ""
        return f"{label(key)}: {', '.join(ids[:4])}{more}"

    what = " and ".join(differs) if len(differs) < 3 else \
        f"{', '.join(differs[:-1])} and {differs[-1]}"
    return (f"source mixes {what}: {' and '.join(label(k) for k in keys)}; "
            "analyse each group apart (one source folder per group): "
            + "; ".join(runs_of(k) for k in keys))


def check_one_rig(runs: Sequence[RunData]) -> None:
    """Runs of several rigs are never pooled into one analysis (their outputs need not share
    a unit or a quantity): :class:`HysteresisError` naming them."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for r in runs:
        groups.setdefault((str(r.config.get("rig", "")),), []).append(r.run_id)
    mix = describe_mix(groups, ("rigs",))
    if mix is not None:
        raise HysteresisError(mix)


def split_single_runs(runs: Sequence[RunData], *, heldout_fraction: float = 0.3
                      ) -> tuple[list[RunData], dict[str, str]]:
    """A configuration recorded in one run only (as many labs record one run per shape) is
    split in time: its head identifies, its last ``heldout_fraction`` is held out. Returns the
    runs and, per split configuration, a note saying what was done (for the log and report).

    Configurations with several runs are left as they are: their roles decide.
    """
    check_heldout_fraction(heldout_fraction)
    by: dict[str, list[RunData]] = {}
    for r in runs:
        by.setdefault(r.config_key, []).append(r)
    out: list[RunData] = []
    notes: dict[str, str] = {}
    for key, rs in by.items():
        if len(rs) != 1:
            out.extend(rs)
            continue
        run = rs[0]
        cut = tail_start(run.n, heldout_fraction)
        if cut is None:
            out.append(run)
            continue
        out += [run.segment(0, cut, role=IDENTIFICATION, suffix="head"),
                run.segment(cut, run.n, role=HELDOUT, suffix="tail", keep_history=True)]
        notes[key] = split_note(run.run_id, run.t[cut] - run.t[0], run.t[-1] - run.t[cut],
                                heldout_fraction)
    return out, notes


def concat_runs(runs: list[RunData], *, run_id: str | None = None,
                session: bool = False) -> RunData:
    """Several records of one configuration as one run (time made continuous). Models see one
    long input sequence: each record from its own start (its time since start kept through
    ``starts``), or with ``session`` as one record, each run's input moved to start where the
    last one stopped (the mechanism held between the runs)."""
    if not runs:
        raise HysteresisError("concat_runs needs at least one run")
    if len(runs) == 1 and not session:
        return runs[0]
    ts, ys, t1, t2, starts = [], [], [], [], []
    us: list[FloatArray] = []
    offset, n = 0.0, 0
    for r in runs:
        starts.append(n)
        ts.append(r.t - r.t[0] + offset)
        offset = float(ts[-1][-1]) + r.dt
        us.append(r.u + (float(us[-1][-1]) - float(r.u[0]) if session and us else 0.0))
        ys.append(r.y)
        t1.append(r.tension)
        t2.append(r.tension_out)
        n += r.n
    cat = np.concatenate
    return RunData(
        run_id=run_id or "+".join(r.run_id for r in runs), t=cat(ts), u=cat(us), y=cat(ys),
        tension=None if any(x is None for x in t1) else cat([x for x in t1 if x is not None]),
        tension_out=None if any(x is None for x in t2) else cat([x for x in t2 if x is not None]),
        config=dict(runs[-1 if session else 0].config),
        excitation=runs[-1].excitation if session else "+".join(r.excitation for r in runs),
        role=runs[-1 if session else 0].role, starts=(0,) if session else tuple(starts),
        record_start_s=0.0 if session else None,
    )


def chain_records(runs: Sequence[RunData]) -> tuple[list[RunData], dict[str, list[str]]]:
    """Each held-out run as the end of the session recorded before it: a rig that runs one
    excitation after another without resetting the mechanism starts every run in the state the
    last one left, and a relative encoder zeroes the output there, so that state sets the
    whole run's output level, not only its first cycle.

    Within a configuration, runs are ordered by ``started_at``; a held-out run recorded after
    others gets ``whole`` = the earlier runs' input and its own, joined end to end (the
    input held where the last run stopped; time made continuous, so a creep goes on across
    the join), with ``rezeroed`` set: the model predicts the session and its prediction of
    the run is moved to the run's own zero. Runs without a start time, segments of a record
    and runs whose session lacks a tension channel the run carries are left as they are.
    Returns the runs and, per chained run, the runs recorded before it."""
    by: dict[str, list[RunData]] = {}
    for r in runs:
        by.setdefault(r.config_key, []).append(r)
    chained: dict[str, RunData] = {}
    before: dict[str, list[str]] = {}
    for rs in by.values():
        timed = sorted((r for r in rs if r.started_at is not None and r.whole is None),
                       key=lambda r: (r.started_at, r.run_id))
        for k, run in enumerate(timed):
            if k == 0 or run.role != HELDOUT:
                continue
            session = timed[:k + 1]
            if any((getattr(p, c) is None) != (getattr(run, c) is None)
                   for p in session for c in ("tension", "tension_out")):
                continue
            whole = concat_runs(session, run_id=f"{run.run_id}:session", session=True)
            n0 = whole.n - run.n
            chained[run.run_id] = RunData(
                run_id=run.run_id, t=run.t, u=run.u, y=run.y, tension=run.tension,
                tension_out=run.tension_out,
                config=dict(run.config), excitation=run.excitation, role=run.role,
                whole=whole, offset=n0, rezeroed=True, started_at=run.started_at)
            before[run.run_id] = [p.run_id for p in session[:-1]]
    return [chained.get(r.run_id, r) for r in runs], before

