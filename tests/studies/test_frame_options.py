"""Frame-task options of the study's weight and rectification experiments reach the detector."""

from __future__ import annotations

import numpy as np
import pytest

from camera_models.camera import load_camera
from pipeline.angles import Intrinsics
from pipeline.detect import detect
from pipeline.thesis_pose import EQUAL_WEIGHTS, STUDY_WEIGHTS
from scenes.scenario import Scenario
from scenes.view import camera_geometry, project
from studies.engine.frame import _detect_options
from tests.helpers.synthetic import draw_markers


def test_task_options_become_detector_options():
    camera = load_camera("canon-t6-18mm")
    assert _detect_options({}, camera) == {}
    assert _detect_options({"quest_weights": "equal"}, camera)["quest_weights"] == EQUAL_WEIGHTS
    rect = _detect_options({"rectification": {"alpha": 1}}, camera)
    assert rect["alpha"] == 1.0 and rect["calibration"].width_px == 5184
    with pytest.raises(ValueError, match=r"^quest_weights: expected one of tuned, equal"):
        _detect_options({"quest_weights": "heavy"}, camera)


def test_equal_and_tuned_weights_give_different_study_attitudes_on_the_same_markers():
    """Same five marker pixels, the study's chain: the weights change only QUEST's answer."""
    sc = Scenario(camera="logitech-c270", range_m=1.5, yaw_deg=20.0)
    g = camera_geometry(sc.camera)
    uv = project(g, sc.camera_pose(), sc.marker_positions_world_m())
    image = draw_markers((g.height_px, g.width_px), uv, (1.0, 1.0, 1.0), 2.0, peak=1.0)
    intr = Intrinsics.from_geometry(g)
    tuned = detect(image, intr, tracker="best", estimator="thesis", quest_weights=STUDY_WEIGHTS)
    equal = detect(image, intr, tracker="best", estimator="thesis", quest_weights=EQUAL_WEIGHTS)
    assert tuned.pose is not None and equal.pose is not None
    assert tuned.pose.range_m == pytest.approx(equal.pose.range_m)  # inverse perspective: no weights
    assert not np.allclose(tuned.pose.quaternion_wxyz(), equal.pose.quaternion_wxyz())
