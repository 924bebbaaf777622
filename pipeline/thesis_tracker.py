"""The study's marker tracker, kept as it was (docs/source-study.md §5).

1. Resize to 50 % for the Canon T6 (``cv2.resize`` at fx = fy = 0.5, bilinear).
2. BGR → HSV (H 0–180, S and V 0–255); one ``inRange`` mask per colour.
3. Morphological close, elliptical 5×5 kernel, 5 iterations; erode, elliptical kernel of
   size (2, 4), 4 iterations.
4. ``SimpleBlobDetector`` on the inverted mask: minDistBetweenBlobs 2.5, area 2–100000,
   convexity / circularity / inertia filters on with minimum 0.
5. A side is seen when a colour has exactly 5 blobs, colours tried red, green, blue,
   yellow; numbering by :func:`pipeline.markers.number_study`.
6. Angles by the study's formula (:func:`pipeline.angles.study_angles`).

Weaknesses kept and documented:

* The close merges blobs closer than about 20 processed pixels (dilation by 2 px five
  times), i.e. 40 px in the T6's full frame: the "blob merging" the study named.
* The (2, 4) erosion kernel is anchored off-centre ((1, 2)), so four iterations remove 4
  px on the left and 8 px at the top but only 4 at the bottom: blobs under ~13 processed
  pixels tall vanish, and survivors' centres shift by about 1 px right and 2 px down.
* The red range [81, 0, 96]–[180, 35, 255] is nearly unsaturated: it catches the white,
  saturated cores of bright LEDs of any colour whose hue is 81–180, not red light; the
  blue range shares hues 84–180 with it.
* One wrong blob count in a colour (a reflection, a merged pair) loses the side.
* OpenCV 5 refuses a filter minimum of exactly 0: 1e-9 is used (the same blobs pass).
* Crops (not the study's full frames) are padded with background before blob detection,
  so the background region, as in a full frame, exceeds maxArea and is filtered out.
* The HSV ranges came from hand tuning on close-range images; :func:`derive_hsv_ranges`
  is that procedure made repeatable.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics, full_pixel, resized_pixel, study_angles
from pipeline.failures import Failure
from pipeline.image_io import as_bgr, to_uint8
from pipeline.markers import Blob, TrackResult, number_study
from scenes.led import SIDE_COLOURS

HsvBox = tuple[tuple[int, int, int], tuple[int, int, int]]

STUDY_HSV_RANGES: dict[str, list[HsvBox]] = {
    "red": [((81, 0, 96), (180, 35, 255))],
    "green": [((70, 64, 50), (85, 143, 255))],
    "blue": [((84, 40, 152), (180, 255, 255))],
    "yellow": [((12, 190, 45), (26, 255, 255))],
}
"""The study's inRange thresholds per colour (docs/source-study.md §5.2); a colour may have several boxes."""


@dataclass(frozen=True)
class ThesisTrackerSettings:
    """Parameters of the study's tracker (defaults: the study's values).

    Attributes
    ----------
    hsv_ranges
        Per colour, a list of (low, high) HSV boxes whose union is the mask.
    resize
        Scale applied before processing (0.5 for the T6, 1 for the webcams); None picks
        by the image width (≥ 3000 px → 0.5).
    close_iterations, erode_iterations
        Morphology iterations.
    min_dist_between_blobs, min_area, max_area
        SimpleBlobDetector settings.
    """

    hsv_ranges: dict[str, list[HsvBox]] | None = None
    resize: float | None = None
    close_iterations: int = 5
    erode_iterations: int = 4
    min_dist_between_blobs: float = 2.5
    min_area: float = 2.0
    max_area: float = 100000.0

    def ranges(self) -> dict[str, list[HsvBox]]:
        """The HSV boxes in use."""
        return STUDY_HSV_RANGES if self.hsv_ranges is None else self.hsv_ranges


_TINY = 1e-9
"""OpenCV 5 refuses a minimum of exactly 0 for these filters; 1e-9 passes the same blobs."""


def _blob_detector(s: ThesisTrackerSettings):
    p = cv2.SimpleBlobDetector_Params()
    p.minDistBetweenBlobs = s.min_dist_between_blobs
    p.filterByArea, p.minArea, p.maxArea = True, s.min_area, s.max_area
    p.filterByConvexity, p.minConvexity = True, _TINY
    p.filterByCircularity, p.minCircularity = True, _TINY
    p.filterByInertia, p.minInertiaRatio = True, _TINY
    return cv2.SimpleBlobDetector_create(p)


def colour_mask(hsv: NDArray[np.uint8], boxes: list[HsvBox], s: ThesisTrackerSettings) -> NDArray[np.uint8]:
    """The study's mask of one colour: union of inRange boxes, closed then eroded."""
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in boxes:
        mask |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    close_k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    erode_k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2, 4))
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, close_k, iterations=s.close_iterations)
    return cv2.erode(mask, erode_k, iterations=s.erode_iterations)


def thesis_track(
    image,
    intrinsics: Intrinsics,
    settings: ThesisTrackerSettings | None = None,
    crop_origin_px: tuple[int, int] = (0, 0),
) -> TrackResult:
    """Run the study's tracker on a BGR image.

    Parameters
    ----------
    image
        BGR image (any array :func:`pipeline.image_io.as_bgr` accepts): the full frame,
        or a crop of it starting at ``crop_origin_px``.
    intrinsics
        Full-frame intrinsics (its size and focal lengths feed the study's angle formula).
    settings
        Tracker parameters; default the study's.
    crop_origin_px
        Full-frame pixel (u, v) of the image's top-left pixel.
    """
    s = settings or ThesisTrackerSettings()
    bgr, reason = as_bgr(image)
    if bgr is None:
        return TrackResult(None, None, reason, failure=Failure.IMAGE)
    bgr = to_uint8(bgr)
    scale = s.resize if s.resize is not None else (0.5 if intrinsics.width_px >= 3000 else 1.0)
    h, w = bgr.shape[:2]
    if scale != 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        bgr = cv2.resize(bgr, size, interpolation=cv2.INTER_LINEAR)
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    detector = _blob_detector(s)
    counts, all_blobs = {}, []
    u0, v0 = crop_origin_px
    for colour in SIDE_COLOURS:
        boxes = s.ranges().get(colour, [])
        if not boxes:
            counts[colour] = 0
            continue
        mask = colour_mask(hsv, boxes, s)
        keypoints, pad = _detect(detector, mask, s.max_area)
        uv = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2) - pad
        uf, vf = full_pixel(uv[:, 0], uv[:, 1], scale)
        blobs = [
            Blob(float(a) + u0, float(b) + v0, float(np.pi * (k.size / 2) ** 2), colour)
            for a, b, k in zip(uf, vf, keypoints, strict=True)
        ]
        all_blobs += blobs
        counts[colour] = len(blobs)
        if len(blobs) == 5:
            full = np.array([[b.u, b.v] for b in blobs])
            return _numbered(colour, full, intrinsics, scale, all_blobs)
    summary = ", ".join(f"{c}: {n}" for c, n in counts.items())
    return TrackResult(
        None, None, f"no colour with exactly 5 blobs ({summary})", all_blobs, failure=Failure.NO_COLOUR_WITH_FIVE
    )


def _detect(detector, mask: NDArray[np.uint8], max_area: float):
    """SimpleBlobDetector on the inverted mask, padded so its background exceeds ``max_area``.

    In a full frame the background (one huge "blob" of the inverted mask) is far larger
    than maxArea and is filtered out; in a small crop it is not, and it displaces a
    marker's keypoint. Padding the crop with background restores the full-frame result.
    """
    if not mask.any():
        return [], 0
    h, w = mask.shape
    pad = 0
    while (h + 2 * pad) * (w + 2 * pad) <= 2 * max_area:
        pad += 64
    inv = cv2.copyMakeBorder(255 - mask, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255) if pad else 255 - mask
    return detector.detect(inv), pad


def _numbered(colour, full_uv, intrinsics: Intrinsics, scale: float, blobs) -> TrackResult:
    ur, vr = resized_pixel(full_uv[:, 0], full_uv[:, 1], scale)
    processed = (round(intrinsics.width_px * scale), round(intrinsics.height_px * scale))
    az, el = study_angles(ur, vr, processed, intrinsics)
    try:
        order = number_study(az, el)
    except ValueError as exc:
        return TrackResult(None, None, str(exc), blobs, failure=Failure.NUMBERING)
    return TrackResult(colour, full_uv[order], None, blobs, [], az[order], el[order])


def derive_hsv_ranges(
    images, colour: str, margin: tuple[int, int, int] = (3, 10, 10), percentiles: tuple[float, float] = (1.0, 99.0)
) -> list[HsvBox]:
    """The study's threshold-setting procedure, made repeatable (docs/source-study.md §10).

    From close-range (150 mm) captures of one side lit in ``colour``: take the lit
    pixels (V above Otsu's threshold of each image's V channel), and span the given
    percentiles of their H, S and V, widened by ``margin`` (H, S, V), with V's top at 255.
    A hue range crossing 0/180 (red) is returned as two boxes.

    Parameters
    ----------
    images
        BGR captures (arrays), each showing the lit target of ``colour``.
    colour
        The colour lit in every image.
    margin
        Widening of the percentile span, HSV units.
    percentiles
        Lower and upper percentiles of the lit pixels' values.
    """
    if colour not in SIDE_COLOURS:
        raise ValueError(f"colour: expected one of {', '.join(SIDE_COLOURS)}, got {colour!r}")
    samples = []
    for k, image in enumerate(images):
        bgr, reason = as_bgr(image)
        if bgr is None:
            raise ValueError(f"images[{k}]: {reason}")
        hsv = cv2.cvtColor(to_uint8(bgr), cv2.COLOR_BGR2HSV)
        val = hsv[..., 2]
        thr, _ = cv2.threshold(val, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        lit = val > thr
        if lit.sum() < 5:
            raise ValueError(f"images[{k}]: no lit pixels found")
        samples.append(hsv[lit])
    px = np.concatenate(samples).astype(np.float64)
    lo_p, hi_p = percentiles
    hue = px[:, 0]
    # shift hues by 90 when that makes the span narrower (a red cluster around 0/180)
    shifted = (hue + 90) % 180
    use_shift = np.ptp(np.percentile(shifted, [lo_p, hi_p])) < np.ptp(np.percentile(hue, [lo_p, hi_p]))
    h_lo, h_hi = np.percentile(shifted if use_shift else hue, [lo_p, hi_p])
    h_lo, h_hi = h_lo - margin[0], h_hi + margin[0]
    s_lo, s_hi = np.percentile(px[:, 1], [lo_p, hi_p]) + np.array([-margin[1], margin[1]])
    v_lo = np.percentile(px[:, 2], lo_p) - margin[2]
    s_lo, s_hi, v_lo = int(max(0, np.floor(s_lo))), int(min(255, np.ceil(s_hi))), int(max(0, np.floor(v_lo)))
    if use_shift:
        h_lo, h_hi = h_lo - 90, h_hi - 90
    h_lo, h_hi = int(np.floor(h_lo)), int(np.ceil(h_hi))
    if h_lo < 0 or h_hi > 179:  # wraps: split into two boxes
        boxes = []
        if h_lo < 0:
            boxes += [((h_lo + 180, s_lo, v_lo), (179, s_hi, 255)), ((0, s_lo, v_lo), (min(h_hi, 179), s_hi, 255))]
        else:
            boxes += [((h_lo, s_lo, v_lo), (179, s_hi, 255)), ((0, s_lo, v_lo), (h_hi - 180, s_hi, 255))]
        return boxes
    return [((h_lo, s_lo, v_lo), (h_hi, s_hi, 255))]
