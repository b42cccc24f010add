"""Stage ``discrepancy_study``: how strong must each effect be before the workflow finds it?

    python -m pipelines.discrepancy_study                      # conf/discrepancy_study.yaml
    python -m pipelines.discrepancy_study effects_selected=[drift] 'strengths.drift=[1,2]'
    python -m pipelines.discrepancy_study +workflow.physical_evidence=false

For every (effect, strength, configuration pair) the virtual rig simulates the pair's runs with
that one effect switched on (seed 001's three excitations: the decaying sine identifies, the
triangle and trapezoid are held out), the runs go through the ingest stage's pure functions, and
the workflow sees only the dataset rows: the effect is hidden from it. Each case records what
was named first, the held-out RMSE before and after (pooled and per configuration) and the
physical evidence. Clean runs of every pair are included. The table says where each effect is
found, where it also halves the held-out error, and what it is mistaken for below that.

Writes ``<out>.json`` (every case) and ``<out>.md`` (the table), both atomically, and logs them
to MLflow as one run when tracking is on.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf.errors import MissingMandatoryValue, OmegaConfBaseException

from hysteresis.discrepancy.runs import RunData
from hysteresis.discrepancy.workflow import (
    Evaluation,
    WorkflowSettings,
    base_factory_for,
    run_workflow,
)
from pipelines import schemas
from pipelines.schemas import StudyExpectation
from pipelines.skeleton import Stage, TrackContext
from rig_io.atomic import write_text_atomic

log = logging.getLogger(__name__)

#: Seed 001's three excitations, 3 periods per amplitude (short enough for a sweep).
STUDY_EXCITATIONS: dict[str, dict[str, Any]] = {
    "sine_decay": {"kind": "sine_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                   "periods_per_amplitude": 3, "frequency_hz": 0.25},
    "triangle_decay": {"kind": "triangle_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                       "periods_per_amplitude": 3, "slope_mm_s": 6.0},
    "trapezoid_decay": {"kind": "trapezoid_decay", "amplitudes_mm": [6.0, 4.5, 3.0, 1.5],
                        "periods_per_amplitude": 3, "slope_mm_s": 6.0, "dwell_s": 1.0},
}


#: What an ``expect`` row of the study can ask of a case.
OUTCOMES = ("halved", "named", "clean")


class StudyError(Exception):
    """Bad configuration for the discrepancy study."""


Settings = schemas.DiscrepancyStudyConfig


@dataclass
class StudyResult:
    """What :func:`run` found: every single-effect case, every two-effect case, the pairs
    studied and the seconds the cases took."""

    cases: list[dict[str, Any]]
    combos: list[dict[str, Any]]
    pairs: dict[str, Any]
    elapsed_s: float


#: What a config must give.
REQUIRED = "out=<path stem> is required"


def hidden_effect_runs(effects: Mapping[str, float], configs: Sequence[tuple[float, float]], *,
                       seed: int = 3, rate_hz: float = 20.0,
                       excitations: Mapping[str, Mapping[str, Any]] | None = None,
                       identify: Sequence[str] = ("sine_decay",)) -> list[RunData]:
    """Virtual-rig runs with ``effects`` switched on, as the workflow sees them (dataset rows
    only: the effect's name and strength are not passed on)."""
    import rig_io.virtual as rig
    from pipelines.discrepancy_data import rows_from_raw, runs_from_dataset

    exc = dict(excitations or STUDY_EXCITATIONS)
    raws = [rig.simulate_run(curve_angle_deg=phi, radius_mm=r, excitation=dict(e),
                             effects=dict(effects) or None, seed=seed)
            for phi, r in configs for e in exc.values()]
    rows, meta = rows_from_raw(raws)
    return runs_from_dataset(rows, meta, identify_excitations=list(identify), rate_hz=rate_hz)


def per_configuration_heldout(report: Mapping[str, Any], stage: int) -> dict[str, float]:
    """Held-out RMSE of each configuration after ``stage`` effects were added (0 = base)."""
    ev: Evaluation = report["_evaluations"][stage]
    out: dict[str, float] = {}
    for g in report["_groups"]:
        e = np.concatenate([r.y - ev.held_pred[r.run_id] for r in g.heldout])
        out[g.key] = float(np.sqrt(np.mean(e**2)))
    return out


def study_case(effect: str | None, strength: float, pair: str,
               configs: Sequence[tuple[float, float]], *, seed: int = 3,
               rate_hz: float = 20.0, base: str = "gamma",
               workflow: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One (effect, strength, pair) case: hide the effect, run the workflow, score the answer.
    ``workflow`` holds :class:`WorkflowSettings` fields (thresholds, ``physical_evidence``)."""
    effects = {effect: strength} if effect else {}
    runs = hidden_effect_runs(effects, configs, seed=seed, rate_hz=rate_hz)
    t0 = time.perf_counter()
    rep = run_workflow(runs, base_factory_for(base), base_name=base,
                       settings=WorkflowSettings(**dict(workflow or {})))
    named = [e["name"] for e in rep["effects"]]
    case: dict[str, Any] = {
        "effect": effect or "clean", "strength": float(strength), "pair": pair,
        "configurations": [list(c) for c in configs], "named": named,
        "measured": [m["name"] for m in rep["measured_within_reach"]],
        "verdict": rep["verdict"],
        "heldout_rmse_before": rep["summary"]["heldout_rmse_before"],
        "first_named": named[0] if named else None,
        "correct": (named[:1] == [effect]) if effect else not named,
        "seconds": round(time.perf_counter() - t0, 2),
        "ranking": [{k: s[k] for k in ("name", "relative_gain", "delta_bic")}
                    | {"load_cells_corroborated": s["load_cell_evidence"]["corroborated"]}
                    for s in (rep["rankings"][0] if rep["rankings"] else [])],
    }
    if named:
        first = rep["effects"][0]
        before = per_configuration_heldout(rep, 0)
        after = per_configuration_heldout(rep, 1)
        case["heldout_rmse_after"] = first["heldout_rmse_after"]
        case["reduction"] = 1.0 - first["heldout_rmse_after"] / first["heldout_rmse_before"]
        case["reduction_per_configuration"] = {k: 1.0 - after[k] / before[k] for k in before}
    else:
        case["heldout_rmse_after"] = case["heldout_rmse_before"]
        case["reduction"] = 0.0
        case["reduction_per_configuration"] = {}
    red = case["reduction_per_configuration"].values()
    case["halved"] = bool(case["correct"] and effect and red and min(red) >= 0.5)
    return case


def combination_case(effects: Mapping[str, float], pair: str,
                     configs: Sequence[tuple[float, float]], *, seed: int = 3,
                     rate_hz: float = 20.0, base: str = "gamma",
                     workflow: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Several effects hidden at once: are they all named (in any order), and how much of the
    held-out RMSE do the added terms remove together, in each configuration?"""
    runs = hidden_effect_runs(effects, configs, seed=seed, rate_hz=rate_hz)
    rep = run_workflow(runs, base_factory_for(base), base_name=base,
                       settings=WorkflowSettings(**dict(workflow or {})))
    named = [e["name"] for e in rep["effects"]]
    measured = [m["name"] for m in rep["measured_within_reach"]]
    before = per_configuration_heldout(rep, 0)
    after = per_configuration_heldout(rep, len(named))
    return {"effects": dict(effects), "label": " + ".join(f"{k} {v:g}" for k, v in
                                                          effects.items()),
            "pair": pair, "named": named, "measured": measured,
            # added: every hidden effect's term is in the model; named: or the load cells
            # show it and the report names it as already reproduced (not added)
            "all_added": set(effects) <= set(named),
            "all_named": set(effects) <= set(named) | set(measured),
            "extra": [n for n in named + measured if n not in effects],
            "heldout_rmse_before": rep["summary"]["heldout_rmse_before"],
            "heldout_rmse_after": rep["summary"]["heldout_rmse_after"],
            "reduction": rep["summary"]["heldout_reduction"],
            "reduction_per_configuration": {k: 1.0 - after[k] / before[k] for k in before}}


def run_combinations(*, strengths: Mapping[str, float], pairs: Mapping[str, Any],
                     seed: int = 3, rate_hz: float = 20.0, base: str = "gamma",
                     workflow: Mapping[str, Any] | None = None, n_jobs: int = 2,
                     progress: bool = True) -> list[dict[str, Any]]:
    """Every two-effect combination of ``strengths`` (one strength per effect) on each pair."""
    from itertools import combinations

    from joblib import Parallel, delayed
    from tqdm import tqdm

    from rig_io.virtual.effects import EFFECT_NAMES

    bad = sorted(set(strengths) - set(EFFECT_NAMES))
    if bad:
        raise StudyError(f"combinations: unknown effect(s) {bad}; known: {list(EFFECT_NAMES)}")
    jobs = [({a: float(strengths[a]), b: float(strengths[b])}, p)
            for p in pairs for a, b in combinations(sorted(strengths), 2)]
    it = tqdm(jobs, desc="two-effect combinations", disable=not progress)
    return list(Parallel(n_jobs=n_jobs)(
        delayed(combination_case)(e, p, [(float(c[0]), float(c[1])) for c in pairs[p]],
                                  seed=seed, rate_hz=rate_hz, base=base, workflow=workflow)
        for e, p in it))


def run_study(*, strengths: Mapping[str, Sequence[float]],
              pairs: Mapping[str, Sequence[Sequence[float]]], seed: int = 3,
              rate_hz: float = 20.0, base: str = "gamma",
              workflow: Mapping[str, Any] | None = None, n_jobs: int = 2,
              progress: bool = True) -> list[dict[str, Any]]:
    """Every case (clean runs of each pair first); pure apart from the simulation."""
    from joblib import Parallel, delayed
    from tqdm import tqdm

    from rig_io.virtual.effects import EFFECT_NAMES

    bad = sorted(set(strengths) - set(EFFECT_NAMES))
    if bad:
        raise StudyError(f"unknown effect(s) {bad}; known: {list(EFFECT_NAMES)}")
    if not pairs:
        raise StudyError("pairs: give at least one named list of [curve_angle_deg, radius_mm]")
    cfgs = {name: [(float(c[0]), float(c[1])) for c in cs] for name, cs in pairs.items()}
    jobs: list[tuple[str | None, float, str]] = [(None, 0.0, p) for p in cfgs]
    jobs += [(e, float(s), p) for p in cfgs for e, ss in strengths.items() for s in ss]
    fields = set(WorkflowSettings.__dataclass_fields__)
    unknown = sorted(set(workflow or {}) - fields)
    if unknown:
        raise StudyError(f"unknown workflow setting(s) {unknown}; known: {sorted(fields)}")
    wf = {k: (tuple(v) if k == "candidates" else v) for k, v in (workflow or {}).items()}
    one = partial(_case_job, cfgs=cfgs, seed=seed, rate_hz=rate_hz, base=base, workflow=wf)
    it = tqdm(jobs, desc="discrepancy study", disable=not progress)
    return list(Parallel(n_jobs=n_jobs)(delayed(one)(j) for j in it))


def _case_job(job: tuple[str | None, float, str], *, cfgs: Mapping[str, Any], seed: int,
              rate_hz: float, base: str, workflow: Mapping[str, Any]) -> dict[str, Any]:
    effect, strength, pair = job
    return study_case(effect, strength, pair, cfgs[pair], seed=seed, rate_hz=rate_hz,
                      base=base, workflow=workflow)


def detection_limits(cases: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per effect and pair: the smallest strength named first, and the smallest also halved."""
    out: dict[str, dict[str, Any]] = {}
    for c in cases:
        if c["effect"] == "clean":
            continue
        d = out.setdefault(c["effect"], {}).setdefault(
            c["pair"], {"named_from": None, "halved_from": None, "mistaken_for": []})
        s = c["strength"]
        if c["correct"] and (d["named_from"] is None or s < d["named_from"]):
            d["named_from"] = s
        if c["halved"] and (d["halved_from"] is None or s < d["halved_from"]):
            d["halved_from"] = s
        if c["first_named"] and not c["correct"]:
            d["mistaken_for"].append(f"{c['first_named']} at {s:g}")
    return out


def shortfalls(cases: Sequence[Mapping[str, Any]], combos: Sequence[Mapping[str, Any]],
               expect: Sequence[StudyExpectation], *,
               combination_reduction: float) -> list[str]:
    """The study's expectations a run did not meet, one line each (empty: all met).

    Clean cases must name nothing; each combination must name every hidden effect and remove
    at least ``combination_reduction`` of the pooled held-out RMSE; each ``expect`` row
    (``effect``, ``strength``, ``pair``, ``outcome``, ``min_reduction``) must show its outcome
    where the study ran that case."""
    out = [f"clean on pair {c['pair']}: named {c['named']}" for c in cases
           if c["effect"] == "clean" and c["named"]]
    for c in combos:
        if not c["all_named"]:
            out.append(f"{c['label']} on pair {c['pair']}: named {c['named']}, "
                       f"measured {c['measured']}")
        elif c["reduction"] < combination_reduction:
            out.append(f"{c['label']} on pair {c['pair']}: terms remove "
                       f"{100 * c['reduction']:.0f} % < {100 * combination_reduction:.0f} %")
    by_key = {(c["effect"], float(c["strength"]), c["pair"]): c for c in cases}
    for e in expect:
        case = by_key.get((e.effect, float(e.strength), e.pair))
        missed = _missed(e, case) if case is not None else None
        if missed:
            out.append(missed)
    return out


def _missed(e: StudyExpectation, c: Mapping[str, Any]) -> str | None:
    """How case ``c`` falls short of expectation ``e`` (None: it does not)."""
    what = f"{e.effect} {float(e.strength):g} on pair {e.pair}"
    if e.outcome == "clean":
        return f"{what}: expected no effect, named {c['named']}" if c["named"] else None
    if not c["correct"]:
        return f"{what}: named first {c['first_named']!r}"
    if e.outcome == "halved" and not c["halved"]:
        per = ", ".join(f"{100 * v:.0f} %" for v in c["reduction_per_configuration"].values())
        return f"{what}: not halved in every configuration ({per})"
    if e.outcome == "named" and c["reduction"] < float(e.min_reduction):
        return (f"{what}: removes {100 * c['reduction']:.0f} % < "
                f"{100 * float(e.min_reduction):.0f} %")
    return None


def _check_expect(expect: Sequence[StudyExpectation], pairs: Mapping[str, Any]) -> None:
    """An ``expect`` row that names no known effect, pair or outcome could never be checked:
    stop before any case runs."""
    from rig_io.virtual.effects import EFFECT_NAMES

    for i, e in enumerate(expect):
        for key, value, known in (("effect", e.effect, EFFECT_NAMES),
                                  ("pair", e.pair, tuple(pairs)),
                                  ("outcome", e.outcome, OUTCOMES)):
            if value not in known:
                raise StudyError(f"expect[{i}]: unknown {key} {value!r}; known: {list(known)}")


def markdown(cases: Sequence[Mapping[str, Any]]) -> str:
    """The study as Markdown: one row per case, then the detection limits."""
    lines = ["# Discrepancy workflow: detection study", "",
             "Each row hides one effect (or none) in virtual-rig runs of a configuration pair; "
             "`reduction` is the held-out RMSE removed by the first named effect (pooled, then "
             "the smaller of the two configurations).", "",
             "| pair | effect | strength | held-out RMSE before (mm) | named | measured | "
             "reduction | min per config | halved |",
             "|---|---|---|---|---|---|---|---|---|"]
    for c in cases:
        per = c["reduction_per_configuration"]
        lines.append(
            f"| {c['pair']} | {c['effect']} | {c['strength']:g} | "
            f"{c['heldout_rmse_before']:.3f} | {', '.join(c['named']) or '-'} | "
            f"{', '.join(c.get('measured', [])) or '-'} | {100 * c['reduction']:.0f} % | "
            f"{(f'{100 * min(per.values()):.0f} %') if per else '-'} | "
            f"{'yes' if c['halved'] else ('-' if c['effect'] == 'clean' else 'no')} |")
    lines += ["", "## Detection limits", "",
              "| effect | pair | named first from | halved from | mistaken for |",
              "|---|---|---|---|---|"]
    for eff, by_pair in detection_limits(cases).items():
        for pair, d in by_pair.items():
            lines.append(f"| {eff} | {pair} | {_fmt(d['named_from'])} | "
                         f"{_fmt(d['halved_from'])} | {', '.join(d['mistaken_for']) or '-'} |")
    clean = [c for c in cases if c["effect"] == "clean"]
    lines += ["", "Clean runs: " + ", ".join(
        f"{c['pair']} {c['verdict'] if c['correct'] else 'named ' + ', '.join(c['named'])}"
        for c in clean), ""]
    return "\n".join(lines)


def markdown_combinations(cases: Sequence[Mapping[str, Any]]) -> str:
    """Two-effect cases as Markdown."""
    ok = sum(bool(c["all_named"]) for c in cases)
    added = sum(bool(c["all_added"]) for c in cases)
    lines = ["", "## Two effects at once", "",
             f"Both effects named in {ok} of {len(cases)} cases, both terms added in {added}; "
             "`measured` are effects the load cells show that the final model already "
             "reproduces (named, not added); `reduction` is the held-out RMSE removed by all "
             "added terms (pooled; worst configuration).", "",
             "| pair | hidden effects | added (in order) | measured | both named | before (mm) "
             "| reduction | worst configuration |", "|---|---|---|---|---|---|---|---|"]
    for c in cases:
        per = c["reduction_per_configuration"].values()
        lines.append(f"| {c['pair']} | {c['label']} | {', '.join(c['named']) or '-'} | "
                     f"{', '.join(c['measured']) or '-'} | "
                     f"{'yes' if c['all_named'] else 'no'} | {c['heldout_rmse_before']:.3f} | "
                     f"{100 * c['reduction']:.0f} % | {100 * min(per):.0f} % |")
    return "\n".join(lines) + "\n"


def _fmt(x: float | None) -> str:
    return "not reached" if x is None else f"{x:g}"


def settings(cfg: Any) -> Settings:
    """The study's typed settings (:func:`pipelines.schemas.settings`); a missing ``out``, an
    unknown or mistyped setting is named in one line."""
    try:
        s = schemas.settings(Settings, cfg)
    except MissingMandatoryValue:
        raise StudyError(REQUIRED) from None
    except OmegaConfBaseException as err:
        raise StudyError(f"{err.full_key}: {str(err).splitlines()[0]}") from None
    if not s.out:
        raise StudyError(REQUIRED)
    return s


def out_paths(s: Settings) -> tuple[Path, Path]:
    """``<out>.json`` and ``<out>.md`` (links refused, not followed: never resolved)."""
    out = Path(os.path.abspath(os.path.expanduser(s.out)))
    return out.with_suffix(".json"), out.with_suffix(".md")


def run(cfg: Any) -> StudyResult:
    """Every case the settings select; writes nothing. Every setting is checked before the
    first case runs (the two-effect part before the long single-effect part).

    ``cfg``: the study's :class:`Settings`, a composed ``conf/discrepancy_study.yaml`` or a
    hand-written mapping (settings it leaves out take their defaults; a free mapping given,
    e.g. ``strengths``, replaces the default one whole)."""
    s = settings(cfg)
    pairs = _selected_pairs(s.pairs, s.pairs_selected or list(s.pairs), "")
    strengths = _selected_strengths(s.strengths, s.effects_selected)
    combo_pairs = _selected_pairs(s.pairs, s.combinations.pairs_selected, "combinations: ") \
        if s.combinations.strengths else {}
    _check_effects(s.combinations.strengths, "combinations: ")
    _check_expect(s.expect, s.pairs)
    t0 = time.perf_counter()
    common: dict[str, Any] = {"seed": s.seed, "rate_hz": s.rate_hz, "base": s.base_family,
                              "workflow": dict(s.workflow), "n_jobs": s.n_jobs,
                              "progress": s.progress}
    cases = run_study(strengths=strengths, pairs=pairs, **common)
    combos: list[dict[str, Any]] = []
    if s.combinations.strengths:
        combos = run_combinations(strengths=dict(s.combinations.strengths), pairs=combo_pairs,
                                  **common)
    return StudyResult(cases=cases, combos=combos, pairs=pairs,
                       elapsed_s=round(time.perf_counter() - t0, 1))


def _selected_pairs(pairs: Mapping[str, Any], chosen: Sequence[str], what: str
                    ) -> dict[str, Any]:
    missing = [p for p in chosen if p not in pairs]
    if missing:
        raise StudyError(f"{what}unknown pair(s) {missing}; defined: {sorted(pairs)}")
    return {p: pairs[p] for p in chosen}


def _selected_strengths(strengths: Mapping[str, Any], effects: Sequence[str] | None
                        ) -> dict[str, Any]:
    if effects is None:
        return dict(strengths)
    unknown = sorted(set(effects) - set(strengths))
    if unknown:
        raise StudyError(f"effects_selected {unknown} have no strengths; "
                         f"defined: {sorted(strengths)}")
    return {e: strengths[e] for e in effects}


def _check_effects(strengths: Mapping[str, Any], what: str) -> None:
    from rig_io.virtual.effects import EFFECT_NAMES

    bad = sorted(set(strengths) - set(EFFECT_NAMES))
    if bad:
        raise StudyError(f"{what}unknown effect(s) {bad}; known: {list(EFFECT_NAMES)}")


def write(result: StudyResult, s: Settings) -> list[Path]:
    """``<out>.json`` (every case, the detection limits, the settings) and ``<out>.md`` (the
    tables), both atomically; returns their paths."""
    doc = {"cases": result.cases, "detection_limits": detection_limits(result.cases),
           "combinations": result.combos,
           "settings": {"seed": s.seed, "rate_hz": s.rate_hz, "base_family": s.base_family,
                        "workflow": s.workflow, "strengths": s.strengths},
           "pairs": result.pairs, "elapsed_s": result.elapsed_s}
    json_path, md_path = out_paths(s)
    write_text_atomic(json_path, json.dumps(doc, indent=1) + "\n")
    write_text_atomic(md_path, markdown(result.cases) + (
        markdown_combinations(result.combos) if result.combos else ""))
    return [json_path, md_path]


def track(tracker: Any, result: StudyResult, s: Settings, files: Sequence[Path]) -> None:
    """One MLflow run under the stage's parent: each case's reduction, the counts, the
    settings and the two files."""
    from pipelines.tracking import StageRun

    cases, combos = result.cases, result.combos
    with StageRun(tracker, "discrepancy_study") as stage_run, tracker.run(
            "discrepancy_study", parent_id=stage_run.parent_id,
            tags={"stage": "discrepancy_study", "kind": "analysis"}) as run_id:
        metrics = {f"{c['pair']}.{c['effect']}.{c['strength']:g}.reduction": c["reduction"]
                   for c in cases if math.isfinite(c["reduction"])}
        metrics["cases_correct"] = float(sum(bool(c["correct"]) for c in cases))
        metrics["cases"] = float(len(cases))
        if combos:
            metrics["combinations_all_named"] = float(sum(bool(c["all_named"]) for c in combos))
            metrics["combinations_all_added"] = float(sum(bool(c["all_added"]) for c in combos))
            metrics["combinations"] = float(len(combos))
        params = {"base_family": s.base_family,
                  **{f"workflow.{k}": str(v) for k, v in s.workflow.items()}}
        tracker.log(run_id, params=params, metrics=metrics)
        for f in files:
            tracker.log_artifact(run_id, f, "reports")


def _run_and_write(s: Settings) -> StudyResult:
    result = run(s)
    files = write(result, s)
    log.info("wrote %s and %s (%d cases, %.0f s)", *files, len(result.cases), result.elapsed_s)
    return result


def _track(ctx: TrackContext, s: Settings, result: StudyResult) -> None:
    track(ctx.tracker, result, s, list(out_paths(s)))


def _verdict(s: Settings, result: StudyResult) -> None:
    """The study's expectations, after the tables are written and tracked: a shortfall raises
    :class:`StudyError` naming each case."""
    _warn_unchecked(s.expect, result.cases)
    missed = shortfalls(result.cases, result.combos, s.expect,
                        combination_reduction=s.expect_combination_reduction)
    if missed:
        raise StudyError(f"the study fell short of {len(missed)} expectation(s) "
                         f"(tables written to {out_paths(s)[1]}):\n  " + "\n  ".join(missed))


def _summary(s: Settings, result: StudyResult) -> str:
    ok = sum(bool(c["halved"]) for c in result.cases)
    return f"{len(result.cases)} cases; {ok} named first and halved; table: {out_paths(s)[1]}"


STAGE = Stage("discrepancy_study", Settings, run=_run_and_write, track=_track,
              convert=settings, after=_verdict, errors=(StudyError,), announce=_summary)


def stage(cfg: Any) -> list[dict[str, Any]]:
    """The whole study from a config (:func:`run`, :func:`write`, :func:`track`), then its
    expectations: a shortfall raises :class:`StudyError` naming each case, after the tables
    are written. Returns the single-effect cases."""
    result: StudyResult = STAGE.execute(cfg)
    return result.cases


def _warn_unchecked(expect: Sequence[StudyExpectation], cases: Sequence[Mapping[str, Any]]
                    ) -> None:
    """Expectations the selection left out: say so rather than pass them silently."""
    ran = {(c["effect"], float(c["strength"]), c["pair"]) for c in cases}
    unchecked = [e for e in expect if (e.effect, float(e.strength), e.pair) not in ran]
    if unchecked:
        log.warning("%d expectation(s) not checked, their cases did not run: %s",
                    len(unchecked), ", ".join(f"{e.effect} {float(e.strength):g} on "
                                              f"pair {e.pair}" for e in unchecked))


if __name__ == "__main__":
    STAGE.main()
