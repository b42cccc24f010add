"""``make cluster-check``: the team set-up end to end, on this machine, then gone again.

1. a throwaway **PostgreSQL** (``initdb`` into a temporary folder, password auth, 127.0.0.1),
2. an **MLflow tracking server** on it (``mlflow server``, PostgreSQL backend store, proxied
   artifact store in the temporary folder, 127.0.0.1),
3. a local **Ray** head node (``ray start --head --block``, every port on 127.0.0.1 picked
   free, its own temp dir),
4. the virtual-rig dataset (generate + ingest, no tracking) and a **24-configuration fit
   sweep** through Hydra's Ray launcher (``hydra/launcher=ray_cluster``) with
   ``tracking=server``,
5. the runs counted in the server: ``lost N`` = jobs without exactly one FINISHED model run
   under the sweep's parent,
6. everything stopped by process group (each service was started in its own session) and
   checked gone.

Exit 0 only for ``lost 0`` with every service stopped.

    python -m pipelines.cluster_check                      # what make cluster-check runs
    python -m pipelines.cluster_check --keep ../cc         # keep logs and data there
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import json
import logging
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipelines import localserv
from pipelines.common import REPO_ROOT

log = logging.getLogger("cluster_check")

ANGLES = (15, 30, 45, 60, 75, 90)
RADII = (30, 45, 60, 75)


class ClusterCheckError(Exception):
    """A service that would not come up, or a sweep that did not run."""


@dataclass
class Services:
    """Endpoints of the running services and their processes (stopped in reverse order)."""

    workdir: Path
    postgres_uri: str = ""
    tracking_uri: str = ""
    ray_address: str = ""
    procs: list[tuple[str, subprocess.Popen[bytes]]] = field(default_factory=list)
    left_behind: dict[str, list[int]] = field(default_factory=dict)
    #: folders removed after the services stopped
    cleanup: list[Path] = field(default_factory=list)


# --------------------------------------------------------------------------------------
# PostgreSQL
# --------------------------------------------------------------------------------------


def _pg_bin(name: str) -> str:
    """Debian keeps the server binaries in /usr/lib/postgresql/<major>/bin (not on PATH)."""
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"),
                   key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    if found:
        return found[-1]
    which = shutil.which(name)
    if which:
        return which
    raise ClusterCheckError(f"PostgreSQL's {name} not found: `make postgresql` installs it")


def _as_postgres(cmd: Sequence[str]) -> list[str]:
    """PostgreSQL refuses to run as root: run it as the ``postgres`` system user then."""
    if os.geteuid() == 0:
        return ["runuser", "-u", "postgres", "--", *cmd]
    return list(cmd)


def start_postgres(services: Services) -> None:
    # Its own folder outside the work folder: the postgres user must be able to reach it
    # (a test's tmp_path is private to root).
    root = Path(tempfile.mkdtemp(prefix="tsm-pg-"))
    services.cleanup.append(root)
    data, sock = root / "data", root / "sock"
    sock.mkdir(parents=True)
    password = secrets.token_hex(12)
    pwfile = root / "pw"
    pwfile.touch(mode=0o600)  # readable by its owner only, before the secret goes in
    pwfile.write_text(password + "\n")
    if os.geteuid() == 0:
        for p in (root, sock, pwfile):
            shutil.chown(p, "postgres")
    subprocess.run(_as_postgres([_pg_bin("initdb"), "-D", str(data), "-U", "mlflow",
                                 "--auth=scram-sha-256", f"--pwfile={pwfile}", "-E", "UTF8",
                                 "--no-instructions"]),
                   check=True, capture_output=True, timeout=180)
    port = localserv.free_port()
    proc = localserv.start(
        _as_postgres([_pg_bin("postgres"), "-D", str(data), "-h", localserv.LOOPBACK,
                      "-p", str(port), "-k", str(sock), "-c", "max_connections=200",
                      "-c", "fsync=off"]),
        log=services.workdir / "logs" / "postgres.log")
    services.procs.append(("postgres", proc))
    deadline = time.monotonic() + 60
    while True:
        ok = subprocess.run([_pg_bin("pg_isready"), "-h", localserv.LOOPBACK, "-p", str(port)],
                            capture_output=True, check=False).returncode == 0
        if ok:
            break
        if proc.poll() is not None or time.monotonic() > deadline:
            raise ClusterCheckError("PostgreSQL did not start: "
                                    + (services.workdir / "logs" / "postgres.log").read_text())
        time.sleep(0.3)
    import psycopg2

    conn = psycopg2.connect(host=localserv.LOOPBACK, port=port, user="mlflow",
                            password=password, dbname="postgres")
    conn.autocommit = True
    with conn.cursor() as cur:
        cur.execute("CREATE DATABASE mlflow")
    conn.close()
    services.postgres_uri = (f"postgresql+psycopg2://mlflow:{password}@{localserv.LOOPBACK}:"
                             f"{port}/mlflow")


# --------------------------------------------------------------------------------------
# MLflow server and Ray head
# --------------------------------------------------------------------------------------


def start_mlflow_server(services: Services, *, workers: int = 2) -> None:
    port = localserv.free_port()
    artifacts = services.workdir / "artifacts"
    artifacts.mkdir()
    cmd, env = localserv.mlflow_server_launch(
        sys.executable, services.postgres_uri, artifacts_uri=artifacts.resolve().as_uri(),
        port=port, workers=workers)
    log_file = services.workdir / "logs" / "mlflow.log"
    proc = localserv.start(cmd, log=log_file, cwd=services.workdir, env=env)
    services.procs.append(("mlflow", proc))
    url = f"http://{localserv.LOOPBACK}:{port}"
    localserv.wait_http(f"{url}/health", timeout=180, proc=proc, log=log_file)
    services.tracking_uri = url


def start_ray_head(services: Services, *, num_cpus: int = 2) -> None:
    ports = {name: localserv.free_port() for name in (
        "port", "node-manager-port", "object-manager-port", "dashboard-agent-listen-port",
        "dashboard-agent-grpc-port", "metrics-export-port", "runtime-env-agent-port",
        "ray-client-server-port")}
    low = localserv.free_port(start=30000, stop=39000)
    temp = Path(tempfile.mkdtemp(prefix="tsmray-", dir="/tmp"))  # ray wants a short path
    services.cleanup.append(temp)
    ray = str(Path(sys.executable).with_name("ray"))
    cmd = [ray, "start", "--head", "--block", "--node-ip-address", localserv.LOOPBACK,
           "--num-cpus", str(num_cpus), "--include-dashboard", "false",
           "--temp-dir", str(temp), "--min-worker-port", str(low),
           "--max-worker-port", str(low + 200), "--disable-usage-stats",
           *[f"--{k}={v}" for k, v in ports.items()]]
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0",
           "MLFLOW_TRACKING_URI": services.tracking_uri,
           "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO_ROOT),
                                                       os.environ.get("PYTHONPATH")]))}
    log_file = services.workdir / "logs" / "ray.log"
    proc = localserv.start(cmd, log=log_file, env=env, cwd=REPO_ROOT)
    services.procs.append(("ray", proc))
    address = f"{localserv.LOOPBACK}:{ports['port']}"
    deadline = time.monotonic() + 120
    while True:
        ready = subprocess.run([ray, "status", "--address", address], capture_output=True,
                               check=False, env=env, timeout=60).returncode == 0
        if ready:
            break
        if proc.poll() is not None or time.monotonic() > deadline:
            raise ClusterCheckError("Ray head did not start:\n" + log_file.read_text()[-3000:])
        time.sleep(1.0)
    services.ray_address = address


def stop_all(services: Services) -> None:
    """Stop every service (reverse start order) and record any process left in its group."""
    for name, proc in reversed(services.procs):
        localserv.stop(proc, timeout=30)
        left = localserv.group_alive(proc.pid)
        if left:
            services.left_behind[name] = left
    for folder in services.cleanup:
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def team_services(workdir: Path, *, ray: bool = True, num_cpus: int = 2) -> Iterator[Services]:
    """PostgreSQL + MLflow server (+ Ray head) on 127.0.0.1 for the block, then stopped."""
    services = Services(workdir=workdir)
    (workdir / "logs").mkdir(parents=True, exist_ok=True)
    try:
        t0 = time.perf_counter()
        start_postgres(services)
        start_mlflow_server(services)
        if ray:
            start_ray_head(services, num_cpus=num_cpus)
        log.info("services up in %.1f s: tracking %s, ray %s", time.perf_counter() - t0,
                 services.tracking_uri, services.ray_address or "-")
        yield services
    finally:
        stop_all(services)


# --------------------------------------------------------------------------------------
# the sweep
# --------------------------------------------------------------------------------------


def prepare_data(root: Path, *, log_file: Path) -> None:
    """The standard virtual campaign, ingested, under ``root`` (no tracking)."""
    quiet = "['progress=false']"
    with log_file.open("ab") as fh:
        subprocess.run([sys.executable, "-m", "pipelines.run_all", f"paths.root={root}",
                        "tracking=off", "stages=[generate,ingest]", "progress=false",
                        f"overrides.generate={quiet}", f"overrides.ingest={quiet}",
                        f"hydra.run.dir={root}/outputs/prepare"],
                       check=True, cwd=REPO_ROOT, timeout=1800, stdout=fh,
                       stderr=subprocess.STDOUT)


def sweep_command(*, root: Path, sweep_dir: Path, launcher: str, tracking_uri: str,
                  overrides: Sequence[str], ray_address: str | None = None,
                  n_jobs: int = 2) -> list[str]:
    """``python -m pipelines.fit -m ...`` through the Ray or the joblib launcher."""
    cmd = [sys.executable, "-m", "pipelines.fit", "-m", f"paths.root={root}",
           "tracking=server", f"tracking.uri={tracking_uri}", "progress=false", "cache=false",
           f"hydra.sweep.dir={sweep_dir}"]
    if launcher == "ray":
        cmd += ["hydra/launcher=ray_cluster", f"hydra.launcher.ray.init.address={ray_address}"]
    else:
        cmd += [f"hydra.launcher.n_jobs={n_jobs}"]
    return [*cmd, *overrides]


def run_sweep(cmd: Sequence[str], *, log_file: Path, env: dict[str, str] | None = None,
              timeout: float = 3600) -> tuple[int, float]:
    """Run a sweep to its end; (exit code, wall seconds)."""
    t0 = time.perf_counter()
    with log_file.open("ab") as fh:
        proc = subprocess.run(list(cmd), stdout=fh, stderr=subprocess.STDOUT, cwd=REPO_ROOT,
                              env=env, timeout=timeout, check=False)
    return proc.returncode, time.perf_counter() - t0


def count_runs(tracking_uri: str, sweep_dir: Path, *, experiment: str = "tsm-hysteresis"
               ) -> dict[str, Any]:
    """The sweep's model runs in the server: how many, how many FINISHED, per configuration."""
    from mlflow import MlflowClient

    parent_file = sweep_dir / "mlflow_parent_run_id"
    if not parent_file.exists():
        return {"parent": None, "runs": 0, "finished": 0, "keys": [], "with_dataset": 0}
    parent = parent_file.read_text().strip()
    client = MlflowClient(tracking_uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        return {"parent": parent, "runs": 0, "finished": 0, "keys": [], "with_dataset": 0}
    runs = client.search_runs([exp.experiment_id],
                              f"tags.mlflow.parentRunId = '{parent}' and tags.kind = 'model'",
                              max_results=5000)
    finished = [r for r in runs if r.info.status == "FINISHED"]
    keys = sorted({(r.data.tags.get("family", ""), r.data.tags.get("configuration", ""))
                   for r in finished})
    return {"parent": parent, "runs": len(runs), "finished": len(finished),
            "keys": [list(k) for k in keys],
            "with_dataset": sum(1 for r in finished
                                if r.inputs is not None and r.inputs.dataset_inputs)}


def grid_overrides(*, families: Sequence[str] = ("gamma",), angles: Sequence[int] = ANGLES,
                   radii: Sequence[int] = RADII) -> list[str]:
    return [f"family={','.join(families)}" if len(families) > 1 else f"family={families[0]}",
            f"config.curve_angle_deg={','.join(map(str, angles))}",
            f"config.radius_mm={','.join(map(str, radii))}"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keep", type=Path, default=None,
                        help="work folder to keep (default: a temporary one, removed)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    tmp = tempfile.mkdtemp(prefix="tsm-cluster-") if args.keep is None else None
    work = Path(tmp) if tmp else args.keep
    work.mkdir(parents=True, exist_ok=True)
    expected = len(ANGLES) * len(RADII)
    result: dict[str, Any] = {"expected": expected}
    lost = expected
    services: Services | None = None
    try:
        root = work / "root"
        t0 = time.perf_counter()
        (work / "logs").mkdir(parents=True, exist_ok=True)
        prepare_data(root, log_file=work / "logs" / "prepare.log")
        result["prepare_s"] = round(time.perf_counter() - t0, 1)
        with team_services(work) as services:
            sweep_dir = work / "multirun" / "ray"
            cmd = sweep_command(root=root, sweep_dir=sweep_dir, launcher="ray",
                                tracking_uri=services.tracking_uri,
                                ray_address=services.ray_address, overrides=grid_overrides())
            code, wall = run_sweep(cmd, log_file=work / "logs" / "sweep.log")
            counted = count_runs(services.tracking_uri, sweep_dir)
            lost = expected - len(counted["keys"])
            result.update({"sweep_exit": code, "sweep_s": round(wall, 1),
                           "runs": counted["runs"], "finished": counted["finished"],
                           "with_dataset": counted["with_dataset"],
                           "backend": services.postgres_uri.split("@")[-1]})
    finally:
        if services is not None:
            result["left_behind"] = services.left_behind
        result["lost"] = lost
        print(json.dumps(result, indent=1))
        print(f"lost {lost}")
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    ok = lost == 0 and result.get("sweep_exit") == 0 and not result.get("left_behind") \
        and result.get("runs") == expected
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
