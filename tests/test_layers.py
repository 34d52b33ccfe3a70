"""The packages are layered and no module imports itself back: ``fmu_models`` at the bottom,
``estimators`` above it, ``cosim`` on top. Every import statement counts, also those inside
functions and under ``if TYPE_CHECKING``: a module may not import (directly or through
others) a module that imports it, and no package imports one above it."""
from __future__ import annotations

import ast
from pathlib import Path

from cosim.core.schedule import _sccs

ROOT = Path(__file__).parents[1]
LAYERS = ("fmu_models", "estimators", "cosim")


def modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package)."""
    found = {}
    for top in LAYERS:
        for f in sorted((ROOT / top).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            package = parts[-1] == "__init__"
            found[".".join(parts[:-1] if package else parts)] = (f, package)
    return found


def import_graph() -> dict[str, dict[str, int]]:
    """Module -> {imported project module: line of the first such import}."""
    mods = modules()

    def resolve(name: str) -> str | None:
        parts = name.split(".")
        while parts and ".".join(parts) not in mods:
            parts.pop()
        return ".".join(parts) or None

    graph: dict[str, dict[str, int]] = {}
    for name, (path, package) in mods.items():
        here = name if package else name.rpartition(".")[0]
        edges: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = here.split(".")
                    pkg = pkg[:len(pkg) - node.level + 1]
                    base = ".".join(pkg + ([base] if base else []))
                # "from pkg import module" imports the module; "from mod import name" the module
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            for t in targets:
                r = resolve(t)
                if r is not None and r != name:
                    edges.setdefault(r, node.lineno)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (the scheduler's
    strong-component search, which finds the algebraic loops of a co-simulation)."""
    return [sorted(c) for c in _sccs(list(graph), graph) if len(c) > 1]


def test_no_import_cycle_between_modules():
    graph = import_graph()
    assert len(graph) > 50
    found = cycles(graph)
    detail = [" -> ".join(c) + ": " + "; ".join(f"{a} imports {b} (line {graph[a][b]})" for a in c for b in graph[a]
                                               if b in c) for c in found]
    assert not found, "import cycles:\n" + "\n".join(detail)


def test_no_package_imports_one_above_it():
    rank = {top: i for i, top in enumerate(LAYERS)}
    upward = [f"{a} imports {b} (line {line})" for a, edges in import_graph().items() for b, line in edges.items()
              if rank[b.split(".")[0]] > rank[a.split(".")[0]]]
    assert not upward, "imports against the layers:\n" + "\n".join(upward)


def test_the_infrastructure_imports_only_the_errors():
    """``fmu_models.infra`` is below the plant models: it may import nothing of the project
    but itself and ``fmu_models.errors``."""
    bad = [f"{a} imports {b}" for a, edges in import_graph().items() if a.startswith("fmu_models.infra")
           for b in edges if not (b.startswith("fmu_models.infra") or b == "fmu_models.errors")]
    assert not bad, bad


def test_the_checker_sees_a_cycle():
    """The check itself: a made-up cycle through a function-level import is found."""
    assert cycles({"a": {"b": 1}, "b": {"c": 3}, "c": {"a": 9}, "d": {"a": 1}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b": 1}, "b": {}}) == []
