"""Which named effects the runs cannot tell apart, and what would separate them.

Some effects leave the same output on the channels a source carries, so naming one of them is a
guess. The workflow then answers with the class:

* ``dead_zone or asymmetry``: a one-way backlash of width ``b`` is a dead zone of width ``b``
  (or a static band of half that width about a shifted rest) plus an input offset, which a
  shift-invariant plant turns into an output offset. On the output the three are one effect;
  the input load cell separates them when the backlash sits ahead of it (the tension then
  stands still for the dead travel after every reversal, :mod:`.backlash`).

Each class is a set of ``(effect, form)`` pairs (``form`` None: every form of the effect) and the
load-cell claim that separates its members when the runs carry the channel.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: class label -> (members, the claim of :mod:`.evidence` that separates them, the channel).
CLASSES: dict[str, tuple[frozenset[tuple[str, str | None]], str, str]] = {
    "dead_zone or asymmetry": (
        frozenset({("dead_zone", "backlash"), ("dead_zone", "dead_band"),
                   ("asymmetry", "one_way_backlash")}),
        "dead_travel", "the input tension"),
}


def class_of(name: str, form: str) -> str | None:
    """The class of ``(name, form)``, or None when it is told apart from every other."""
    for label, (members, _, _) in CLASSES.items():
        if (name, form) in members or (name, None) in members:
            return label
    return None


def statement(effect: Mapping[str, Any], has_tension: bool) -> dict[str, Any] | None:
    """The identifiability answer for the first effect named (``effect``: a report entry with
    its ``name``, ``form`` and ``evidence``): None when it stands alone, else the class, its
    members and why it is not split. With the separating channel present, a reading that shows
    the named member's claim splits the class (the name stands); one that does not, or a
    missing channel, leaves the class."""
    label = class_of(str(effect["name"]), str(effect.get("form", "")))
    if label is None:
        return None
    members, claim, channel = CLASSES[label]
    ev = (effect.get("evidence") or {}).get("load_cell_evidence") or {}
    if has_tension and ev.get("claim") == claim and ev.get("corroborated"):
        return None
    names = sorted({m[0] for m in members})
    why = (f"not separable without {channel}" if not has_tension else
           f"not separable on these runs: {channel} does not show the {claim.replace('_', ' ')} "
           "that would tell them apart")
    return {"class": names, "label": label, "named": effect["name"], "form": effect.get("form"),
            "statement": f"{label}: {why}"}
