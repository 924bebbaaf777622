"""The colour curve of a light through a camera, checked against colorimetry and OpenCV."""

from __future__ import annotations

import colour
import cv2
import numpy as np
import pytest

from camera_models.camera import load_camera
from pipeline.thesis_tracker import STUDY_HSV_RANGES
from scenes import spectra
from scenes.diffusers import colour_module_patch
from studies.engine.colour_reach import in_boxes, patch_colours, raw_response, reach


def test_in_boxes_is_opencvs_inrange():
    rng = np.random.default_rng(4)
    hsv = np.stack([rng.integers(0, 181, 5000), rng.integers(0, 256, 5000), rng.integers(0, 256, 5000)], 1)
    hsv = hsv.astype(np.uint8)
    for boxes in STUDY_HSV_RANGES.values():
        expected = np.zeros(len(hsv), bool)
        for lo, hi in boxes:
            expected |= cv2.inRange(hsv[:, None, :], np.array(lo), np.array(hi))[:, 0] > 0
        assert np.array_equal(in_boxes(hsv, boxes), expected)


def test_daylight_white_stays_neutral_at_every_exposure():
    # white balance makes a D65-lit white neutral; clipping after it clips every channel alike
    cam = load_camera("canon-t6-18mm")
    hsv = patch_colours(cam, raw_response(cam, spectra.illuminant_shape("D65")), np.geomspace(0.05, 50, 25))
    assert hsv[:, 1].max() <= 3
    assert np.all(np.diff(hsv[:, 2].astype(int)) >= 0) and hsv[-1, 2] == 255


@pytest.mark.parametrize("patch", ["orange", "moderate red", "yellow green", "blue", "green", "yellow", "purple"])
def test_hue_of_a_lit_colour_chart_patch_matches_colorimetry(patch):
    # CIE 1931 colorimetry (colour-science) of D65 light off a ColorChecker patch, against the T6's rendering
    # below clip. Tolerance 10 OpenCV hue units (20°): the sensor curves are the EOS 100D's under the 1300D's
    # DNG matrix (camera_models/data/ssf/README.md), not the 1300D's own
    cam = load_camera("canon-t6-18mm")
    light = spectra.illuminant_shape("D65") * colour_module_patch("ColorChecker N Ohta", patch)
    xyz = colour.sd_to_XYZ(colour.SpectralDistribution(dict(zip(spectra.WAVELENGTHS_NM, light, strict=True))))
    srgb = np.clip(colour.XYZ_to_sRGB(0.2 * xyz / xyz[1]), 0, 1)
    expected = int(cv2.cvtColor(np.uint8([[np.round(255 * srgb)]]), cv2.COLOR_RGB2HSV)[0, 0, 0])
    got = int(patch_colours(cam, raw_response(cam, light), np.array([0.5]))[0, 0])
    assert min(abs(got - expected), 180 - abs(got - expected)) <= 10


def test_blue_and_yellow_leds_reach_their_boxes_on_the_t6():
    # the unclipped colours of these LEDs lie inside the study's boxes (H 84-180 and 12-26): a known reach
    cam = load_camera("canon-t6-18mm")
    for side in ("blue", "yellow"):
        r = reach(cam, side)
        assert r.span(side)[0] < 1.0  # already below the clip level
