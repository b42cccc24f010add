"""Every paper reference in the docs ("seed 001", "Table 4.1", "eq. 27", "Fig. 4.12") has a
row in docs/glossary.md saying which paper it is and what the project takes from it."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GLOSSARY = REPO / "docs" / "glossary.md"

_NUM = r"(?:\d+(?:\.\d+)?|[IVX]+)"
#: (kind, pattern): a reference and an optional range end (``eq. 27-31``, ``eq. 16/18``).
PATTERNS = (
    ("seed", re.compile(r"\bseed[ _-]?(00\d)(?!\d)", re.IGNORECASE)),
    ("table", re.compile(rf"\bTables? ({_NUM})(?:\s*-\s*({_NUM}))?\b")),
    ("eq", re.compile(r"\b[Ee]qs?\. ?(\d+(?:\.\d+)?)(?:\s*-\s*(\d+(?:\.\d+)?))?"
                      r"(?:/(\d+(?:\.\d+)?))?")),
    ("fig", re.compile(r"\bFigs?\. ?(\d+(?:\.\d+)?)(?:\s*-\s*(\d+(?:\.\d+)?))?")),
)


def _expand(first: str, last: str | None) -> list[str]:
    """``4.7``..``4.10`` -> 4.7, 4.8, 4.9, 4.10; ``27``..``31`` -> 27..31; one item else."""
    if last is None or not first[0].isdigit() or not last[0].isdigit():
        return [first] if last is None else [first, last]
    head_a, _, tail_a = first.rpartition(".")
    head_b, _, tail_b = last.rpartition(".")
    if head_a != head_b or int(tail_b) < int(tail_a) or int(tail_b) - int(tail_a) > 40:
        return [first, last]
    prefix = f"{head_a}." if head_a else ""
    return [f"{prefix}{n}" for n in range(int(tail_a), int(tail_b) + 1)]


def references(text: str) -> set[str]:
    """Normalised references in ``text``: ``seed 001``, ``table 4.1``, ``eq. 27``, ``fig. 4.12``."""
    found: set[str] = set()
    for kind, pattern in PATTERNS:
        for m in pattern.finditer(text):
            if kind == "seed":
                found.add(f"seed {m.group(1)}")
                continue
            items = _expand(m.group(1), m.group(2))
            if kind == "eq" and m.group(3):  # eq. 16/18: both, not a range
                items.append(m.group(3))
            prefix = {"table": "table ", "eq": "eq. ", "fig": "fig. "}[kind]
            found.update(prefix + i for i in items)
    return found


def glossary_entries() -> set[str]:
    """The references the glossary's tables define (first column of every table row, and
    the paper names)."""
    entries: set[str] = set()
    for line in GLOSSARY.read_text(encoding="utf-8").splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            first = line.split("|")[1]
            entries |= references(first)
    return entries


def test_the_reference_patterns_find_what_docs_write() -> None:
    text = ("seed 001 Table 4.1, seed-002 Table I, seed000 Tables 2-4, eq. 27-31 and eq. 16/18, "
            "Eq. 4.7-4.10, Fig. 4.12; a table view is not a reference")
    assert references(text) == {
        "seed 001", "seed 002", "seed 000", "table 4.1", "table I", "table 2", "table 3",
        "table 4", "eq. 27", "eq. 28", "eq. 29", "eq. 30", "eq. 31", "eq. 16", "eq. 18",
        "eq. 4.7", "eq. 4.8", "eq. 4.9", "eq. 4.10", "fig. 4.12"}


def test_every_paper_reference_in_the_docs_has_a_glossary_entry() -> None:
    docs = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
    known = glossary_entries()
    assert {"seed 000", "seed 001", "seed 002", "table 4.1", "eq. 27"} <= known
    missing: dict[str, list[str]] = {}
    for doc in docs:
        if doc == GLOSSARY:
            continue
        for ref in sorted(references(doc.read_text(encoding="utf-8")) - known):
            missing.setdefault(ref, []).append(str(doc.relative_to(REPO)))
    assert not missing, f"paper references without a docs/glossary.md row: {missing}"


def test_the_readme_links_the_glossary() -> None:
    assert "docs/glossary.md" in (REPO / "README.md").read_text(encoding="utf-8")
