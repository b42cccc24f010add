"""Benchmark of the discrepancy workflow.

``injector``: what ``make discrepancy`` answers (automatic base) on the independent
injector's matrix (every effect at two strengths on three plants, and clean sources), with
seconds per source. The rest: one virtual-rig configuration
(90 deg / 30 mm) with a hidden time delay and drift, seed 001 excitations with 3 periods per
amplitude, analysed at 20 Hz with the Gamma base. Reports the wall time of the whole
locate -> name -> add loop, and the ratio against the reference joint refit by backfitting
(the generic path every non-Gamma family takes) measured in the same run.
"""

from __future__ import annotations

import time
from typing import Any
from unittest import mock


def _runs() -> list[Any]:
    from pipelines.discrepancy_study import hidden_effect_runs

    return hidden_effect_runs({"time_delay": 1.0, "drift": 2.0}, [(90.0, 30.0)])


def _time(fn: Any, repeat: int = 2) -> tuple[float, Any]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run() -> dict[str, Any]:
    from hysteresis.discrepancy import effects
    from hysteresis.discrepancy.workflow import base_factory_for, run_workflow

    runs = _runs()
    factory = base_factory_for("gamma")

    def workflow() -> dict[str, Any]:
        return run_workflow(runs, factory, base_name="gamma")

    workflow()  # warm numba caches
    t_exact, rep = _time(workflow)
    with mock.patch.object(effects, "_joint_linear", lambda *a, **k: None):
        t_backfit, rep_bf = _time(workflow)
    n_samples = sum(r.n for r in runs)
    injector = injector_sources()
    return {
        "injector": injector,
        "blas_limit": blas_limit(),
        "samples_analysed": n_samples,
        "effects_found": [e["name"] for e in rep["effects"]],
        "heldout_rmse_before": rep["summary"]["heldout_rmse_before"],
        "heldout_rmse_after": rep["summary"]["heldout_rmse_after"],
        "workflow_s_exact_joint": t_exact,
        "workflow_s_backfitting_reference": t_backfit,
        "speedup_exact_vs_backfitting": t_backfit / t_exact,
        "effects_found_backfitting": [e["name"] for e in rep_bf["effects"]],
        "heldout_rmse_after_backfitting": rep_bf["summary"]["heldout_rmse_after"],
    }


#: The injector matrix: each injected effect at two strengths, plus clean sources.
STRENGTHS = (1.0, 2.0)


def injector_cases() -> dict[str, dict[str, float]]:
    """Case name -> injected effects: clean (two noise seeds: ``#1`` names the seed), every
    effect at each of :data:`STRENGTHS`."""
    from hysteresis.discrepancy.inject import INJECTED

    cases: dict[str, dict[str, float]] = {"clean": {}, "clean#1": {}}
    for s in STRENGTHS:
        cases.update({f"{name}@{s:g}": {name: s} for name in INJECTED})
    return cases


def injector_sources(cases: dict[str, dict[str, float]] | None = None) -> dict[str, Any]:
    """What ``make discrepancy`` does (:func:`pipelines.discrepancy.analyse`: automatic base,
    the workflow, a second base when the first leaves a residual) on three 80 s runs from the
    independent injector (plain Gamma, Preisach and Bouc-Wen plants): per source the seconds,
    the base kept, the verdict, what was named and the held-out change against the best plain
    family; the summary scores the matrix against the workflow's bar (hidden effect named first
    and held-out RMSE at least halved; no effect named on clean sources).

    ``python -m bench.bench_discrepancy --injector`` runs it alone; ``run()`` includes it."""
    from hydra import compose, initialize_config_dir

    from hysteresis.discrepancy.inject import PLANTS, injected_runs
    from pipelines.common import CONF_DIR, to_container
    from pipelines.discrepancy import analyse

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = to_container(compose("discrepancy"))
    out: dict[str, Any] = {}
    for case, effects in (cases or injector_cases()).items():
        for plant in PLANTS:
            runs = injected_runs(plant, effects,
                                 seed=int(case.split("#")[1]) if "#" in case else 0)
            t0 = time.perf_counter()
            rep, _ = analyse(runs, auto_families=dict(cfg["auto_families"]),
                             max_bases=int(cfg["max_bases"]),
                             base_retry_factor=float(cfg["base_retry_factor"]))
            named = [e["name"] for e in rep["effects"]]
            cut = float(rep["summary"]["heldout_reduction_vs_best_plain"])
            hidden = next(iter(effects), None)
            out[f"{plant}:{case}"] = {
                "seconds": round(time.perf_counter() - t0, 2), "base": rep["base_family"],
                "bases_tried": [t["base"] for t in rep["bases_tried"] or []],
                "verdict": rep["verdict"], "named": named,
                "heldout_reduction_vs_best_plain": round(cut, 3),
                "rmse_over_noise": round(float(rep["residual"]["rmse_over_noise"]), 2),
                "hit": (not named) if hidden is None
                else bool(named and named[0] == hidden and cut >= 0.5)}
    rows = list(out.values())
    effect_rows = [v for k, v in out.items() if ":clean" not in k]
    clean_rows = [v for k, v in out.items() if ":clean" in k]
    out["_summary"] = {
        "sources": len(rows), "max_seconds": max(v["seconds"] for v in rows),
        "over_60_s": sum(v["seconds"] > 60 for v in rows),
        "named_first_and_halved": sum(v["hit"] for v in effect_rows),
        "effect_sources": len(effect_rows),
        "false_effects_on_clean": sum(not v["hit"] for v in clean_rows),
        "clean_sources": len(clean_rows)}
    return out


#: The bases a verdict must not depend on: every auto family, given explicitly.
BASES = ("gamma", "gamma_free", "preisach", "bouc_wen", "coleman_hodgdon")


def base_independence(cases: dict[str, dict[str, float]] | None = None) -> dict[str, Any]:
    """Per injector source, the first effect named (or none) with each of :data:`BASES` given
    explicitly and with ``auto``; the summary counts the sources on which every base agrees
    with auto, and each base's agreement. Default cases: clean and every effect at strength 1.

    Two readings per base: ``first``, the given base's own answer (``base_check`` off), and
    ``stage``, what the stage answers with its defaults (``base_misfit_fallback``): when that
    base fits ``base_misfit_factor`` x worse plain than the best family, or its answer is
    neither clean nor within ``base_retry_factor`` x the noise floor, and the best family's
    model with its terms predicts ``workflow.min_relative_gain`` better than the base's with
    its terms, the best family's answer, taken from that family's row.

    ``python -m bench.bench_discrepancy --bases`` runs it alone (about 25 min on 2 cores)."""
    from hydra import compose, initialize_config_dir

    from hysteresis.discrepancy.inject import PLANTS, injected_runs
    from pipelines.common import CONF_DIR, to_container
    from pipelines.discrepancy import (
        analyse,
        asks_best_family,
        best_family_answers,
        choose_base,
    )

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = to_container(compose("discrepancy"))
    families = dict(cfg["auto_families"])
    factor = float(cfg["base_misfit_factor"])
    min_gain = float(cfg["workflow"]["min_relative_gain"])
    retry = float(cfg["base_retry_factor"])
    if cases is None:
        cases = {k: v for k, v in injector_cases().items()
                 if k == "clean" or k.endswith("@1")}
    out: dict[str, Any] = {}
    for case, effects in cases.items():
        for plant in PLANTS:
            runs = injected_runs(plant, effects,
                                 seed=int(case.split("#")[1]) if "#" in case else 0)
            row: dict[str, Any] = {}
            for base in ("auto", *BASES):
                t0 = time.perf_counter()
                if base == "auto":
                    rep, _ = analyse(runs, auto_families=families,
                                     max_bases=int(cfg["max_bases"]),
                                     base_retry_factor=float(cfg["base_retry_factor"]))
                else:
                    params = {k: v for k, v in families[base].items() if k != "family"}
                    rep, _ = analyse(runs, base_family=str(families[base].get("family", base)),
                                     base_params=params, auto_families=families,
                                     base_check=False)
                named = [e["name"] for e in rep["effects"]]
                row[base] = {"first": named[0] if named else None, "named": named,
                             "verdict": rep["verdict"],
                             "heldout_rmse_before": rep["summary"]["heldout_rmse_before"],
                             "heldout_rmse_after": rep["summary"]["heldout_rmse_after"],
                             "rmse_over_noise": rep["residual"]["rmse_over_noise"],
                             "seconds": round(time.perf_counter() - t0, 1)}
            _, _, plain = choose_base(runs, families)
            best = min(plain, key=plain.__getitem__)
            for base in BASES:
                own = row[base]
                asked = asks_best_family(
                    {"verdict": own["verdict"],
                     "residual": {"rmse_over_noise": own["rmse_over_noise"]}},
                    plain_ratio=own["heldout_rmse_before"] / plain[best], factor=factor,
                    retry_factor=retry)
                misfit = (base != best and asked and best_family_answers(
                    own["heldout_rmse_after"], row[best]["heldout_rmse_after"],
                    min_gain=min_gain))
                row[base]["misfit"] = bool(misfit)
                row[base]["stage"] = row[best]["first"] if misfit else row[base]["first"]
            auto = row["auto"]["first"]
            row["all_agree"] = all(row[b]["first"] == auto for b in BASES)
            row["all_agree_stage"] = all(row[b]["stage"] == auto for b in BASES)
            out[f"{plant}:{case}"] = row
    rows = list(out.values())
    out["_summary"] = {
        "sources": len(rows),
        "all_bases_agree_with_auto": sum(r["all_agree"] for r in rows),
        "agree_with_auto_by_base": {b: sum(r[b]["first"] == r["auto"]["first"] for r in rows)
                                    for b in BASES},
        "stage_all_bases_agree_with_auto": sum(r["all_agree_stage"] for r in rows),
        "stage_agree_with_auto_by_base": {
            b: sum(r[b]["stage"] == r["auto"]["first"] for r in rows) for b in BASES},
        "misfit_flagged_by_base": {b: sum(r[b]["misfit"] for r in rows) for b in BASES}}
    return out


def blas_limit(calls: int = 300) -> dict[str, float]:
    """The one-BLAS-thread limit as identification enters it (thousands of times a
    workflow): the cached controller against ``threadpool_limits``, which rescans the loaded
    libraries on every call."""
    from threadpoolctl import threadpool_limits

    from hysteresis._blas import single_thread_blas

    def ours() -> None:
        for _ in range(calls):
            with single_thread_blas():
                pass

    def reference() -> None:
        for _ in range(calls):
            with threadpool_limits(limits=1, user_api="blas"):
                pass

    ours()
    t_ours, _ = _time(ours)
    t_ref, _ = _time(reference)
    return {"us_per_call_ours": 1e6 * t_ours / calls, "us_per_call_reference": 1e6 * t_ref / calls,
            "speedup": t_ref / t_ours}


if __name__ == "__main__":
    import argparse
    import json

    parser = argparse.ArgumentParser(
        prog="python -m bench.bench_discrepancy",
        description="The discrepancy workflow's bench; prints its figures as JSON.")
    part = parser.add_mutually_exclusive_group()
    part.add_argument("--injector", action="store_true",
                      help="only the independent injector's matrix (about 10 min on 2 cores)")
    part.add_argument("--bases", action="store_true",
                      help="only the base-independence table (about 25 min on 2 cores)")
    args = parser.parse_args()
    if args.injector:
        print(json.dumps(injector_sources(), indent=1))
    elif args.bases:
        print(json.dumps(base_independence(), indent=1))
    else:
        print(json.dumps(run(), indent=1))
