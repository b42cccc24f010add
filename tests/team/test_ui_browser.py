"""The MLflow UI as users see it: a small ``make pipeline``, the UI on loopback (what
``make ui`` runs), headless chromium. The link ``make ui`` prints opens the experiment's runs
table (not the GenAI traces overview); the table lists the pipeline's runs with their
datasets; a run page shows ``heldout.rmse``; the Models tab lists one logged model per
configuration; the pipeline's report.html shows its headline, units in every table header
and no raw Markdown; screenshots go to ``data/reports/ui/``; no process is left behind.

Needs playwright and a system chromium: ``make ui-check`` installs both (requirements-team.lock,
apt-get) and runs this file; CI runs that target. ``make test`` leaves tests/team/ out: it
needs the team venv.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sync_api = pytest.importorskip(
    "playwright.sync_api",
    reason="browser check needs playwright: `make ui-check` or `make team-test` (CI)")

from pipelines import localserv  # noqa: E402
from pipelines.run_all import compose_stage, run_pipeline  # noqa: E402
from tests.pipelines.pipeline_data import mlflow_store, small_pipeline  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
SHOTS = Path(os.environ.get("TSM_UI_SHOTS", REPO / "data" / "reports" / "ui"))



def _chromium() -> str:
    path = os.environ.get("TSM_CHROMIUM") or shutil.which("chromium") \
        or shutil.which("chromium-browser")
    if not path:
        pytest.fail("no system chromium: `make ui-check` installs Debian's chromium")
    return path


@pytest.fixture(scope="module")
def pipeline_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small ``make pipeline`` (4 configurations, linear and gamma) in its own folder."""
    root = tmp_path_factory.mktemp("ui")
    mlflow_store(root)
    cfg = compose_stage("pipeline", small_pipeline(root))
    result = run_pipeline(cfg)
    assert result.parent_run_id is not None
    return root


def _browser(pw: Any) -> Any:
    return pw.chromium.launch(executable_path=_chromium(), headless=True,
                              args=["--no-sandbox", "--disable-gpu"])


@contextlib.contextmanager
def _ui_page(uri: str, cwd: Path, log_name: str) -> Iterator[tuple[Any, str]]:
    """The MLflow UI on ``uri`` (a free loopback port) and a chromium page on it; afterwards
    the UI and its workers must be gone."""
    port = localserv.free_port()
    url = f"http://{localserv.LOOPBACK}:{port}"
    cmd = localserv.mlflow_ui_command(sys.executable, uri, port)
    with localserv.running(cmd, log=cwd / log_name, url=f"{url}/health", timeout=90,
                           cwd=cwd) as server:
        pgid = server.pid
        with sync_api.sync_playwright() as pw:
            browser = _browser(pw)
            try:
                yield browser.new_page(viewport={"width": 1600, "height": 1000}), url
            finally:
                browser.close()
    assert localserv.group_alive(pgid) == []  # the UI and its workers are gone


def test_ui_lists_the_pipelines_runs_and_a_run_page_shows_heldout_rmse(
        pipeline_store: Path) -> None:
    tmp_path = pipeline_store
    from mlflow import MlflowClient

    client = MlflowClient(f"sqlite:///{tmp_path}/mlflow.db")
    exp = client.get_experiment_by_name("tsm-hysteresis")
    children = client.search_runs([exp.experiment_id], "tags.kind = 'model'")
    assert len(children) == 4
    child = children[0]
    dataset = child.inputs.dataset_inputs[0].dataset
    assert exp.tags["mlflow.experimentKind"] == "custom_model_development"

    SHOTS.mkdir(parents=True, exist_ok=True)
    with _ui_page(f"sqlite:///{tmp_path}/mlflow.db", tmp_path, "ui.log") as (page, url):
        # the link `make ui` prints: the experiment's runs table (MLflow 3.17's UI
        # picks GenAI vs model-training pages from its workflowType switch)
        page.goto(f"{url}/#/experiments/{exp.experiment_id}"
                  "?workflowType=machine_learning")
        page.get_by_text("pipeline", exact=True).first.wait_for(timeout=90_000)
        assert "/runs" in page.url
        assert page.get_by_text("matching runs").count() >= 1
        close = page.get_by_role("button", name="Close")
        if close.count():  # the assistant side panel hides half of the table
            close.first.click()
        # expand the pipeline's parent run: its model runs, each with its dataset
        page.locator('[data-component-id*="runnamecellrenderer"]').first.click()
        for run in children:
            page.get_by_text(run.info.run_name, exact=True).first.wait_for(
                timeout=60_000)
        page.get_by_text(dataset.name).first.wait_for(timeout=30_000)
        page.screenshot(path=str(SHOTS / "runs_table.png"))
        # one run's page: its metrics, heldout.rmse among them
        page.goto(f"{url}/#/experiments/{exp.experiment_id}/runs/"
                  f"{child.info.run_id}?workflowType=machine_learning")
        page.get_by_placeholder("Search metrics").fill("heldout.")
        page.get_by_text("heldout.rmse", exact=True).first.wait_for(timeout=60_000)
        value = f"{child.data.metrics['heldout.rmse']}"[:8]
        assert page.get_by_text(value).count() >= 1  # its value, as logged
        page.screenshot(path=str(SHOTS / "run_page.png"), full_page=True)
    assert (SHOTS / "runs_table.png").stat().st_size > 10_000
    assert (SHOTS / "run_page.png").stat().st_size > 10_000


def test_the_models_tab_lists_one_logged_model_per_configuration(
        pipeline_store: Path) -> None:
    """Each configuration's champion is an MLflow 3 logged model: the client finds one per
    configuration, each the output of its run, and the experiment's Models tab shows them."""
    import mlflow
    from mlflow import MlflowClient

    uri = f"sqlite:///{pipeline_store}/mlflow.db"
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tsm-hysteresis")
    mlflow.set_tracking_uri(uri)
    try:
        models = mlflow.search_logged_models(experiment_ids=[exp.experiment_id],
                                             output_format="list")
    finally:
        mlflow.set_tracking_uri(None)
    configurations = {r.data.tags["configuration"]
                      for r in client.search_runs([exp.experiment_id], "tags.kind = 'model'")}
    assert len(configurations) == 2  # the quick campaign's
    assert len(models) == len(configurations)
    for model in models:
        run = client.get_run(model.source_run_id)
        assert [o.model_id for o in run.outputs.model_outputs] == [model.model_id]
        assert model.tags["family"] == run.data.tags["family"]
    with _ui_page(uri, pipeline_store, "ui-models.log") as (page, url):
        page.goto(f"{url}/#/experiments/{exp.experiment_id}/models"
                  "?workflowType=machine_learning")
        for model in models:
            page.get_by_text(model.name, exact=True).first.wait_for(timeout=90_000)
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "models_tab.png"))


def test_the_report_reads_as_a_report_in_a_browser(pipeline_store: Path) -> None:
    """report.html in chromium: the headline first, a unit in the header of every table
    (and in every error column's), per-configuration thumbnails, and no Markdown left raw."""
    report = pipeline_store / "data" / "reports" / "report.html"
    assert report.is_file()
    with sync_api.sync_playwright() as pw:
        browser = _browser(pw)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(report.as_uri())
            headline = page.locator("#headline").inner_text()
            assert " wins " in headline and "RMSE" in headline and " mm" in headline
            first = page.locator("body > *").nth(1).inner_text()
            assert first == headline  # right under the title
            tables = page.locator("table")
            assert tables.count() >= 4
            error_words = ("rmse", "sse", "error", "median_own", "median_nearest")
            for i in range(tables.count()):
                heads = tables.nth(i).locator("th").all_inner_texts()
                assert any("[" in h and "]" in h for h in heads), heads
                for h in heads:
                    if any(w in h.lower() for w in error_words):
                        assert "[" in h, (h, heads)
            text = page.locator("body").inner_text()
            assert "`" not in text and "**" not in text
            thumbs = page.locator(".thumbs img")
            assert thumbs.count() == 2  # the quick campaign's configurations
            for i in range(thumbs.count()):  # lazy images load once scrolled to
                thumbs.nth(i).scroll_into_view_if_needed()
                page.wait_for_function("(img) => img.complete && img.naturalWidth > 0",
                                       arg=thumbs.nth(i).element_handle(), timeout=30_000)
            SHOTS.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(SHOTS / "report.png"), full_page=False)
        finally:
            browser.close()
