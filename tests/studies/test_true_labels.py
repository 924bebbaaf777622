"""Labels that are true: failure causes from the detector's codes, the drive that works best,
colour separability with the observed confusion beside it."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from pipeline.angles import Intrinsics
from pipeline.evaluate import evaluate_detection
from pipeline.thesis_tracker import STUDY_HSV_RANGES, in_range_mask
from scenes.view import camera_geometry
from studies.catalog import webcam_vs_dslr
from studies.engine.scoring import failure_cause
from tests.helpers.synthetic import draw_markers, hsv_to_bgr, marker_pixels

CAMERA = "logitech-c270"


def test_markers_outside_the_study_colour_box_are_named_a_colour_box_failure():
    """Saturated red LEDs (HSV 0, 255, 255) lie outside the study's printed red box (a pale
    violet-pink): its tracker finds no red blob, and the cause says colour box, not signal-to-noise."""
    uv, _ = marker_pixels(CAMERA, 1.0, 0.0)
    img = draw_markers((720, 1280), uv, hsv_to_bgr(0, 255, 255), 9.0, profile="disc")
    assert not in_range_mask(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), STUDY_HSV_RANGES["red"]).any()  # independent
    truth = {"markers_px": uv.tolist(), "range_m": 1.0, "yaw_deg": 0.0, "side": "red"}
    ev = evaluate_detection(img, Intrinsics.from_geometry(camera_geometry(CAMERA)), truth, tracker="thesis")
    assert ev["failure"] == "no-colour-with-five" and ev["side_blobs"] == 0
    row = {**ev, "core_saturated_fraction_mean": 0.0, "marker_spacing_px": 60.0, "core_diameter_px": 9.0}
    assert failure_cause(row) == "colour box"
    assert failure_cause({**row, "core_saturated_fraction_mean": 0.9}) == "colour box (cores clipped)"
    # the study's own red (inside its box) is found: the label is about the box, not the blobs' brightness
    img = draw_markers((720, 1280), uv, hsv_to_bgr(170, 25, 255), 9.0, profile="disc")
    ev = evaluate_detection(img, Intrinsics.from_geometry(camera_geometry(CAMERA)), truth, tracker="thesis")
    assert ev["side"] == "red"


def _frames(current: float, correct: int, colour_ok: int, chroma: float, n: int = 16) -> list[dict]:
    """``n`` best-tracker frames at 4 m: ``correct`` of them right (side and pose), ``colour_ok`` detections
    of the right side, the rest detected as yellow; half red, half green."""
    rows = []
    for i in range(n):
        side = ("red", "green")[i % 2]
        detected = i < colour_ok or i >= n - (n - colour_ok)
        right = i < colour_ok
        rows.append(
            {
                "camera": CAMERA, "beacon": "v2", "environment": "dark", "led_current_mA": current,
                "tracker": "best", "estimator": "best", "side": side, "nominal_yaw_deg": 0.0,
                "range_m": 4.0, "nominal_range_m": 4.0, "detected": detected,
                "side_detected": side if right else "yellow", "side_correct": right,
                "numbering_correct": right, "range_err_m": 0.0 if i < correct else 5.0, "yaw_err_deg": 0.0,
                "failure": "", "core_saturated_fraction_mean": 0.0, "marker_spacing_px": 50.0,
                "core_diameter_px": 5.0,
                **{f"marker{k}_{c}": 100.0 for k in range(1, 6) for c in "RGB"},
                **{
                    f"marker{k}_{c}_chroma": (0.6 if side == "red" else 0.2) + chroma * ((i * 7 + k) % 5 - 2) / 2
                    for k in range(1, 6)
                    for c in "rg"
                },
            }
        )  # fmt: skip
    return rows


def test_the_best_drive_is_the_one_that_works_best():
    # neither drive reaches P ≥ 0.95; 2 mA is right in 13 of 16 frames, 20 mA in 2 of 16 but with better separated
    # colours: the old ranking (far limit, then separability) took 20 mA
    frame = pd.DataFrame(_frames(2.0, 13, 13, chroma=0.08) + _frames(20.0, 2, 2, chroma=0.01))
    summary = webcam_vs_dslr.analyse(frame)
    seps = {s["led_current_mA"]: s["min_mahalanobis"] for s in summary["colour_separability"]}
    assert seps[20.0] > seps[2.0]  # the trap is set
    top = summary["ranking"][0]
    assert top["at_led_current_mA"] == 2.0 and top["correct"] == "13 of 16"


def test_separability_names_the_pairs_run_and_the_confusion_seen():
    frame = pd.DataFrame(_frames(2.0, 13, 13, chroma=0.08))
    summary = webcam_vs_dslr.analyse(frame)
    sep = summary["colour_separability"][0]
    wrong = [r for r in _frames(2.0, 13, 13, chroma=0.08) if r["detected"] and not r["side_correct"]]
    counted = {(r["side"], r["side_detected"]): 0 for r in wrong}
    for r in wrong:
        counted[(r["side"], r["side_detected"])] += 1
    assert {(c["true"], c["named"]): c["frames"] for c in sep["confused"]} == counted
    text = webcam_vs_dslr.separability_text(sep)
    assert "of 1 pair among the sides run (green, red)" in text and "Bayes" not in text
    assert f"observed: 13 of {len(wrong) + 13} detections the right colour" in text
    for (true, named), k in counted.items():
        assert f"{k} {true} named {named} (a side not run)" in text
    # read back from standard JSON (inf written as null, ``no_overlap`` beside it) the words are the same
    perfect = {"pairs": [{"pair": "green-red", "mahalanobis": None, "no_overlap": True, "bayes_error": 0.0}]}
    assert webcam_vs_dslr.separability_text(perfect).startswith("no overlap in any 1 pair among the sides run")
    assert np.isfinite(sep["min_mahalanobis"])
