"""A discrepancy source that mixes rigs, output units or output quantities is refused, naming
each group and its runs, before the analysis (one RMSE over mm and deg means nothing)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pipelines import discrepancy, discrepancy_data
from rig_io.folder import write_run_folder
from rig_io.synthetic import make_raw_run
from tests.cleanroom import riglog


def _run_stage(source: Path, report: Path, monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    analysed: list[Any] = []
    monkeypatch.setattr(discrepancy, "analyse", lambda *a, **k: analysed.append(a))
    with pytest.raises(discrepancy.DiscrepancyError) as info:
        discrepancy.run({"source": str(source), "report": str(report), "progress": False,
                         "tracking": {"enabled": False}})
    analysed.append(str(info.value))
    return analysed


def test_a_clean_room_source_of_two_rigs_is_refused_naming_both_before_the_analysis(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    src, report = tmp_path / "raw", tmp_path / "out" / "discrepancy.json"
    runs = {p.name for p in riglog.write_mixed_source(src, n_each=2, bending_delay_s=12.0)}
    *calls, msg = _run_stage(src, report, monkeypatch)
    assert calls == []  # refused before the analysis
    assert msg.startswith("source mixes rigs, output units and output quantities: "), msg
    assert "tsm-bench (2 runs, output mm)" in msg, msg
    assert "bending-joint (2 runs, output deg, tip_angle_deg)" in msg, msg
    assert "analyse each group apart" in msg and all(r in msg for r in runs), msg
    assert not report.parent.exists() or list(report.parent.iterdir()) == []


def test_project_runs_of_two_rigs_are_refused(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    src = tmp_path / "raw"
    for i in range(2):
        write_run_folder(make_raw_run(f"bench{i}", duration_s=4.0, seed=i + 1), src)
        write_run_folder(make_raw_run(f"joint{i}", duration_s=4.0, seed=i + 5,
                                      rig="bending-joint", unit="deg",
                                      quantity="tip_angle_deg"), src)
    *calls, msg = _run_stage(src, tmp_path / "out" / "d.json", monkeypatch)
    assert calls == []
    assert msg.startswith("source mixes rigs and output units: "), msg
    assert "bending-joint (2 runs, output deg): joint0, joint1" in msg, msg
    assert "tsm-bench (2 runs, output mm): bench0, bench1" in msg, msg


def _meta(rig: str, unit: str, source: str = "encoder", quantity: str | None = None
          ) -> dict[str, Any]:
    channels: dict[str, Any] = {"encoder": {"unit": unit}}
    if quantity:
        channels[source] = {"quantity": quantity}
    return {"rig": rig, "units": {"output": unit}, "output_source": source,
            "manifest": {"rig": rig, "channels": channels}}


def test_one_rig_in_two_units_or_two_quantities_is_refused_and_one_kind_is_not() -> None:
    with pytest.raises(discrepancy.DiscrepancyError,
                       match=r"^source mixes output units: tsm-bench \(1 run, output mm\) and "
                             r"tsm-bench \(2 runs, output deg\)"):
        discrepancy_data.check_one_kind({"a": _meta("tsm-bench", "mm"),
                                         "b": _meta("tsm-bench", "deg"),
                                         "c": _meta("tsm-bench", "deg")})
    with pytest.raises(discrepancy.DiscrepancyError, match=r"^source mixes output quantities: "):
        discrepancy_data.check_one_kind({
            "a": _meta("bending-joint", "deg", "camera", "tip_angle_deg"),
            "b": _meta("bending-joint", "deg")})
    # the output encoder and a tracker measuring the same quantity are one kind
    discrepancy_data.check_one_kind({"a": _meta("tsm-bench", "mm"),
                                     "b": _meta("tsm-bench", "mm", "tracker", "output_mm")})


def test_runs_of_two_rigs_given_directly_are_never_pooled() -> None:
    import numpy as np

    from hysteresis.discrepancy.analysis import analyse
    from hysteresis.discrepancy.runs import RunData

    t = np.arange(50) * 0.1
    runs = [RunData(f"r{i}", t, np.sin(t), np.sin(t), config={"rig": rig})
            for i, rig in enumerate(("tsm-bench", "bending-joint"))]
    with pytest.raises(discrepancy.DiscrepancyError, match="source mixes rigs: tsm-bench"):
        analyse(runs, auto_families={"linear": {}})
