"""schemas.settings: the one conversion of a stage's config into its typed settings object."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf
from omegaconf.errors import MissingMandatoryValue, ValidationError

from pipelines import schemas


def test_settings_fills_defaults_drops_foreign_keys_and_types_nested_nodes() -> None:
    s = schemas.settings(schemas.FitConfig, {"paths": {"root": "."}, "n_jobs": 1,
                                             "not_a_fit_key": 3, "config": {"rig": "A"}})
    assert isinstance(s, schemas.FitConfig)
    assert s.n_jobs == 1 and s.paths == {"root": "."} and s.tracking is None
    assert isinstance(s.config, schemas.ConfigurationSelection) and s.config.rig == "A"
    assert s.signals == schemas.Signals()
    assert schemas.settings(schemas.FitConfig, s) is s


def test_settings_accepts_a_composed_node_and_resolves_it() -> None:
    node = OmegaConf.create({"paths": {"root": "r", "reports": "${paths.root}/rep"},
                             "out_dir": "${paths.reports}/c", "report": "x.md"})
    s = schemas.settings(schemas.CompensateConfig, node)
    assert s.out_dir == "r/rep/c" and s.seed001 == schemas.Seed001Settings()


def test_settings_refuses_a_wrong_type_and_a_missing_mandatory_value() -> None:
    with pytest.raises(ValidationError, match="n_jobs"):
        schemas.settings(schemas.FitConfig, {"n_jobs": "two"})
    with pytest.raises(MissingMandatoryValue):
        schemas.settings(schemas.CompensateConfig, {"paths": {}})
