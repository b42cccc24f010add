"""bench.compare_outputs: two roots' outputs compared byte for byte, wall-clock masked."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from bench import compare_outputs as co


def _root(tmp: Path, name: str, *, seconds: float, value: float, when: str) -> Path:
    root = tmp / name
    rep = root / "data" / "reports"
    rep.mkdir(parents=True)
    key = "24fdd46fc834b218" if name == "before" else "fadcfd5b2f19692c"
    (rep / "summary.json").write_text(json.dumps(
        {"rmse": value, "elapsed_s": seconds, "stages": [{"seconds": seconds, "n": 3}],
         "note": f"written {when}", "key": key, "multiplier": float("nan"),
         "fit_seconds": seconds / 1e4, "tiny": 0.049111264997918624}))
    (rep / "report.md").write_text(f"# Report\n\n36 files in {seconds:.1f} s -> {root}/x\n")
    pd.DataFrame({"family": ["gamma"], "rmse": [value], "fit_s": [seconds]}).to_parquet(
        rep / "metrics.parquet")
    (rep / ".hydra").mkdir()
    (rep / ".hydra" / "config.yaml").write_text(f"t: {seconds}\n")
    (root / "data" / "mlruns").mkdir()
    (root / "data" / "mlruns" / "meta.yaml").write_text(f"t: {seconds}\n")
    return root


def test_wall_clock_fields_and_roots_are_masked(tmp_path: Path) -> None:
    a = _root(tmp_path, "before", seconds=1.5, value=0.25, when="2026-11-26T20:00:01Z")
    b = _root(tmp_path, "after", seconds=9.25, value=0.25, when="2026-11-27T08:30:00Z")
    assert co.compare(a, b, ["pipeline"]) == []
    assert co.main([str(a), str(b)]) == 0


def test_a_changed_result_or_a_missing_file_is_named(tmp_path: Path) -> None:
    a = _root(tmp_path, "before", seconds=1.5, value=0.25, when="2026-11-26T20:00:01Z")
    b = _root(tmp_path, "after", seconds=1.5, value=0.2500001, when="2026-11-26T20:00:01Z")
    problems = co.compare(a, b, ["pipeline"])
    assert problems == ["differs: data/reports/metrics.parquet",
                        "differs: data/reports/summary.json"]
    (b / "data" / "reports" / "report.md").unlink()
    assert "only in" in co.compare(a, b, ["pipeline"])[0]
    assert co.main([str(a), str(b)]) == 1
