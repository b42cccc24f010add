"""Which named effects the runs cannot tell apart, and what would separate them.

Some effects leave the same output on the channels a source carries, so naming one of them is a
guess. The workflow then answers with the class:

* ``dead_zone or asymmetry``: a one-way backlash of width ``b`` is a dead zone of width ``b``
  (or a static band of half that width about a shifted rest) plus an input offset, which a
  shift-invariant plant turns into an output offset. On the output the three are one effect;
  the input load cell separates them when the backlash sits ahead of it (the tension then
  stands still for the dead travel after every reversal, :mod:`.backlash`).
* ``saturation or tendon_elongation``: a stretch with the square of the output tension, which
  follows the output through the follower's spring, is a static curvature of the output, as a
  soft stop or a cubic softening is; the output tension separates them only where it is more
  than an affine function of the output (a spring follower's ``T_out = F0 + k y`` is not: its
  square is a quadratic of the output, which a plant's own asymmetric loop also is).

Each class is a set of ``(effect, form)`` pairs (``form`` None: every form of the effect) and the
load-cell claim that separates its members when the runs carry the channel.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: class label -> (members, the load-cell claim of :mod:`.evidence` that separates them or None
#: when a term on the channel does, the channel (a :class:`.runs.RunData` field), its name).
CLASSES: dict[str, tuple[frozenset[tuple[str, str | None]], str | None, str, str]] = {
    "dead_zone or asymmetry": (
        frozenset({("dead_zone", "backlash"), ("dead_zone", "dead_band"),
                   ("asymmetry", "one_way_backlash")}),
        "dead_travel", "tension", "the input tension"),
    # a stretch with the square of the output tension, which follows the output through the
    # output spring, is a static curvature of the output, as a soft stop or a softening is
    "saturation or tendon_elongation": (
        frozenset({("saturation", "soft"), ("saturation", "cubic"),
                   ("tendon_elongation", "square_output")}),
        None, "tension_out", "the output tension"),
}


def class_of(name: str, form: str) -> str | None:
    """The class of ``(name, form)``, or None when it is told apart from every other."""
    for label, (members, _, _, _) in CLASSES.items():
        if (name, form) in members or (name, None) in members:
            return label
    return None


def statement(effect: Mapping[str, Any], channels: set[str] | frozenset[str], *,
              follows_output: float | None = None) -> dict[str, Any] | None:
    """The identifiability answer for the first effect named (``effect``: a report entry with
    its ``name``, ``form`` and ``evidence``; ``channels``: the tension channels every run
    carries): None when it stands alone, else the class, its members and why it is not
    split. With the separating channel present the class splits: through a load-cell reading
    that shows the named member's claim (a reading that does not leaves the class), or, for a
    class without a reading, through the term on that channel, which competed in the fit;
    unless that channel is the output tension and it follows the output (``follows_output``:
    :func:`.evidence.output_tension_follows`, at least :data:`.evidence.FOLLOWS_OUTPUT_R2`),
    when the term on it is only another curve of the output. (On clean-room sources with a
    spring follower, a stretch with the output tension's square was named alone on a clean
    generalised Prandtl-Ishlinskii plant whose loop is asymmetric, a clean tendon-sheath and
    rate terms, and never where it was hidden.)"""
    from hysteresis.discrepancy.evidence import FOLLOWS_OUTPUT_R2

    label = class_of(str(effect["name"]), str(effect.get("form", "")))
    if label is None:
        return None
    members, claim, channel, text = CLASSES[label]
    present = channel in channels
    follows = (claim is None and channel == "tension_out" and follows_output is not None
               and follows_output >= FOLLOWS_OUTPUT_R2)
    ev = (effect.get("evidence") or {}).get("load_cell_evidence") or {}
    if present and not follows and (
            claim is None or (ev.get("claim") == claim and ev.get("corroborated"))):
        return None
    names = sorted({m[0] for m in members})
    why = (f"not separable without {text}" if not present else
           f"not separable on these runs: {text} follows the output (an affine function of "
           f"it, R^2 {follows_output:.3f}), so a term on it is a static curve of the output"
           if follows else
           f"not separable on these runs: {text} does not show the {str(claim).replace('_', ' ')} "
           "that would tell them apart")
    return {"class": names, "label": label, "named": effect["name"], "form": effect.get("form"),
            "statement": f"{label}: {why}"}


def force_statement(effect: Mapping[str, Any], speed_share: float | None, *,
                    min_gain: float, max_delta_bic: float) -> dict[str, Any] | None:
    """A stretch named on a tension that carries a speed-dependent force.

    ``tendon_elongation`` reads the input tension. When that tension follows the input speed
    (``speed_share``: :func:`.evidence.tension_speed_share` at least
    :data:`.evidence.SPEED_SHARE`) and ``rate_dependence`` alone also clears the bar (the
    round's runner-up, by ``min_gain`` and ``max_delta_bic``), the shortfall the stretch
    explains may be a rate-dependent force reaching the output through the tendon's
    compliance: the tension shows the force, not its cause. Returns the class, or None."""
    from hysteresis.discrepancy.evidence import SPEED_SHARE

    if effect.get("name") != "tendon_elongation" or speed_share is None \
            or speed_share < SPEED_SHARE:
        return None
    rival = (effect.get("evidence") or {}).get("runner_up") or {}
    if rival.get("name") != "rate_dependence" or rival["relative_gain"] < min_gain \
            or rival["delta_bic"] > max_delta_bic:
        return None
    label = "rate_dependence or tendon_elongation"
    return {"class": ["rate_dependence", "tendon_elongation"], "label": label,
            "named": effect["name"], "form": effect.get("form"),
            "statement": (
                f"{label}: the input speed explains {100 * speed_share:.0f} % of the input "
                "tension that a rate-independent map leaves, so the stretch that reads it may "
                "be how a rate-dependent force reaches the output (rate_dependence alone "
                f"removes {100 * rival['relative_gain']:.0f} % of the held-out error); not "
                "separable on these runs")}
