"""Every setting a stage's ``--help`` lists comes with its meaning (the ``#:`` comment above
its field, or a nested node's class docstring)."""

from __future__ import annotations

import pytest

from pipelines import cli, schemas

#: Settings still printed without a meaning: the discrepancy stage's and study's own fields and
#: the discrepancy workflow's knobs, whose dataclasses are documented where they will live.
#: Remove an entry once its field has a ``#:`` comment; the list only ever shrinks.
WITHOUT_MEANING = {
    ("discrepancy", "paths"),
    ("discrepancy", "base_retry_factor"),
    ("discrepancy", "base_misfit_factor"),
    ("discrepancy", "workflow.candidates"),
    ("discrepancy", "workflow.max_effects"),
    ("discrepancy", "workflow.progress"),
    ("discrepancy", "progress"),
    ("discrepancy_study", "paths"),
    ("discrepancy_study", "expect_combination_reduction"),
    ("discrepancy_study", "base_family"),
    ("discrepancy_study", "progress"),
}


def _settings(stage: str) -> list[tuple[str, str, str]]:
    return list(cli._settings(schemas.STAGE_SCHEMAS[stage]))


@pytest.mark.parametrize("stage", sorted(schemas.STAGE_SCHEMAS))
def test_every_setting_has_a_meaning(stage: str) -> None:
    missing = [name for name, _, meaning in _settings(stage)
               if not meaning and (stage, name) not in WITHOUT_MEANING]
    assert not missing, (f"{stage}: settings without a meaning in --help (add a '#:' comment "
                         f"above each field): {missing}")


def test_the_allow_list_names_only_settings_still_without_a_meaning() -> None:
    """An entry whose setting gained a meaning (or was renamed away) must leave the list."""
    present = {(stage, name): meaning for stage in schemas.STAGE_SCHEMAS
               for name, _, meaning in _settings(stage)}
    stale = sorted(key for key in WITHOUT_MEANING if present.get(key, "x"))
    assert not stale, f"remove from WITHOUT_MEANING: {stale}"
