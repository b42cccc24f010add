"""The command-line guard inside config groups and run_all's per-stage overrides."""

from __future__ import annotations

import pytest

from pipelines.cli import CommandLineError, check_overrides


@pytest.mark.parametrize(("stage", "argv", "named", "near"), [
    ("fit", ["tracking.enabeld=false"], "tracking.enabeld", "enabled"),
    ("generate", ["campaign.sed=7"], "campaign.sed", "seed"),
    ("fit", ["family=gamma", "family.n_operatrs=21"], "family.n_operatrs", "n_operators"),
    ("fit", ["+family.n_operatrs=21"], "family.n_operatrs", "n_operators"),
])
def test_a_misspelt_key_inside_a_group_is_named_with_its_near_names(
        stage: str, argv: list[str], named: str, near: str) -> None:
    with pytest.raises(CommandLineError, match=rf"unknown setting '{named}'.*'{near}'"):
        check_overrides(stage, argv)


def test_a_key_of_another_option_is_refused_once_the_option_is_chosen() -> None:
    check_overrides("fit", ["family.n_starts=2"])  # some family has it
    with pytest.raises(CommandLineError, match="family.n_starts"):
        check_overrides("fit", ["family=gamma", "family.n_starts=2"])


def test_a_group_value_of_the_wrong_type_names_the_key() -> None:
    with pytest.raises(CommandLineError, match=r"effects.drift='strong' is not a number"):
        check_overrides("generate", ["effects.drift=strong"])
    with pytest.raises(CommandLineError, match=r"tracking.enabled='yes' is not true or false"):
        check_overrides("fit", ["tracking.enabled=yes"])


@pytest.mark.parametrize("argv", [
    ["family=gamma", "family.n_operators=21"], ["effects.drift=0.5"], ["campaign.seed=3"],
    ["tracking=server", "tracking.uri=http://localhost:5000"], ["+rig.params.mu=0.2"],
    ["paths.root=elsewhere"], ["effects=drift_only"],
])
def test_what_the_groups_hold_is_accepted(argv: list[str]) -> None:
    stage = "generate" if any(a.split("=")[0].lstrip("+").split(".")[0] in
                              ("effects", "campaign", "rig") for a in argv) else "fit"
    check_overrides(stage, argv)


def test_run_all_checks_each_stage_override_before_anything_runs() -> None:
    with pytest.raises(CommandLineError,
                       match=r"in overrides.fit: fit: unknown setting 'n_jbos'.*'n_jobs'"):
        check_overrides("pipeline", ["overrides.fit=['n_jbos=2']"])
    with pytest.raises(CommandLineError, match=r"overrides.validate: validate: cross='often'"):
        check_overrides("pipeline", ["overrides.validate=['cross=often']"])
    check_overrides("pipeline", ["overrides.fit=['+family_overrides.bouc_wen.n_starts=2']"])
