"""The layout stays true: no package imports a later stage, no import cycles, and no
library module is used only by the tests."""

from __future__ import annotations

from pathlib import Path

from tests.helpers.import_graph import cycles, import_graph, layer_violations

ROOT = Path(__file__).resolve().parents[1]


def test_no_stage_imports_a_later_one():
    assert layer_violations(import_graph(ROOT)) == []


def test_no_import_cycles():
    assert cycles(import_graph(ROOT)) == []


def test_the_checks_fail_on_planted_violations(tmp_path):
    """A scene module importing a study, and two pipeline modules importing each other."""
    for pkg in ("scenes", "camera_models", "pipeline", "studies", "studies/engine"):
        (tmp_path / pkg).mkdir(parents=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "studies/engine/runner.py").write_text("X = 1\n")
    (tmp_path / "scenes/render.py").write_text("def f():\n    from studies.engine import runner\n")
    (tmp_path / "pipeline/a.py").write_text("from . import b\n")
    (tmp_path / "pipeline/b.py").write_text("import pipeline.a\n")
    (tmp_path / "camera_models/ok.py").write_text("from scenes.render import f\n")
    graph = import_graph(tmp_path)
    assert layer_violations(graph) == ["scenes.render → studies.engine.runner"]
    assert cycles(graph) == [["pipeline.a", "pipeline.b"]]


def test_every_library_module_is_used_outside_the_tests():
    """A module under scenes/, camera_models/, pipeline/ or studies/ that only tests import
    belongs under tests/ (entry points: the command line, plugins loaded by name)."""
    graph = import_graph(ROOT)
    used = {target for targets in graph.values() for target in targets}
    entry_points = {"studies.cli.app", "studies.cli.__main__"}
    packages = {m for m in graph if any(other.startswith(m + ".") for other in graph)}
    unused = sorted(m for m in graph if m not in used | entry_points | packages)
    assert unused == []
