"""The saturation-table experiment: its frame tasks, CSV and summary from rows, the auto-exposure 'settled' test,
real cases through the engine's render → capture path and the resumable runner."""

from __future__ import annotations

import csv
import json
import math

import pytest

from camera_models.camera import load_camera
from scenes.beacon import beacon_design
from studies.engine.frame import render_batch_key
from studies.experiments import saturation_table
from studies.experiments.saturation_table import (
    FIELDS,
    ae_settled,
    saturation_rows,
    saturation_rows_of,
    saturation_tasks,
    summary_markdown,
    write_csv,
)


def _row(camera="logitech-c270", foam=True, sheets=1, drive=5.0, marker=1, sat=0.5, mode="auto"):
    return {
        "camera": camera,
        "range_m": 2.0,
        "foam": foam,
        "paper_sheets": sheets,
        "led_current_mA": drive,
        "marker": marker,
        "core_radius_px": 1.5,
        "core_pixels": 9,
        "saturated_fraction": sat,
        "saturated_fraction_R": sat,
        "saturated_fraction_G": 0.0,
        "saturated_fraction_B": 0.0,
        "peak_DN": 1023,
        "clip_DN": 1023,
        "exposure_mode": mode,
        "exposure_s": 1 / 15,
        "iso": None,
        "gain_code": 255,
        "analog_gain": 16.0,
        "ae_metered_mean": 0.001,
        "ae_settled": True,
        "seed": 0,
    }


def test_ae_settled_needs_three_equal_frames():
    assert ae_settled([(0.01, 10, 0.1), (0.0666, 255, 0.01), (0.0666, 255, 0.01), (0.0666, 255, 0.01)])
    assert not ae_settled([(0.0666, 200, 0.01), (0.0666, 255, 0.01), (0.0666, 255, 0.01)])
    assert not ae_settled([(0.0666, 255, 0.01)])


def test_csv_and_summary(tmp_path):
    rows = [_row(marker=m, sat=0.2 * m) for m in range(1, 6)] + [
        _row(foam=False, sheets=0, marker=m) for m in range(1, 6)
    ]
    write_csv(rows, tmp_path / "t.csv")
    with open(tmp_path / "t.csv", encoding="utf-8") as f:
        back = list(csv.DictReader(f))
    assert tuple(back[0]) == FIELDS and len(back) == 10 and back[0]["iso"] == ""
    md = summary_markdown(rows)
    assert "| foam + 1 sheet | 0.60 (0.20-1.00) |" in md
    assert "| bare LED | 0.50 |" in md
    assert "Webcam auto exposure" in md and "| logitech-c270 | 2 m | foam + 1 sheet | 5 mA | 66.67 ms | 255 |" in md


def _json(rows: list[dict]) -> str:
    return json.dumps(rows, sort_keys=True)  # NaN compares equal as text


def test_tasks_cover_camera_range_diffuser_drive():
    """2 cameras × 2 ranges × 4 diffusers × 4 drives, drive innermost; one render batch per drive set."""
    tasks = saturation_tasks(["canon-t6-18mm", "logitech-c270"], spp=3, oversampling=1, seed=7)
    assert len(tasks) == 2 * 2 * 4 * 4
    keys = [(t["scenario"]["camera"], t["scenario"]["range_m"], t["scenario"]["foam"], t["scenario"]["paper_sheets"],
             t["scenario"]["led_current_mA"]) for t in tasks]  # fmt: skip
    assert keys[:5] == [
        ("canon-t6-18mm", 2.0, False, 0, 2.0),
        ("canon-t6-18mm", 2.0, False, 0, 5.0),
        ("canon-t6-18mm", 2.0, False, 0, 10.0),
        ("canon-t6-18mm", 2.0, False, 0, 20.0),
        ("canon-t6-18mm", 2.0, True, 0, 2.0),
    ]
    assert len(set(keys)) == len(keys)
    for t in tasks:
        s = t["scenario"]
        assert (s["beacon"], s["side"], s["yaw_deg"], s["environment"], s["paper_colour"]) == (
            "v2", "red", 0.0, "dark", "white"
        )  # fmt: skip
        assert s["camera_height_m"] == 0.0 and t["seed"] == 7 and "exposure" not in t  # the camera's own exposure
        assert t["render"] == {"spp": 3, "oversampling": 1, "crop": "target", "seed": 7}
    assert len({render_batch_key(t) for t in tasks}) == 2 * 2 * 4  # the four drives share a render
    with pytest.raises(ValueError, match="cameras"):
        saturation_tasks(["no-such-camera"])


def test_t6_case_through_the_engine_and_the_store(tmp_path, mitsuba_variant, monkeypatch):
    """T6 at 5 m, bare LED, 20 mA: the camera file's manual exposure, core sizes from the lens, stored rows reused."""
    tasks = saturation_tasks(
        ["canon-t6-18mm"], ranges_m=[5.0], drives_mA=[20.0], diffusers=[(False, 0)], spp=1, oversampling=1
    )
    rows = saturation_rows(tmp_path, tasks, workers=1)
    assert [r["marker"] for r in rows] == [1, 2, 3, 4, 5]
    cam = load_camera("canon-t6-18mm")
    clip = min(cam.sensor.white_level_DN, 2**cam.sensor.adc_bits - 1)
    # marker 1 is on the optical axis at 5 m: its lit face images to D f / (2 × 5 m) px
    radius = 0.5 * beacon_design("v2").lit_face_diameter_m * cam.geometry.focal_length_px / 5.0
    assert rows[0]["core_radius_px"] == pytest.approx(radius, abs=1e-3)
    for r in rows:
        assert (r["camera"], r["range_m"], r["foam"], r["paper_sheets"], r["led_current_mA"]) == (
            "canon-t6-18mm", 5.0, False, 0, 20.0
        )  # fmt: skip
        assert r["exposure_mode"] == "manual" and r["iso"] == 6400 and r["exposure_s"] == pytest.approx(1 / 60)
        assert r["ae_metered_mean"] is None and r["ae_settled"] is None and r["seed"] == 0
        assert r["clip_DN"] == clip and 0 < r["peak_DN"] <= clip
        assert abs(r["core_pixels"] - math.pi * r["core_radius_px"] ** 2) <= 2 * math.pi * r["core_radius_px"] + 2
        assert 0.0 <= r["saturated_fraction"] <= 1.0
        assert r["saturated_fraction"] == 0 or r["peak_DN"] == clip  # a clipped core pixel is the peak
        for c in "RGB":
            assert math.isnan(r[f"saturated_fraction_{c}"]) or 0.0 <= r[f"saturated_fraction_{c}"] <= 1.0
    assert _json(saturation_rows_of(tasks[0])) == _json(rows)  # the stored rows are the function's, unchanged

    def no_capture(task):
        raise AssertionError("re-captured a stored frame")

    monkeypatch.setattr(saturation_table, "capture_frame", no_capture)
    again = saturation_rows(tmp_path, tasks, workers=1)
    assert _json(again) == _json(rows)


@pytest.mark.slow
def test_one_real_webcam_case_through_render_and_capture(tmp_path, mitsuba_variant):
    tasks = saturation_tasks(["logitech-c270"], ranges_m=[5.0], drives_mA=[20.0], diffusers=[(False, 0)], spp=1)
    rows = saturation_rows(tmp_path, tasks, workers=1)
    assert [r["marker"] for r in rows] == [1, 2, 3, 4, 5]
    assert all(0.0 <= r["saturated_fraction"] <= 1.0 for r in rows)
    assert rows[0]["exposure_mode"] == "auto" and rows[0]["gain_code"] is not None
    assert rows[0]["ae_settled"] in (True, False) and 0.0 <= rows[0]["ae_metered_mean"] <= 1.0
