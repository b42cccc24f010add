"""The order `make test` hands files to its workers is the one tests/conftest.py sets."""

from __future__ import annotations

import re

from tests.conftest import LONGEST_FIRST, REPO


def test_every_longest_first_file_exists():
    missing = [f for f in LONGEST_FIRST if not (REPO / "tests" / f).is_file()]
    assert missing == [], "renamed or removed test files are still listed in LONGEST_FIRST"


def test_make_test_keeps_the_collection_order():
    # without --no-loadscope-reorder xdist sorts the files by their number of tests and the
    # longest files (one or two tests each) start last
    recipe = re.search(r"^test:.*\n((?:\t.*\n)+)", (REPO / "Makefile").read_text(), re.M)
    assert recipe is not None
    assert "--dist loadfile" in recipe.group(1) and "--no-loadscope-reorder" in recipe.group(1)
