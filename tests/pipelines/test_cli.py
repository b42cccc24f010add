"""The command line refuses what a stage does not know, before Hydra composes anything."""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pipelines import cli

REPO = Path(__file__).resolve().parents[2]
MODULES = {"fit": "fit", "validate": "validate", "report": "report",
           "unseen_shape": "unseen_shape", "run_all": "pipeline", "ingest": "ingest",
           "generate": "generate", "discrepancy": "discrepancy", "compensate": "compensate",
           "discrepancy_study": "discrepancy_study"}


def _run(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(("args", "named"), [
    (["+famly=gamma"], "unknown setting 'famly' (did you mean"),
    (["config.curve_angle_deg=ninety"], "config.curve_angle_deg='ninety' is not a number"),
])
def test_a_misspelt_key_or_a_mistyped_value_is_one_line_and_exit_2(
        tmp_path: Path, args: list[str], named: str) -> None:
    done = _run(tmp_path, "pipelines.fit", *args)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fit: "), done.stderr
    assert named in lines[0]
    assert not any(tmp_path.iterdir()), "nothing may be written for a refused command"


@pytest.mark.parametrize(("args", "named"), [
    (["famly=gamma"], "unknown setting 'famly' (did you mean"),
    (["+famly=gamma"], "'+' adds keys only to free mappings"),
    (["n_jobs=two"], "n_jobs='two' is not an integer"),
    (["config.curve_angel_deg=90"], "'config.curve_angel_deg' under 'config' (did you mean "
                                    "'curve_angle_deg'?)"),
    (["-m", "cache=true,maybe"], "cache='maybe' is not true or false"),
    (["config.radius_mm=[30,thirty]"], "config.radius_mm='thirty' is not a number"),
])
def test_the_guard_names_the_key_and_what_it_expects(args: list[str], named: str) -> None:
    with pytest.raises(cli.CommandLineError) as err:
        cli.check_overrides("fit", args)
    assert named in str(err.value) and "\n" not in str(err.value)


def test_help_lists_every_setting_with_its_meaning(tmp_path: Path) -> None:
    done = _run(tmp_path, "pipelines.fit", "--help")
    assert done.returncode == 0, done.stderr
    assert "max_samples = 2000000" in done.stdout
    assert "Per-run limit of the fit" in done.stdout
    assert "config.curve_angle_deg = null" in done.stdout
    assert "Config groups" in done.stdout and "family" in done.stdout


@pytest.mark.parametrize("stage", sorted(set(MODULES.values())))
def test_every_stage_has_a_help_page(stage: str) -> None:
    text = cli.help_text(stage)
    assert text.count("\n  ") >= 3 and "Settings" in text


def test_plus_still_adds_keys_to_free_mappings() -> None:
    cli.check_overrides("fit", ["+family_overrides.gamma.n_operators=21"])
    cli.check_overrides("fit", ["family=gamma", "family.n_operators=21"])
    cli.check_overrides("discrepancy",
                        ["base_family=gamma", "+base_params={constraint: free}"])
    cli.check_overrides("fit", ["-m", "hydra/launcher=ray", "config.curve_angle_deg=15,90"])
    with pytest.raises(cli.CommandLineError, match="'config.n_operators' under 'config'"):
        cli.check_overrides("fit", ["+config.n_operators=21"])


def test_every_command_in_the_docs_passes_the_guard() -> None:
    files = [*glob.glob(str(REPO / "docs" / "*.md")), str(REPO / "README.md"),
             str(REPO / "Makefile"), *glob.glob(str(REPO / "conf" / "*.yaml"))]
    checked = 0
    for path in files:
        text = Path(path).read_text().replace("\\\n", " ")
        for m in re.finditer(r"pipelines\.(\w+)((?:[ \t]+[^\s`#;|&)\"']+)*)", text):
            if m.group(1) not in MODULES:
                continue
            args = [a for a in m.group(2).split() if ("=" in a or a.startswith("-"))
                    and "$" not in a and "<" not in a and "{" not in a]
            if args:
                cli.check_overrides(MODULES[m.group(1)], args)
                checked += 1
    assert checked >= 40
