"""The tracking server's database URI (password included) never reaches a command line,
where every local user can read it (``ps``); the live check is in tests/team."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

from pipelines import cluster_check, localserv

URI = "postgresql+psycopg2://mlflow:Sup3rSecretPw@127.0.0.1:5432/mlflow"


def test_the_installed_mlflow_server_reads_its_store_uri_from_that_variable() -> None:
    from mlflow.cli import server

    option = next(p for p in server.params if p.name == "backend_store_uri")
    assert option.envvar == localserv.BACKEND_STORE_ENV


def test_the_started_mlflow_server_gets_the_database_uri_by_environment_only(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    started: dict[str, Any] = {}

    def start(cmd: list[str], **kw: Any) -> object:
        started.update(cmd=list(cmd), **kw)
        return type("Proc", (), {"pid": 0, "poll": lambda self: None})()

    monkeypatch.setattr(localserv, "start", start)
    monkeypatch.setattr(localserv, "wait_http", lambda *a, **k: None)
    services = cluster_check.Services(workdir=tmp_path, postgres_uri=URI)
    cluster_check.start_mlflow_server(services)
    assert started["cmd"][:4] == [sys.executable, "-m", "mlflow", "server"]
    assert not [a for a in started["cmd"] if "Sup3rSecretPw" in a or "postgresql" in a]
    assert started["env"][localserv.BACKEND_STORE_ENV] == URI
