"""Work bounded by size: the fit's per-run sample limit (a clear refusal before any fit) and
a log line per finished fit."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from pipelines.core import fit as fit_stage
from pipelines.stages import PipelineError
from tests.pipelines.pipeline_data import make_dataset, stage_cfg

RUN = "phi090_r030_sine_decay_0001"


def test_a_run_beyond_max_samples_is_refused_before_any_fit(tmp_path: Path) -> None:
    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    n = int((data["run_id"] == RUN).sum())
    with pytest.raises(PipelineError) as err:
        fit_stage.run(stage_cfg(tmp_path, max_samples=n - 1), dataset=data)
    msg = str(err.value)
    assert f"run {RUN} has {n} samples" in msg and f"max_samples={n - 1}" in msg
    assert "Nothing was fitted" in msg
    assert not list((tmp_path / "data/interim/models").rglob("*.json"))
    # at the limit it fits
    fits = fit_stage.run(stage_cfg(tmp_path, max_samples=n), dataset=data)
    assert fits["error"].isna().all() and (fits["n_samples"] == n).all()


def test_each_finished_fit_is_logged_with_its_time_and_large_runs_are_announced(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    data = make_dataset(angles=(90,), radii=(30,), dt=0.2)
    monkeypatch.setattr(fit_stage, "LARGE_RUN", 10)
    with caplog.at_level(logging.INFO, logger="pipelines.fit"):
        fit_stage.run(stage_cfg(tmp_path, families=["linear", "gamma"]), dataset=data)
    lines = [r.getMessage() for r in caplog.records]
    done = [m for m in lines if m.startswith("fit ") and "elapsed" in m]
    assert len(done) == 2 and done[0].startswith("fit 1/2: ") and done[1].startswith("fit 2/2")
    assert all("tsm-bench_phi090_r030 sine_decay" in m for m in done)
    assert any("2 of 2 models identify on runs of 10 samples or more" in m for m in lines)
