"""No import circle inside ``hysteresis`` (lazy, in-function imports included), the model
layer does not reach up into the pipelines, no module of ``pipelines`` imports a stage
module, and the stages read their settings as attributes."""

from __future__ import annotations

import ast
import re
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
#: Commands that are libraries too (imported for their functions): not stages.
TOOLS = {"lineage", "cluster_check", "compile_kernels", "docs_figures"}
#: Stage imports still to be moved below the stages: none (kept as the place to name one,
#: with its reason, should a move ever be under way).
STILL_IMPORTED: set[tuple[str, str]] = set()
#: Modules whose settings are still read as a mapping: none; every module of pipelines/
#: reads attributes of its typed settings.
STILL_MAPPINGS: set[str] = set()


def _modules() -> dict[str, Path]:
    """Every module of ``pipelines`` by its dotted name under the package
    (``fit``, ``core.fit``)."""
    out = {}
    for path in PIPELINES.rglob("*.py"):
        parts = list(path.relative_to(PIPELINES).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if parts:
            out[".".join(parts)] = path
    return out


def stage_modules() -> set[str]:
    """Stage modules: each a command (``python -m pipelines.<stage>``); what one writes,
    another reads through pipelines.artifacts, and its work is a core of pipelines.core."""
    return {name for name, path in _modules().items() if _is_command(path)} - TOOLS


def _is_command(path: Path) -> bool:
    """The module has a top-level ``if __name__ == "__main__":``."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Compare) \
                and isinstance(node.test.left, ast.Name) and node.test.left.id == "__name__":
            return True
    return False


def _pipeline_imports(path: Path) -> set[str]:
    """The ``pipelines`` modules ``path`` imports anywhere (dotted under the package)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            if node.module == "pipelines":
                out |= {a.name for a in node.names}
            elif node.module.startswith("pipelines."):
                base = node.module.removeprefix("pipelines.")
                out |= {base, *(f"{base}.{a.name}" for a in node.names)}
        elif isinstance(node, ast.Import):
            out |= {a.name.removeprefix("pipelines.") for a in node.names
                    if a.name.startswith("pipelines.")}
    return out


def test_the_stage_modules_are_the_commands() -> None:
    stages = stage_modules()
    assert {"generate", "ingest", "fit", "validate", "unseen_shape", "report", "run_all",
            "discrepancy", "discrepancy_study", "compensate"} <= stages
    assert not any(name.startswith("core") for name in stages)


def test_no_module_of_pipelines_imports_a_stage_module() -> None:
    stages = stage_modules()
    found = set()
    for name, path in _modules().items():
        for target in _pipeline_imports(path) & stages:
            if target != name:
                found.add((name, target))
    assert found <= STILL_IMPORTED, f"imports of a stage module: {sorted(found - STILL_IMPORTED)}"
    assert not any(src == "run_all" for src, _ in found)


def test_the_import_checks_see_a_planted_stage_import(tmp_path: Path) -> None:
    planted = tmp_path / "x.py"
    planted.write_text("from pipelines import fit\nfrom pipelines.core import report\n"
                       "import pipelines.validate\n", encoding="utf-8")
    assert {"fit", "core", "core.report", "validate"} <= _pipeline_imports(planted)


#: ``cfg["setting"]``, ``cfg.get("setting")`` and the same on the other names a config went
#: by (``plain``, ``conf``, ``pipeline`` ...): a setting read from a mapping, not an attribute.
_MAPPING_LOOKUP = re.compile(
    r"\b(cfg|cfgd|conf|plain|pipeline|icfg|gcfg|settings)(\[\s*[\"']|\.get\()")


def test_settings_are_read_as_attributes_not_mapping_lookups() -> None:
    found = []
    for name, path in _modules().items():
        if name.split(".")[0] in STILL_MAPPINGS:
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            if _MAPPING_LOOKUP.search(line):
                found.append(f"{path.relative_to(PIPELINES.parent)}:{n}: {line.strip()}")
    assert not found, "settings read from a mapping:\n" + "\n".join(found)
    assert _MAPPING_LOOKUP.search('x = cfg["signals"]')
    assert _MAPPING_LOOKUP.search("x = plain.get('tracking')")
