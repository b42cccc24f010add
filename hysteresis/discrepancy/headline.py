"""The discrepancy report's one-sentence answer: which effect was added and by how much it cut
the held-out error, or why nothing was, and what the reader must know about the base. Pure:
the JSON-ready report in, a string out."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def headline(report: Mapping[str, Any]) -> str:
    """One sentence: which effect was added and by how much it cut the held-out error (and
    which effects the load cells show that the model already reproduces)."""
    also = _measured(report) + _bases_tried(report) + _misfit(report)
    if not report["effects"]:
        return _nothing_added(report, also)
    parts = []
    ident = report.get("identifiability")
    for i, e in enumerate(report["effects"]):
        cut = 1.0 - e["heldout_rmse_after"] / e["heldout_rmse_before"]
        name = f"{e['name']} ({_form(e)})" if e.get("form") else e["name"]
        if i == 0 and ident:
            name = ident["statement"]
        parts.append(f"{name} (held-out RMSE {e['heldout_rmse_before']:.4g} -> "
                     f"{e['heldout_rmse_after']:.4g}, -{100 * cut:.1f} %)")
    return f"base {report['base_family']} is missing: " + "; then ".join(parts) + also


def _form(effect: Mapping[str, Any]) -> str:
    """The named form, or the forms the held-out runs cannot tell apart."""
    ties = effect.get("forms_not_separable") or []
    if len(ties) < 2:
        return str(effect["form"])
    return " or ".join(ties) + ": not separable on these runs"


def _measured(report: Mapping[str, Any]) -> str:
    """What the load cells show that the model already reproduces (named, not added)."""
    measured = [m["name"] for m in report.get("measured_within_reach", [])]
    return (f"; the load cells also show {', '.join(measured)}, already reproduced by the "
            "model (named, not added)") if measured else ""


def _bases_tried(report: Mapping[str, Any]) -> str:
    """``auto`` tried several bases: the best plain one and each one's RMSE with its terms."""
    tried = report.get("bases_tried") or []
    if len(tried) <= 1 or not report.get("base_selection"):
        return ""
    plain = min(report["base_selection"], key=report["base_selection"].__getitem__)
    others = "; ".join(" + ".join([t["base"], *t["effects"]])
                       + f" {t['heldout_rmse_after']:.4g}"
                       + (" (no term alone near the noise: not searched further)"
                          if t.get("stopped") else "") for t in tried)
    return (f"; base chosen with its terms (best plain family: {plain}; held-out RMSE "
            f"after the terms: {others})")


def _misfit(report: Mapping[str, Any]) -> str:
    """A given base that fits worse than the best family: who answered, or a caution."""
    misfit = report.get("base_misfit")
    given = report.get("given_base")
    if misfit and given:
        named = ", ".join(given["effects"]) or given["verdict"].replace("_", " ")
        return (f"; answered with {misfit['best_family']} because the given base "
                f"{misfit['base']} fits this source {misfit['ratio']:.1f}x worse held out "
                f"plain and {misfit['ratio_with_terms']:.1f}x worse with its terms (with it: "
                f"{named}, which may be its own misfit)")
    if misfit:
        return (f"; caution: base {misfit['base']} with its terms fits this source "
                f"{misfit['ratio']:.1f}x worse held out than {misfit['best_family']} plain, so "
                "what is named may be the base's misfit (base_family=auto picks the best)")
    return ""


def _nothing_added(report: Mapping[str, Any], also: str) -> str:
    """No term added: clean to the noise, or a residual no candidate reduces."""
    ratio = float(report["residual"]["rmse_over_noise"])
    rmse = f"held-out RMSE {report['summary']['heldout_rmse_before']:.4g}, {ratio:.1f}x " \
           "the noise floor"
    reach = report.get("within_base_reach") or []
    absorbed = (f"; within the base's reach (it absorbs them, so these runs cannot tell "
                f"them apart from it): {', '.join(reach)}") if reach else ""
    dependence = report.get("base_dependence")
    if dependence:
        return f"unexplained: {dependence['note']} ({rmse}){also}"
    if report["verdict"] == "unexplained":
        tried_terms = ", ".join(s["name"] for s in (report.get("rankings") or [[]])[0])
        return (f"unexplained: the base {report['base_family']} leaves a residual no "
                f"candidate term explains ({rmse}; tried: {tried_terms or 'none'})"
                f"{_refused(report)}; see the located segments{absorbed}{also}")
    return (f"no missing effect: no candidate term beats the noise on the held-out runs "
            f"(base {report['base_family']}, {rmse}){absorbed}{also}")


#: A candidate the load cells refused is told in the headline when it cut the held-out error by
#: at least this fraction (the stage's default bar for naming an effect): the reader should know
#: the output alone would have named it.
REFUSED_SHOWN_GAIN = 0.2

#: What each load-cell reading measures (the readings of :mod:`.friction`).
_READING = {"speed_ratio": "friction at speed over friction at low speed",
            "direction_ratio": "friction pulling over friction releasing",
            "dead_travel": "dead travel after a reversal, as a fraction of the span"}


def _refused(report: Mapping[str, Any]) -> str:
    """The first round's candidates that cut the held-out error as much as a named effect
    must, refused because the load cells do not show what they claim."""
    out = []
    for s in (report.get("rankings") or [[]])[0]:
        ev = s.get("load_cell_evidence") or {}
        gain = float(s.get("relative_gain", 0.0))
        if ev.get("corroborated") is not False or gain < REFUSED_SHOWN_GAIN:
            continue
        forms = sorted({str(p["form"]) for p in (s.get("parameters") or {}).values()
                        if isinstance(p, Mapping) and p.get("form")})
        reads = ", ".join(f"{float(v):.2f}" for v in (ev.get("per_configuration") or {}).values()
                          if v is not None)
        claim = str(ev.get("claim", ""))
        out.append(f"{s['name']}{' (' + ', '.join(forms) + ')' if forms else ''} would cut "
                   f"it {100 * gain:.0f} % but the load cells do not show it "
                   f"({_READING.get(claim, claim)}: {reads or 'not read'})")
    return "; " + "; ".join(out) if out else ""
