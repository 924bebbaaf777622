"""studies.experiments.e2e_detection: the study's primary test on the engine's frame path, its
summaries against counts recomputed from the rows, crop alignment, the CLI."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from studies.engine.frame import aligned_radiance, capture_frame
from studies.engine.scoring import detection_success, pose_success
from studies.engine.sweep import Execution
from studies.experiments.e2e_detection import (
    ALIGN_PX,
    SUMMARY_COLUMNS,
    aggregate,
    default_options,
    run,
    tasks,
)

TINY = {"spp": 1, "oversampling": 1, "near_field_spp": 16, "crop": "target", "seed": 0}
ENGINE_COLUMNS = {
    "range_m", "yaw_deg", "nominal_range_m", "nominal_yaw_deg", "seed", "tracker", "estimator", "detected",
    "side_detected", "side_correct", "numbering_correct", "centroid_rms_px", "range_est_m", "range_err_m",
    "yaw_est_deg", "yaw_err_deg", "reason", "failure", "core_saturated_fraction_mean", "exposure_s", "iso",
}  # fmt: skip
PAIRS = {(t, e) for t in ("thesis", "best") for e in ("thesis", "best")}


def test_tasks_are_the_study_primary_test():
    """Full grid: 5 ranges × 7 yaws × 3 seeds of the T6 at ISO 6400, 1/60 s, crops aligned to 16 px, no jitter."""
    grid = tasks(default_options())
    assert len(grid) == 5 * 7 * 3
    assert [(t["scenario"]["range_m"], t["scenario"]["yaw_deg"], t["seed"]) for t in grid[:4]] == [
        (1.0, 0.0, 0),
        (1.0, 0.0, 1),
        (1.0, 0.0, 2),
        (1.0, 5.0, 0),
    ]
    for t in grid:
        s = t["scenario"]
        assert (s["camera"], s["beacon"], s["side"], s["environment"]) == ("canon-t6-18mm", "v2", "red", "dark")
        assert (s["foam"], s["paper_sheets"], s["paper_colour"], s["led_current_mA"]) == (True, 1, "matched", 20.0)
        assert s["camera_height_m"] == 0.0 and t["nominal"] == {"range_m": s["range_m"], "yaw_deg": s["yaw_deg"]}
        assert t["exposure"]["iso"] == 6400 and t["exposure"]["exposure_s"] == pytest.approx(1 / 60)
        assert t["align_px"] == 16 and "trackers" not in t and "estimators" not in t  # both of each
    quick = tasks(default_options(quick=True))
    assert sorted({(t["scenario"]["range_m"], t["scenario"]["yaw_deg"]) for t in quick}) == [
        (r, y) for r in (1.0, 3.0, 5.0) for y in (0.0, 15.0, 30.0)
    ]
    assert len(quick) == 9


def _row(tracker="best", estimator="best", detected=True, side="red", numbered=True, range_err=0.0, yaw_err=0.0,
         failure="", sat=0.0, range_m=2.0):  # fmt: skip
    return {
        "tracker": tracker, "estimator": estimator, "nominal_range_m": range_m, "nominal_yaw_deg": 0.0,
        "range_m": range_m, "detected": detected, "side_detected": side, "side_correct": side == "red",
        "numbering_correct": numbered, "range_err_m": range_err, "yaw_err_deg": yaw_err, "failure": failure,
        "core_saturated_fraction_mean": sat, "marker_spacing_px": 50.0, "core_diameter_px": 4.0,
    }  # fmt: skip


def test_aggregate_counts_and_errors_by_hand():
    """Four frames at 2 m: a pose success, a detection with range 15 % off, a wrong side, a miss."""
    rows = [
        _row(range_err=0.05, yaw_err=-1.0, sat=0.2),
        _row(range_err=0.3, yaw_err=3.0, sat=0.4),
        _row(side="green", range_err=0.01, yaw_err=0.0, sat=0.0),
        _row(detected=False, side=None, numbered=False, range_err=math.nan, yaw_err=math.nan, failure="too-few-blobs"),
    ]
    s = aggregate(rows)
    assert (s["frames"], s["detection_successes"], s["pose_successes"]) == (4, 2, 1)
    assert s["detection_rate"] == 0.5 and s["pose_success_rate"] == 0.25
    assert s["range_err_median_abs_m"] == pytest.approx(0.175)  # over the two detection successes only
    assert s["range_err_rms_m"] == pytest.approx(math.sqrt((0.05**2 + 0.3**2) / 2))
    assert s["yaw_err_median_abs_deg"] == pytest.approx(2.0)
    assert s["yaw_err_rms_deg"] == pytest.approx(math.sqrt(5.0))
    assert s["core_saturated_fraction_mean"] == pytest.approx(0.15)
    assert (s["top_failure"], s["top_failure_count"]) == ("too-few-blobs", 1)
    assert s["top_cause"] in {"pose", "colour", "resolution / merging"} and s["top_cause_count"] == 1  # one each


def test_aligned_radiance_pads_to_jpeg_blocks_and_keeps_the_pixels():
    from scenes import spectra
    from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance

    grid = PixelGrid(5184, 3456, 4186.0, (2591.5, 1727.5), 2431, 1590, 37, 21, 2)
    image = np.arange(np.prod(grid.shape), dtype=np.float32).reshape(grid.shape)
    comp = RadianceComponent("led:red", image, np.asarray(spectra.led_shape(630.0, 20.0)))
    padded = aligned_radiance(SpectralRadiance(grid, (comp,), {}, "synthetic"), 16)
    g = padded.grid
    assert g.x0 % ALIGN_PX == 0 and g.y0 % ALIGN_PX == 0 and g.width % ALIGN_PX == 0 and g.height % ALIGN_PX == 0
    assert g.x0 <= grid.x0 and g.x0 + g.width >= grid.x0 + grid.width
    out = padded.components[0].image_W_m2_sr
    assert out.shape == g.shape and out.sum() == image.sum()
    r0, c0 = 2 * (grid.y0 - g.y0), 2 * (grid.x0 - g.x0)
    assert np.array_equal(out[r0 : r0 + image.shape[0], c0 : c0 + image.shape[1]], image)


def test_real_chain_at_tiny_settings(tmp_path, mitsuba_variant):
    """Render → capture → both trackers × estimators at 2 m and 3 m, 20°; the summaries recounted from the rows."""
    options = replace(default_options(), ranges_m=(2.0, 3.0), yaws_deg=(20.0,), seeds=1, render=dict(TINY))
    result = run(tmp_path, options, Execution(workers=1))
    rows = result.rows
    assert len(rows) == 2 * 4
    assert (
        {(r["tracker"], r["estimator"]) for r in rows[:4]}
        == PAIRS
        == {(r["tracker"], r["estimator"]) for r in rows[4:]}
    )
    for row in rows:
        assert ENGINE_COLUMNS <= set(row)
        assert row["range_m"] == row["nominal_range_m"] and row["yaw_deg"] == row["nominal_yaw_deg"] == 20.0
        assert row["iso"] == 6400 and row["exposure_s"] == pytest.approx(1 / 60)
        assert 0.0 <= row["core_saturated_fraction_mean"] <= 1.0
        assert row["side_correct"] == (row["side_detected"] == "red")
        assert detection_success(row) == bool(
            row["detected"] and row["side_detected"] == "red" and row["numbering_correct"]
        )
        if math.isfinite(row["range_err_m"]):
            assert row["range_est_m"] == pytest.approx(row["range_m"] + row["range_err_m"])
        if math.isfinite(row["yaw_err_deg"]):
            assert math.remainder(row["yaw_est_deg"] - 20.0 - row["yaw_err_deg"], 360.0) == pytest.approx(0, abs=1e-9)

    for summary in (result.summary_by_range, result.summary):
        assert len(summary) == 2 * 4
        for s in summary:
            assert s.get("yaw_deg", 20.0) == 20.0
            group = [r for r in rows if (r["tracker"], r["estimator"], r["nominal_range_m"]) ==
                     (s["tracker"], s["estimator"], s["range_m"])]  # fmt: skip
            good = [r for r in group if r["detected"] and r["side_detected"] == "red" and r["numbering_correct"]]
            pose = [r for r in good if abs(r["range_err_m"]) <= 0.1 * r["range_m"] and abs(r["yaw_err_deg"]) <= 5]
            assert (s["frames"], s["detection_successes"], s["pose_successes"]) == (1, len(good), len(pose))
            assert s["pose_successes"] == sum(pose_success(r) for r in group)
            if good:
                assert s["range_err_rms_m"] == pytest.approx(abs(good[0]["range_err_m"]))
            else:
                assert math.isnan(s["range_err_rms_m"])

    # the crop the detector saw starts and ends on 16-px blocks, around the unaligned crop
    task = tasks(replace(options, ranges_m=(3.0,)))[0]
    aligned, plain = capture_frame(task), capture_frame({k: v for k, v in task.items() if k != "align_px"})
    (x0, y0), (px, py) = aligned.origin, plain.origin
    h, w = aligned.image_bgr.shape[:2]
    assert x0 % 16 == 0 and y0 % 16 == 0 and w % 16 == 0 and h % 16 == 0
    assert 0 <= px - x0 < 16 and 0 <= py - y0 < 16
    assert x0 + w >= px + plain.image_bgr.shape[1] and y0 + h >= py + plain.image_bgr.shape[0]

    table = pd.read_csv(result.paths["results"])
    assert len(table) == len(rows) and ENGINE_COLUMNS <= set(table.columns)
    assert (tmp_path / "results.parquet").is_file()
    summary = pd.read_csv(result.paths["summary_by_range"])
    assert tuple(summary.columns) == ("range_m", *SUMMARY_COLUMNS)
    assert summary["detection_successes"].sum() == sum(detection_success(r) for r in rows)
    assert summary["pose_successes"].sum() == sum(pose_success(r) for r in rows)
    text = result.paths["markdown"].read_text()
    assert "20 mA" in text and "foam + 1 sheet(s) of matched paper" in text and "ISO 6400" in text
    config = json.loads(result.paths["config"].read_text())
    assert config["align_px"] == 16 and config["options"]["seeds"] == 1
    again = run(tmp_path, options, Execution(workers=1))  # resumed from the stored frames
    assert json.dumps(again.rows, sort_keys=True) == json.dumps(rows, sort_keys=True)


def test_full_frame_check_at_tiny_settings(tmp_path, mitsuba_variant):
    """The table's task for 2 m, 15° again on the whole 18 MP frame: the crop's answers are the table's rows."""
    options = replace(default_options(), ranges_m=(2.0,), yaws_deg=(15.0,), seeds=1, render=dict(TINY))
    result = run(tmp_path, options, Execution(workers=1), full_frame=True)
    check = result.full_frame_check
    assert [(c["tracker"], c["estimator"]) for c in check] == [(r["tracker"], r["estimator"]) for r in result.rows]
    assert {(c["tracker"], c["estimator"]) for c in check} == PAIRS
    for c, row in zip(check, result.rows, strict=True):
        assert (c["nominal_range_m"], c["nominal_yaw_deg"], c["seed"]) == (2.0, 15.0, 0)
        assert (c["side_crop"], c["reason_crop"]) == (row["side_detected"], row["reason"])
        assert c["detection_success_crop"] == detection_success(row) and c["pose_success_crop"] == pose_success(row)
        assert json.dumps(c["range_est_m_crop"]) == json.dumps(row["range_est_m"])
        same = c["side_crop"] == c["side_full"] and c["reason_crop"] == c["reason_full"]
        assert c["same_side_and_reason"] == same
    assert len(pd.read_csv(result.paths["full_frame_check"])) == 4
    assert "## Full frame vs crop (2 m, 15°, seed 0)" in result.paths["markdown"].read_text()


def test_cli_rejects_zero_seeds(capsys, monkeypatch, tmp_path):
    from studies.cli.app import main

    monkeypatch.setattr(sys, "argv", ["beacon-sim", "e2e-detection", "--out", str(tmp_path), "--seeds", "0"])
    with pytest.raises(SystemExit) as exc:
        main()
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "seeds: expected an integer >= 1" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "tasks").exists()
