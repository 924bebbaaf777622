"""The study's mask's near-miss measures on images with known answers (pipeline.mask_measures)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.angles import Intrinsics
from pipeline.mask_measures import box_distance, marker_mask_measures
from pipeline.thesis_tracker import ThesisTrackerSettings, survivor_size, thesis_track

WEBCAM = Intrinsics(600.0, 600.0, 319.5, 239.5, 640, 480)
T6 = Intrinsics(3000.0, 3000.0, 2591.5, 1727.5, 5184, 3456)
UV = np.array([[200.0, 240.0], [260.0, 240.0], [320.0, 240.0], [380.0, 240.0], [440.0, 240.0]])


def _bgr_of(hsv: tuple[int, int, int]) -> np.ndarray:
    return cv2.cvtColor(np.uint8([[hsv]]), cv2.COLOR_HSV2BGR)[0, 0]


def _discs(shape, uv, diameter: float, hsv) -> np.ndarray:
    image = np.zeros((*shape, 3), np.uint8)
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    for u, v in uv:
        image[(xx - u) ** 2 + (yy - v) ** 2 <= (diameter / 2) ** 2] = _bgr_of(hsv)
    return image


def test_box_distance_is_euclidean_with_circular_hue():
    box = [((70, 64, 50), (85, 143, 255))]
    pixels = [[75, 100, 200], [60, 100, 200], [90, 100, 200], [75, 30, 20], [175, 100, 200]]
    # inside; 10 below in hue; 5 above; S 34 and V 30 below; hue 175 is 75 from 70 going round (180 period)
    expected = [0.0, 10.0, 5.0, np.hypot(34, 30), 75.0]
    assert box_distance(pixels, box) == pytest.approx(expected)
    # the nearest of two boxes counts; a red hue near 0 is 4 codes from a box ending at 176 (round the circle)
    two = [((0, 0, 0), (10, 255, 255)), ((100, 0, 0), (176, 255, 255))]
    assert box_distance([[50, 9, 9], [2, 9, 9], [178, 9, 9]], two) == pytest.approx([40.0, 0.0, 2.0])


def test_in_box_discs_measure_their_own_height():
    green = (77, 100, 220)  # inside the study's green box
    diameter = 21
    image = _discs((480, 640), UV, diameter, green)
    m = marker_mask_measures(image, WEBCAM, UV, [4.0] * 5, "green")
    assert m.box_distance <= 1.0  # the HSV -> BGR -> HSV round trip moves a code at most
    assert m.in_box_fraction == 1.0
    assert m.closed_height_px == pytest.approx(diameter, abs=1)  # closing a convex disc leaves it
    assert m.survivor_height_px == survivor_size(ThesisTrackerSettings())[1] == 13


def test_colour_outside_the_box_has_its_distance_and_no_region():
    image = _discs((480, 640), UV, 21, (60, 100, 220))  # hue 10 codes below green's 70
    m = marker_mask_measures(image, WEBCAM, UV, [4.0] * 5, "green")
    assert m.box_distance == pytest.approx(10.0, abs=1.0)
    assert m.in_box_fraction == 0.0 and m.closed_height_px == 0.0


def test_t6_frames_are_measured_on_the_half_size_image():
    uv = UV * 4  # a T6-sized frame: the tracker halves it
    image = _discs((3456, 5184), uv, 40, (77, 100, 220))
    m = marker_mask_measures(image, T6, uv, [8.0] * 5, "green")
    assert m.closed_height_px == pytest.approx(20, abs=1.5)


@pytest.mark.parametrize("diameter", [9, 11, 13, 17, 21])
def test_the_survivor_height_decides_the_trackers_blobs(diameter):
    """Closed regions under the survivor height vanish in the study's tracker; taller ones are blobs."""
    image = _discs((480, 640), UV, diameter, (77, 100, 220))
    m = marker_mask_measures(image, WEBCAM, UV, [3.0] * 5, "green")
    found = thesis_track(image, WEBCAM)
    green = sum(b.colour == "green" for b in found.blobs)
    assert (green == 5) == (m.closed_height_px >= m.survivor_height_px)


def test_markers_closer_than_the_close_reach_merge_and_small_ones_are_lost():
    """Two discs 14 px apart (centre to centre, 21 px wide) join under the close (it bridges gaps up to
    ~20 px); discs under the survivor height have no eroded pixel."""
    uv = UV.copy()
    uv[1] = uv[0] + [14.0, 0.0]  # markers 1 and 2 overlap after closing
    image = _discs((480, 640), uv, 21, (77, 100, 220))
    m = marker_mask_measures(image, WEBCAM, uv, [3.0] * 5, "green")
    assert m.merged_markers == 2 and m.lost_markers == 0
    small = _discs((480, 640), UV, 9, (77, 100, 220))
    m = marker_mask_measures(small, WEBCAM, UV, [3.0] * 5, "green")
    assert m.merged_markers == 0 and m.lost_markers == 5


def test_a_shared_processed_image_gives_the_same_measures():
    from pipeline.thesis_tracker import processed_hsv

    image = _discs((480, 640), UV, 17, (77, 100, 220))
    own = marker_mask_measures(image, WEBCAM, UV, [3.0] * 5, "green")
    shared = processed_hsv(image, WEBCAM, ThesisTrackerSettings())
    assert marker_mask_measures(image, WEBCAM, UV, [3.0] * 5, "green", processed=shared) == own
