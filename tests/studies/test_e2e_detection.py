"""studies.experiments.e2e_detection: table structure, ground truth consistent with the detector, crop alignment, CLI."""

from __future__ import annotations

import csv
import sys

import numpy as np
import pytest

from studies.experiments.e2e_detection import (
    ALIGN_PX,
    DETECTION_COLUMNS,
    SUMMARY_COLUMNS,
    E2EConfig,
    Frame,
    aligned_radiance,
    run_e2e,
    write_outputs,
)
from tests.helpers.synthetic import draw_markers

RED_LED_BGR = (0.03, 0.06, 1.0)


def synthetic_frames(config: E2EConfig, scenario, seed: int) -> Frame:
    """Red Gaussian spots where a pinhole camera sees the markers (independent of the e2e truth code)."""
    from scenes.view import project

    uv = project(scenario.geometry, scenario.camera_pose(), scenario.marker_positions_world_m())
    origin = (int(uv[:, 0].min()) // 16 * 16 - 64, int(uv[:, 1].min()) // 16 * 16 - 64)
    shape = (int(np.ptp(uv[:, 1])) + 160, int(np.ptp(uv[:, 0])) + 160)
    rng = np.random.default_rng(seed)
    img = draw_markers(shape, uv, RED_LED_BGR, 2.0, peak=0.8, background=0.02, noise_sigma=0.004, rng=rng,
                       origin_px=origin)  # fmt: skip
    return Frame(img, origin, 0.0)


def test_synthetic_easy_case_ground_truth_matches_the_detector(tmp_path):
    """Spots at the true marker pixels: the best tracker + best estimator recover range (camera → marker 1) and yaw."""
    ranges, yaws = (2.0, 4.0), (20.0,)
    result = run_e2e(ranges, yaws, seeds=range(1), frame_source=synthetic_frames)
    assert len(result.rows) == len(ranges) * len(yaws) * 4
    assert {(r["tracker"], r["estimator"]) for r in result.rows} == {
        (t, e) for t in ("thesis", "best") for e in ("thesis", "best")
    }
    for row in result.rows:
        assert set(row) == set(DETECTION_COLUMNS)
        if row["tracker"] != "best":
            continue
        assert row["detected"] and row["side_called"] == "red" and row["numbering_correct"], row
        assert row["range_est_m"] == pytest.approx(row["range_m"] + row["range_err_m"])
        tol_m = 0.003 * row["range_m"] if row["estimator"] == "best" else 0.01 * row["range_m"]
        assert abs(row["range_err_m"]) < tol_m, row
        assert abs(row["yaw_err_deg"]) < (1.0 if row["estimator"] == "best" else 3.0), row  # a sign slip gives 40°
    paths = write_outputs(result, tmp_path)
    with open(paths["detections"]) as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == DETECTION_COLUMNS and len(table) == len(result.rows)
    with open(paths["summary"]) as fh:
        summary = list(csv.DictReader(fh))
    assert tuple(summary[0]) == ("range_m", "yaw_deg", *SUMMARY_COLUMNS) and len(summary) == 2 * 4
    best = [s for s in summary if s["tracker"] == "best" and s["estimator"] == "best"]
    assert all(s["detection_rate"] == "1" and float(s["range_err_rms_m"]) < 0.012 for s in best)
    text = paths["markdown"].read_text()
    assert "20 mA" in text and "foam + 1 sheet(s) of matched paper" in text and "ISO 6400" in text


def test_aligned_radiance_pads_to_jpeg_blocks_and_keeps_the_pixels():
    from scenes import spectra
    from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance

    grid = PixelGrid(5184, 3456, 4186.0, (2591.5, 1727.5), 2431, 1590, 37, 21, 2)
    image = np.arange(np.prod(grid.shape), dtype=np.float32).reshape(grid.shape)
    comp = RadianceComponent("led:red", image, np.asarray(spectra.led_shape(630.0, 20.0)))
    padded = aligned_radiance(SpectralRadiance(grid, (comp,), {}, "synthetic"))
    g = padded.grid
    assert g.x0 % ALIGN_PX == 0 and g.y0 % ALIGN_PX == 0 and g.width % ALIGN_PX == 0 and g.height % ALIGN_PX == 0
    assert g.x0 <= grid.x0 and g.x0 + g.width >= grid.x0 + grid.width
    out = padded.components[0].image_W_m2_sr
    assert out.shape == g.shape and out.sum() == image.sum()
    r0, c0 = 2 * (grid.y0 - g.y0), 2 * (grid.x0 - g.x0)
    assert np.array_equal(out[r0 : r0 + image.shape[0], c0 : c0 + image.shape[1]], image)


def test_one_rendered_condition_tiny_settings(tmp_path):
    """The real chain (render → capture → both trackers × estimators) on one condition, at tiny settings."""
    config = E2EConfig(spp=1, oversampling=1, near_field_spp=16, crop="target")
    result = run_e2e((3.0,), (20.0,), seeds=range(1), config=config)
    assert len(result.rows) == 4
    for row in result.rows:
        assert row["crop_u0"] % ALIGN_PX == 0 and row["crop_v0"] % ALIGN_PX == 0
        assert row["side_true"] == "red" and row["range_m"] == 3.0 and row["yaw_deg"] == 20.0
        assert 0.0 <= row["core_saturated_fraction"] <= 1.0
        assert row["detected"] == (row["markers_found"] and row["side_correct"])
        assert row["detected"] or row["reason"]
        if row["range_err_m"] is not None:
            assert row["range_est_m"] == pytest.approx(3.0 + row["range_err_m"])
    assert {"render", "capture", "detect_and_score"} <= set(result.seconds)
    paths = write_outputs(result, tmp_path)
    assert all(p.exists() for p in paths.values())


def test_cli_registers_the_command(capsys, monkeypatch, tmp_path):
    from studies.cli.app import main

    monkeypatch.setattr(sys, "argv", ["beacon-sim", "e2e-detection", "--out", str(tmp_path), "--seeds", "0"])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    assert "seeds: expected an integer >= 1" in capsys.readouterr().err
