"""Fixtures every test folder shares: where the lab's shared data lives."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


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
