"""What the study's colour mask makes of the true markers: continuous measures of a near miss.

The study's tracker answers yes or no (exactly five blobs of a colour, docs/source-study.md §5), and
that answer flips on one pixel of blob height or one hue code. A calibration that compares the
simulator with what the study saw needs to know *how near* a frame came, so this module measures,
at the markers' true positions and for one colour's boxes, on the tracker's own processed image
(the 50 % resize for the T6, HSV in OpenCV's 8-bit codes):

``box_distance``
    Median, over the pixels of the five marker cores, of each pixel's distance to the colour's
    nearest HSV box, in HSV code units (H circular with period 180; 0 inside a box). How far the
    markers' colour is from being caught.
``in_box_fraction``
    Fraction of those core pixels inside a box.
``closed_height_px``
    Mean over the five markers of the height, processed pixels, of the connected region of the
    *closed* mask (before the final erosion) at the marker; 0 where the mask has nothing there.
    The final erosion keeps a region only if it is at least ``survivor_height_px`` tall
    (13 px with the study's kernel), so the difference says how near a blob came to vanishing.
``merged_markers``
    Markers whose closed region holds another marker too (the close joined them: "blob merging").
``lost_markers``
    Markers with no pixel of the final (eroded) mask in their closed region: no blob can come of them.

The close is computed in a window around the markers grown by its reach; a region larger than
the window (a lit wall caught by the near-white "red" box) is measured as far as the window goes,
which still reads as "one large region".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.angles import Intrinsics, resized_pixel
from pipeline.thesis_tracker import (
    CLOSE_KERNEL,
    ERODE_KERNEL,
    HsvBox,
    ThesisTrackerSettings,
    close_reach,
    in_range_mask,
    processed_hsv,
    survivor_size,
)

__all__ = ["MaskMeasures", "box_distance", "marker_mask_measures"]

WINDOW_MARGIN_PX = 40
"""Processed pixels added around the markers' cores (beyond the close's reach) for the window in
which the close is computed (assumed: wider than a marker's blob at the close ranges measured)."""


@dataclass(frozen=True)
class MaskMeasures:
    """Continuous measures of one colour's mask at the true markers (see the module docstring).

    Attributes
    ----------
    box_distance
        Median core-pixel distance to the colour's boxes, HSV code units (0: inside).
    in_box_fraction
        Fraction of core pixels inside a box, 0-1.
    closed_height_px
        Mean height of the closed mask's region at each marker, processed px.
    survivor_height_px
        Height a closed region needs to survive the final erosion, processed px.
    merged_markers, lost_markers
        Markers sharing their closed region with another one; markers whose region the erosion removes
        (or that have none).
    """

    box_distance: float
    in_box_fraction: float
    closed_height_px: float
    survivor_height_px: int
    merged_markers: int = 0
    lost_markers: int = 0


def box_distance(hsv: ArrayLike, boxes: list[HsvBox]) -> NDArray[np.float64]:
    """Distance of HSV pixels to the nearest of ``boxes``, HSV code units (0 inside).

    Hue is circular with period 180 (OpenCV's 8-bit hue); S and V are linear.

    Examples
    --------
    >>> box_distance([[100, 20, 200], [10, 20, 200]], [((81, 0, 96), (180, 35, 255))]).tolist()
    [0.0, 10.0]
    """
    px = np.asarray(hsv, dtype=np.float64).reshape(-1, 3)
    if not boxes:
        return np.full(len(px), np.inf)
    best = np.full(len(px), np.inf)
    for lo, hi in boxes:
        lo_h, hi_h = float(lo[0]), float(hi[0])
        h = px[:, 0]
        inside_h = (h >= lo_h) & (h <= hi_h)
        below, above = (lo_h - h) % 180.0, (h - hi_h) % 180.0
        dh = np.where(inside_h, 0.0, np.minimum(below, above))
        ds = np.maximum.reduce([lo[1] - px[:, 1], np.zeros(len(px)), px[:, 1] - hi[1]])
        dv = np.maximum.reduce([lo[2] - px[:, 2], np.zeros(len(px)), px[:, 2] - hi[2]])
        best = np.minimum(best, np.sqrt(dh**2 + ds**2 + dv**2))
    return best


def marker_mask_measures(
    image_bgr: NDArray[np.uint8],
    intrinsics: Intrinsics,
    markers_uv: ArrayLike,
    core_radius_px: ArrayLike,
    colour: str,
    *,
    settings: ThesisTrackerSettings | None = None,
    crop_origin_px: tuple[int, int] = (0, 0),
    processed: tuple[NDArray[np.uint8], float] | None = None,
) -> MaskMeasures:
    """Measure one colour's mask at the true markers (the module docstring says what and why).

    Parameters
    ----------
    image_bgr
        The saved image (BGR, 8-bit), the full frame or a crop starting at ``crop_origin_px``.
    intrinsics
        Full-frame intrinsics (the tracker's resize rule reads its width).
    markers_uv
        (5, 2) true marker centres, full-frame px.
    core_radius_px
        (5,) marker core radii, full-frame px (at least one processed pixel is used).
    colour
        Whose boxes (``settings``' ranges; the study's by default).
    settings, crop_origin_px
        As :func:`pipeline.thesis_tracker.thesis_track`.
    processed
        The tracker's processed image and its scale (:func:`pipeline.thesis_tracker.processed_hsv` of
        ``image_bgr`` with these settings), when the caller has it already: several threshold variants
        of one frame share it.
    """
    s = settings or ThesisTrackerSettings()
    boxes = s.ranges().get(colour, [])
    hsv, scale = processed if processed is not None else processed_hsv(image_bgr, intrinsics, s)
    h, w = hsv.shape[:2]
    uv = np.asarray(markers_uv, dtype=np.float64).reshape(-1, 2) - np.asarray(crop_origin_px, dtype=np.float64)
    ur, vr = resized_pixel(uv[:, 0], uv[:, 1], scale)
    radii = np.maximum(np.asarray(core_radius_px, dtype=np.float64).reshape(-1) * scale, 1.0)
    survivor = survivor_size(s)[1]
    core_px, heights = [], []
    rx, ry = close_reach(s)
    reach = max(rx, ry) * 2 + WINDOW_MARGIN_PX
    x0 = max(math.floor(np.min(ur - radii)) - reach, 0)
    x1 = min(math.ceil(np.max(ur + radii)) + reach + 1, w)
    y0 = max(math.floor(np.min(vr - radii)) - reach, 0)
    y1 = min(math.ceil(np.max(vr + radii)) + reach + 1, h)
    if x1 <= x0 or y1 <= y0 or not boxes:
        return MaskMeasures(math.nan, 0.0, 0.0, survivor, 0, len(ur))  # no marker in the image, or no box
    window = hsv[y0:y1, x0:x1]
    closed = cv2.morphologyEx(
        in_range_mask(window, boxes), cv2.MORPH_CLOSE, CLOSE_KERNEL, iterations=s.close_iterations
    )
    _, labels, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    eroded = cv2.erode(closed, ERODE_KERNEL, iterations=s.erode_iterations)
    surviving = set(np.unique(labels[eroded > 0]).tolist()) - {0}
    gy, gx = np.mgrid[y0:y1, x0:x1]
    regions = []
    for u, v, r in zip(ur, vr, radii, strict=True):
        core = (gx - u) ** 2 + (gy - v) ** 2 <= r * r
        if not core.any():  # a core between pixel centres: its nearest pixel
            iy, ix = int(np.clip(round(v), y0, y1 - 1)), int(np.clip(round(u), x0, x1 - 1))
            core = (gy == iy) & (gx == ix)
        core_px.append(window[core])
        found = labels[core]
        found = found[found > 0]
        region = int(np.bincount(found).argmax()) if found.size else 0
        regions.append(region)
        heights.append(float(stats[region, cv2.CC_STAT_HEIGHT]) if region else 0.0)
    dist = box_distance(np.concatenate(core_px), boxes)
    shared = [r and regions.count(r) > 1 for r in regions]
    return MaskMeasures(
        box_distance=float(np.median(dist)),
        in_box_fraction=float(np.mean(dist == 0)),
        closed_height_px=float(np.mean(heights)),
        survivor_height_px=survivor,
        merged_markers=int(sum(shared)),
        lost_markers=int(sum(r not in surviving for r in regions)),
    )
