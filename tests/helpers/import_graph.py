"""The project's import graph, read from the source with :mod:`ast` (every ``import``,
at module level or inside functions), and the layering rules it must follow.

The frame flows scenes → camera_models → pipeline → studies; inside studies, the
engine → the catalog of studies → experiments → the command line. A module may import
its own layer and the layers before it, never a later one, and no group of modules may
import each other in a cycle.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from pathlib import Path

LAYERS = (
    "scenes",
    "camera_models",
    "pipeline",
    "studies.engine",
    "studies.catalog",
    "studies.experiments",
    "studies.cli",
)
"""Layers in the order of the frame; the first prefix that names a module is its layer."""

PACKAGES = ("scenes", "camera_models", "pipeline", "studies")


def module_name(root: Path, path: Path) -> str:
    """Dotted module name of ``path`` under ``root``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph(root: Path, packages: Iterable[str] = PACKAGES) -> dict[str, set[str]]:
    """Module → the project modules it imports (anywhere in its code)."""
    files = {module_name(root, p): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        targets: set[str] = set()
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join([*anchor, base] if base else anchor)
                names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in files else base for alias in node.names]
            else:
                continue
            for name in names:
                while name and name not in files:  # the longest prefix that is a project module
                    name = name.rpartition(".")[0]
                if name and name != module:
                    targets.add(name)
        graph[module] = targets
    return graph


def layer(module: str) -> int:
    """Index of ``module``'s layer in :data:`LAYERS` (the package ``studies`` itself is the engine's)."""
    for i, prefix in enumerate(LAYERS):
        if module == prefix or module.startswith(prefix + "."):
            return i
    if module == "studies":
        return LAYERS.index("studies.engine")
    raise ValueError(f"{module}: in no layer")


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """``a → b`` for every import of a later layer."""
    return sorted(f"{a} → {b}" for a, targets in graph.items() for b in targets if layer(b) > layer(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Groups of modules that import each other (strongly connected components of size > 1),
    by Tarjan's algorithm."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found
