"""Which run identifies a model and which judges it: the one rule fit, validate and the
discrepancy workflow share (docs/pipeline.md, "Which run identifies").

A run's role comes from its manifest or importer mapping (``excitation.role``) when it has
one; otherwise from its excitation kind (the kinds a stage identifies on). A configuration
recorded in one run only is split in time: its head identifies, its tail (the last
``heldout_fraction``) is held out and judged from the state the head left.

Pure functions of names, kinds and sample counts: the stages apply them to their own data
structures (a processed table for fit and validate, arrays for the discrepancy workflow).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hysteresis.base import HysteresisError

IDENTIFICATION = "identification"
HELDOUT = "heldout"
#: Manifest ``excitation.role`` words that mark a run for identification / for judging only.
IDENTIFY_ROLES = ("identify", "identification", "fit", "train")
HELDOUT_ROLES = ("held_out", "heldout", "validation", "test")
#: Suffix of the held-out tail of a configuration recorded in one run.
TAIL = ".tail"
#: Neither the head nor the tail of a split run may be shorter than this (samples).
MIN_SEGMENT = 20
#: The held-out share of a split run must lie in this range.
HELDOUT_FRACTION_RANGE = (0.05, 0.5)


def normalise_role(role: Any, *, run_id: str = "") -> str | None:
    """``IDENTIFICATION``, ``HELDOUT`` or ``None`` (no role given) for a manifest's word.

    A word that is neither raises :class:`HysteresisError` naming the accepted ones: a typo
    such as ``helduot`` must not quietly turn a test run into an identification run.
    """
    if role is None:
        return None
    word = str(role).strip().lower()
    if not word:
        return None
    if word in IDENTIFY_ROLES:
        return IDENTIFICATION
    if word in HELDOUT_ROLES:
        return HELDOUT
    where = f"run {run_id}: " if run_id else ""
    raise HysteresisError(
        f"{where}excitation.role {role!r} is not a role; use one of "
        f"{', '.join(IDENTIFY_ROLES)} (identifies) or {', '.join(HELDOUT_ROLES)} (judges only)")


def manifest_role(meta: Mapping[str, Any], *, run_id: str = "") -> str | None:
    """The role a run's metadata (ingest's ``runs.json`` entry, or a manifest) gives it."""
    exc = (meta.get("manifest") or {}).get("excitation") or meta.get("excitation") or {}
    role = exc.get("role") if isinstance(exc, Mapping) else None
    return normalise_role(role, run_id=run_id)


def run_role(given: str | None, kind: str, identify_kinds: set[str] | frozenset[str]) -> str:
    """A run's role: the one its manifest gives, else ``IDENTIFICATION`` for a run of a kind
    the stage identifies on and ``HELDOUT`` for any other."""
    if given is not None:
        return given
    return IDENTIFICATION if kind in identify_kinds else HELDOUT


def check_heldout_fraction(fraction: float) -> float:
    low, high = HELDOUT_FRACTION_RANGE
    if not low <= fraction <= high:
        raise HysteresisError(
            f"single_run_heldout_fraction must be in [{low}, {high}], got {fraction}")
    return float(fraction)


def tail_start(n_samples: int, heldout_fraction: float) -> int | None:
    """Where the held-out tail of a one-run configuration starts (sample index), or ``None``
    when the head or the tail would be shorter than :data:`MIN_SEGMENT`."""
    cut = int(round(n_samples * (1.0 - check_heldout_fraction(heldout_fraction))))
    if cut < MIN_SEGMENT or n_samples - cut < MIN_SEGMENT:
        return None
    return cut


def split_note(run_id: str, head_s: float, tail_s: float, heldout_fraction: float,
               tail_kind: str | None = None) -> str:
    """The sentence the log and the report give for a split run."""
    kind = f", excitation {tail_kind!r}" if tail_kind else ""
    return (f"one run ({run_id}): identifies on its first {head_s:.1f} s, judged on its last "
            f"{tail_s:.1f} s ({100 * heldout_fraction:.0f} %{kind})")
