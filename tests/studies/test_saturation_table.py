"""The saturation-table study: CSV and summary from rows, the auto-exposure 'settled' test, one real case (slow)."""

from __future__ import annotations

import csv

import pytest

from studies.experiments.saturation_table import FIELDS, ae_settled, saturation_rows, summary_markdown, write_csv


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


@pytest.mark.slow
def test_one_real_case_through_render_and_capture(mitsuba_variant):
    rows = saturation_rows(["logitech-c270"], ranges_m=[5.0], drives_mA=[20.0], diffusers=[(False, 0)], spp=1)
    assert [r["marker"] for r in rows] == [1, 2, 3, 4, 5]
    assert all(0.0 <= r["saturated_fraction"] <= 1.0 for r in rows)
    assert rows[0]["exposure_mode"] == "auto" and rows[0]["gain_code"] is not None
