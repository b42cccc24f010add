"""Contract test of the stages' command line, as a user sees it.

Written from the user documentation (README.md, docs/pipeline.md, conf/*.yaml, the Makefile)
and the issue's words alone, by a session that never read the implementation (pipelines/,
hysteresis/, rig_io/, the other tests, bench/). The promises checked, for every stage command
the docs name (generate, ingest, fit, validate, unseen_shape, report, discrepancy,
discrepancy_study, compensate, run_all = `make pipeline`):

* a misspelt existing setting, without and with ``+``, is refused: exit status 2 (README),
  no Python traceback, one line of output naming the misspelt key (the last non-empty line of
  stderr) and the nearest known name; with ``+`` it says "did you mean ..." (issue);
* a wrong-typed value of an integer / boolean / float setting is refused the same way, the
  line naming the key and the expected type (issue: "a wrong type names the key and the
  expected type, with no traceback");
* neither writes anything under the data folder or an MLflow store: each call runs in its own
  empty folder, which is both the working folder and ``TSM_PROJECT_ROOT`` (conf/paths);
* ``--help`` exits 0 and lists the stage's settings with their meanings (a documented
  setting of the stage is printed with a sentence of text).

The issue also promises each refusal "in under 3 s". Times depend on the machine, so nothing
here asserts a time: the wall time of every failing call is recorded and printed (``-s``), and
``tests/cleanroom/cli_timing.py`` measures them one by one for a benchmark. The calls run
concurrently (4 at a time) to keep the file within about a minute, which inflates those times.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

_HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("tsm_cleanroom_cli_timing", _HERE / "cli_timing.py")
assert _spec is not None and _spec.loader is not None
cli = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = cli  # dataclasses look their module up by name
_spec.loader.exec_module(cli)

STAGES = {s.name: s for s in cli.STAGES}
TYPE_WORDS = {
    "int": ("integer", "int", "whole number"),
    "bool": ("true or false", "boolean", "bool", "true/false"),
    "float": ("number", "float", "real"),
}
EXTRA = {case[0]: case for case in cli.EXTRA}
# What a stage would write if it ran: the data folders and the local MLflow store
# (mlflow.db and its side files, mlartifacts/). Hydra's own run folder (outputs/) is not
# counted.
WORKERS = 4


def _written(files: list[str]) -> list[str]:
    return [f for f in files
            if f.split("/")[0] in ("data", "mlartifacts") or f.startswith("mlflow.db")]


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, str], Any]:
    """Every call of every stage, each in its own empty project root, 4 at a time."""
    calls = [(s.name, kind, cli.arguments(s, kind)) for s in cli.STAGES for kind in cli.KINDS]
    calls += [(stage, name, args) for name, stage, args, *_ in cli.EXTRA]
    calls.append((cli.CONTROL[0], "control", cli.CONTROL[1]))
    base = tmp_path_factory.mktemp("cli-contract")

    def one(call: tuple[str, str, tuple[str, ...]]) -> Any:
        stage, kind, args = call
        return cli.run_args(stage, kind, args, base / f"{stage}-{kind}")

    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        done = list(pool.map(one, calls))
    out = {(r.stage, r.kind): r for r in done}
    times = {cli.label(r): round(r.seconds, 2) for r in done
             if r.kind not in ("help", "control")}
    print(f"\nwall time of the failing calls (s, {WORKERS} concurrent; no assertion):")
    print(json.dumps(times, indent=1))
    return out


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def _show(res: Any) -> str:
    return (f"\n$ python {' '.join(res.argv)}\nexit {res.returncode}, {res.seconds:.2f} s"
            f"\n--- stdout ---\n{res.stdout[-1500:]}\n--- stderr ---\n{res.stderr[-1500:]}")


def _refusal_problems(res: Any, key: str) -> list[str]:
    """What is wrong with a refusal: exit 2, no traceback, one line naming ``key``, no writes."""
    problems = []
    if res.returncode != 2:
        problems.append(f"exit status {res.returncode}, not 2 (README: exit status 2)")
    if "Traceback" in res.stdout or "Traceback" in res.stderr:
        problems.append("a Python traceback is printed")
    err = _lines(res.stderr)
    if not err:
        problems.append("nothing on stderr")
    elif key not in err[-1]:
        problems.append(f"stderr's last non-empty line does not name {key!r}: {err[-1]!r}")
    every = _lines(res.stdout) + err
    if len(every) != 1:
        problems.append(f"{len(every)} non-empty lines of output, not one")
    written = _written(res.files)
    if written:
        problems.append(f"wrote data or an MLflow store under the project root: {written[:5]}")
    return problems


@pytest.mark.parametrize("kind", ["misspelt", "misspelt_plus"])
@pytest.mark.parametrize("stage_name", list(STAGES))
def test_misspelt_setting_is_refused_naming_it(results: dict, stage_name: str, kind: str) -> None:
    stage = STAGES[stage_name]
    res = results[(stage_name, kind)]
    leaf = stage.misspelt.rsplit(".", 1)[-1]
    problems = _refusal_problems(res, leaf)
    last = (_lines(res.stderr) or [""])[-1]
    right = stage.setting.rsplit(".", 1)[-1]
    if right not in last:
        problems.append(f"the nearest known name {right!r} is not offered")
    if kind == "misspelt_plus" and "did you mean" not in last.lower():
        problems.append("'+key' on a typed stage: no 'did you mean ...'")
    assert not problems, "; ".join(problems) + _show(res)


@pytest.mark.parametrize("stage_name", list(STAGES))
def test_wrong_type_is_refused_naming_key_and_type(results: dict, stage_name: str) -> None:
    stage = STAGES[stage_name]
    res = results[(stage_name, "wrong_type")]
    problems = _refusal_problems(res, stage.typed_key.rsplit(".", 1)[-1])
    last = (_lines(res.stderr) or [""])[-1].lower()
    words = TYPE_WORDS[stage.typed_kind]
    if not any(re.search(rf"\b{re.escape(w)}\b", last) for w in words):
        problems.append(f"the expected type ({stage.typed_kind}: one of {words}) is not named")
    assert not problems, "; ".join(problems) + _show(res)


def _meaning(help_text: str, setting: str) -> str:
    """The text printed with ``setting`` in a help listing: after its name on its line (less
    the default) and on the following lines indented deeper than that line."""
    lines = help_text.splitlines()
    pattern = re.compile(rf"^(\s*){re.escape(setting)}\b(.*)$")
    for i, line in enumerate(lines):
        m = pattern.match(line)
        if not m:
            continue
        indent = len(m.group(1))
        same = re.sub(r"^\s*[=:]\s*\S+", "", m.group(2))  # drop "= <default>"
        text = [same]
        for nxt in lines[i + 1:]:
            if not nxt.strip() or len(nxt) - len(nxt.lstrip()) <= indent:
                break
            text.append(nxt.strip())
        return " ".join(text).strip()
    return ""


@pytest.mark.parametrize("stage_name", list(STAGES))
def test_help_lists_settings_with_meanings(results: dict, stage_name: str) -> None:
    stage = STAGES[stage_name]
    res = results[(stage_name, "help")]
    problems = []
    if res.returncode != 0:
        problems.append(f"exit status {res.returncode}, not 0")
    if "Traceback" in res.stdout or "Traceback" in res.stderr:
        problems.append("a Python traceback is printed")
    text = res.stdout + res.stderr
    for setting in (stage.setting, stage.typed_key):
        if not re.search(rf"(?m)^\s*{re.escape(setting)}\b", text):
            problems.append(f"setting {setting!r} is not listed")
    meaning = _meaning(text, stage.setting)
    if len(re.findall(r"[A-Za-z]{2,}", meaning)) < 3:
        problems.append(f"setting {stage.setting!r} has no meaning printed with it: {meaning!r}")
    written = _written(res.files)
    if written:
        problems.append(f"--help wrote under the project root: {written[:5]}")
    assert not problems, "; ".join(problems) + _show(res)


@pytest.mark.parametrize("case", list(EXTRA))
def test_more_documented_keys_are_refused_the_same_way(results: dict, case: str) -> None:
    """Keys inside config groups, run_all's per-stage overrides and the README's examples."""
    _name, stage, _args, kind, key, hint = EXTRA[case]
    res = results[(stage, case)]
    problems = _refusal_problems(res, key)
    last = (_lines(res.stderr) or [""])[-1]
    if kind == "misspelt" and hint not in last:
        problems.append(f"the nearest known name {hint!r} is not offered")
    if kind == "wrong_type" and not any(
            re.search(rf"\b{re.escape(w)}\b", last.lower()) for w in TYPE_WORDS[hint]):
        problems.append(f"the expected type ({hint}) is not named")
    assert not problems, "; ".join(problems) + _show(res)


def test_plus_inside_a_free_mapping_is_accepted(results: dict) -> None:
    """README: "`+` adds keys only inside free mappings (`+family_overrides.gamma...=21`)"."""
    res = results[(cli.CONTROL[0], "control")]
    assert res.returncode == 0, _show(res)
    assert "n_operators: 21" in res.stdout, _show(res)
    assert "Traceback" not in res.stdout + res.stderr, _show(res)
