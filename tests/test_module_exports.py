"""Every library module states its public names, and the statement stays true.

Each module under ``scenes``, ``camera_models``, ``pipeline`` and ``studies`` (``__init__``
files aside) is imported and checked:

- it defines ``__all__``;
- every name in ``__all__`` exists in the module;
- no name is listed twice;
- every name that another repository module (library, ``tests/`` or ``scripts/``) imports from
  it with ``from <module> import <name>`` is listed (``*`` and ``_``-prefixed names aside).

A ``__main__`` module runs its program when imported, so its ``__all__`` is read from its
source instead.

Notes
-----
The importers are found by parsing the repository's ``.py`` files with :mod:`ast`, relative
imports resolved against the importing module's package.
"""

from __future__ import annotations

import ast
import importlib
import sys
from collections import Counter
from functools import cache
from pathlib import Path

import pytest

from tests.helpers.import_graph import PACKAGES, module_name

ROOT = Path(__file__).resolve().parents[1]
IMPORTERS = (*PACKAGES, "tests", "scripts")
"""Top-level folders whose modules count as importers."""

MODULES = sorted(
    module_name(ROOT, path)
    for pkg in PACKAGES
    for path in (ROOT / pkg).rglob("*.py")
    if path.name != "__init__.py" and "__pycache__" not in path.parts
)


def _path(module: str) -> Path:
    return ROOT / (module.replace(".", "/") + ".py")


@cache
def _imported_names() -> dict[str, dict[str, set[str]]]:
    """Module → name → the other modules that import that name from it (``from m import name``)."""
    found: dict[str, dict[str, set[str]]] = {}
    for top in IMPORTERS:
        for path in sorted((ROOT / top).rglob("*.py")):
            importer = module_name(ROOT, path)
            package = importer if path.name == "__init__.py" else importer.rpartition(".")[0]
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not isinstance(node, ast.ImportFrom):
                    continue
                source = node.module or ""
                if node.level:
                    parts = package.split(".")
                    anchor = parts[: len(parts) - (node.level - 1)]
                    source = ".".join([*anchor, source] if source else anchor)
                if source == importer:
                    continue
                for alias in node.names:
                    if alias.name != "*" and not alias.name.startswith("_"):
                        found.setdefault(source, {}).setdefault(alias.name, set()).add(importer)
    return found


def _static_exports(module: str) -> tuple[list[str] | None, set[str]]:
    """``__all__`` and the top-level bindings of a module, read from its source (not run)."""
    exports = None
    bound: set[str] = set()
    for node in ast.parse(_path(module).read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                bound.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
                if isinstance(target, ast.Name) and target.id == "__all__" and node.value is not None:
                    exports = list(ast.literal_eval(node.value))
    return exports, bound


def _exports(module: str) -> tuple[list[str] | None, set[str]]:
    """``__all__`` of a module (``None`` without one) and the names it has."""
    if module.rpartition(".")[2] == "__main__":
        return _static_exports(module)
    mod = importlib.import_module(module)
    exports = getattr(mod, "__all__", None)
    return (None if exports is None else list(exports)), set(vars(mod))


def test_every_package_module_is_found():
    assert len(MODULES) > 100
    assert "scenes.render" in MODULES and "studies.cli.app" in MODULES


@pytest.mark.parametrize("module", MODULES)
def test_module_states_its_public_names(module):
    exports, names = _exports(module)
    assert exports is not None, f"{module} has no __all__"
    assert all(isinstance(name, str) for name in exports)
    assert sorted(set(exports) - names) == [], f"{module}: __all__ lists names it does not define"
    assert [name for name, n in Counter(exports).items() if n > 1] == [], f"{module}: __all__ repeats names"
    imported = _imported_names().get(module, {})
    unlisted = {name: sorted(users) for name, users in imported.items() if name not in exports}
    assert unlisted == {}, f"{module}: names other modules import but __all__ leaves out"


def test_the_importer_scan_resolves_relative_imports(tmp_path, monkeypatch):
    """A relative ``from .b import x`` counts as importing ``x`` from ``pkg.b``; ``*`` and ``_x`` do not."""
    for top in IMPORTERS:
        (tmp_path / top).mkdir()
    (tmp_path / "pipeline/a.py").write_text("from .b import x, _y\nfrom pipeline.b import *\n")
    (tmp_path / "tests/t.py").write_text("from pipeline.b import z\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    _imported_names.cache_clear()
    try:
        assert _imported_names() == {"pipeline.b": {"x": {"pipeline.a"}, "z": {"tests.t"}}}
    finally:
        _imported_names.cache_clear()
