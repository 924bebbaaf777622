"""The one-level replay of SimpleBlobDetector against OpenCV's own detector (the reference)."""

import cv2
import numpy as np
import pytest

from pipeline.binary_blobs import blob_centres, detect_two_level, threshold_levels
from pipeline.thesis_tracker import ThesisTrackerSettings, blob_detector_params
from studies.experiments.bench import speckle_mask


def _opencv(image, params):
    keypoints = cv2.SimpleBlobDetector_create(params).detect(image)
    points = np.array([k.pt for k in keypoints], np.float32).reshape(-1, 2)
    return points, np.array([k.size for k in keypoints], np.float32)


def _params(**kw):
    p = cv2.SimpleBlobDetector_Params()
    for k, v in kw.items():
        setattr(p, k, v)
    return p


def _shapes_mask(rng, size=(160, 200)):
    """Discs, ellipses, rings (a hole: its own contour) and touching pairs on white (inverted)."""
    img = np.full(size, 255, np.uint8)
    for _ in range(25):
        centre = (int(rng.integers(0, size[1])), int(rng.integers(0, size[0])))
        axes = (int(rng.integers(1, 12)), int(rng.integers(1, 12)))
        cv2.ellipse(img, centre, axes, float(rng.uniform(0, 180)), 0, 360, 0, -1)
        if rng.random() < 0.3:  # a white hole inside
            cv2.ellipse(img, centre, (max(axes[0] // 3, 1), max(axes[1] // 3, 1)), 0, 0, 360, 255, -1)
        if rng.random() < 0.3:  # a close neighbour: groups with more than one blob
            cv2.circle(img, (centre[0] + int(rng.integers(2, 6)), centre[1]), 1, 0, -1)
    return img


STUDY = blob_detector_params(ThesisTrackerSettings())
PARAMS = {
    "study": STUDY,
    "opencv defaults": _params(),
    "wide grouping": _params(minDistBetweenBlobs=12.0, minArea=1.0, minRepeatability=3, filterByInertia=False),
    "one in three levels": _params(minArea=2.0, minRepeatability=6, thresholdStep=30.0, minConvexity=0.5),
    "white blobs": _params(blobColor=255, minArea=2.0, filterByCircularity=True, minCircularity=0.3),
}


@pytest.mark.parametrize("name", PARAMS)
@pytest.mark.parametrize("seed", range(6))
def test_same_keypoints_as_opencv_on_shapes(name, seed):
    image = _shapes_mask(np.random.default_rng(seed))
    points, sizes = detect_two_level(image, PARAMS[name])
    ref_points, ref_sizes = _opencv(image, PARAMS[name])
    np.testing.assert_array_equal(points, ref_points)
    np.testing.assert_array_equal(sizes, ref_sizes)


@pytest.mark.parametrize(
    ("level", "close", "erode", "at_least"),
    [(20, 0, 0, 1500), (24, 0, 0, 3000), (32, 0, 0, 500), (16, 0, 1, 1000), (16, 0, 2, 100), (32, 2, 1, 50)],
)
def test_same_keypoints_as_opencv_on_noise_masks(level, close, erode, at_least):
    image = speckle_mask(level + 10 * erode, (180, 240), level, close, erode)
    points, sizes = detect_two_level(image, STUDY)
    ref_points, ref_sizes = _opencv(image, STUDY)
    assert len(ref_points) >= at_least  # the masks that made OpenCV slow: many blobs
    np.testing.assert_array_equal(points, ref_points)
    np.testing.assert_array_equal(sizes, ref_sizes)


def test_groups_of_several_blobs_are_replayed_not_taken_as_one():
    """Two specks 2 px apart (closer than minDistBetweenBlobs 2.5): OpenCV keeps the second as a
    member of the first's group, so one keypoint at the confidence-weighted mean of the
    members, not two; a speck 3 px from both stays its own."""
    image = np.full((40, 40), 255, np.uint8)
    image[10:12, 10:12] = 0
    image[10:12, 13:15] = 0  # 3 px right of the first: its own group
    image[20:22, 20:22] = 0
    image[20:22, 22:24] = 0  # touching: one contour
    image[30:32, 10:12] = 0
    image[31:33, 12:14] = 0  # diagonal neighbours: contours 2 px apart
    points, _ = detect_two_level(image, STUDY)
    ref, _ = _opencv(image, STUDY)
    np.testing.assert_array_equal(points, ref)
    assert len(blob_centres(np.where(image > 50, 255, 0).astype(np.uint8), STUDY).radius) > len(points)


def test_threshold_levels_are_opencvs():
    assert threshold_levels(STUDY) == [50.0 + 10 * k for k in range(17)]  # 50, 60, … 210


def test_an_image_with_levels_between_the_thresholds_is_refused():
    image = np.full((10, 10), 255, np.uint8)
    image[3, 3] = 100  # binarises to 255 at the level 50 and to 0 at 110
    with pytest.raises(ValueError, match="image: expected every pixel at or below 50 or above 210"):
        detect_two_level(image, STUDY)
