"""Are two project roots' outputs byte-identical? For a change that must not alter results.

    python -m bench.compare_outputs <root-before> <root-after> [--stage pipeline ...]

Run ``make pipeline compensate discrepancy`` in a clone of the commit before a change and in
one of the commit after, then compare: every file those targets write under ``data/``
(processed dataset, models, predictions, reports, compensation and discrepancy outputs) must
be present in both and hold the same bytes. Two kinds of content are allowed to differ, and
only after they are masked:

- wall-clock fields: a JSON/YAML key or table column that measures time spent or tells when
  (``seconds``, ``elapsed_s``, ``started`` ...) and the "in 12.3 s" of a report's prose;
- the project root itself, where a file names it (a report's link to its own folder);
- content keys and hashes (16 to 64 hex digits, ``*.sha256`` files): a cache key holds the
  code's hash and the dataset's (whose run index names the root), so it changes with any
  commit and any clone; what the keys stand for is compared itself.

A parquet file is compared as its table (pyarrow writes its own version into the footer);
an image is compared by its pixels where the bytes differ (PNG metadata). The MLflow store,
Hydra's run folders and logs are not outputs. Exits 1 naming every file that differs.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

#: What each make target writes, relative to a project root.
STAGE_OUTPUTS: dict[str, tuple[str, ...]] = {
    "pipeline": ("data/raw", "data/processed", "data/interim", "data/reports"),
    "compensate": ("data/reports/compensation", "data/reports/compensation.md"),
    "discrepancy": ("data/reports/discrepancy.json", "data/reports/discrepancy_plots"),
}
#: Not outputs: the tracking store, Hydra's folders, logs, caches of compiled code.
IGNORED_PARTS = {"mlruns", "mlflow", ".hydra", "outputs", "multirun", "__pycache__",
                 "numba-cache", ".locks"}
IGNORED_SUFFIXES = {".log", ".db", ".sqlite", ".lock", ".tmp", ".sha256"}
#: A table column that is a time measurement (Table 4.4's per-step times and their ratios).
TIMING_COLUMN = re.compile(r"(_ms|_s|_seconds|^ratio_to_ours)$")
#: Files that are wall-clock measurements as a whole: only their keys are compared.
TIMING_FILES = {"pipeline_timing.json"}
#: A key or column that measures time spent, or tells when: masked before comparing.
WALL_CLOCK = re.compile(
    r"(^|_)(seconds|second|secs|elapsed|elapsed_s|wall|wall_s|duration|duration_s|time_s|"
    r"cpu_s|started|start_time|end_time|finished|timestamp|created|written_at|at|"
    r"runtime|runtime_s|took|took_s|per_run_s|fit_s|total_s|s_per_run)$")
PROSE_TIME = re.compile(r"\b\d+(\.\d+)?\s?(s|ms|min)\b")
#: a hex key or digest (not the digits of a number: one letter at least, no decimal point)
HEX_KEY = re.compile(r"(?<![.\d])\b(?=[0-9]*[a-f])[0-9a-f]{16,64}\b")
ISO_TIME = re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2}(\.\d+)?(Z|[+-]\d{2}:?\d{2})?")


def output_files(root: Path, stages: Iterable[str]) -> dict[str, Path]:
    """Relative path -> file, for every output the given stages write under ``root``."""
    found: dict[str, Path] = {}
    for stage in stages:
        for rel in STAGE_OUTPUTS[stage]:
            base = root / rel
            if not base.exists():
                continue
            files = [base] if base.is_file() else sorted(p for p in base.rglob("*") if p.is_file())
            for path in files:
                parts = set(path.relative_to(root).parts)
                if parts & IGNORED_PARTS or path.suffix in IGNORED_SUFFIXES:
                    continue
                found[str(path.relative_to(root))] = path
    return found


def _mask_json(value: Any) -> Any:
    if isinstance(value, float) and value != value:
        return "<nan>"  # NaN != NaN: two equal files would differ
    if isinstance(value, dict):
        return {k: ("<time>" if WALL_CLOCK.search(str(k).lower()) else _mask_json(v))
                for k, v in value.items()}
    if isinstance(value, list):
        return [_mask_json(v) for v in value]
    if isinstance(value, str):
        return ISO_TIME.sub("<when>", value)
    return value


def _keys_of(text: str) -> Any:
    def keys(value: Any) -> Any:
        return {k: keys(v) for k, v in value.items()} if isinstance(value, dict) else None

    return keys(json.loads(text))


def _mask_markdown_tables(text: str) -> str:
    """The cells of timing columns in markdown tables (``| ... | mean_ms | ... |``)."""
    out: list[str] = []
    timing: list[int] = []
    for line in text.splitlines():
        if not line.startswith("|"):
            timing = []
            out.append(line)
            continue
        cells = line.split("|")
        if not timing and not set(line) <= set("|-: "):
            timing = [i for i, c in enumerate(cells) if TIMING_COLUMN.search(c.strip())]
            if not timing:
                timing = [-1]  # a table without timing columns
        out.append("|".join("<time>" if i in timing and not set(c) <= set("-: ")
                            and c.strip() not in ("",) and not TIMING_COLUMN.search(c.strip())
                            else c for i, c in enumerate(cells)))
    return "\n".join(out)


def _masked_text(text: str, root: Path) -> str:
    text = _mask_markdown_tables(text)
    text = text.replace(str(root.resolve()), "<root>").replace(str(root), "<root>")
    text = ISO_TIME.sub("<when>", text)
    text = HEX_KEY.sub("<key>", text)
    return PROSE_TIME.sub("<time>", text)


def _table(path: Path) -> Any:
    import pandas as pd

    frame = pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path)
    keep = [c for c in frame.columns if not WALL_CLOCK.search(str(c).lower())
            and not TIMING_COLUMN.search(str(c))]
    return frame[keep]


def _same_table(a: Path, b: Path) -> bool:
    ta, tb = _table(a), _table(b)
    return list(ta.columns) == list(tb.columns) and ta.equals(tb)


def _same_image(a: Path, b: Path) -> bool:
    import matplotlib.image as mpimg
    import numpy as np

    pa, pb = mpimg.imread(a), mpimg.imread(b)
    return pa.shape == pb.shape and bool(np.array_equal(pa, pb))


def same_content(a: Path, b: Path, root_a: Path, root_b: Path) -> bool:
    """True when two files hold the same output once wall-clock fields and roots are masked."""
    raw_a, raw_b = a.read_bytes(), b.read_bytes()
    if raw_a == raw_b:
        return True
    suffix = a.suffix.lower()
    if suffix in (".parquet", ".csv"):
        return _same_table(a, b)
    if suffix == ".png":
        return _same_image(a, b)
    try:
        text_a, text_b = raw_a.decode("utf-8"), raw_b.decode("utf-8")
    except UnicodeDecodeError:
        return False
    if a.name in TIMING_FILES:
        return _keys_of(text_a) == _keys_of(text_b)
    if suffix == ".json":
        try:
            return bool(_mask_json(json.loads(_masked_text(text_a, root_a)))
                        == _mask_json(json.loads(_masked_text(text_b, root_b))))
        except json.JSONDecodeError:
            pass
    return _masked_text(text_a, root_a) == _masked_text(text_b, root_b)


def compare(before: Path, after: Path, stages: Iterable[str]) -> list[str]:
    """Every difference between the two roots' outputs (empty when identical)."""
    stages = list(stages)
    a, b = output_files(before, stages), output_files(after, stages)
    problems = [f"only in {before}: {rel}" for rel in sorted(set(a) - set(b))]
    problems += [f"only in {after}: {rel}" for rel in sorted(set(b) - set(a))]
    for rel in sorted(set(a) & set(b)):
        if not same_content(a[rel], b[rel], before, after):
            problems.append(f"differs: {rel}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--stage", action="append", choices=sorted(STAGE_OUTPUTS),
                        help="compare only these targets' outputs (default: all three)")
    args = parser.parse_args(argv)
    stages = args.stage or list(STAGE_OUTPUTS)
    problems = compare(args.before, args.after, stages)
    n = len(output_files(args.before, stages))
    for line in problems:
        print(line)
    print(f"{n} output files of {', '.join(stages)}: "
          + ("identical" if not problems else f"{len(problems)} differences"))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
