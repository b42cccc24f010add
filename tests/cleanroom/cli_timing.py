"""Wall time of the command-line calls that must fail fast (a benchmark helper).

Written from the user documentation (README.md, docs/pipeline.md, conf/*.yaml, the Makefile)
and the words of the issue alone, by a session that never read the implementation.

The issue promises that a misspelt key (with or without ``+``) and a mistyped value each fail
"in under 3 s with one line naming the key". The tests (``test_cli_contract.py``) assert no
time (machines differ); this script runs the same failing calls one after another, each in
its own empty project root (``TSM_PROJECT_ROOT`` and the working folder), and prints a JSON
object ``{"<stage> <kind> <argument>": seconds, ...}`` plus the load average it ran under:

    PYTHONPATH=$PWD .venv/bin/python tests/cleanroom/cli_timing.py [--repeat N] [--stage fit ...]

It is also the one place that lists the calls: the contract test loads it by file path.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Stage:
    """One stage command and the documented settings the calls use."""

    name: str  # python -m pipelines.<name>
    setting: str  # a real setting of the stage (docs / conf / --cfg job)
    misspelt: str  # the same setting, misspelt
    value: str  # a value of the right type for it
    typed_key: str  # an integer / boolean / float setting
    typed_kind: str  # "int" | "bool" | "float"
    wrong_value: str  # a value that is not of that type


# Every stage the docs name as a Hydra app with typed settings (README "Everyday commands" and
# the paragraph after it: generate, ingest, fit, validate, unseen_shape, report, discrepancy,
# discrepancy_study, compensate and the whole pipeline = run_all).
STAGES: tuple[Stage, ...] = (
    Stage("generate", "overwrite", "overwirte", "true", "n_jobs", "int", "two"),
    Stage("ingest", "force", "froce", "true", "limits.max_file_mb", "float", "big"),
    Stage("fit", "n_jobs", "n_jbos", "1", "max_samples", "int", "lots"),
    Stage("validate", "cross", "corss", "true", "cross", "bool", "perhaps"),
    Stage("unseen_shape", "eval_excitations", "eval_excitatons", "[band_random]", "dpi", "int",
          "high"),
    Stage("report", "metric", "metirc", "rmse", "plots.per_configuration", "bool", "sometimes"),
    Stage("discrepancy", "base_family", "base_famly", "gamma", "analysis_rate_hz", "float",
          "fast"),
    Stage("discrepancy_study", "pairs_selected", "pairs_selectd", "[a]", "rate_hz", "float",
          "quick"),
    Stage("compensate", "seed001.model_input", "seed001.model_inptu", "command",
          "seed002.trials", "int", "five"),
    Stage("run_all", "fit_excitations", "fit_excitatons", "[sine_decay]", "n_jobs", "int",
          "two"),
)

# More refusals the docs promise, beyond one top-level setting per stage: a key inside a
# config group's node (conf/tracking/local.yaml `enabled`, conf/generate.yaml
# `campaign.seed=7` and `effects.time_delay=1.0`, README `family=gamma family.n_operators=21`),
# a key inside run_all's per-stage overrides (docs/pipeline.md "overrides.<stage>"; README:
# "each command line is checked ... before anything runs"; `stages=[fit]` keeps the call short
# even where the check comes late) and the README's own two examples.
# (label, stage, arguments, "misspelt" | "wrong_type", key named, nearest name or type kind)
EXTRA: tuple[tuple[str, str, tuple[str, ...], str, str, str], ...] = (
    ("readme_plus_famly", "fit", ("+famly=gamma",), "misspelt", "famly", "family"),
    ("readme_curve_angle_ninety", "fit", ("config.curve_angle_deg=ninety",), "wrong_type",
     "curve_angle_deg", "float"),
    ("group_tracking_enabeld", "fit", ("tracking.enabeld=false",), "misspelt", "enabeld",
     "enabled"),
    ("group_campaign_sed", "generate", ("campaign.sed=7",), "misspelt", "sed", "seed"),
    ("group_family_n_operatrs", "fit", ("family=gamma", "family.n_operatrs=21"), "misspelt",
     "n_operatrs", "n_operators"),
    ("group_effects_drift_strong", "generate", ("effects.drift=strong",), "wrong_type", "drift",
     "float"),
    ("run_all_overrides_fit_n_jbos", "run_all", ("overrides.fit=['n_jbos=2']", "stages=[fit]"),
     "misspelt", "n_jbos", "n_jobs"),
)
# A control: `+` inside a free mapping is accepted (README), so the refusals above are not a
# blanket refusal of `+`.
CONTROL = ("fit", ("+family_overrides.gamma.n_operators=21", "--cfg", "job"))

# kind -> the argument list after `python -m pipelines.<stage>`
KINDS = ("misspelt", "misspelt_plus", "wrong_type", "help")
FAILING_KINDS = ("misspelt", "misspelt_plus", "wrong_type")


def arguments(stage: Stage, kind: str) -> list[str]:
    if kind == "misspelt":
        return [f"{stage.misspelt}={stage.value}"]
    if kind == "misspelt_plus":
        return [f"+{stage.misspelt}={stage.value}"]
    if kind == "wrong_type":
        return [f"{stage.typed_key}={stage.wrong_value}"]
    if kind == "help":
        return ["--help"]
    raise ValueError(kind)


@dataclass
class Result:
    stage: str
    kind: str
    argv: list[str]
    returncode: int
    stdout: str
    stderr: str
    seconds: float
    root: Path
    files: list[str]  # every path (relative to root) that exists after the call


def environment(root: Path) -> dict[str, str]:
    env = dict(os.environ)
    # the checkout under test first (the venv's .pth may name another checkout)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    env["TSM_PROJECT_ROOT"] = str(root)  # conf/paths/default.yaml: paths.root
    env.setdefault("MPLBACKEND", "Agg")
    # a user's shell may name a tracking server or a parent run: not here
    for name in ("MLFLOW_TRACKING_URI", "TSM_MLFLOW_PARENT_RUN_ID"):
        env.pop(name, None)
    return env


def run_call(stage: Stage, kind: str, root: Path, timeout: float = 120.0) -> Result:
    """Run one call in the empty folder ``root`` (working folder and project root)."""
    return run_args(stage.name, kind, arguments(stage, kind), root, timeout)


def run_args(stage: str, kind: str, args: list[str] | tuple[str, ...], root: Path,
             timeout: float = 120.0) -> Result:
    """``python -m pipelines.<stage> <args>`` in the empty folder ``root``."""
    root.mkdir(parents=True, exist_ok=True)
    argv = [sys.executable, "-m", f"pipelines.{stage}", *args]
    start = time.perf_counter()
    try:
        proc = subprocess.run(argv, cwd=root, env=environment(root), capture_output=True,
                              text=True, timeout=timeout, check=False)
        code, out, err = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as exc:
        code = -999
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err = (exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or ""))
        err += f"\n[cli_timing: timed out after {timeout} s]"
    seconds = time.perf_counter() - start
    files = sorted(str(p.relative_to(root)) for p in root.rglob("*"))
    return Result(stage, kind, argv[1:], code, out, err, seconds, root, files)


def label(result: Result) -> str:
    return f"{result.stage} {result.kind} {' '.join(result.argv[2:])}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs per call (the minimum is kept)")
    parser.add_argument("--stage", action="append", help="only these stages (repeatable)")
    args = parser.parse_args()
    stages = [s for s in STAGES if not args.stage or s.name in args.stage]
    times: dict[str, float] = {}
    codes: dict[str, int] = {}
    with tempfile.TemporaryDirectory(prefix="tsm-cli-timing-") as tmp:
        for i, stage in enumerate(stages):
            for kind in FAILING_KINDS:
                best = None
                for r in range(args.repeat):
                    res = run_call(stage, kind, Path(tmp) / f"{i}-{kind}-{r}")
                    best = res.seconds if best is None else min(best, res.seconds)
                    codes[label(res)] = res.returncode
                times[label(res)] = round(float(best or 0.0), 3)
        if not args.stage:
            for name, stage_name, extra, _kind, _key, _hint in EXTRA:
                best = None
                for r in range(args.repeat):
                    res = run_args(stage_name, name, extra, Path(tmp) / f"x-{name}-{r}")
                    best = res.seconds if best is None else min(best, res.seconds)
                    codes[label(res)] = res.returncode
                times[label(res)] = round(float(best or 0.0), 3)
    print(json.dumps({"wall_s": times, "returncode": codes,
                      "max_wall_s": max(times.values(), default=0.0),
                      "loadavg": list(os.getloadavg()), "cpus": os.cpu_count()}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
