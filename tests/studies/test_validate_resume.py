"""validate resumes without re-deriving the thresholds from the same preliminary frames."""

from __future__ import annotations

from studies.catalog import validate


def test_derived_thresholds_are_reused_only_for_the_same_preliminary_tasks(tmp_path, monkeypatch):
    calls = []

    def derive(tasks):
        calls.append(len(tasks))
        return {"red": [[[0, 1, 2], [3, 4, 5]]], "green": [], "blue": [], "yellow": []}

    monkeypatch.setattr(validate, "derive_thresholds", derive)
    tasks = [{"scenario": {"side": "red", "range_m": 0.15}, "seed": 0}]
    first = validate._derived_thresholds(tmp_path, tasks)
    assert validate._derived_thresholds(tmp_path, tasks) == first and calls == [1]
    validate._derived_thresholds(tmp_path, [*tasks, {**tasks[0], "seed": 1}])
    assert calls == [1, 2]
