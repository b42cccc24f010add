"""``tracking=server`` against the real thing: a throwaway PostgreSQL, ``mlflow server`` on
loopback with a proxied artifact store, a small ``make pipeline`` logging to it; the runs,
their datasets, artifacts and the registered champions are read back through the server,
and a champion loads by name in a fresh process. Every service is stopped and checked gone.

Needs psycopg2 and Debian's postgresql: ``make team-test`` installs both and runs this file
(CI runs that target). `make test` leaves tests/team/ out: these need the team venv.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("psycopg2", reason="needs psycopg2 + postgresql: `make team-test` (CI)")

from mlflow import MlflowClient  # noqa: E402

from pipelines import cluster_check, localserv, registry  # noqa: E402
from pipelines.run_all import compose_stage, run_pipeline  # noqa: E402

SHORT = [f"campaign.excitations.{i}.periods_per_amplitude=2" for i in range(3)]


def _listed(stage: str, overrides: list[str]) -> str:
    return f"overrides.{stage}=[{','.join(repr(o) for o in overrides)}]"


def test_pipeline_logs_and_registers_through_a_postgresql_backed_server(
        tmp_path: Path) -> None:
    work = tmp_path / "services"
    work.mkdir()
    with cluster_check.team_services(work, ray=False) as services:
        assert services.postgres_uri.startswith("postgresql+psycopg2://mlflow:")
        assert "@127.0.0.1:" in services.postgres_uri
        uri = services.tracking_uri
        assert uri.startswith("http://127.0.0.1:")
        # the database password is in no process's arguments (ps shows them to every user)
        password = services.postgres_uri.split("://", 1)[1].split("@", 1)[0].split(":", 1)[1]
        assert len(password) >= 16
        argv = _command_lines()
        assert argv and not [a for a in argv if password in a]
        assert [a for a in argv if "mlflow" in a and "server" in a]  # the server was seen
        root = tmp_path / "root"
        cfg = compose_stage("pipeline", [
            f"paths.root={root}", "n_jobs=1", "progress=false", "tracking=server",
            f"tracking.uri={uri}",
            _listed("generate", ["campaign=quick", "n_jobs=1", "progress=false", *SHORT]),
            _listed("ingest", ["progress=false"]),
            _listed("fit", ["families=[linear,gamma]"]),
            _listed("report", ["plots.dpi=40"]),
        ])
        result = run_pipeline(cfg)
        client = MlflowClient(uri)
        exp = client.get_experiment_by_name("tsm-hysteresis")
        assert exp is not None
        assert exp.tags["mlflow.experimentKind"] == "custom_model_development"
        # the server chose where artifacts go: its proxied store, not a client path
        assert exp.artifact_location.startswith("mlflow-artifacts:")
        runs = client.search_runs([exp.experiment_id], "tags.kind = 'model'")
        assert len(runs) == 4 and all(r.info.status == "FINISHED" for r in runs)
        assert all(r.data.tags["mlflow.parentRunId"] == result.parent_run_id for r in runs)
        assert all({d.dataset.name.split(":")[1] for d in r.inputs.dataset_inputs}
                   == {"sine_decay", "band_random+mixed_sine+trapezoid_decay+triangle_decay"}
                   for r in runs)
        arts = {a.path for a in client.list_artifacts(runs[0].info.run_id)}
        assert {"model", "metrics.json"} <= arts
        # uploaded through the server into its artifact store on disk
        assert list((work / "artifacts").rglob("model.json"))
        # the PostgreSQL store holds them (not a stray local file)
        assert not (root / "mlflow.db").exists()

        table = registry.champion_table(registry_tracker(uri))
        assert sorted(table["name"]) == ["tsm.tsm-bench_phi015_r030",
                                         "tsm.tsm-bench_phi090_r030"]
        code = ("import sys, mlflow, numpy as np, pandas as pd\n"
                "mlflow.set_tracking_uri(sys.argv[1])\n"
                "m = mlflow.pyfunc.load_model('models:/tsm.tsm-bench_phi090_r030@champion')\n"
                "y = m.predict(pd.DataFrame({'input': np.linspace(-3, 3, 61)}))['output']\n"
                "print(float(np.abs(y).max()))\n")
        out = subprocess.run([sys.executable, "-c", code, uri], capture_output=True,
                             text=True, timeout=180, check=True)
        assert 0.5 < float(out.stdout.strip().splitlines()[-1]) < 10.0
    assert services.left_behind == {}
    for _, proc in services.procs:
        assert proc.poll() is not None and localserv.group_alive(proc.pid) == []


def registry_tracker(uri: str) -> object:
    from pipelines import tracking

    return tracking.Tracker(tracking.settings_from_config({"uri": uri}, root="."))


def _command_lines() -> list[str]:
    """Every process's command line (what ``ps`` shows any local user)."""
    lines = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                raw = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            lines.append(raw.replace(b"\0", b" ").decode(errors="replace"))
    return lines
