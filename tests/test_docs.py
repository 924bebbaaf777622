"""What the docs say about the code and the repository, checked where it can be."""

from __future__ import annotations

import ast
import glob
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ("README.md", "docs/architecture.md")
TOP = ("results/", "studies/", "scenes/", "camera_models/", "pipeline/", "docs/", "tests/", "scripts/")


def _cited_paths(text: str) -> set[str]:
    """Repository paths cited in backticks (``<...>`` placeholders and run outputs under ``out/`` left out)."""
    paths = set()
    for token in re.findall(r"`([^`\s]+)`", text):
        token = token.rstrip(".,;:)")
        if token.startswith(TOP) and "<" not in token and "$" not in token:
            paths.add(token)
    return paths


def test_every_path_the_docs_cite_exists():
    missing = []
    for doc in DOCS:
        for path in _cited_paths((ROOT / doc).read_text()):
            if not glob.glob(str(ROOT / path.split(":")[0])):
                missing.append(f"{doc}: {path}")
    assert missing == []


def test_the_check_finds_a_removed_path():
    assert _cited_paths("see `results/e2e_detection/` and `results/saturation_table.*`") == {
        "results/e2e_detection/",
        "results/saturation_table.*",
    }
    assert not glob.glob(str(ROOT / "results/e2e_detection/"))


def _function_level_imports(path: Path) -> set[str]:
    """Names of the functions of ``path`` that import inside their body."""
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            for inner in ast.walk(node):
                if inner is not node and isinstance(inner, ast.Import | ast.ImportFrom):
                    found.add(node.name)
    return found


def test_bench_function_level_imports_are_documented():
    """docs/architecture.md names every function of bench.py that imports in its body (besides Dask's
    and matplotlib's, which the general rule covers)."""
    text = (ROOT / "docs/architecture.md").read_text()
    section = text[text.index("## Deliberate lazy imports") : text.index("## Where things are written")]
    bench = ROOT / "studies/experiments/bench.py"
    tree = ast.parse(bench.read_text())
    covered = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            mods = {
                (n.module if isinstance(n, ast.ImportFrom) else n.names[0].name) or ""
                for n in ast.walk(node)
                if n is not node and isinstance(n, ast.Import | ast.ImportFrom)
            }
            if mods and all(m.split(".")[0] in ("dask", "matplotlib") for m in mods):
                covered.add(node.name)
    undocumented = sorted(f for f in _function_level_imports(bench) - covered if f"`{f}`" not in section)
    assert undocumented == []


def test_capture_chains_render_and_capture_as_the_docs_say():
    """The docs name every module that chains render and capture outside ``capture_frame``."""
    text = (ROOT / "docs/architecture.md").read_text()
    chaining = []
    for path in ROOT.glob("studies/**/*.py"):
        src = path.read_text()
        if re.search(r"\brender(_scenario)?\(", src) and re.search(r"\b(run_)?capture\(", src):
            chaining.append(path.relative_to(ROOT).as_posix())
    assert chaining and all(p in text for p in chaining if p != "studies/engine/frame.py")
