"""Fixtures every test folder shares: where the lab's shared data lives."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Two test workers share two cores, and every stage the tests start is a process of its own:
# a BLAS pool of one thread per core in each of them only oversubscribes the cores (OpenBLAS
# threads spin while they wait). Set before the workers and their subprocesses start; a value
# the caller set is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

#: The files that take longest (seconds on 2 cores), longest first. `make test` runs
#: a file on one worker (``--dist loadfile``) and, with ``--no-loadscope-reorder``, hands the
#: files out in collection order (xdist would otherwise sort them by their number of tests and
#: start the one-test crash and sweep files last), so starting with the longest lets the short
#: ones fill in around them and both workers finish together.
LONGEST_FIRST = (
    "hysteresis/test_discrepancy_rig.py",  # ~65-90 s
    "pipelines/test_crash_recovery.py",  # ~40-90 s: which stages are killed is random
    "pipelines/test_sweep.py",  # ~30-40 s
    "pipelines/test_config_composition.py",  # ~25-30 s
    "pipelines/test_discrepancy_pipeline.py",
    "pipelines/test_discrepancy_base_check.py",
    "pipelines/test_concurrent_sweeps.py",
    "pipelines/test_discrepancy_study.py",
    "pipelines/test_end_to_end.py",
    "pipelines/test_compensate.py",
    "hysteresis/test_compensation.py",
    "pipelines/test_generate.py",
    "pipelines/test_run_lifecycle.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def key(item: pytest.Item) -> int:
        path = Path(str(item.path)).resolve()
        if not path.is_relative_to(REPO / "tests"):
            return len(rank)
        return rank.get(path.relative_to(REPO / "tests").as_posix(), len(rank))

    items.sort(key=key)  # stable: the other files keep their order


@pytest.fixture(scope="session")
def catheter_dir() -> Path:
    """The real tendon-catheter runs, read in place (never copied into the repository).

    The data share sits beside the repository (``../shared``, as on the CI machine);
    ``TSM_SHARED_DIR`` points elsewhere. Missing data fails the test: a skip here would hide
    that the real-data checks did not run."""
    shared = Path(os.environ.get("TSM_SHARED_DIR", REPO.parent / "shared"))
    folder = shared / "real-data" / "tendon-catheter"
    if not folder.is_dir():
        pytest.fail(f"real catheter data not found at {folder}: put the lab's shared folder "
                    "beside the repository or set TSM_SHARED_DIR")
    return folder


@pytest.fixture(scope="session")
def stage_auto_families() -> dict:
    """The discrepancy stage's plain families for ``base_family=auto``, as composed from
    ``conf/discrepancy.yaml``."""
    from hydra import compose, initialize_config_dir

    from pipelines.common import CONF_DIR, to_container

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return dict(to_container(compose("discrepancy"))["auto_families"])
