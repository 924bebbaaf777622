"""False targets in real photographs: scikit-image's bundled photos show no beacon.

Every photo is run as ``beacon-sim detect PHOTO --fx <larger side>`` would run it: the
whole image is the frame, fx = fy = its larger side in px (a normal lens, 53° across),
the principal point at its centre. Our (best) tracker must report no target in any of
them; the study's (thesis) tracker does report some, and that measured rate is what
:data:`pipeline.detect.REAL_PHOTO_FALSE_POSITIVES` records and ``detect --tracker thesis``
prints as a note.

Measured (scikit-image 0.26, OpenCV 5.0), colour photos, full size: the study's tracker
reports a red side in ``coffee`` (0.39 m) and a blue side in ``rocket`` (0.90 m), 2 of 9;
at the study's 50 % resize a red side in ``rocket`` only (0.38 m), 1 of 9. Ours: 0 of 9
at both scales. Grey photos: 0 for both (no hue, no side colour).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import skimage.data

from pipeline.angles import Intrinsics
from pipeline.detect import REAL_PHOTO_FALSE_POSITIVES, detect
from pipeline.failures import Failure

GREY_PHOTOS = ("camera", "coins", "moon", "page", "text", "brick", "grass", "gravel")
"""Real greyscale photographs bundled with scikit-image (no download)."""


@cache
def _photo(name: str) -> np.ndarray:
    """A bundled photo as BGR (colour) or H×W (grey) uint8."""
    if name.startswith("motorcycle_"):
        left, right, _ = skimage.data.stereo_motorcycle()
        rgb = left if name.endswith("left") else right
    else:
        rgb = getattr(skimage.data, name)()
    return np.ascontiguousarray(rgb[..., 2::-1]) if rgb.ndim == 3 else rgb


def _intrinsics(image: np.ndarray) -> Intrinsics:
    h, w = image.shape[:2]
    f = float(max(w, h))
    return Intrinsics(f, f, (w - 1) / 2, (h - 1) / 2, w, h)


@cache
def _reports_target(name: str, tracker: str, resize: float | None) -> bool:
    image = _photo(name)
    result = detect(image, _intrinsics(image), tracker=tracker, resize=resize)
    assert result.failure is not Failure.IMAGE, result.reason
    return bool(result.markers)


def _false_positives(tracker: str, resize: float | None = None, photos=REAL_PHOTO_FALSE_POSITIVES.photos) -> set[str]:
    return {name for name in photos if _reports_target(name, tracker, resize)}


def test_the_photos_are_real_colour_photographs():
    for name in REAL_PHOTO_FALSE_POSITIVES.photos:
        image = _photo(name)
        assert image.ndim == 3 and image.shape[2] == 3 and min(image.shape[:2]) >= 300, name
        # colour: the channels differ (a grey image has B = G = R)
        assert np.abs(image[..., 0].astype(int) - image[..., 2].astype(int)).mean() > 2.0, name
    assert len(REAL_PHOTO_FALSE_POSITIVES.photos) == 9


@pytest.mark.parametrize("resize", [None, 0.5])
def test_best_tracker_reports_no_target_in_real_photos(resize):
    assert _false_positives("best", resize) == set()
    assert _false_positives("best", resize, GREY_PHOTOS) == set()
    assert REAL_PHOTO_FALSE_POSITIVES.false_positives["best"] == ()


def test_thesis_tracker_false_positive_rate_is_the_documented_one():
    found = _false_positives("thesis")
    n = len(REAL_PHOTO_FALSE_POSITIVES.photos)
    rate = len(found) / n
    # measured 2 of 9 (coffee, rocket): a bound of one photo either side of that
    assert 1 / n <= rate <= 3 / n, sorted(found)
    # the figure the detect command prints is this measurement
    assert found == set(REAL_PHOTO_FALSE_POSITIVES.false_positives["thesis"])
    assert REAL_PHOTO_FALSE_POSITIVES.rate("thesis") == pytest.approx(rate)
    assert f"{len(found)} of {n}" in REAL_PHOTO_FALSE_POSITIVES.note("thesis")
    # at the study's 50 % resize: measured 1 of 9 (rocket)
    assert 1 <= len(_false_positives("thesis", 0.5)) <= 2
    # no hue, no side: the grey photos give nothing
    assert _false_positives("thesis", None, GREY_PHOTOS) == set()


def test_a_false_target_is_an_ordinary_looking_answer():
    """What a user sees: a numbered side and a range, nothing that marks it as false."""
    image = _photo("coffee")
    out = detect(image, _intrinsics(image), tracker="thesis").to_dict()
    assert out["side"] == "red" and len(out["markers"]) == 5 and out["reason"] is None
    assert 0.3 < out["range_m"] < 0.5  # measured 0.388 m
