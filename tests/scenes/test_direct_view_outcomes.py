"""The detectors' outcomes on whole frames rendered the old way (path tracer, per-geometry
background) and the new way (primary rays, room background): a small paired set, same
tasks and sensor-noise seeds (slow: each frame renders and runs both trackers)."""

from __future__ import annotations

import pytest

from scenes.scenario import RenderSettings

pytestmark = [pytest.mark.usefixtures("mitsuba_variant"), pytest.mark.slow]

OLD = {"direct": "path", "background": "geometry"}
NEW = {"direct": "primary", "background": "room"}
STUDY_RENDER = {"spp": 4, "oversampling": 2, "crop": "beacon", "near_field_spp": 1024}
"""``studies.engine.tasks.RENDER`` (the studies' render settings), written out so this test
reads only the frame path from ``studies``."""


def paired_tasks() -> list[dict]:
    """Webcam and T6 whole frames over ranges, yaws, sides, V1/V2 and diffusers, 2 seeds each."""
    diffused = {"foam": True, "paper_sheets": 1, "paper_colour": "matched", "led_current_mA": 2.0}
    conditions = [
        {"camera": "logitech-c270", "range_m": 2.0, "yaw_deg": 0.0, **diffused},
        {"camera": "logitech-c270", "range_m": 4.0, "yaw_deg": 30.0, "side": "green", **diffused},
        {
            "camera": "logitech-c270",
            "range_m": 3.0,
            "yaw_deg": -20.0,
            "beacon": "v1",
            "environment": "lit-room",
            **diffused,
        },
        {"camera": "canon-t6-18mm", "range_m": 5.0, "yaw_deg": 10.0, "led_current_mA": 2.0},
        {"camera": "canon-t6-18mm", "range_m": 8.0, "yaw_deg": 10.0, "environment": "dark-room", **diffused},
        {"camera": "canon-t6-18mm", "range_m": 12.0, "yaw_deg": 0.0, "side": "blue", **diffused},
    ]
    return [
        {"scenario": c, "seed": seed, "full_frame": True, "render": dict(STUDY_RENDER)}
        for c in conditions
        for seed in (0, 1)
    ]


def outcomes(task: dict, mode: dict) -> list[tuple]:
    from studies.engine.frame import simulate_frame
    from studies.engine.scoring import detection_success, pose_success

    RenderSettings(**{**task["render"], **mode}).validate()
    rows = simulate_frame({**task, "render": {**task["render"], **mode}})
    return [(r["tracker"], r["estimator"], detection_success(r), pose_success(r), r.get("side_detected")) for r in rows]


def test_detector_outcomes_are_unchanged_on_a_paired_set():
    """Every tracker × estimator's detection and pose success (and the side it reports) on
    the old and the new render of 12 paired whole frames: at most one frame changes, and
    each detector's success count by at most one.

    Measured: 11 of 12 frames identical; the one that changed (C270, 4 m, 30°, green, seed 1:
    the best tracker fails on the old render, succeeds on the new) is a borderline frame
    whose outcome flips with *either* change alone (primary rays with the old background,
    or the path tracer with the room background: the webcam's auto exposure meters the
    background), not with the old path's own render seed (0, 1, 2) or 64 spp."""
    changed = 0
    counts: dict[tuple, list[int]] = {}
    for task in paired_tasks():
        old, new = outcomes(task, OLD), outcomes(task, NEW)
        changed += old != new
        for o, n in zip(old, new, strict=True):
            c = counts.setdefault(o[:2], [0, 0, 0, 0])
            c[0] += o[2]
            c[1] += n[2]
            c[2] += o[3]
            c[3] += n[3]
    assert changed <= 1
    for c in counts.values():
        assert abs(c[0] - c[1]) <= 1 and abs(c[2] - c[3]) <= 1, counts
