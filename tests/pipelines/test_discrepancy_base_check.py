"""A chosen base that does not fit the source is flagged, not trusted: on an independent
injector's clean Preisach plant, the thesis' sum-to-one Gamma base "finds" an asymmetry; the
stage's base check says the base fits many times worse than the best standard family."""

from __future__ import annotations

from typing import Any

import pytest
from hydra import compose, initialize_config_dir

from hysteresis.discrepancy.inject import injected_runs
from hysteresis.discrepancy.workflow import base_factory_for, run_workflow
from pipelines.common import CONF_DIR, to_container
from pipelines.discrepancy import base_misfit, headline


@pytest.fixture(scope="module")
def families() -> dict[str, Any]:
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return dict(to_container(compose("discrepancy"))["auto_families"])


def test_a_base_that_cannot_take_the_loop_shape_is_flagged(families: dict[str, Any]) -> None:
    runs = injected_runs("preisach", {})
    rep = run_workflow(runs, base_factory_for("gamma"), base_name="gamma")
    assert rep["effects"], "the misfit this check is for: a clean source gets an effect"
    misfit = base_misfit(runs, rep, families, factor=1.5)
    assert misfit is not None and misfit["best_family"] in ("preisach", "bouc_wen")
    assert misfit["ratio"] > 5.0
    assert "caution: base gamma fits this source" in headline({**rep, "base_misfit": misfit})


def test_a_base_that_fits_is_not_flagged(families: dict[str, Any]) -> None:
    runs = injected_runs("gamma", {"time_delay": 1.0})
    rep = run_workflow(runs, base_factory_for("gamma"), base_name="gamma")
    assert [e["name"] for e in rep["effects"]] == ["time_delay"]
    assert base_misfit(runs, rep, families, factor=1.5) is None
    assert "caution" not in headline({**rep, "base_misfit": None})
