"""Clean-room data generators: written from the physics (the papers, textbook forms) and the
format specification alone, by sessions that had not read the implementation they test."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

HERE = Path(__file__).resolve().parent


def load(name: str) -> ModuleType:
    """A generator of this folder by file name (``rate_forms``), imported by path as its
    author wrote it to be used."""
    spec = importlib.util.spec_from_file_location(f"cleanroom_{name}", HERE / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    # registered before it runs: a dataclass looks its module up by name while it is made
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def stage_runs(source: Path, work: Path) -> list[Any]:
    """A clean-room source of three runs ingested and read as the discrepancy stage does (the
    decaying sine identifies, 25 Hz); nothing may be rejected."""
    from pipelines.discrepancy_data import ingest_source, runs_from_dataset

    rows, meta, rep = ingest_source(source, work)
    assert rep["rejected"] == [] and len(meta) == 3
    return runs_from_dataset(rows, meta, identify_excitations=["sine_decay"], rate_hz=25.0)
