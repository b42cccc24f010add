"""The named physical effects of the virtual rig, each switchable with a strength.

These names are the vocabulary of the discrepancy workflow; every effect has its own
signature in the runs (see docs/virtual-rig.md). Strength 0 is off, 1 is the nominal size;
the physical constants below say what "nominal" means.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

EFFECT_NAMES = ("rate_dependence", "tendon_elongation", "time_delay", "drift", "asymmetry",
                "saturation", "dead_zone")

#: Nominal sizes (strength 1).
RATE_GAIN = 1.0  # friction grows by up to +100 % with sliding speed ...
RATE_V0_MM_S = 10.0  # ... over this speed scale (tanh)
ELONGATION_PER_N2 = 5.0e-6  # extra strain per N^2 of tension (constructional stretch)
TIME_DELAY_S = 0.05  # latency of the output measurement
DRIFT_MM = 0.3  # creep/thermal offset of the output ...
DRIFT_TAU_S = 60.0  # ... approached with this time constant
ASYMMETRY = 0.3  # mu (1 + a) pulling, mu (1 - a) releasing
SATURATION_STOP_MM = 6.0  # follower stop at 6 (1 - 0.3 s) mm from rest
SATURATION_SHRINK = 0.3
DEAD_ZONE_MM = 0.4  # full width of the actuator-side backlash


@dataclass(frozen=True)
class EffectStrengths:
    """Strength of every named effect (0.0 = off)."""

    rate_dependence: float = 0.0
    tendon_elongation: float = 0.0
    time_delay: float = 0.0
    drift: float = 0.0
    asymmetry: float = 0.0
    saturation: float = 0.0
    dead_zone: float = 0.0

    @classmethod
    def from_mapping(cls, effects: Mapping[str, float] | None) -> EffectStrengths:
        """Validate names and strengths (unknown name or negative/non-finite strength raise)."""
        if not effects:
            return cls()
        bad = sorted(set(effects) - set(EFFECT_NAMES))
        if bad:
            raise ValueError(f"unknown effect(s) {bad}; known effects: {list(EFFECT_NAMES)}")
        clean: dict[str, float] = {}
        for name, value in effects.items():
            try:
                s = float(value)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"effect {name!r}: strength must be a number, got {value!r}"
                                 ) from exc
            if not math.isfinite(s) or s < 0.0:
                raise ValueError(f"effect {name!r}: strength must be finite and >= 0, got {s}")
            clean[name] = s
        if clean.get("asymmetry", 0.0) * ASYMMETRY >= 1.0:
            raise ValueError("effect 'asymmetry': strength must be below "
                             f"{1.0 / ASYMMETRY:.3g} (friction would vanish on release)")
        if clean.get("saturation", 0.0) * SATURATION_SHRINK >= 1.0:
            raise ValueError("effect 'saturation': strength must be below "
                             f"{1.0 / SATURATION_SHRINK:.3g}")
        return cls(**clean)

    def as_dict(self) -> dict[str, float]:
        return {name: float(getattr(self, name)) for name in EFFECT_NAMES}

    def active(self) -> list[str]:
        return [name for name in EFFECT_NAMES if getattr(self, name) > 0.0]

    # --- what each strength means physically -------------------------------------------
    def rate_gain(self) -> float:
        return RATE_GAIN * self.rate_dependence

    def rate_v0_mm_s(self) -> float:
        return RATE_V0_MM_S

    def elongation_coeff(self) -> float:
        """Extra stretch per mm of tendon per N^2 (quadratic: load-dependent compliance)."""
        return ELONGATION_PER_N2 * self.tendon_elongation

    def delay_s(self) -> float:
        return TIME_DELAY_S * self.time_delay

    def drift_mm(self, t_s: float) -> float:
        return DRIFT_MM * self.drift * (1.0 - math.exp(-t_s / DRIFT_TAU_S))

    def asymmetry_fraction(self) -> float:
        return ASYMMETRY * self.asymmetry

    def saturation_stop_mm(self) -> float:
        if self.saturation <= 0.0:
            return math.inf
        return SATURATION_STOP_MM * (1.0 - SATURATION_SHRINK * self.saturation)

    def dead_zone_mm(self) -> float:
        return DEAD_ZONE_MM * self.dead_zone
