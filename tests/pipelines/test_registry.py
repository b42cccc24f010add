"""Model registry: one registered model per configuration, alias ``champion`` on the family
with the lowest held-out RMSE, loadable as a pyfunc in a fresh process."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hysteresis.base import HysteresisModel
from pipelines import registry, tracking
from pipelines.core import fit as fit_stage
from pipelines.core import validate as validate_stage
from tests.pipelines.pipeline_data import make_dataset, mlflow_store, stage_cfg

REPO = Path(__file__).resolve().parents[2]


def _store_with_model_runs(root: Path, fits: pd.DataFrame, metrics: pd.DataFrame,
                           data_hash: str) -> tracking.Tracker:
    """A new store at ``root`` holding a parent run and one model run per fit."""
    mlflow_store(root)
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=root))
    parent = tracker.start_run("pipeline", tags={"kind": "parent"})
    tracking.log_model_runs(tracker, parent, fits=fits, metrics=metrics, base_params={},
                            tags={"dataset_hash": data_hash})
    tracker.end_run(parent)
    return tracker


@pytest.fixture(scope="module")
def registered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    root = tmp_path_factory.mktemp("registry")
    data = make_dataset(angles=(15, 90), radii=(30,), dt=0.2)
    cfg = stage_cfg(root, heldout=["triangle_decay", "trapezoid_decay"])
    fits = fit_stage.run(cfg, dataset=data)
    metrics, _ = validate_stage.run(cfg, dataset=data)
    tracker = _store_with_model_runs(root, fits, metrics, "h1")
    done = registry.register_champions(tracker, fits, metrics, data_hash="h1",
                                       units=("mm", "mm"))
    return {"root": root, "data": data, "fits": fits, "metrics": metrics, "tracker": tracker,
            "done": done}


def test_one_champion_per_configuration_with_the_lowest_heldout_rmse(
        registered: dict[str, object]) -> None:
    done = registered["done"]
    metrics = registered["metrics"]
    tracker = registered["tracker"]
    assert isinstance(done, list) and isinstance(metrics, pd.DataFrame)
    assert sorted(r.name for r in done) == ["tsm.tsm-bench_phi015_r030",
                                            "tsm.tsm-bench_phi090_r030"]
    assert all(r.new for r in done)
    held = metrics[metrics["split"] == "heldout"].groupby(
        ["curve_angle_deg", "family"])["rmse"].mean()
    table = registry.champion_table(tracker).set_index("name")
    assert len(table) == 2
    for phi in (15, 90):
        row = table.loc[f"tsm.tsm-bench_phi{phi:03d}_r030"]
        best = held.loc[float(phi)]
        assert row["family"] == best.idxmin()
        assert float(row["heldout.rmse"]) == pytest.approx(best.min(), rel=1e-12)
        assert row["dataset_hash"] == "h1"
    # the version lives in the model's own child run (registry -> run -> dataset lineage)
    run = tracker.client.get_run(table.iloc[0]["run_id"])
    assert run.data.tags["model_key"] == table.iloc[0]["model_key"]
    # the large curve angle has real hysteresis: a hysteresis family wins there, not linear
    assert table.loc["tsm.tsm-bench_phi090_r030"]["family"] != "linear"


def test_each_version_wraps_a_logged_model_from_code_with_units_and_an_example(
        registered: dict[str, object], tmp_path: Path) -> None:
    """MLflow 3's way: one logged model per champion, the output of its run, its code a
    file (set_model), a signature whose units are in the metadata, an input example."""
    import mlflow
    import yaml

    tracker = registered["tracker"]
    client = tracker.client  # type: ignore[attr-defined]
    uri = tracker.settings.tracking_uri  # type: ignore[attr-defined]
    exp_id = tracker.experiment_id  # type: ignore[attr-defined]
    mlflow.set_tracking_uri(uri)
    try:
        models = mlflow.search_logged_models(experiment_ids=[exp_id], output_format="list")
    finally:
        mlflow.set_tracking_uri(None)
    table = registry.champion_table(tracker).set_index("name")
    assert len(models) == len(table) == 2
    for name, row in table.iterrows():
        version = client.get_model_version(name, row["version"])
        model = client.get_logged_model(version.source.removeprefix("models:/"))
        assert model.source_run_id == row["run_id"] == version.run_id
        run = client.get_run(row["run_id"])
        assert [o.model_id for o in run.outputs.model_outputs] == [model.model_id]
        assert model.tags["family"] == row["family"] == version.tags["family"]
        assert version.tags["configuration"] == name.split(".", 1)[1]
        assert version.tags["score"].startswith("held-out RMSE ")
        assert row["family"] in version.description and "held-out RMSE" in version.description
        assert {m.key for m in model.metrics} >= {"heldout.rmse"}
        registered_model = client.get_registered_model(name)
        assert registered_model.tags["champion_family"] == row["family"]
        assert row["family"] in registered_model.description
        folder = Path(mlflow.artifacts.download_artifacts(
            artifact_uri=model.artifact_location, dst_path=str(tmp_path / name),
            tracking_uri=uri))
        mlmodel = yaml.safe_load((folder / "MLmodel").read_text())
        pyfunc = mlmodel["flavors"]["python_function"]
        # the code file is the model: nothing pickled (a pickled model has python_model.pkl)
        assert pyfunc["loader_module"] == "mlflow.pyfunc.loaders.code_model"
        assert (folder / "pyfunc_model.py").is_file() and "python_model" not in pyfunc
        assert not list(folder.rglob("*.pkl"))
        assert mlmodel["metadata"]["signature_units"] == {"input": "mm", "output": "mm",
                                                          "state": "JSON"}
        assert version.tags["unit.output"] == "mm" and version.tags["score"].endswith(" mm")
        assert [c["name"] for c in json.loads(mlmodel["signature"]["inputs"])] == ["input",
                                                                                 "state"]
        example = json.loads((folder / "input_example.json").read_text())
        assert len(example["data"]) == 40


def test_registering_again_with_nothing_changed_adds_no_version(
        registered: dict[str, object]) -> None:
    tracker = registered["tracker"]
    fits, metrics = registered["fits"], registered["metrics"]
    assert isinstance(fits, pd.DataFrame) and isinstance(metrics, pd.DataFrame)
    again = registry.register_champions(tracker, fits, metrics, data_hash="h1")
    assert [r.new for r in again] == [False, False]
    moved = registry.register_champions(tracker, fits, metrics, data_hash="h2")
    assert [r.version for r in moved] == ["2", "2"]  # new data: a new champion version
    assert registry.champion_table(tracker)["dataset_hash"].tolist() == ["h2", "h2"]


def test_a_version_of_the_same_run_model_and_data_is_reused_not_made_again(
        registered: dict[str, object]) -> None:
    """Create if absent (what a server store relies on): with the alias gone, registering
    the same champions again points the alias back at the existing versions."""
    tracker = registered["tracker"]
    fits, metrics = registered["fits"], registered["metrics"]
    assert isinstance(fits, pd.DataFrame) and isinstance(metrics, pd.DataFrame)
    client = tracker.client  # type: ignore[attr-defined]
    before = registry.champion_table(tracker).set_index("name")["version"].astype(str)
    name = "tsm.tsm-bench_phi090_r030"
    client.delete_registered_model_alias(name, registry.ALIAS)
    n_versions = len(client.search_model_versions("name LIKE 'tsm.%'"))
    data_hash = registry.champion_table(tracker, [n for n in before.index if n != name])[
        "dataset_hash"].iloc[0]
    again = registry.register_champions(tracker, fits, metrics, data_hash=str(data_hash))
    assert [r.new for r in again] == [False, False]
    assert len(client.search_model_versions("name LIKE 'tsm.%'")) == n_versions
    after = registry.champion_table(tracker).set_index("name")["version"].astype(str)
    assert after.to_dict() == before.to_dict()


def _register_at_once(root: str, tables: str, barrier: Any) -> None:
    """One of two processes registering the same champions into one store at once."""
    fits, metrics = pd.read_pickle(f"{tables}/fits.pkl"), pd.read_pickle(f"{tables}/metrics.pkl")
    tracker = tracking.Tracker(tracking.settings_from_config({}, root=root))
    tracker.client  # noqa: B018 - the store is opened before the race starts
    barrier.wait(timeout=120)
    registry.register_champions(tracker, fits, metrics, data_hash="h-race")


def test_two_processes_registering_at_once_add_one_version_per_configuration(
        registered: dict[str, object], tmp_path: Path) -> None:
    import multiprocessing

    fits, metrics = registered["fits"], registered["metrics"]
    assert isinstance(fits, pd.DataFrame) and isinstance(metrics, pd.DataFrame)
    root = tmp_path / "store"
    tracker = _store_with_model_runs(root, fits, metrics, "h-race")
    fits.to_pickle(tmp_path / "fits.pkl")
    metrics.to_pickle(tmp_path / "metrics.pkl")
    ctx = multiprocessing.get_context("spawn")  # no store connection inherited by a fork
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_register_at_once, args=(str(root), str(tmp_path), barrier))
             for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(timeout=180)
    assert [p.exitcode for p in procs] == [0, 0]
    versions = tracker.client.search_model_versions("name LIKE 'tsm.%'")
    assert len(versions) == 2, sorted((v.name, v.version, v.run_id) for v in versions)
    assert len({v.run_id for v in versions}) == len(versions)
    assert {v.name for v in versions} == {"tsm.tsm-bench_phi015_r030",
                                          "tsm.tsm-bench_phi090_r030"}
    assert sorted(map(str, registry.champion_table(tracker)["version"])) == ["1", "1"]


def test_pyfunc_in_a_fresh_process_equals_the_familys_predict(
        registered: dict[str, object], tmp_path: Path) -> None:
    root, fits, data = registered["root"], registered["fits"], registered["data"]
    assert isinstance(fits, pd.DataFrame) and isinstance(data, pd.DataFrame)
    assert isinstance(root, Path)
    tracker = registered["tracker"]
    table = registry.champion_table(tracker)
    u = data.loc[data["excitation"] == "triangle_decay", "input"].to_numpy()[:400]
    np.save(tmp_path / "u.npy", u)
    code = (
        "import sys, mlflow, numpy as np, pandas as pd\n"
        "mlflow.set_tracking_uri(sys.argv[1])\n"
        "for name in sys.argv[3:]:\n"
        "    m = mlflow.pyfunc.load_model(f'models:/{name}@champion')\n"
        "    y = m.predict(pd.DataFrame({'input': np.load(sys.argv[2] + '/u.npy')}))\n"
        "    np.save(f'{sys.argv[2]}/{name}.npy', y['output'].to_numpy())\n"
    )
    uri = tracker.settings.tracking_uri  # type: ignore[attr-defined]
    subprocess.run([sys.executable, "-c", code, uri, str(tmp_path), *table["name"]],
                   check=True, cwd=tmp_path, timeout=120)
    for row in table.to_dict("records"):
        model_json = fits.loc[fits["key"] == row["model_key"], "model_json"].iloc[0]
        own = HysteresisModel.from_json(str(model_json)).predict(u)
        got = np.load(tmp_path / f"{row['name']}.npy")
        assert got.shape == own.shape
        assert np.max(np.abs(got - own)) <= 1e-12


def test_state_column_continues_from_a_state_and_load_champion_gives_the_family(
        registered: dict[str, object]) -> None:
    tracker, data, fits = registered["tracker"], registered["data"], registered["fits"]
    assert isinstance(data, pd.DataFrame) and isinstance(fits, pd.DataFrame)
    name = "tsm.tsm-bench_phi090_r030"
    uri = tracker.settings.tracking_uri  # type: ignore[attr-defined]
    model = registry.load_champion(name, tracking_uri=uri)
    champ = registry.champion_table(tracker).set_index("name").loc[name]
    assert isinstance(model, HysteresisModel) and model.to_dict()["family"] == champ["family"]
    u = data.loc[data["excitation"] == "sine_decay", "input"].to_numpy()[:300]
    stateful, memory = 0, 0.0
    for model_json in fits["model_json"]:
        fam = HysteresisModel.from_json(str(model_json))
        whole = fam.predict(u)
        if not hasattr(fam, "simulate"):
            continue
        stateful += 1
        _, state = fam.simulate(u[:150])
        text = registry.encode_state(state)
        json.loads(text)  # plain JSON in the frame
        frame = pd.DataFrame({"input": u[150:], "state": [text] + [None] * (len(u) - 151)})
        second = registry.predict_frame(fam, frame)["output"].to_numpy()
        assert np.max(np.abs(second - whole[150:])) <= 1e-12
        rest = registry.predict_frame(fam, frame[["input"]])["output"].to_numpy()
        memory = max(memory, float(np.max(np.abs(rest - whole[150:]))))
    assert stateful >= 2  # linear and gamma both carry a state
    # without the state a hysteresis model restarts from rest: the state column matters
    assert memory > 1e-3
    with pytest.raises(registry.RegistryError):
        registry.predict_frame(model, pd.DataFrame({"u": u}))
    with pytest.raises(registry.RegistryError):
        registry.load_champion("tsm.no-such-model", tracking_uri=uri)


def test_compensation_takes_its_model_from_the_registry_when_configured(
        registered: dict[str, object]) -> None:
    from pipelines import compensate
    from pipelines.compensation.settings import Seed001Ours

    tracker = registered["tracker"]
    uri = tracker.settings.tracking_uri  # type: ignore[attr-defined]
    ours = Seed001Ours(registry="tsm", registry_alias=registry.ALIAS)
    model = compensate.registry_model(ours, "tsm-bench", 90.0, 30.0, tracking_uri=uri)
    champ = registry.champion_table(tracker).set_index("name").loc["tsm.tsm-bench_phi090_r030"]
    assert model.to_dict()["family"] == champ["family"]
    fits = registered["fits"]
    assert isinstance(fits, pd.DataFrame)
    own = HysteresisModel.from_json(str(fits.loc[fits["key"] == champ["model_key"],
                                                 "model_json"].iloc[0]))
    u = np.linspace(-3.0, 3.0, 50)
    assert np.array_equal(model.predict(u), own.predict(u))
    with pytest.raises(registry.RegistryError):  # shape B was never registered here
        compensate.registry_model(ours, "tsm-bench", 60.0, 60.0, tracking_uri=uri)
