"""Locate -> name -> add -> show, repeated until no candidate beats the noise.

The base family is fitted per configuration on its identification run and judged on that
configuration's held-out runs. Each round:

1. **locate**: residual analysis of the current model on every run (:mod:`.locate`);
2. **name**: every remaining candidate's term is added in turn, refitted jointly on the
   identification run, and scored by the held-out error it removes, penalised by the Bayesian
   information criterion (BIC) with an effective sample size from the residual's correlation
   time, so that a term fitting noise or structure that does not generalise loses;
3. **add**: the winner (if it clears the gain and BIC thresholds and improves most held-out
   runs) joins the model, keeping its parameters per configuration; every candidate is scored
   after a joint refit, in which the earlier terms' nonlinear parameters are searched again
   with the candidate in place, from two starting points (:func:`.effects.fit_joint`);
4. **show**: RMSE before/after on identification and held-out runs, recorded per effect.

When the search ends, effects the load cells show (:mod:`.evidence`) that the final model did not
take are scored once more and reported as ``measured_within_reach``: named, not added.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
from tqdm import tqdm

from hysteresis._blas import single_thread_blas
from hysteresis.base import HysteresisError, HysteresisModel
from hysteresis.discrepancy._ops import FloatArray
from hysteresis.discrepancy.effects import (
    CANDIDATES,
    EFFECT_NAMES,
    FORM_ON_BASE_FACTOR,
    BaseFactory,
    ComposedModel,
    Effect,
    Term,
    claiming,
    fit_joint,
    fit_with_effect,
    memoised_fits,
    only_forms,
    screened_sse,
)
from hysteresis.discrepancy.errors import DiscrepancyError
from hysteresis.discrepancy.evidence import (
    corroboration,
    output_tension_follows,
    tension_speed_share,
)
from hysteresis.discrepancy.identifiability import force_statement, statement
from hysteresis.discrepancy.library import screen
from hysteresis.discrepancy.locate import autocorrelation, locate
from hysteresis.discrepancy.parallel import map_ordered
from hysteresis.discrepancy.runs import RunData, concat_runs

log = logging.getLogger(__name__)


@dataclass
class WorkflowSettings:
    """Knobs of the workflow (defaults are what the tests and the pipeline use)."""

    candidates: tuple[str, ...] = EFFECT_NAMES
    max_effects: int = 3
    #: A candidate must remove at least this fraction of the held-out RMSE ...
    min_relative_gain: float = 0.2
    #: ... lower the held-out BIC by at least this much ...
    max_delta_bic: float = -10.0
    #: ... and improve at least this fraction of the held-out runs.
    min_runs_improved: float = 0.5
    #: Stop when the held-out RMSE is within this factor of the measurement-noise floor.
    noise_factor: float = 2.0
    #: Physical evidence beyond the output fit: a candidate that claims something the load
    #: cells can read (a friction change, a dead travel) must show in that reading and goes
    #: first when it does (False: judge on the output alone, for comparison).
    physical_evidence: bool = True
    #: When no single candidate clears the bar and nothing is named yet, try every pair: two
    #: effects that interact (the base bends to one and hides the other) are added together
    #: when the pair removes at least ``min_relative_gain`` more than its better member alone.
    #: After a first effect the search would look for a third and a fourth at once: it was
    #: the slowest sources' largest cost (a Bouc-Wen plant's strength-2 speed friction: 73 of
    #: its 119 s CPU, for nothing), and a pair it added carried a passenger.
    pair_search: bool = True
    #: The pair search tries the pairs with at least one member among this many of the best
    #: single candidates (by delta BIC; 15 of the 21 pairs of seven at 3). The partner may rank
    #: anywhere: a member of an interacting pair often makes the fit worse alone (a correct
    #: delay against a base that bent to mimic it). ``None``: every pair.
    pair_pool: int | None = 3
    #: Search the earlier terms' nonlinear parameters again with each candidate in place, from
    #: two starting points (:func:`.effects.fit_joint`; False: they stay where they were
    #: chosen, only the linear parameters are refitted).
    joint_retune: bool = True
    #: ``no_missing_effect`` only while the held-out RMSE stays within this multiple of the
    #: measurement-noise floor (:func:`.locate.noise_floor`); a larger residual that no
    #: candidate explains is ``unexplained``, never called clean.
    clean_factor: float = 5.0
    #: Processes that score the candidates (forked; 0: every core this process may use,
    #: 1: in this process; the stage sets it from its own ``workers``). The answer does not
    #: depend on it.
    workers: int = 1
    progress: bool = False
    #: After an effect is named, each of its other forms is fitted in its place and judged on
    #: the held-out runs; the forms within :data:`FORM_BIC_MARGIN` of the named one are
    #: reported as not separable from it (False: the form the identification fit chose, alone).
    compare_forms: bool = True


@dataclass
class Group:
    """One configuration: its identification run and held-out runs."""

    key: str
    ident: RunData
    heldout: list[RunData]


def group_runs(runs: Sequence[RunData]) -> list[Group]:
    """Runs grouped by configuration; each group needs one identification and >= 1 held-out run."""
    by: dict[str, list[RunData]] = {}
    for r in runs:
        by.setdefault(r.config_key, []).append(r)
    groups = []
    for key, rs in by.items():
        ident = [r for r in rs if r.role == "identification"]
        held = [r for r in rs if r.role == "heldout"]
        if not ident:
            raise HysteresisError(f"configuration {key}: no identification run "
                                  f"(runs: {', '.join(r.run_id for r in rs)})")
        if not held:
            raise HysteresisError(f"configuration {key}: no held-out run to judge on "
                                  f"(runs: {', '.join(r.run_id for r in rs)})")
        # Several identification records of one configuration are fitted as one sequence.
        groups.append(Group(key, concat_runs(ident), held))
    if not groups:
        raise HysteresisError("no runs given")
    return groups


def effective_n(residual: FloatArray) -> float:
    """Sample size corrected for correlation: N / (lag where the autocorrelation < 1/e)."""
    n = residual.size
    acf = autocorrelation(residual, min(n - 1, 2000))
    below = np.flatnonzero(acf < np.exp(-1.0))
    tau = int(below[0]) if below.size else n
    return float(max(n / max(tau, 1), 2.0))


def delta_bic(rmse_before: float, rmse_after: float, k: int, n_eff: float) -> float:
    """BIC change of a model with ``k`` more parameters: n_eff ln(MSE ratio) + k ln(n_eff)."""
    ratio = max(rmse_after, 1e-300) ** 2 / max(rmse_before, 1e-300) ** 2
    return n_eff * float(np.log(ratio)) + k * float(np.log(n_eff))


def _rmse(e: FloatArray) -> float:
    return float(np.sqrt(np.mean(e**2)))


@dataclass
class Evaluation:
    """Predictions of a set of per-configuration models on all runs."""

    ident_pred: dict[str, FloatArray] = field(default_factory=dict)
    held_pred: dict[str, FloatArray] = field(default_factory=dict)
    #: The models that made them, by configuration.
    models: dict[str, ComposedModel] = field(default_factory=dict)

    def errors(self, groups: Sequence[Group]) -> tuple[FloatArray, FloatArray]:
        e_id = np.concatenate([g.ident.y - self.ident_pred[g.ident.run_id] for g in groups])
        e_h = np.concatenate([r.y - self.held_pred[r.run_id] for g in groups for r in g.heldout])
        return e_id, e_h

    def per_run_rmse(self, groups: Sequence[Group]) -> dict[str, float]:
        return {r.run_id: _rmse(r.y - self.held_pred[r.run_id]) for g in groups for r in g.heldout}


def evaluate(models: dict[str, ComposedModel], groups: Sequence[Group]) -> Evaluation:
    ev = Evaluation(models=dict(models))
    for g in groups:
        m = models[g.key]
        ev.ident_pred[g.ident.run_id] = m.predict(g.ident)
        for r in g.heldout:
            ev.held_pred[r.run_id] = m.predict(r)
    return ev


def fit_models(base_factory: BaseFactory, groups: Sequence[Group],
               terms: dict[str, list[Term]]) -> dict[str, ComposedModel]:
    return {g.key: ComposedModel(base_factory, terms.get(g.key, [])).fit(g.ident) for g in groups}


def score_candidate(effect: Effect, base_factory: BaseFactory, groups: Sequence[Group],
                    terms: dict[str, list[Term]], before: Evaluation,
                    n_eff: float, load_cells: dict[str, Any] | None = None, *,
                    joint_retune: bool = True) -> dict[str, Any]:
    """Add ``effect`` to every configuration's model, refit, and measure what it removes;
    for a candidate with a load-cell claim, also read the load cells for it (``load_cells``:
    that reading when already made, it does not depend on the model).
    ``joint_retune``: search the earlier terms' nonlinear parameters again (:func:`fit_joint`).

    Where the load cells show what the effect claims, only the forms that make the claim are
    searched: the reading measured the mechanism (on the virtual rig a friction asymmetry the
    two load cells read was otherwise fitted as a held loading gain, a form the reading does
    not speak for, and lost its place to a stretch)."""
    evidence = load_cells if load_cells is not None else corroboration(
        effect.name, [g.ident for g in groups])
    if evidence.get("corroborated"):
        effect = claiming(effect)
    models = {}
    for g in groups:
        fixed = terms.get(g.key, [])
        models[g.key] = (fit_joint(base_factory, fixed, effect, g.ident) if joint_retune
                         else fit_with_effect(base_factory, fixed, effect, g.ident))
    after = evaluate(models, groups)
    e_id0, e_h0 = before.errors(groups)
    e_id1, e_h1 = after.errors(groups)
    h0, h1 = _rmse(e_h0), _rmse(e_h1)
    k = effect.n_params * len(groups)
    d_bic = delta_bic(h0, h1, k, n_eff)
    r0, r1 = before.per_run_rmse(groups), after.per_run_rmse(groups)
    improved = float(np.mean([r1[k_] < r0[k_] for k_ in r0]))
    # SINDy-style evidence: how much of the held-out residual the term's contribution explains.
    delta = np.concatenate([after.held_pred[r.run_id] - before.held_pred[r.run_id]
                            for g in groups for r in g.heldout])
    den = float(np.dot(delta, delta))
    explained = 0.0
    if den > 0:
        explained = float(np.dot(e_h0, delta) ** 2 / (den * float(np.dot(e_h0, e_h0))))
    params = {}
    for g in groups:
        term = models[g.key].terms[-1]
        coef = models[g.key].coef_
        params[g.key] = {**term.to_dict(), "coefficients": [float(c) for c in coef]}
    forms = {models[g.key].terms[-1].form for g in groups}
    if evidence.get("claim") is not None and not effect.claims(forms):
        # a backlash claims a dead travel at the reversals, a direction-dependent friction a
        # pull/release ratio; a static dead band or a direction-dependent gain claims nothing
        # the load cells read
        evidence = {"claim": None, "per_configuration": {}, "corroborated": None,
                    "note": f"form {'/'.join(sorted(forms))} makes no load-cell claim"}
    return {
        "name": effect.name,
        "models": models,
        "after": after,
        "rmse_before": _rmse(e_id0),
        "rmse_after": _rmse(e_id1),
        "heldout_rmse_before": h0,
        "heldout_rmse_after": h1,
        "relative_gain": 1.0 - h1 / h0 if h0 > 0 else 0.0,
        "delta_bic": float(d_bic),
        "n_eff": n_eff,
        "n_params": k,
        "runs_improved": improved,
        "residual_explained": explained,
        # A load-cell claim must show in the load cells (None: the candidate makes no such
        # claim, or the runs lack the channels the reading needs).
        "load_cell_evidence": evidence,
        "heldout_per_run": {rid: {"before": r0[rid], "after": r1[rid]} for rid in r0},
        "parameters": params,
    }


def _best_pair(scores: list[dict[str, Any]], base_factory: BaseFactory, groups: Sequence[Group],
               current: Evaluation, n_eff: float, load_cells: dict[str, Any],
               st: WorkflowSettings) -> list[dict[str, Any]]:
    """Two candidates that clear the bar only together (greedy search cannot see them).

    Every pair of candidates whose evidence does not contradict them, at least one of them
    among the ``pair_pool`` best, is tried: the one with
    the better delta BIC alone is fitted first, the other on top. The pair is judged against
    the model before both, like a single candidate (gain, delta BIC with both terms'
    parameters, held-out runs improved), and must also remove ``min_relative_gain`` more than
    its better member alone: the interaction itself has to clear the bar, so a strong single
    term cannot carry a passenger in. Returns ``[first, second]`` scores (the second relative
    to the first) of the best pair by delta BIC, or ``[]``.
    """
    from itertools import combinations

    pool = [s for s in scores
            if not st.physical_evidence or s["load_cell_evidence"]["corroborated"] is not False]
    lead = len(pool) if st.pair_pool is None else max(1, int(st.pair_pool))
    h0 = _rmse(current.errors(groups)[1])
    r0 = current.per_run_rmse(groups)
    best: list[dict[str, Any]] = []
    best_bic = np.inf
    # sorted by delta BIC: a is the better one
    pairs = [(i, j) for i, j in combinations(range(len(pool)), 2) if i < lead]

    def second(pair: tuple[int, int]) -> dict[str, Any]:
        a, b = pool[pair[0]], pool[pair[1]]
        on_a = {g.key: list(a["models"][g.key].terms) for g in groups}
        return score_candidate(CANDIDATES[b["name"]], base_factory, groups, on_a, a["after"],
                               n_eff, load_cells[b["name"]], joint_retune=st.joint_retune)

    scored = map_ordered(second, pairs, workers=st.workers, expected=(HysteresisError,))
    for (i, j), s2 in zip(pairs, scored, strict=True):
        if isinstance(s2, BaseException):
            continue
        a, b = pool[i], pool[j]
        h1 = s2["heldout_rmse_after"]
        k = a["n_params"] + s2["n_params"]
        d_bic = delta_bic(h0, h1, k, n_eff)
        r1 = s2["after"].per_run_rmse(groups)
        gain = 1.0 - h1 / h0 if h0 > 0 else 0.0
        joint = {"names": [a["name"], b["name"]], "relative_gain": gain, "delta_bic": d_bic,
                 "n_params": k, "runs_improved": float(np.mean([r1[r] < r0[r] for r in r0])),
                 "gain_over_better_member": gain - max(a["relative_gain"], b["relative_gain"]),
                 "heldout_rmse_before": h0, "heldout_rmse_after": h1}
        if (gain >= st.min_relative_gain and d_bic <= st.max_delta_bic
                and joint["gain_over_better_member"] >= st.min_relative_gain
                and joint["runs_improved"] >= st.min_runs_improved
                and d_bic < best_bic):
            best_bic = d_bic
            s2["pair"] = joint
            best = [a, s2]
    return best


def _clears_bar(s: dict[str, Any], st: WorkflowSettings) -> bool:
    """The output's bar: gain, delta BIC and the held-out runs improved."""
    return bool(s["relative_gain"] >= st.min_relative_gain and s["delta_bic"] <= st.max_delta_bic
                and s["runs_improved"] >= st.min_runs_improved)


def _accept(s: dict[str, Any], st: WorkflowSettings) -> bool:
    if not st.physical_evidence:
        return _clears_bar(s, st)
    return _clears_bar(s, st) and s["load_cell_evidence"]["corroborated"] is not False


def _compact_locate(loc: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in loc.items() if k != "noise_floor_per_run"}


def reach_check(base_factory: BaseFactory, ident: RunData, names: Sequence[str], *,
                strength: float = 0.1, tol: float = 0.3) -> dict[str, float]:
    """How much of each effect the plain base family absorbs on its own.

    The base's own prediction is distorted by the effect's term at a moderate strength
    (input-side: the middle of its parameter grid; output-side: features scaled to
    ``strength`` x the output's standard deviation); the plain base is refitted to the distorted
    signal. Returns the remaining fraction of the distortion (near 0: within the base's reach).
    """
    # through the composed model, so a base that reads a channel (play widths following the
    # output tension) is the same model here as in the search
    base = ComposedModel(base_factory).fit(ident)
    y0 = base.predict(ident)
    out: dict[str, float] = {}
    for name in names:
        eff = CANDIDATES[name]
        if not eff.available(ident):
            continue
        grid = [g for g in eff.grid(ident) if eff.form(g) == eff.first_form]
        theta = grid[len(grid) // 2]
        ctx = eff.context(ident)
        seen = eff.delayed(ident, theta)  # the same path as the composed model's input
        u = (eff.transform_input(seen, seen.u, theta, ctx) if eff.side_of(theta) == "input"
             else ident.u)
        y_syn = base.predict(replace(ident, u=u))
        if eff.n_linear_of(theta):
            phi = eff.features(ident, theta, y_syn, ctx)
            contrib = phi @ np.ones(phi.shape[1])
            sd = float(np.std(contrib))
            if sd > 0:
                y_syn = y_syn + contrib * (strength * float(np.std(y0)) / sd)
        dist = _rmse(y_syn - y0)
        if dist == 0:
            continue
        distorted = replace(ident, y=y_syn)
        refit = ComposedModel(base_factory).fit(distorted)
        out[name] = _rmse(y_syn - refit.predict(distorted)) / dist
    return out


#: The held-out runs are judged as the end of the session recorded before them (runs joined
#: by :func:`.runs.chain_records`) once that lowers the held-out RMSE by this fraction.
SESSION_GAIN = 0.1


def _fit_plain(base_factory: BaseFactory, groups: list[Group], base_name: str
               ) -> dict[str, ComposedModel]:
    """The base alone on each configuration; a base that cannot take these runs at all (a
    Preisach plane of positive density under an output flat around zero) is one line naming
    the way out, not a traceback from inside its fit."""
    try:
        return fit_models(base_factory, groups, {g.key: [] for g in groups})
    except DiscrepancyError:
        raise
    except HysteresisError as err:
        raise DiscrepancyError(
            f"base {base_name} cannot be fitted to these runs ({err}); base_family=auto "
            "ranks the families and passes over one that cannot") from None


def run_workflow(runs: Sequence[RunData], base_factory: BaseFactory, *, base_name: str,
                 settings: WorkflowSettings | None = None,
                 model_error: dict[str, FloatArray] | None = None,
                 session: Sequence[RunData] | None = None,
                 reach_within: float | None = None) -> dict[str, Any]:
    """The whole workflow (see :func:`_run_workflow`), BLAS pinned to one thread: the problems
    are thousands of tiny least-squares solves where threads only add contention."""
    with single_thread_blas(), memoised_fits():
        return _run_workflow(runs, base_factory, base_name=base_name, settings=settings,
                             model_error=model_error, session=session,
                             reach_within=reach_within)


def _run_workflow(runs: Sequence[RunData], base_factory: BaseFactory, *, base_name: str,
                  settings: WorkflowSettings | None = None,
                  model_error: dict[str, FloatArray] | None = None,
                  session: Sequence[RunData] | None = None,
                  reach_within: float | None = None) -> dict[str, Any]:
    """The whole workflow; returns the report dict (plus ``_models``/``_evaluations`` for plots).

    ``model_error`` optionally maps identification run ids to a model-error signal (the UKF's
    f_h of seed 000); it is regressed on each winner's term as extra evidence.

    ``session``: the same runs with each held-out run joined to the runs recorded before it.
    Each round first asks whether the model as it stands predicts them
    :data:`SESSION_GAIN` better so (only predictions change: the fits are on the
    identification runs); from the round where it does, the held-out runs are judged that
    way, and every earlier step is re-evaluated on them (report: ``runs_joined``, each
    round's comparison until then).
    A plain base may miss it while an effect it lacks (a speed term at a run's first sample)
    hides the state the earlier runs left.

    ``reach_within``: the workflow stops after scoring its first round's candidates when none
    of them alone brings the held-out RMSE within this many times the noise floor (report:
    ``stopped``; nothing named, no pair searched). For a base asked only whether one term
    explains the source to the noise (:func:`.ranking.auto_base` after a clean answer above
    it), the later rounds were most of its cost and, one term short, are not expected to
    get there.
    """
    st = settings or WorkflowSettings()
    groups = group_runs(runs)
    joins: list[dict[str, Any]] = []  # each round's comparison, until the runs are joined
    _check_candidates(st.candidates)
    terms: dict[str, list[Term]] = {g.key: [] for g in groups}
    models = _fit_plain(base_factory, groups, base_name)
    current = evaluate(models, groups)
    all_runs = _runs_of(groups)
    reach = reach_check(base_factory, groups[0].ident, st.candidates)
    within = sorted(k for k, v in reach.items() if v < 0.3)
    effects: list[dict[str, Any]] = []
    located: list[dict[str, Any]] = []
    rankings: list[list[dict[str, Any]]] = []
    screens: list[dict[str, list[dict[str, Any]]]] = []
    evaluations = [current]
    remaining = [n for n in st.candidates if all(CANDIDATES[n].available(r) for r in all_runs)]
    skipped = [n for n in st.candidates if n not in remaining]
    failed: dict[str, str] = {}
    # The load cells' reading depends on the data only: made once, reused every round.
    load_cells = {n: corroboration(n, [g.ident for g in groups]) for n in remaining}
    # The last round's scores, while they were made against the model as it stands.
    final_scores: dict[str, dict[str, Any]] = {}
    stopped: dict[str, Any] | None = None
    for round_ in range(st.max_effects + 1):
        if session is not None and not any(j["joined"] for j in joins) and (
                switched := _joined_session(session, evaluations, groups, round_, joins)):
            groups, evaluations = switched
            all_runs, current = _runs_of(groups), evaluations[-1]
        preds = [current.ident_pred.get(r.run_id, current.held_pred.get(r.run_id))
                 for r in all_runs]
        loc = locate(all_runs, [p for p in preds if p is not None])
        model_name = "+".join([base_name, *[e["name"] for e in effects]])
        located.append({"round": round_, "model": model_name, **_compact_locate(loc)})
        _, e_h = current.errors(groups)
        if round_ == st.max_effects or not remaining \
                or _rmse(e_h) <= st.noise_factor * loc["noise_floor"]:
            break
        n_eff = float(sum(effective_n(r.y - current.held_pred[r.run_id])
                          for g in groups for r in g.heldout))
        scores = _score_all(remaining, base_factory, groups, terms, current, n_eff, load_cells,
                            st, round_, failed)
        rankings.append([_public(s) for s in scores])
        screens.append(_screen(groups, current, remaining))
        final_scores = {s["name"]: s for s in scores}
        if reach_within is not None and round_ == 0 and (
                stopped := _out_of_reach(scores, loc["noise_floor"], reach_within)):
            break
        added = _winners(scores, st, len(effects), loc["rmse_over_noise"],
                         partial(_best_pair, scores, base_factory, groups, current, n_eff,
                                 load_cells, st), noise_floor=loc["noise_floor"])
        if not added:
            break
        for k, offered in enumerate(added):
            # judged against the model before this addition (a pair's second: after the
            # first, which it was fitted on, so a pair keeps its forms)
            chosen, forms = (compare_forms(offered, base_factory, groups, terms, current, n_eff,
                                           load_cells[offered["name"]], st,
                                           noise_floor=loc["noise_floor"],
                                           switch=len(added) == 1)
                             if st.compare_forms else (offered, None))
            effects.append(_effect_entry(chosen, added, k, scores, loc, groups, current,
                                         model_error, forms))
            for g in groups:
                terms[g.key] = list(chosen["models"][g.key].terms)
            models, current = chosen["models"], chosen["after"]
            evaluations.append(current)
            remaining.remove(chosen["name"])
            final_scores = {}
    measured = (_measured_within_reach(remaining, load_cells, base_factory, groups, terms,
                                       current, base_name, [e["name"] for e in effects], st,
                                       final_scores)
                if st.physical_evidence and stopped is None else [])
    return _assemble(groups, evaluations, all_runs, base_name, effects, st, models, {
        "located": located, "within_base_reach": within, "measured_within_reach": measured,
        "within_base_reach_note": _reach_note(within, base_name),
        "reach_remaining_fraction": reach,
        "candidates_skipped": {n: "needs a channel the runs do not carry (tension)"
                               for n in skipped},
        "candidates_failed": failed, "rankings": rankings, "library_screen": screens,
        "runs_joined": joins, "stopped": stopped})


def _out_of_reach(scores: Sequence[Mapping[str, Any]], noise_floor: float,
                  reach_within: float) -> dict[str, Any] | None:
    """Why the workflow stops after its first round (:func:`_run_workflow`'s ``reach_within``):
    no candidate alone brings the held-out RMSE within ``reach_within`` x ``noise_floor``.
    None when one does (or none could be scored: nothing to judge by)."""
    if not scores or noise_floor <= 0:
        return None
    best = min(scores, key=lambda s: float(s["heldout_rmse_after"]))
    over = float(best["heldout_rmse_after"]) / noise_floor
    if over <= reach_within:
        return None
    note = (f"stopped after the first round: no term alone brings the held-out RMSE within "
            f"{reach_within:g}x the noise floor (best: {best['name']}, {over:.2g}x)")
    log.info(note)
    return {"round": 0, "best": best["name"], "best_over_noise": over,
            "reach_within": reach_within, "note": note}


def _check_candidates(names: Sequence[str]) -> None:
    for name in names:
        if name not in CANDIDATES:
            raise HysteresisError(f"unknown candidate {name!r}; known: {', '.join(EFFECT_NAMES)}")


def _settles_output(s: dict[str, Any], st: WorkflowSettings, noise_floor: float) -> bool:
    """Does a candidate the load cells contradict explain the output to the noise by itself?

    A load-cell reading is a model of the drive (a dead travel read as the intercept of the
    tension's rise, a friction ratio on the sliding samples), and a drive unlike the one it
    assumes can read against an effect that is there: a friction step ahead of a linear
    spring reads -0.11 of the span clean, so a 1 mm backlash in front of a textbook Bouc-Wen
    read -0.05 while its term left 1.0x the noise floor and the source was ``unexplained``.
    Such a candidate clears the bar when, alone, it leaves the held-out residual within
    ``noise_factor`` x the noise floor (nothing is then left for the effect the reading
    would prefer)."""
    if not (st.physical_evidence and s["load_cell_evidence"]["corroborated"] is False):
        return False
    return bool(_clears_bar(s, st) and s["heldout_rmse_after"] <= st.noise_factor * noise_floor)


def _overruled(s: dict[str, Any], noise_floor: float) -> dict[str, Any]:
    """``s`` with its evidence saying the load cells did not show it, and why it is named."""
    ev = s["load_cell_evidence"]
    over = s["heldout_rmse_after"] / noise_floor if noise_floor > 0 else 0.0
    return {**s, "load_cell_evidence": {
        **ev, "note": f"the load cells do not show its {ev['claim']}; named because it alone "
                      f"leaves {over:.1f}x the noise floor held out"}}


def _winners(scores: list[dict[str, Any]], st: WorkflowSettings, n_effects: int,
             over_noise: float, pairs: Callable[[], list[dict[str, Any]]], *,
             noise_floor: float = 0.0) -> list[dict[str, Any]]:
    """This round's additions: the best acceptable candidate, a candidate the load cells
    contradict that explains the output to the noise alone (:func:`_settles_output`), or a
    pair (``pairs``)."""
    # A change the load cells show is measured, not inferred from the output:
    # an acceptable candidate with that corroboration goes ahead of the others.
    winner = next((s for s in scores if st.physical_evidence and _accept(s, st)
                   and s["load_cell_evidence"]["corroborated"]), None)
    if winner is None:
        # A contradicted term that settles the output ranks by its delta BIC among the
        # acceptable ones: behind them it lost to a held gain that left 11x the noise
        # where it left 1.8x (a backlash in front of a Bouc-Wen loop, loaded start).
        winner = next((s for s in scores
                       if _accept(s, st) or _settles_output(s, st, noise_floor)), None)
        if winner is not None and not _accept(winner, st):
            winner = _overruled(winner, noise_floor)
    if winner is not None:
        return [winner]
    # Pairs only before a first effect, and while what is left would not be called clean: a
    # residual within the clean band has nothing for two more terms to explain, and the
    # pair search is the workflow's most expensive step.
    if (st.pair_search and n_effects == 0 and st.max_effects >= 2
            and over_noise > st.clean_factor):
        return pairs()
    return []


def _runs_of(groups: Sequence[Group]) -> list[RunData]:
    return [r for g in groups for r in (g.ident, *g.heldout)]


def _joined_session(session: Sequence[RunData], evaluations: Sequence[Evaluation],
                    groups: Sequence[Group], round_: int, joins: list[dict[str, Any]]
                    ) -> tuple[list[Group], list[Evaluation]] | None:
    """The session's groups and every step re-evaluated on them, when the model as it stands
    (the last evaluation's) predicts the joined held-out runs :data:`SESSION_GAIN` better than
    it does the separate ones; else None. The comparison is appended to ``joins``."""
    joined = group_runs(session)
    now = evaluations[-1]
    ev = evaluate(now.models, joined)
    apart, together = _rmse(now.errors(groups)[1]), _rmse(ev.errors(joined)[1])
    ok = together <= (1.0 - SESSION_GAIN) * apart
    joins.append({"round": round_, "heldout_rmse_separate": apart,
                  "heldout_rmse_joined": together, "joined": ok})
    if not ok:
        return None
    return joined, [evaluate(e.models, joined) for e in evaluations[:-1]] + [ev]


def _score_all(remaining: Sequence[str], base_factory: BaseFactory, groups: Sequence[Group],
               terms: dict[str, list[Term]], current: Evaluation, n_eff: float,
               load_cells: dict[str, dict[str, Any]], st: WorkflowSettings, round_: int,
               failed: dict[str, str]) -> list[dict[str, Any]]:
    """Every remaining candidate scored against the current model, best delta BIC first; a
    candidate the base cannot be refitted with goes to ``failed`` with the reason."""
    def score(name: str) -> dict[str, Any]:
        return score_candidate(CANDIDATES[name], base_factory, groups, terms, current, n_eff,
                               load_cells[name], joint_retune=st.joint_retune)

    scores = []
    results = map_ordered(score, remaining, workers=st.workers, expected=(HysteresisError,))
    it = tqdm(zip(remaining, results, strict=True), total=len(remaining),
              desc=f"round {round_}: candidates", disable=not st.progress)
    for name, result in it:
        if isinstance(result, BaseException):
            # The base cannot be refitted with this term (e.g. a density that no longer
            # fits): the candidate is reported as not scorable, the others go on.
            failed[name] = str(result)
        else:
            scores.append(result)
    scores.sort(key=lambda s: s["delta_bic"])
    return scores


def _assemble(groups: Sequence[Group], evaluations: list[Evaluation],
              all_runs: Sequence[RunData], base_name: str, effects: list[dict[str, Any]],
              st: WorkflowSettings, models: dict[str, ComposedModel], parts: dict[str, Any]
              ) -> dict[str, Any]:
    """The report: verdict, identifiability, residual and summary, with ``parts`` (located
    rounds, reach, rankings, screens) in their places."""
    current = evaluations[-1]
    e_id0, e_h0 = evaluations[0].errors(groups)
    e_id1, e_h1 = current.errors(groups)
    residual = _final_residual(groups, current)
    channels = {c for c in ("tension", "tension_out")
                if all(getattr(r, c) is not None for r in all_runs)}
    report: dict[str, Any] = {
        "base_family": base_name,
        "verdict": _verdict(effects, residual, st.clean_factor),
        # the first effect's class when the channels present cannot tell it from another
        "identifiability": _identifiability(effects, channels, groups, st),
        "residual": residual,
        "effects": effects,
        "located": parts["located"],
        "within_base_reach": parts["within_base_reach"],
        "measured_within_reach": parts["measured_within_reach"],
        "within_base_reach_note": parts["within_base_reach_note"],
        "reach_remaining_fraction": parts["reach_remaining_fraction"],
        "candidates_skipped": parts["candidates_skipped"],
        "candidates_failed": parts["candidates_failed"],
        "rankings": parts["rankings"],
        "library_screen": parts["library_screen"],
        "runs_joined": parts["runs_joined"],
        "stopped": parts["stopped"],
        "summary": {
            "configurations": [g.key for g in groups],
            "identification_runs": [g.ident.run_id for g in groups],
            "heldout_runs": [r.run_id for g in groups for r in g.heldout],
            "rmse_before": _rmse(e_id0), "rmse_after": _rmse(e_id1),
            "heldout_rmse_before": _rmse(e_h0), "heldout_rmse_after": _rmse(e_h1),
            "heldout_reduction": 1.0 - _rmse(e_h1) / _rmse(e_h0) if _rmse(e_h0) > 0 else 0.0,
        },
    }
    report["_models"] = models
    report["_evaluations"] = evaluations
    report["_groups"] = groups
    return report


def _identifiability(effects: list[dict[str, Any]], channels: set[str],
                     groups: Sequence[Group], st: WorkflowSettings) -> dict[str, Any] | None:
    """The first effect's class: a pair the channels cannot tell apart, or a stretch that reads
    a tension carrying a speed-dependent force."""
    if not effects:
        return None
    fixed = statement(effects[0], channels,
                      follows_output=output_tension_follows([g.ident for g in groups])
                      if "tension_out" in channels else None)
    if fixed is not None or effects[0]["name"] != "tendon_elongation":
        return fixed
    return force_statement(effects[0], tension_speed_share([g.ident for g in groups]),
                           min_gain=st.min_relative_gain, max_delta_bic=st.max_delta_bic)


#: Another form of a named effect is told apart from the named one when the held-out runs
#: prefer one of them by this much BIC or more (Kass and Raftery's "very strong") ...
FORM_BIC_DECISIVE = 10.0
#: ... or by at least this much ("positive") while the two forms' held-out predictions differ
#: by this multiple of the measurement-noise floor (RMS) or more. Else the record cannot tell
#: them apart and both are reported: with thousands of nearly white samples a BIC difference of
#: 4-6 came from held-out errors 0.5-1.5 % apart, a clean-room tanh stop against a cubic
#: softening, or a 400 s exponential creep against a linear one, on an 80 s record.
FORM_BIC_MARGIN = 2.0
FORM_APART_NOISE = 0.5


def compare_forms(chosen: dict[str, Any], base_factory: BaseFactory, groups: Sequence[Group],
                  terms: dict[str, list[Term]], before: Evaluation, n_eff: float,
                  load_cells: dict[str, Any], st: WorkflowSettings, *, noise_floor: float,
                  switch: bool = True) -> tuple[dict[str, Any], dict[str, Any]]:
    """Each other reported form of the ``chosen`` effect fitted in its place (its grid points
    only, the same earlier ``terms``) and judged on the held-out runs against ``before``.

    The identification fit chose the form; the held-out runs judge it, as they judge the
    effect. Two forms are told apart when the held-out runs prefer one by
    :data:`FORM_BIC_DECISIVE` or more, or by :data:`FORM_BIC_MARGIN` or more while their
    held-out predictions differ by :data:`FORM_APART_NOISE` x the noise floor
    (``noise_floor``) or more; else they are not separable. With ``switch``, a form the
    held-out runs tell apart as better (and that clears the acceptance bar) is taken
    instead: on a Bouc-Wen loop with a soft stop the identification run preferred a hard
    stop, which predicted the held-out runs 15 BIC worse than the soft one. Returns the score
    of the form taken and ``{"named", "forms": {form: {heldout_rmse_after,
    delta_bic_vs_named, prediction_apart_over_noise}}, "not_separable": [named, forms not
    told apart...] or []}``. Where the load cells corroborate the effect's claim, only the
    forms that make it are compared (the chosen one
    was chosen among them)."""
    eff = CANDIDATES[chosen["name"]]

    first = _majority(_forms(chosen["name"], chosen["models"], groups))
    ident = groups[0].ident
    others = [f for f in dict.fromkeys(eff.reported_form(g)
                                       for g in [*eff.grid(ident), *eff.compare_grid(ident)])
              if f != first]
    if load_cells.get("corroborated"):
        others = [f for f in others if eff.claims({f})]

    def only(form: str) -> Effect:
        return only_forms(eff, lambda g: eff.reported_form(g) == form, compared=True)

    single = {f: only(f) for f in [first, *others]}

    by_screen = _apart_on_screen(single, first, others, base_factory, groups, terms)
    others = [f for f in others if f not in by_screen]

    def score(form: str) -> dict[str, Any]:
        return score_candidate(single[form], base_factory, groups, terms, before, n_eff,
                               load_cells, joint_retune=st.joint_retune)

    scored = {first: chosen}
    for form, s in zip(others, map_ordered(score, others, workers=st.workers,
                                           expected=(HysteresisError,)), strict=True):
        if not isinstance(s, BaseException):
            scored[form] = s
    held = [r.run_id for g in groups for r in g.heldout]

    def apart(a: dict[str, Any], b: dict[str, Any]) -> float:
        """RMS difference of two fits' held-out predictions, in noise floors."""
        d = np.concatenate([a["after"].held_pred[k] - b["after"].held_pred[k] for k in held])
        return _rmse(d) / max(noise_floor, 1e-300)

    def told_apart(d_bic: float, d_pred: float) -> bool:
        return d_bic >= FORM_BIC_DECISIVE or (d_bic >= FORM_BIC_MARGIN
                                              and d_pred >= FORM_APART_NOISE)

    # a form that contains the named one as a limit is not taken in its place: the
    # identification fit chose the limit, and the held-out runs' preference for the freer form
    # came from its freedom (a viscous damper on the Bouc-Wen plant: |v|^0.93, 18 BIC)
    nesting = {eff.label(t) for t, simpler in eff.nests.items() if eff.label(simpler) == first}
    named = first
    best = min(scored, key=lambda f: scored[f]["heldout_rmse_after"])
    gain_bic = -delta_bic(chosen["heldout_rmse_after"], scored[best]["heldout_rmse_after"], 0,
                          n_eff)
    if (switch and best not in nesting and told_apart(gain_bic, apart(scored[best], chosen))
            and _accept(scored[best], st)):
        named = best
    h_named = scored[named]["heldout_rmse_after"]
    out = {f: {"heldout_rmse_after": s["heldout_rmse_after"],
               "delta_bic_vs_named": delta_bic(h_named, s["heldout_rmse_after"], 0, n_eff),
               "prediction_apart_over_noise": apart(s, scored[named])}
           for f, s in scored.items() if f != named}
    ties = [f for f, v in out.items()
            if not told_apart(abs(v["delta_bic_vs_named"]), v["prediction_apart_over_noise"])]
    out.update({f: {"screened_identification_sse_ratio": r} for f, r in by_screen.items()})
    info = {"named": named, "chosen_on_identification": first, "forms": out,
            "not_separable": [named, *ties] if ties else []}
    return scored[named], info


def _apart_on_screen(single: Mapping[str, Effect], first: str, others: Sequence[str],
                     base_factory: BaseFactory, groups: Sequence[Group],
                     terms: dict[str, list[Term]]) -> dict[str, float]:
    """The forms (of ``others``) a slow base's screening base fits more than
    ``FORM_ON_BASE_FACTOR`` worse on the identification runs than ``first``, with that SSE
    ratio; {} for a base fast enough to search itself.

    A slow base refits for every form compared (seconds each); forms that far apart are told
    apart on the screen, as the search itself does (a Bouc-Wen base's hard stop and cubic
    softening cost 3.5 s of a 60 s source)."""
    def screened(form: str) -> float | None:
        sses = [screened_sse(base_factory, terms.get(g.key, []), single[form], g.ident)
                for g in groups]
        return None if any(x is None for x in sses) else float(sum(x or 0.0 for x in sses))

    own = screened(first) if others else None
    if own is None:
        return {}
    out = {}
    for f in others:
        alt = screened(f)
        if alt is not None and alt > FORM_ON_BASE_FACTOR * own:
            out[f] = alt / max(own, 1e-300)
    return out


def _majority(forms: Mapping[str, str]) -> str:
    values = list(forms.values())
    return max(set(values), key=values.count)


def _effect_entry(chosen: dict[str, Any], added: Sequence[dict[str, Any]], k: int,
                  scores: Sequence[dict[str, Any]], loc: dict[str, Any], groups: Sequence[Group],
                  current: Evaluation, model_error: dict[str, FloatArray] | None,
                  form_comparison: dict[str, Any] | None = None) -> dict[str, Any]:
    """The report's entry for an added effect (``chosen``, the ``k``-th of ``added`` this
    round): its evidence, the form each configuration took, the forms the held-out runs cannot
    tell from it (:func:`compare_forms`) and the errors before and after."""
    eff = CANDIDATES[chosen["name"]]
    evidence = {
        "signature": eff.signature,
        "term": eff.term,
        "relative_gain": chosen["relative_gain"],
        "delta_bic": chosen["delta_bic"],
        "n_eff": chosen["n_eff"],
        "n_params": chosen["n_params"],
        "runs_improved": chosen["runs_improved"],
        "residual_explained": chosen["residual_explained"],
        "load_cell_evidence": chosen["load_cell_evidence"],
        "heldout_per_run": chosen["heldout_per_run"],
        "parameters": chosen["parameters"],
        "runner_up": next((
            {"name": s["name"], "delta_bic": s["delta_bic"],
             "relative_gain": s["relative_gain"]}
            for s in scores if s["name"] != chosen["name"]), None),
        "located_before": _signature_stats(loc),
    }
    if len(added) == 2:
        evidence["added_jointly_with"] = added[1 - k]["name"]
        evidence["pair"] = added[1]["pair"]
    if model_error:
        evidence["model_error_regression"] = _regress_model_error(
            model_error, groups, current, chosen["after"])
    forms = _forms(chosen["name"], chosen["models"], groups)
    evidence["form_per_configuration"] = forms
    if form_comparison is not None:
        evidence["form_comparison"] = form_comparison["forms"]
        evidence["form_chosen_on_identification"] = form_comparison["chosen_on_identification"]
    return {
        "name": chosen["name"],
        "form": _majority(forms),
        # the forms the held-out runs cannot tell from the named one (itself first), or []
        "forms_not_separable": (form_comparison or {}).get("not_separable", []),
        "evidence": evidence,
        "rmse_before": chosen["rmse_before"],
        "rmse_after": chosen["rmse_after"],
        "heldout_rmse_before": chosen["heldout_rmse_before"],
        "heldout_rmse_after": chosen["heldout_rmse_after"],
    }


def _screen(groups: Sequence[Group], current: Evaluation,
            names: Sequence[str]) -> dict[str, list[dict[str, Any]]]:
    """The sparse screen of the linear forms (:func:`.library.screen`) on each configuration's
    identification residual of the current model."""
    out = {}
    for g in groups:
        pred = current.ident_pred[g.ident.run_id]
        out[g.key] = screen(g.ident, g.ident.y - pred, pred, names)
    return out


def _forms(name: str, models: Mapping[str, ComposedModel],
           groups: Sequence[Group]) -> dict[str, str]:
    """The physical form of effect ``name`` each configuration's model took."""
    out = {}
    for g in groups:
        term = next(t for t in models[g.key].terms if t.effect.name == name)
        out[g.key] = term.form
    return out


def _final_residual(groups: Sequence[Group], current: Evaluation) -> dict[str, Any]:
    """The held-out residual of the final model against the measurement noise, and where
    it is largest (what is left for a user to look at)."""
    held = [r for g in groups for r in g.heldout]
    loc = locate(held, [current.held_pred[r.run_id] for r in held])
    return {"heldout_rmse": loc["rmse"], "noise_floor": loc["noise_floor"],
            "rmse_over_noise": loc["rmse_over_noise"], "segments": loc["segments"][:5]}


def _verdict(effects: Sequence[Mapping[str, Any]], residual: Mapping[str, Any],
             clean_factor: float) -> str:
    """``missing_effects_found`` when terms were added; with none, ``no_missing_effect`` only
    if the held-out residual is within ``clean_factor`` x the noise floor, else
    ``unexplained`` (the model misses something none of the candidates names)."""
    if effects:
        return "missing_effects_found"
    return ("no_missing_effect" if residual["rmse_over_noise"] <= clean_factor
            else "unexplained")


#: What each load-cell claim means, for the report's notes.
_CLAIM_TEXT = {
    "dead_travel": "the carriage travels {x} of the input span after every reversal before "
                   "the tendon's tension moves (a dead zone)",
    "direction_ratio": "the friction pulling is {x} times the friction releasing",
    "speed_ratio": "the friction at speed is {x} times the friction at low speed",
}


def _measured_within_reach(remaining: Sequence[str], load_cells: dict[str, dict[str, Any]],
                           base_factory: BaseFactory, groups: Sequence[Group],
                           terms: dict[str, list[Term]], current: Evaluation, base_name: str,
                           added: Sequence[str], st: WorkflowSettings,
                           scored: Mapping[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Effects the load cells show but the final model did not take: named, not added.

    Two effects can leave the same mark on the output (an actuator dead zone and a
    direction-dependent friction both shift the loop from the first motion on), and then the
    term added first reproduces both: the second one's term removes nothing more, so the output
    cannot name it. The load cells can (a dead travel at the reversals, a pull/release friction
    ratio). Each such effect is scored once more against the final model and reported with what
    its term would do; it is not added, because it does not shrink the gap. ``scored``: the
    scores already made against the final model (the search's last round), reused.
    """
    out: list[dict[str, Any]] = []
    h = [r for g in groups for r in g.heldout]
    n_eff = float(sum(effective_n(r.y - current.held_pred[r.run_id]) for r in h))
    model = "+".join([base_name, *added])
    for name in remaining:
        ev = load_cells.get(name, {})
        if not ev.get("corroborated"):
            continue
        s = scored.get(name)
        if s is None:
            try:
                s = score_candidate(CANDIDATES[name], base_factory, groups, terms, current,
                                    n_eff, ev, joint_retune=st.joint_retune)
            except HysteresisError:
                continue
        per = ev["per_configuration"]
        shown = ", ".join(f"{x:.3g}" if ev["claim"] != "dead_travel" else f"{100 * x:.1f} %"
                          for x in per.values())
        change = (f"its term would change the held-out RMSE by "
                  f"{-100 * s['relative_gain']:+.1f} %")
        why = (f"the model so far ({model}) already reproduces its mark on the output: {change}, "
               "under the bar, so it is named but not added" if not _accept(s, st) else
               f"{change}, but the search stopped first (max_effects or the noise floor)")
        out.append({
            "name": name,
            "load_cell_evidence": ev,
            "heldout_rmse_without": s["heldout_rmse_before"],
            "heldout_rmse_with": s["heldout_rmse_after"],
            "relative_gain": s["relative_gain"],
            "delta_bic": s["delta_bic"],
            "parameters": s["parameters"],
            "note": (f"the load cells show {name}: "
                     + _CLAIM_TEXT[ev["claim"]].format(x=shown)
                     + f" in every configuration; {why}"),
        })
    return out


def _reach_note(within: list[str], base_name: str) -> str:
    if not within:
        return f"no candidate is within the {base_name} family's reach"
    one = len(within) == 1
    return (f"{', '.join(within)} {'is' if one else 'are'} already within the {base_name} "
            "family's reach (the plain family absorbs that term's distortion), so "
            f"{'it' if one else 'they'} cannot be found missing from it")


def _public(s: dict[str, Any]) -> dict[str, Any]:
    keys = ("name", "relative_gain", "delta_bic", "rmse_before", "rmse_after",
            "heldout_rmse_before", "heldout_rmse_after", "runs_improved", "residual_explained",
            "load_cell_evidence", "parameters")
    return {k: s[k] for k in keys}


def _signature_stats(loc: dict[str, Any]) -> dict[str, Any]:
    b = loc["breakdown"]
    return {
        "noise_floor": loc["noise_floor"],
        "rmse_over_noise": loc["rmse_over_noise"],
        "phase_rmse": {k: v["rmse"] for k, v in b["phase"].items()},
        "phase_mean": {k: v["mean"] for k, v in b["phase"].items()},
        "velocity_rmse": {k: v["rmse"] for k, v in b["velocity"].items()},
        "amplitude_rmse": {k: v["rmse"] for k, v in b["amplitude"].items()},
        "time_mean": {k: v["mean"] for k, v in b["time"].items()},
    }


def _regress_model_error(model_error: dict[str, FloatArray], groups: Sequence[Group],
                         before: Evaluation, after: Evaluation) -> dict[str, Any]:
    """Regress the model-error rate f_h on the winner term's rate contribution (SINDy-style)."""
    out: dict[str, Any] = {}
    for g in groups:
        f = model_error.get(g.ident.run_id)
        if f is None or f.size != g.ident.n:
            continue
        contrib = after.ident_pred[g.ident.run_id] - before.ident_pred[g.ident.run_id]
        x = np.gradient(contrib, g.ident.t)
        den = float(np.dot(x, x))
        if den == 0:
            continue
        c = float(np.dot(f, x) / den)
        ss = float(np.sum((f - np.mean(f)) ** 2))
        r2 = 1.0 - float(np.sum((f - c * x) ** 2)) / ss if ss > 0 else float("nan")
        out[g.ident.run_id] = {"coefficient": c, "r2": r2}
    return out


def strip_private(report: dict[str, Any]) -> dict[str, Any]:
    """The JSON-able report (drops the fitted objects kept for plotting)."""
    return {k: v for k, v in report.items() if not k.startswith("_")}


#: A discrepancy base must not absorb the effects it is searched for: a free offset takes up a
#: creep and unconstrained weights take up a gain (elongation, saturation). Gamma as a base is
#: therefore the thesis' physical form (weights summing to one, no offset, the widest play at
#: the thesis' 1/6 of the input's range: a span chosen on the data would widen to take up a
#: dead zone, itself a play), but every play starts where the record starts (the fitting
#: defaults' ``start_state="fit"``: a plant starting loaded or at a band edge is clean, and a
#: zero start left its first half second for a term to explain); ``base_params`` still
#: override each entry.
BASE_DEFAULTS: dict[str, dict[str, Any]] = {
    "gamma": {"constraint": "sum_to_one", "fit_offset": False, "start_state": "fit",
              "threshold_fraction": 1.0 / 6.0},
    # plays whose widths follow the output tension (.bases.TensionWidthGamma): the loop's
    # shape free as gamma_free's, its widths the capstan law's
    "gamma_tension": {"constraint": "free", "fit_offset": True, "start_state": "fit",
                      "threshold_fraction": 1.0 / 6.0},
    "linear": {"delay": 0},  # a searched delay would take up the latency looked for
    # the base keeps its physical loop form: the workflow's effects are what bend it, and a
    # form chosen per source would change with the effect hidden in it
    "preisach": {"density_sign": "positive"},
    "coleman_hodgdon": {"b_sign": "negative"},
}

#: Families whose own fit starts every record at rest: as a base, each run starts where the
#: identification record shows the plant starts (:class:`.bases.FromRecordStart`), as the
#: Gamma base takes its fitted start position (``start_state="fit"``) and Preisach starts
#: demagnetised about each run's first input. A plant that starts loaded is then clean, not
#: ``unexplained``.
STARTS_AT_REST = ("bouc_wen", "coleman_hodgdon")

#: Effect forms a base searches on itself as well as on its play-sum screen: a backlash in
#: front of a play sum is a wider play, so the screen fits every width alike, while a smooth
#: loop (Bouc-Wen, Coleman-Hodgdon) behind a backlash is not itself (a Preisach plane's relays
#: shift with it); a backlash whose width follows the speed (``slip``) is a speed-scaled play.
_BACKLASHES = {"dead_zone": "backlash", "rate_dependence": "slip"}
SCREEN_UNSEEN: dict[str, dict[str, str]] = {"bouc_wen": _BACKLASHES,
                                            "coleman_hodgdon": _BACKLASHES}

#: Bases identified in closed form (a least-squares solve): fast enough to search an effect's
#: parameter on themselves. Any other base searches on ``play_sum`` (see ``screen``).
FAST_BASES = ("gamma", "linear", "play_sum", "affine")


def base_factory_for(name: str, *, screen: bool = True,
                     **params: Any) -> Callable[[], HysteresisModel]:
    """Factory for a registered family or one of the local bases (``play_sum``, ``affine``).

    ``screen``: a base outside :data:`FAST_BASES` (an iterative fit: Bouc-Wen,
    Coleman-Hodgdon, Preisach) searches each effect's nonlinear parameter with a play-operator
    sum and is fitted once at the chosen value: a grid of refits of an iterative base is most
    of the workflow's time, and the physical parameter (a delay, a dead band) does not depend
    on which hysteresis model sits beneath it.
    """
    from hysteresis.base import make_family
    from hysteresis.discrepancy.bases import LOCAL_BASES, FromRecordStart, PlaySumModel
    from hysteresis.discrepancy.effects import ScreenedFactory

    params = {**BASE_DEFAULTS.get(name, {}), **params}
    if name in LOCAL_BASES:
        cls = LOCAL_BASES[name]
        return lambda: cls(**params)
    make_family(name, **params)  # fail early on an unknown family or bad parameter
    family: Callable[[], HysteresisModel] = lambda: make_family(name, **params)  # noqa: E731
    real = family
    if name in STARTS_AT_REST:
        real = lambda: FromRecordStart(family)  # noqa: E731
    if screen and name not in FAST_BASES:
        return ScreenedFactory(real, PlaySumModel, unseen=SCREEN_UNSEEN.get(name))
    return real
