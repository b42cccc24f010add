"""The discrepancy analysis' own error: a source or a setting it cannot answer for."""

from __future__ import annotations

from hysteresis.base import HysteresisError


class DiscrepancyError(HysteresisError):
    """Bad source or configuration for the discrepancy analysis (runs of several rigs, a base
    family that does not exist, no family that fits)."""
