"""Planted objectives for ``tests/studies/test_design_search.py``, in a module of their own so
that a search's pool workers (``workers > 1``, spawned) import only this and not the test module
with optuna and pandas."""

from __future__ import annotations


def schaffer(design: dict) -> dict:
    """Schaffer's problem in two variables: f1 = x² + y², f2 = (x-2)² + y² (both minimised;
    Pareto set y = 0, 0 <= x <= 2; front f2 = (2 - √f1)²)."""
    x, y = design["x"], design["y"]
    return {"f1": x * x + y * y, "f2": (x - 2) ** 2 + y * y}
