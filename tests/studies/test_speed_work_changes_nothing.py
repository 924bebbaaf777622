"""Caches and reuse must not change results: a cold run equals a warm run in another order."""

from __future__ import annotations

import json

import pytest

from studies.engine.frame import simulate_frame

pytestmark = pytest.mark.usefixtures("mitsuba_variant")


def _tasks():
    base = {
        "beacon": "v2",
        "side": "red",
        "camera": "logitech-c270",
        "environment": "dark",
        "foam": True,
        "paper_sheets": 1,
        "paper_colour": "matched",
        "yaw_deg": 0.0,
        "camera_height_m": 0.0,
    }
    return [
        {
            "scenario": {**base, "range_m": r, "led_current_mA": i},
            "seed": s,
            "trackers": ["best"],
            "estimators": ["best"],
            "render": {"spp": 2, "oversampling": 1, "crop": "target", "near_field_spp": 64},
        }
        for r in (3.0, 6.0)
        for i in (2.0, 20.0)
        for s in (0, 1)
    ]


def _forget_in_memory():
    from camera_models import optics
    from studies.engine import frame

    optics._UNIT_OPTICS.clear()
    frame._RENDERS.clear()


def _rows(tasks, fresh: bool):
    out = {}
    for t in tasks:
        if fresh:
            _forget_in_memory()
        out[json.dumps(t, sort_keys=True)] = _without_rss(simulate_frame(t))
    return out


def _without_rss(rows):
    from studies.engine.runner import MACHINE_COLUMNS

    return [{k: v for k, v in r.items() if k not in MACHINE_COLUMNS} for r in rows]


def test_cold_and_warm_runs_in_any_order_agree(tmp_path, monkeypatch):
    from studies.engine.sweep import Execution, run_frames

    monkeypatch.setenv("BEACON_SIM_CACHE", str(tmp_path / "cold"))
    cold = _rows(_tasks(), fresh=True)  # every render and lens image computed on its own
    _forget_in_memory()
    # renders from the disk cache, then held in memory and rescaled across drives
    warm = _rows(list(reversed(_tasks())), fresh=False)
    assert json.dumps(cold, sort_keys=True) == json.dumps(warm, sort_keys=True)
    _forget_in_memory()
    batched = run_frames(_tasks(), tmp_path / "study", Execution(workers=1))  # frames batched by render
    expected = [row for t in _tasks() for row in cold[json.dumps(t, sort_keys=True)]]
    assert json.dumps(_without_rss(batched), sort_keys=True) == json.dumps(expected, sort_keys=True)
