"""No import circle inside ``hysteresis`` (lazy, in-function imports included), and the model
layer does not reach up into the pipelines."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "hysteresis"


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the ``hysteresis`` modules it imports anywhere in its body."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, base]) if base else ".".join(up)
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            for t in targets:
                if t in modules and t != name:
                    graph[name].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_planted_circle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle_inside_hysteresis() -> None:
    graph = import_graph()
    assert "hysteresis.bouc_wen" in graph and graph["hysteresis.optimisers"]
    # the package __init__ imports every family to register it; the families never import it
    found = [c for c in cycles(graph)]
    assert found == [], f"import circles: {found}"


def test_the_model_layer_imports_nothing_above_it() -> None:
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                assert not node.module.startswith("pipelines"), (path.name, node.module)
            if isinstance(node, ast.Import):
                assert not any(a.name.startswith("pipelines") for a in node.names), path.name


PIPELINES = PACKAGE.parent / "pipelines"
#: Stage modules: each a command; what one writes, another reads through pipelines.artifacts.
STAGES = {"generate", "ingest", "fit", "validate", "unseen_shape", "report", "discrepancy",
          "discrepancy_study", "compensate", "run_all"}
#: Stage imports still to be moved below the stages (the orchestrator runs every stage).
STILL_IMPORTED = {("run_all", "generate"), ("run_all", "ingest"), ("run_all", "fit"),
                  ("run_all", "validate"), ("run_all", "unseen_shape"), ("run_all", "report")}


def _pipeline_imports(path: Path) -> set[str]:
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "pipelines":
                out |= {a.name for a in node.names}
            elif node.module.startswith("pipelines."):
                out.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            out |= {a.name.split(".")[1] for a in node.names
                    if a.name.startswith("pipelines.")}
    return out


def test_no_stage_reads_another_stage_except_through_the_catalog() -> None:
    found = set()
    for path in PIPELINES.glob("*.py"):
        for target in _pipeline_imports(path) & STAGES:
            if target != path.stem:
                found.add((path.stem, target))
    assert found <= STILL_IMPORTED, f"new stage-to-stage imports: {sorted(found - STILL_IMPORTED)}"
    assert ("report", "validate") not in found and ("validate", "fit") not in found
