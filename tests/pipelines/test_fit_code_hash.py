"""The fit cache key covers the code a family runs: its module and everything it imports."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

import hysteresis.play
import hysteresis.ukf
from pipelines import cache
from pipelines.core import fit as fit_stage
from tests.pipelines.pipeline_data import make_dataset, stage_cfg


@pytest.fixture(autouse=True)
def _fresh_hashes() -> Iterator[None]:
    cache.source_hash.cache_clear()
    yield
    cache.source_hash.cache_clear()


def _edit(monkeypatch: pytest.MonkeyPatch, module_file: str | None) -> None:
    real = cache._read_source
    target = Path(str(module_file))
    monkeypatch.setattr(cache, "_read_source",
                        lambda p: real(p) + b"\n# edited\n" if p == target else real(p))
    cache.source_hash.cache_clear()


def test_editing_a_module_a_family_imports_refits_that_family_only(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = make_dataset(angles=(15,), radii=(30,), dt=0.1)
    cfg = stage_cfg(tmp_path, families=["linear", "gamma"])
    assert not fit_stage.run(cfg, dataset=data)["cached"].any()
    _edit(monkeypatch, hysteresis.ukf.__file__)  # imported by neither family
    assert fit_stage.run(cfg, dataset=data)["cached"].all()
    _edit(monkeypatch, hysteresis.play.__file__)  # the play kernels Gamma imports
    cached = fit_stage.run(cfg, dataset=data).set_index("family")["cached"]
    assert bool(cached["linear"]) and not bool(cached["gamma"])


def test_code_files_follow_relative_lazy_and_chained_imports(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "fampkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "kernel.py").write_text("import math\nK = 1\n")
    (pkg / "helpers.py").write_text("def h():\n    from .sub import kernel\n    return kernel\n")
    (pkg / "family.py").write_text("from . import helpers\nclass Fam:\n    pass\n")
    (pkg / "unused.py").write_text("X = 2\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        import fampkg.family as fam

        assert sorted(cache.code_files("fampkg.family")) == [
            "fampkg", "fampkg.family", "fampkg.helpers", "fampkg.sub", "fampkg.sub.kernel"]
        before = cache.source_hash(fam.Fam)
        (pkg / "unused.py").write_text("X = 3\n")
        cache.source_hash.cache_clear()
        assert cache.source_hash(fam.Fam) == before
        (pkg / "sub" / "kernel.py").write_text("import math\nK = 2\n")
        cache.source_hash.cache_clear()
        assert cache.source_hash(fam.Fam) != before
    finally:
        for name in [m for m in sys.modules if m.startswith("fampkg")]:
            del sys.modules[name]



def test_a_model_file_whose_content_no_longer_matches_its_hash_is_refitted(
        tmp_path: Path) -> None:
    import json

    data = make_dataset(angles=(15,), radii=(30,), dt=0.1)
    cfg = stage_cfg(tmp_path, families=["linear"])
    first = fit_stage.run(cfg, dataset=data)
    path = next((tmp_path / "data/interim/models/linear").glob("*.json"))
    record = json.loads(path.read_text())
    record["model"]["fitted"]["gain_"] += 1.0  # a damaged or hand-edited file
    path.write_text(json.dumps(record))
    again = fit_stage.run(cfg, dataset=data)
    assert not again["cached"].any()  # not trusted: fitted again, and rewritten
    assert again["model_json"].iloc[0] == first["model_json"].iloc[0]
    assert json.loads(path.read_text())["model"] == json.loads(first["model_json"].iloc[0])
    assert fit_stage.run(cfg, dataset=data)["cached"].all()
