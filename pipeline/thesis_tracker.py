"""The study's marker tracker, kept as it was (docs/source-study.md §5).

1. Resize to 50 % for the Canon T6 (``cv2.resize`` at fx = fy = 0.5, bilinear).
2. BGR → HSV (H 0–180, S and V 0–255); one ``inRange`` mask per colour.
3. Morphological close, elliptical 5×5 kernel, 5 iterations; erode, elliptical kernel of
   size (2, 4), 4 iterations. (Computed only in windows around the in-range pixels, grown by
   the morphology's reach: the same masks, bit for bit, as on the whole image.)
4. ``SimpleBlobDetector`` on the inverted mask: minDistBetweenBlobs 2.5, area 2–100000,
   convexity / circularity / inertia filters on with minimum 0. (The mask has two levels, so
   OpenCV's 17 threshold levels see one image: its keypoints come from one level,
   :mod:`pipeline.binary_blobs`, the same keypoints in linear time.)
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
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from pipeline.angles import Intrinsics, full_pixel, resized_pixel, study_angles
from pipeline.binary_blobs import detect_two_level
from pipeline.components import components, group_bounds
from pipeline.failures import Failure
from pipeline.image_io import as_bgr, to_uint8
from pipeline.markers import Blob, TrackResult, number_study
from scenes.led import SIDE_COLOURS

__all__ = [
    "CLOSE_KERNEL",
    "DENSE_MASK_FRACTION",
    "ERODE_KERNEL",
    "MAX_GROUPS",
    "STUDY_HSV_RANGES",
    "WINDOW_OVERHEAD_PX",
    "HsvBox",
    "ThesisTrackerSettings",
    "blob_detector_params",
    "close_reach",
    "colour_mask",
    "derive_hsv_ranges",
    "hsv_histogram",
    "hsv_ranges_from_histogram",
    "in_range_mask",
    "mask_windows",
    "morphology_reach",
    "processed_hsv",
    "survivor_size",
    "thesis_track",
    "windowed_morphology",
]

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


def blob_detector_params(s: ThesisTrackerSettings) -> cv2.SimpleBlobDetector_Params:
    """The study's ``SimpleBlobDetector`` parameters (OpenCV's defaults elsewhere: levels 50-210
    in steps of 10, a blob kept when seen at two or more)."""
    p = cv2.SimpleBlobDetector_Params()
    p.minDistBetweenBlobs = s.min_dist_between_blobs
    p.filterByArea, p.minArea, p.maxArea = True, s.min_area, s.max_area
    p.filterByConvexity, p.minConvexity = True, _TINY
    p.filterByCircularity, p.minCircularity = True, _TINY
    p.filterByInertia, p.minInertiaRatio = True, _TINY
    return p


CLOSE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
"""The study's closing kernel: elliptical 5×5 (docs/source-study.md §5, step 3)."""
ERODE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2, 4))
"""The study's erosion kernel: elliptical, 2 wide and 4 tall (§5, step 3; (width, height) is the
project's reading), anchored at its centre (1, 2)."""


def in_range_mask(hsv: NDArray[np.uint8], boxes: list[HsvBox]) -> NDArray[np.uint8]:
    """The union of the ``inRange`` boxes of one colour (255 in range, 0 elsewhere)."""
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in boxes:
        mask |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    return mask


def _morphology(mask: NDArray[np.uint8], s: ThesisTrackerSettings) -> NDArray[np.uint8]:
    """The study's morphology on a whole mask: close (5×5 ellipse, ``close_iterations``), then
    erode ((2, 4) ellipse, ``erode_iterations``), OpenCV's default borders."""
    closed = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, CLOSE_KERNEL, iterations=s.close_iterations)
    return cv2.erode(closed, ERODE_KERNEL, iterations=s.erode_iterations)


def _kernel_reach(kernel: NDArray[np.uint8]) -> tuple[int, int]:
    """Farthest (x, y) offset, px, of a set element of ``kernel`` from its centre anchor (OpenCV's default)."""
    ys, xs = np.nonzero(kernel)
    ay, ax = kernel.shape[0] // 2, kernel.shape[1] // 2
    return int(np.abs(xs - ax).max()), int(np.abs(ys - ay).max())


def morphology_reach(s: ThesisTrackerSettings) -> tuple[int, int]:
    """How far, (x, y) px, the study's morphology reaches: an output pixel depends only on input
    pixels at most this far along each axis (each dilation and erosion adds its kernel's reach),
    and is 0 where no in-range pixel is that close (close = dilate then erode, so 5 + 5 passes of
    the 5×5 ellipse (reach 2) and 4 of the (2, 4) one (reach 1, 2): 24 px across, 28 down)."""
    cx, cy = _kernel_reach(CLOSE_KERNEL)
    ex, ey = _kernel_reach(ERODE_KERNEL)
    n = 2 * s.close_iterations
    return n * cx + s.erode_iterations * ex, n * cy + s.erode_iterations * ey


MAX_GROUPS = 400
"""Connected regions of in-range pixels up to which :func:`mask_windows` groups them (assumed
from a measurement on the 2-core machine: the pairwise grouping grows as their square, ~25 ms
at 400 regions, as much as the whole 2-Mpx mask's morphology; beyond this the whole mask is
processed, the same result)."""


def close_reach(s: ThesisTrackerSettings) -> tuple[int, int]:
    """(x, y) reach of the close's dilations, px (10, 10)."""
    cx, cy = _kernel_reach(CLOSE_KERNEL)
    return s.close_iterations * cx, s.close_iterations * cy


def _group_gap(s: ThesisTrackerSettings) -> tuple[int, int]:
    """(x, y) Chebyshev gap, px, up to which two regions share a group: their close dilations
    (within r = 10 px of each) then overlap or touch (2·r + 1 = 21 px)."""
    rx, ry = close_reach(s)
    return 2 * rx + 1, 2 * ry + 1


def survivor_size(s: ThesisTrackerSettings) -> tuple[int, int]:
    """Smallest (width, height), px, of a closed region the final erosion leaves a pixel of: the
    span of the erosion kernel's anchor row and column, times the iterations, plus one (5, 13)."""
    ys, xs = np.nonzero(ERODE_KERNEL)
    ay, ax = ERODE_KERNEL.shape[0] // 2, ERODE_KERNEL.shape[1] // 2
    column, row = ys[xs == ax] - ay, xs[ys == ay] - ax
    return (
        s.erode_iterations * int(row.max() - row.min()) + 1,
        s.erode_iterations * int(column.max() - column.min()) + 1,
    )


def mask_windows(
    mask: NDArray[np.uint8], s: ThesisTrackerSettings
) -> list[tuple[int, int, int, int, int, int, int, int]] | None:
    """Windows whose morphology gives every pixel of ``mask``'s morphology that can be non-zero.

    The 8-connected regions of in-range pixels are grouped when their bounding boxes are at
    most 2·r + 1 apart (Chebyshev), r the close's dilation reach (10 px): the dilations of
    different groups then neither overlap nor touch, so no kernel (a connected set) of the
    closing's erosion or of the final erosion spans two groups, and the morphology is the
    union of each group's. A group's result lies within its bounding box grown by r (the
    *kept* box: dilation reaches r, the erosions only remove). Away from the border (more
    than r from it) the closing even lies inside the box, and the final erosion keeps a pixel
    only where the closing holds the erosion kernel's anchor column and row repeated (13 rows,
    5 columns): lower or narrower groups (a lone noise speckle, a JPEG fleck) give nothing
    and are dropped. Each kept box's *window* is the box grown by the morphology's reach
    (:func:`morphology_reach`), clipped to the mask (OpenCV treats the mask's edge the same
    in a window), so every input pixel a kept pixel depends on is in the window.

    Returns
    -------
    list or None
        (x0, y0, x1, y1) of the window, then (x0, y0, x1, y1) of the kept box, px, half-open,
        in mask coordinates; None when there are too many regions to group (:data:`MAX_GROUPS`).
    """
    comps = components(mask)
    if comps is None:
        return []
    stats = comps[3]
    if len(stats) > MAX_GROUPS:
        return None
    x0, y0 = stats[:, 0], stats[:, 1]
    x1, y1 = x0 + stats[:, 2] - 1, y0 + stats[:, 3] - 1  # inclusive
    gx, gy = _group_gap(s)
    gap_x = np.maximum(x0[:, None] - x1[None, :], x0[None, :] - x1[:, None])
    gap_y = np.maximum(y0[:, None] - y1[None, :], y0[None, :] - y1[:, None])
    _, group = connected_components(csr_matrix((gap_x <= gx) & (gap_y <= gy)), directed=False)
    bx0, by0, bx1, by1 = group_bounds(group, int(group.max()) + 1, x0, y0, x1, y1)
    h, w = mask.shape
    rx, ry = close_reach(s)
    need_w, need_h = survivor_size(s)
    inside = (bx0 > rx) & (by0 > ry) & (bx1 < w - 1 - rx) & (by1 < h - 1 - ry)
    keep = ~(inside & ((by1 - by0 + 1 < need_h) | (bx1 - bx0 + 1 < need_w)))
    mx, my = morphology_reach(s)
    out = []
    for a, b, c, d in zip(bx0[keep].tolist(), by0[keep].tolist(), bx1[keep].tolist(), by1[keep].tolist(), strict=True):
        kx0, ky0, kx1, ky1 = max(0, a - rx), max(0, b - ry), min(w, c + 1 + rx), min(h, d + 1 + ry)
        out.append((max(0, kx0 - mx), max(0, ky0 - my), min(w, kx1 + mx), min(h, ky1 + my), kx0, ky0, kx1, ky1))
    return out


WINDOW_OVERHEAD_PX = 4000
"""Cost of one window's OpenCV calls, in pixels of whole-mask morphology (assumed from a
measurement on the 2-core machine: ~0.1 ms per window call against ~12 ns per pixel of the
whole 2592 × 1728 mask); only decides when to process the whole mask instead (same result)."""


DENSE_MASK_FRACTION = 1 / 64
"""Fraction of a mask's pixels set beyond which its whole morphology is computed without
looking for windows (the same result): labelling a set pixel costs ~0.35-0.45 µs
(:func:`pipeline.components.components`), the whole mask's close and erosion ~6-18 ns per
pixel, so beyond about 1/64 of the pixels set the windows cannot pay (assumed from
measurements on the 2-core machine, 2026-12-06: a T6 half-size mask from thresholds derived
as validate derives them, 3.6 M of 4.5 M pixels set, took 180-240 ms to label and window
against 24-31 ms for the whole morphology)."""


def colour_mask(hsv: NDArray[np.uint8], boxes: list[HsvBox], s: ThesisTrackerSettings) -> NDArray[np.uint8]:
    """The study's mask of one colour: union of inRange boxes, closed then eroded.

    The morphology runs only in windows around the in-range pixels
    (:func:`windowed_morphology`), each grown by the morphology's reach
    (:func:`morphology_reach`), so the mask is identical to the whole image's morphology
    (tests/pipeline/test_thesis_windows.py) at a fraction of its cost on a mostly dark frame;
    where the windows would cover the image anyway, the whole image is processed.
    """
    return windowed_morphology(in_range_mask(hsv, boxes), s)


def windowed_morphology(
    mask: NDArray[np.uint8], s: ThesisTrackerSettings, whole_when_cheaper: bool = True
) -> NDArray[np.uint8]:
    """The study's morphology of ``mask``, computed in :func:`mask_windows` only (the same result).

    Parameters
    ----------
    mask
        In-range mask (0 or 255).
    s
        The tracker's settings (iterations).
    whole_when_cheaper
        Process the whole mask instead when the windows would cost more (a mask with
        :data:`DENSE_MASK_FRACTION` of its pixels set, or windows summing to its size with
        :data:`WINDOW_OVERHEAD_PX` each; the same result; False always uses the windows, as the
        tests check them).
    """
    if whole_when_cheaper and cv2.countNonZero(mask) >= DENSE_MASK_FRACTION * mask.size:
        return _morphology(mask, s)
    windows = mask_windows(mask, s)
    if windows is None:
        return _morphology(mask, s)
    if not windows:
        return np.zeros_like(mask)  # no in-range pixel that can contribute
    cost = sum((x1 - x0) * (y1 - y0) + WINDOW_OVERHEAD_PX for x0, y0, x1, y1, *_ in windows)
    if whole_when_cheaper and cost >= mask.size:
        return _morphology(mask, s)
    out = np.zeros_like(mask)
    for wx0, wy0, wx1, wy1, kx0, ky0, kx1, ky1 in windows:
        done = _morphology(mask[wy0:wy1, wx0:wx1], s)
        out[ky0:ky1, kx0:kx1] |= done[ky0 - wy0 : ky1 - wy0, kx0 - wx0 : kx1 - wx0]
    return out


def processed_hsv(bgr: NDArray, intrinsics: Intrinsics, s: ThesisTrackerSettings) -> tuple[NDArray[np.uint8], float]:
    """The image the tracker works on: 8-bit BGR resized by its scale (0.5 for a frame ≥ 3000 px wide
    unless ``s.resize`` says otherwise, bilinear), as HSV; and that scale."""
    bgr = to_uint8(bgr)
    scale = s.resize if s.resize is not None else (0.5 if intrinsics.width_px >= 3000 else 1.0)
    h, w = bgr.shape[:2]
    if scale != 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        bgr = cv2.resize(bgr, size, interpolation=cv2.INTER_LINEAR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV), scale


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
    hsv, scale = processed_hsv(bgr, intrinsics, s)
    params = blob_detector_params(s)
    counts, all_blobs = {}, []
    first_five = None  # every colour's blobs are counted (what each box saw), the side is the study's
    u0, v0 = crop_origin_px
    for colour in SIDE_COLOURS:
        boxes = s.ranges().get(colour, [])
        if not boxes:
            counts[colour] = 0
            continue
        mask = colour_mask(hsv, boxes, s)
        points, sizes, pad = _detect(params, mask, s.max_area)
        uv = points.astype(np.float64) - pad
        uf, vf = full_pixel(uv[:, 0], uv[:, 1], scale)
        blobs = [
            Blob(float(a) + u0, float(b) + v0, np.pi * (float(size) / 2) ** 2, colour)  # float64, as before
            for a, b, size in zip(uf, vf, sizes, strict=True)
        ]
        all_blobs += blobs
        counts[colour] = len(blobs)
        if len(blobs) == 5 and first_five is None:
            first_five = colour, np.array([[b.u, b.v] for b in blobs])
    if first_five is not None:  # the study's rule: the first colour, in its order, with exactly 5
        return _numbered(*first_five, intrinsics, scale, all_blobs)
    summary = ", ".join(f"{c}: {n}" for c, n in counts.items())
    return TrackResult(
        None, None, f"no colour with exactly 5 blobs ({summary})", all_blobs, failure=Failure.NO_COLOUR_WITH_FIVE
    )


def _detect(params: cv2.SimpleBlobDetector_Params, mask: NDArray[np.uint8], max_area: float):
    """SimpleBlobDetector on the inverted mask, padded so its background exceeds ``max_area``:
    keypoint positions (n, 2) and diameters (n,), float32, and the padding, pixels.

    In a full frame the background (one huge "blob" of the inverted mask) is far larger
    than maxArea and is filtered out; in a small crop it is not, and it displaces a
    marker's keypoint. Padding the crop with background restores the full-frame result.
    The mask is two-level, so OpenCV's detector sees the same image at each of its threshold
    levels: :func:`pipeline.binary_blobs.detect_two_level` gives its keypoints from one level,
    in linear instead of quadratic time in the number of blobs.
    """
    if not mask.any():
        return np.zeros((0, 2), np.float32), np.zeros(0, np.float32), 0
    h, w = mask.shape
    pad = 0
    while (h + 2 * pad) * (w + 2 * pad) <= 2 * max_area:
        pad += 64
    inv = cv2.copyMakeBorder(255 - mask, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255) if pad else 255 - mask
    return *detect_two_level(inv, params), pad


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
    images,
    colour: str,
    margin: tuple[int, int, int] = (3, 10, 10),
    percentiles: tuple[float, float] = (1.0, 99.0),
    *,
    regions=None,
) -> list[HsvBox]:
    """The study's threshold-setting procedure, made repeatable (docs/source-study.md §10).

    From close-range (150 mm) captures of one side lit in ``colour``: take the lit
    pixels (V above Otsu's threshold of each image's V channel), or the pixels a person would
    draw the box around (``regions``: the markers' cores), and span the given percentiles of
    their H, S and V, widened by ``margin`` (H, S, V), with V's top at 255. A hue range crossing
    0/180 (red) is returned as two boxes. The same as :func:`hsv_ranges_from_histogram` of the
    images' summed :func:`hsv_histogram`.

    Parameters
    ----------
    images
        BGR captures (arrays), each showing the lit target of ``colour``.
    colour
        The colour lit in every image.
    margin
        Widening of the percentile span, HSV units.
    percentiles
        Lower and upper percentiles of the lit pixels' values, %.
    regions
        Optional boolean masks, one per image (its size): the pixels to span instead of Otsu's lit ones.
    """
    if colour not in SIDE_COLOURS:
        raise ValueError(f"colour: expected one of {', '.join(SIDE_COLOURS)}, got {colour!r}")
    total = np.zeros((3, 256), np.int64)
    for k, image in enumerate(images):
        try:
            total += hsv_histogram(image, None if regions is None else regions[k])
        except ValueError as exc:
            message = str(exc)
            field = "regions" if message.startswith("region:") else "images"
            raise ValueError(f"{field}[{k}]: {message.removeprefix('region: ')}") from None
    return hsv_ranges_from_histogram(total, margin, percentiles)


def hsv_histogram(image, region=None) -> NDArray[np.int64]:
    """Counts of the lit pixels' H, S and V values: a (3, 256) array, row 0 H (0-179), 1 S, 2 V.

    The lit pixels are those above Otsu's threshold of the image's V channel, or ``region`` (a
    boolean mask of the image's size). Histograms of several images add up to that of their pooled
    pixels, so :func:`derive_hsv_ranges` can be computed image by image, in parallel.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.zeros((8, 8, 3), np.uint8); image[2:5, 2:5] = (0, 0, 255)  # a red square (BGR)
    >>> counts = hsv_histogram(image)
    >>> int(counts[0, 0]), int(counts[1, 255]), int(counts[2, 255])
    (9, 9, 9)
    """
    bgr, reason = as_bgr(image)
    if bgr is None:
        raise ValueError(reason)
    hsv = cv2.cvtColor(to_uint8(bgr), cv2.COLOR_BGR2HSV)
    if region is not None:
        lit = np.asarray(region, dtype=bool)
        if lit.shape != hsv.shape[:2]:
            raise ValueError(f"region: expected a mask of the image's size {hsv.shape[:2]}, got {lit.shape}")
    else:
        val = hsv[..., 2]
        thr, _ = cv2.threshold(val, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        lit = val > thr
    if np.count_nonzero(lit) < 5:
        raise ValueError("no lit pixels found")
    return np.stack([np.bincount(hsv[..., c][lit], minlength=256) for c in range(3)]).astype(np.int64)


def hsv_ranges_from_histogram(
    counts: NDArray[np.int64],
    margin: tuple[int, int, int] = (3, 10, 10),
    percentiles: tuple[float, float] = (1.0, 99.0),
) -> list[HsvBox]:
    """:func:`derive_hsv_ranges` from the pooled pixels' :func:`hsv_histogram` (the same boxes).

    Parameters
    ----------
    counts
        (3, 256) counts of H, S and V values.
    margin
        Widening of the percentile span, HSV units.
    percentiles
        Lower and upper percentiles of the pixels' values, %.
    """
    counts = np.asarray(counts, dtype=np.int64)
    if counts.shape != (3, 256) or (counts < 0).any() or counts[0].sum() < 5 or counts[0, 180:].any():
        raise ValueError("counts: expected a (3, 256) histogram of at least 5 pixels with hues 0-179")
    lo_p, hi_p = percentiles
    hue = counts[0]
    shifted = np.roll(hue[:180], 90)  # hue + 90 mod 180: narrower for a red cluster around 0/180
    use_shift = np.ptp(_percentile_of_counts(shifted, [lo_p, hi_p])) < np.ptp(_percentile_of_counts(hue, [lo_p, hi_p]))
    h_lo, h_hi = _percentile_of_counts(shifted if use_shift else hue, [lo_p, hi_p])
    h_lo, h_hi = h_lo - margin[0], h_hi + margin[0]
    s_lo, s_hi = _percentile_of_counts(counts[1], [lo_p, hi_p]) + np.array([-margin[1], margin[1]])
    v_lo = _percentile_of_counts(counts[2], [lo_p])[0] - margin[2]
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


def _percentile_of_counts(counts: NDArray[np.int64], q) -> NDArray[np.float64]:
    """``np.percentile`` (its default, linear method) of the values 0, 1, … counted by ``counts``,
    without expanding them: the two order statistics around each quantile's position, found in
    the cumulative counts, interpolated as NumPy does (the same floats)."""
    cum = np.cumsum(counts)
    n = int(cum[-1])
    g = np.true_divide(np.asarray(q, dtype=np.float64), 100) * (n - 1)
    below = np.floor(g)
    t = g - below
    a = np.searchsorted(cum, below, side="right").astype(np.float64)  # sorted value at index below
    b = np.searchsorted(cum, np.minimum(below + 1, n - 1), side="right").astype(np.float64)
    diff = b - a
    return np.where(t >= 0.5, b - diff * (1 - t), a + diff * t)
