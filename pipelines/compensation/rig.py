"""The plant behind an interface (the virtual rig by default), and how the experiments drive it.

Every experiment reaches the physics only through a :class:`RigBackend`, so tests can swap
in stand-in plants; :class:`Recorder` keeps every sample a loop produced.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

DT_S = 0.01  # the rig's 10 ms control tick


@dataclass(frozen=True)
class RigBackend:
    """``make_rig(rig=, curve_angle_deg=, radius_mm=, effects=, seed=, sensors=)`` returns an
    object with ``reset()`` and ``step(command) -> dict``; ``make_excitation(kind, dt_s=,
    **params) -> (t_s, command)``."""

    make_rig: Callable[..., Any]
    make_excitation: Callable[..., tuple[Any, Any]]


def virtual_backend() -> RigBackend:
    from rig_io.virtual import VirtualRig, make_excitation

    return RigBackend(make_rig=VirtualRig, make_excitation=make_excitation)


def make_rig(backend: RigBackend, rig: str, phi: float, r: float, *, effects: Mapping[str, Any],
             seed: int, sensors: Mapping[str, Any] | None = None) -> Any:
    """One configuration of ``rig``; an empty ``effects`` or ``sensors`` mapping means the
    rig's own."""
    return backend.make_rig(rig=rig, curve_angle_deg=phi, radius_mm=r,
                            effects=dict(effects) or None, seed=seed,
                            sensors=dict(sensors or {}) or None)


class Recorder:
    """Wraps ``rig.step`` and keeps every returned sample (for extra channels and plots)."""

    def __init__(self, rig: Any) -> None:
        self.rig = rig
        self.rows: list[Mapping[str, float]] = []

    def __call__(self, command: float) -> Mapping[str, float]:
        out = self.rig.step(command)
        self.rows.append(out)
        return out  # type: ignore[no-any-return]

    def many(self, commands: np.ndarray) -> list[Mapping[str, float]]:
        """A command sequence known in advance, in one call where the rig has ``step_many``
        (the same readings as tick by tick)."""
        batch = getattr(self.rig, "step_many", None)
        out = list(batch(commands)) if callable(batch) else [
            self.rig.step(float(c)) for c in commands]
        self.rows.extend(out)
        return out

    def column(self, key: str) -> np.ndarray:
        return np.array([float(r.get(key, math.nan)) for r in self.rows])


def fresh(rig: Any) -> Recorder:
    rig.reset()
    return Recorder(rig)


def drive(rig: Any, command: Any) -> Recorder:
    rec = fresh(rig)
    rec.many(np.asarray(command, dtype=np.float64))
    return rec


def progress(items: list[Any], desc: str, enabled: bool) -> Iterable[Any]:
    if not enabled:
        return items
    from tqdm import tqdm

    bar: Iterable[Any] = tqdm(items, desc=desc, leave=False)
    return bar
