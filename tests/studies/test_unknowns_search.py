"""The close-range search over the unknowns: tasks, scoring and the summary on a tiny run."""

from __future__ import annotations

import pandas as pd
import pytest

from scenes.led import SIDE_COLOURS
from studies.engine.sweep import Execution
from studies.engine.unknowns import load_unknowns
from studies.experiments import unknowns_search


def test_search_space_holds_the_build_and_scopes_to_the_t6():
    space = unknowns_search.search_space()
    assert {"housing", "paper_colour", "noise_reduction"} <= {n for n, u in space.items() if u.kind == "fixed"}
    assert "webcam_max_exposure" not in space and "led_drive" in space and "focus_distance" in space
    assert all(u.namespace != "data" for u in space.values())
    points = [{n: u.nominal for n, u in space.items()}]
    tasks = unknowns_search.tasks(points, space, seeds=2)
    assert len(tasks) == len(SIDE_COLOURS) * 2
    assert {t["scenario"]["side"] for t in tasks} == set(SIDE_COLOURS) and all(t["align_px"] == 16 for t in tasks)
    assert tasks[0]["scenario"]["led_current_mA"] == load_unknowns()["led_drive"].nominal


def test_tiny_search_scores_every_point_on_every_side(tmp_path, monkeypatch, mitsuba_variant):
    monkeypatch.setattr(
        unknowns_search, "RENDER", {"spp": 1, "oversampling": 1, "crop": "target", "near_field_spp": 16}
    )
    summary = unknowns_search.run(tmp_path, samples=2, seeds=1, execution=Execution(workers=1))
    table = pd.read_csv(tmp_path / "samples.csv")
    assert len(table) == 2
    expected = table[[f"{s}_detected" for s in SIDE_COLOURS]].all(axis=1)
    assert list(table.consistent) == list(expected)
    assert summary["consistent_points"] == int(expected.sum())
    assert summary["per_side_detected"] == {s: int(table[f"{s}_detected"].sum()) for s in SIDE_COLOURS}
    led = summary["unknowns"]["led_drive"]
    assert led["prior"] == pytest.approx([0.05, 20.0])
    assert summary["unknowns"]["housing"] == {"held_at": "black"}
