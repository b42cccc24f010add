"""What the experiments hand back: tables and figures by name (nothing written yet)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pandas as pd


@dataclass
class Outcome:
    """One experiment's tables (tidy DataFrames) and figures (matplotlib figures), by the
    name each is written under."""

    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: dict[str, Any] = field(default_factory=dict)

    def add(self, other: Outcome) -> None:
        self.tables.update(other.tables)
        self.figures.update(other.figures)


@dataclass
class CompensationResult(Outcome):
    """Every enabled experiment's outcome and the headline numbers; ``started_s`` is the
    ``time.perf_counter()`` at which the experiments started (the report states how long the
    stage took)."""

    metrics: dict[str, float] = field(default_factory=dict)
    started_s: float = 0.0
