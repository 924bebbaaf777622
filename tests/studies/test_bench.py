"""The benchmark's frame measurement runs the study's frame path and reports consistent figures."""

from __future__ import annotations

from camera_models.camera import load_camera
from studies.experiments.bench import BENCH_SCENARIO, frame_vs_memcpy


def test_frame_vs_memcpy_times_a_whole_saved_frame():
    scenario = {**BENCH_SCENARIO, "camera": "logitech-c270", "foam": False, "paper_sheets": 0, "range_m": 8.0}
    out = frame_vs_memcpy(repeats=1, scenario=scenario)
    g = load_camera("logitech-c270").geometry
    assert out["frame_bytes"] == g.width_px * g.height_px * 3  # the whole frame, 8-bit RGB
    assert out["ratio"] == out["frame_s"] / out["memcpy_s"]
    assert out["frame_s"] >= out["camera_s"] + out["detect_s"] > 0
