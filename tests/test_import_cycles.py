"""No import cycle in the package: every import of a finrft module by another, at module level or inside a
function, read from the source with `ast`, forms a graph without cycles; the floor modules import nothing of the
package above them."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import finrft

PACKAGE = Path(finrft.__file__).resolve().parent
# Modules that import no finrft module but each other: what every module above may stand on.
FLOOR = ("finrft.errors", "finrft.files", "finrft.schema", "finrft.methods")


def _name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imported(name: str, path: Path) -> set[str]:
    """The finrft modules ``name`` imports anywhere in its source; ``from X import y`` counts X.y when it is a
    module, else X. A package module's implicit import of its parents is not counted: a package's __init__
    imports its own modules as it likes."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        found.update(t for t in targets if t in MODULES and t != name)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    """Each finrft module's finrft imports: parsed when a test asks, not as every test process collects."""
    return {name: _imported(name, path) for name, path in MODULES.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One cycle of the graph (its modules, the first repeated at the end), or [] when there is none."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        state[node] = 2
        path.pop()
        return []

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return []


def floors(graph: dict[str, set[str]]) -> dict[str, int]:
    """Each module's floor: 0 for one that imports no finrft module, else one above the highest it imports."""
    level: dict[str, int] = {}

    def floor(node: str) -> int:
        if node not in level:
            level[node] = 1 + max((floor(n) for n in graph[node]), default=-1)
        return level[node]

    for node in graph:
        floor(node)
    return level


def test_the_walk_sees_relative_absolute_and_local_imports(graph):
    assert "finrft.scene" in graph["finrft.models"]            # from .scene import ...
    assert "finrft.laws" in graph["finrft.scene"]              # from . import laws
    assert "finrft.reference" in graph["finrft.experiments.plate"]      # inside a function
    assert "finrft.errors" in graph["finrft.laws.table"]       # from ..errors import ...
    assert "finrft.cli" in graph["finrft.__main__"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert floors({"a": {"b"}, "b": set()}) == {"a": 1, "b": 0}


def test_no_import_cycle(graph):
    cycle = _cycle(graph)
    assert not cycle, "import cycle: " + " -> ".join(cycle)


def test_the_floor_imports_only_the_floor(graph):
    for name in FLOOR:
        assert graph[name] <= set(FLOOR), f"{name} imports {sorted(graph[name] - set(FLOOR))}"


def test_laws_import_only_the_floor_and_their_registry(graph):
    allowed = set(FLOOR) | {"finrft.laws"}
    # li2013-planar is Li's fit in another plane: it takes the fit (coefficients, alpha, parameters) from li2013
    shared = {"finrft.laws.li2013_planar": {"finrft.laws.li2013"}}
    for name in MODULES:
        if name.startswith("finrft.laws."):
            extra = shared.get(name, set())
            assert graph[name] <= allowed | extra, f"{name} imports {sorted(graph[name] - allowed - extra)}"
