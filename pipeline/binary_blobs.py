"""OpenCV's ``SimpleBlobDetector`` on a two-level image, in one pass, with the same keypoints.

``SimpleBlobDetector.detect`` thresholds the image at ``minThreshold``, ``minThreshold +
thresholdStep``, … (17 levels at the defaults), finds the blobs of each binarised image
(``findBlobs``: contours, their moments, the area / circularity / inertia / convexity / colour
filters, a radius) and groups the blobs of each level with those of earlier levels: a blob joins
the *first* earlier group whose middle member (by radius) lies closer than
``max(minDistBetweenBlobs, that member's radius, its own radius)``. The grouping compares every
blob with every group, O(n²) per level: on a mask of ~10⁵ noise specks (the study's tracker with
thresholds that take in sensor noise) one call takes minutes.

When every pixel lies at or below the first level or above the last, as the study tracker's
inverted 0/255 masks do, every level binarises to the same image and ``findBlobs`` returns the
same blobs at every level. :func:`detect_two_level` computes them once, with the same OpenCV
primitives in the same order, and replays the grouping exactly: a blob can only ever join a
group whose middle member is one of its *neighbours* (blobs within the joining distance of it),
so blobs with no neighbour form a group of one blob repeated at each level, computed for all of
them at once, and only the few clusters of neighbours are replayed member by member. The
keypoints — positions (the confidence-weighted mean, accumulated in OpenCV's order, rounded to
float32), sizes and their order — equal OpenCV's (tests/pipeline/test_binary_blobs.py compares
them on random and rendered masks).

References
----------
OpenCV 5.x, ``modules/features2d/src/blobdetector.cpp`` (``SimpleBlobDetectorImpl::findBlobs``
and ``detect``).

Examples
--------
>>> import cv2, numpy as np
>>> inverted = np.full((40, 40), 255, np.uint8)
>>> inverted[10:14, 10:14] = 0
>>> p = cv2.SimpleBlobDetector_Params()
>>> p.minArea = 2
>>> pts, sizes = detect_two_level(inverted, p)
>>> pts.tolist()
[[11.5, 11.5]]
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["BlobCentres", "blob_centres", "detect_two_level", "threshold_levels"]


@dataclass(frozen=True)
class BlobCentres:
    """What OpenCV's ``findBlobs`` keeps of each contour, in its order.

    Attributes
    ----------
    xy
        (n, 2) centre (moments m10/m00, m01/m00), pixels, float64.
    radius
        (n,) median distance of the contour's points from the centre, pixels.
    confidence
        (n,) the inertia ratio squared (1 when the inertia filter is off).
    """

    xy: NDArray[np.float64]
    radius: NDArray[np.float64]
    confidence: NDArray[np.float64]


def threshold_levels(params: cv2.SimpleBlobDetector_Params) -> list[float]:
    """The grey levels ``detect`` binarises at, as its loop steps through them (double precision)."""
    levels, t = [], float(params.minThreshold)
    while t < params.maxThreshold:
        levels.append(t)
        t += float(params.thresholdStep)
    return levels


def blob_centres(binary: NDArray[np.uint8], params: cv2.SimpleBlobDetector_Params) -> BlobCentres:
    """OpenCV's ``findBlobs`` on one binarised image (0 or 255), in its order and arithmetic.

    Parameters
    ----------
    binary
        The binarised image, uint8, values 0 and 255.
    params
        The detector's parameters (filters, ``blobColor``).
    """
    contours, _ = cv2.findContours(binary, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    xy, radius, confidence = [], [], []
    h, w = binary.shape
    for contour in contours:
        m = cv2.moments(contour)
        m00 = m["m00"]
        if params.filterByArea and (m00 < params.minArea or m00 >= params.maxArea):
            continue
        if params.filterByCircularity:
            perimeter = np.float64(cv2.arcLength(contour, True))
            with np.errstate(divide="ignore", invalid="ignore"):  # a point's contour: NaN passes, as in C++
                ratio = 4 * np.pi * m00 / (perimeter * perimeter)
            if ratio < params.minCircularity or ratio >= params.maxCircularity:
                continue
        conf = 1.0
        if params.filterByInertia:
            ratio = _inertia_ratio(m["mu20"], m["mu02"], m["mu11"])
            if ratio < params.minInertiaRatio or ratio >= params.maxInertiaRatio:
                continue
            conf = ratio * ratio
        if params.filterByConvexity:
            hull_area = cv2.contourArea(cv2.convexHull(contour))
            if abs(hull_area) < np.finfo(np.float64).eps:
                continue
            ratio = m00 / hull_area
            if ratio < params.minConvexity or ratio >= params.maxConvexity:
                continue
        if m00 == 0.0:
            continue
        cx, cy = m["m10"] / m00, m["m01"] / m00
        if params.filterByColor:
            # cvRound: to nearest, ties to even, as np.rint
            row, col = int(np.rint(cy)), int(np.rint(cx))
            if not (0 <= row < h and 0 <= col < w) or binary[row, col] != params.blobColor:
                continue
        pts = contour.reshape(-1, 2).astype(np.float64)
        dx, dy = cx - pts[:, 0], cy - pts[:, 1]
        dists = np.sort(np.sqrt(dx * dx + dy * dy))
        n = len(dists)
        xy.append((cx, cy))
        radius.append((dists[(n - 1) // 2] + dists[n // 2]) / 2.0)
        confidence.append(conf)
    return BlobCentres(
        np.array(xy, dtype=np.float64).reshape(-1, 2),
        np.array(radius, dtype=np.float64),
        np.array(confidence, dtype=np.float64),
    )


def _inertia_ratio(mu20: float, mu02: float, mu11: float) -> float:
    """OpenCV's ratio of the least to the largest second moment about the centre (1 for a disc)."""
    denominator = np.sqrt((2 * mu11) ** 2 + (mu20 - mu02) ** 2)
    if not denominator > 1e-2:
        return 1.0
    cosmin = (mu20 - mu02) / denominator
    sinmin = 2 * mu11 / denominator
    imin = 0.5 * (mu20 + mu02) - 0.5 * (mu20 - mu02) * cosmin - mu11 * sinmin
    imax = 0.5 * (mu20 + mu02) - 0.5 * (mu20 - mu02) * -cosmin - mu11 * -sinmin
    return imin / imax


def detect_two_level(
    image: NDArray[np.uint8], params: cv2.SimpleBlobDetector_Params
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``cv2.SimpleBlobDetector_create(params).detect(image)`` for an image every one of whose
    pixels binarises the same at every threshold level; the keypoints' positions and sizes.

    Parameters
    ----------
    image
        Single-channel uint8 image (e.g. an inverted 0/255 mask).
    params
        The detector's parameters, OpenCV's defaults where not set.

    Returns
    -------
    points, sizes
        (n, 2) float32 keypoint positions (x, y) and (n,) float32 diameters, pixels, in
        OpenCV's order.

    Raises
    ------
    ValueError
        When a pixel lies between the first and the last level (the levels would differ), or
        ``minRepeatability`` is 0.
    """
    levels = threshold_levels(params)
    if params.minRepeatability < 1:
        raise ValueError(f"minRepeatability: expected at least 1, got {params.minRepeatability}")
    if not levels:
        return np.zeros((0, 2), np.float32), np.zeros(0, np.float32)
    between = (image > levels[0]) != (image > levels[-1])
    if between.any():
        raise ValueError(
            f"image: expected every pixel at or below {levels[0]:g} or above {levels[-1]:g} "
            f"(two levels); {int(between.sum())} lie between"
        )
    binary = np.where(image > levels[0], np.uint8(255), np.uint8(0))
    c = blob_centres(binary, params)
    groups = _replay_grouping(c, len(levels), float(params.minDistBetweenBlobs))
    keep = [g for g in groups if len(g[1]) >= params.minRepeatability]
    points = np.zeros((len(keep), 2), np.float32)
    sizes = np.zeros(len(keep), np.float32)
    lone = [k for k, g in enumerate(keep) if g[2]]
    if lone:  # a lone blob's group is that blob once per level: summed for all at once, in OpenCV's order
        idx = np.array([keep[k][1][0] for k in lone])
        xy, conf = c.xy[idx], c.confidence[idx]
        total, norm = np.zeros_like(xy), np.zeros(len(idx))
        for _ in levels:
            total = total + conf[:, None] * xy
            norm = norm + conf
        points[lone] = (total * (1.0 / norm)[:, None]).astype(np.float32)
        sizes[lone] = c.radius[idx].astype(np.float32) * np.float32(2.0)
    for k, (_, members, is_lone) in enumerate(keep):
        if is_lone:
            continue
        sx = sy = norm = 0.0
        for m in members:
            sx += c.confidence[m] * c.xy[m, 0]
            sy += c.confidence[m] * c.xy[m, 1]
            norm += c.confidence[m]
        inv = 1.0 / norm
        points[k] = (np.float32(sx * inv), np.float32(sy * inv))
        sizes[k] = np.float32(c.radius[members[len(members) // 2]]) * np.float32(2.0)
    return points, sizes


def _neighbours(c: BlobCentres, min_dist: float) -> coo_matrix:
    """Pairs of blobs close enough for one to join a group whose middle member is the other:
    ``not (d >= min_dist and d >= r_i and d >= r_j)``, d as OpenCV computes it."""
    n = len(c.radius)
    if n < 2:
        return coo_matrix((n, n))
    tree = cKDTree(c.xy)
    reach = np.maximum(c.radius, min_dist) * (1 + 1e-9) + 1e-9  # a margin; the exact test follows
    found = [tree.query_pairs(reach.min(), output_type="ndarray")]
    wide = np.flatnonzero(reach > reach.min())  # blobs whose own radius reaches farther
    if len(wide):
        balls = tree.query_ball_point(c.xy[wide], reach[wide])
        counts = np.fromiter(map(len, balls), np.intp, len(wide))
        others = np.concatenate([np.asarray(b, np.intp) for b in balls])
        found.append(np.column_stack([np.repeat(wide, counts), others]))
    ij = np.sort(np.concatenate(found).reshape(-1, 2), axis=1)
    ij = np.unique(ij[ij[:, 0] != ij[:, 1]], axis=0)
    if not len(ij):
        return coo_matrix((n, n))
    d = c.xy[ij[:, 0]] - c.xy[ij[:, 1]]
    dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    near = ~((dist >= min_dist) & (dist >= c.radius[ij[:, 0]]) & (dist >= c.radius[ij[:, 1]]))
    ij = ij[near]
    return coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])), shape=(n, n))


def _replay_grouping(c: BlobCentres, n_levels: int, min_dist: float) -> list[tuple[tuple[int, int], list[int], bool]]:
    """OpenCV's grouping over ``n_levels`` identical levels of blobs ``c``: each group as (its
    creation key (level, blob), its members in OpenCV's order (by radius, stable), whether it is
    a lone blob's), sorted by creation, the order ``detect`` emits them in."""
    pairs = _neighbours(c, min_dist)
    graph = (pairs + pairs.T).tocsr()  # both ways: each blob's neighbours
    n_comp, label = connected_components(graph, directed=False)
    sizes = np.bincount(label, minlength=n_comp)
    # a blob is near itself (distance 0) when the minimum distance or its radius is positive
    self_near = (min_dist > 0) | (c.radius > 0)
    lone = (sizes[label] == 1) & self_near  # joins its own group at every level, and nothing else does
    groups: list[tuple[tuple[int, int], list[int], bool]] = [
        ((0, int(i)), [int(i)] * n_levels, True) for i in np.flatnonzero(lone)
    ]
    rest = np.flatnonzero(~lone)
    if len(rest):
        adjacent = np.split(graph.indices, graph.indptr[1:-1])
        near = {int(i): adjacent[i].tolist() + ([int(i)] if self_near[i] else []) for i in rest}
        groups += _replay(rest.tolist(), near, c.radius, n_levels)
    groups.sort(key=lambda g: g[0])
    return groups


def _replay(blobs: list[int], near: dict[int, list[int]], radius: NDArray[np.float64], n_levels: int):
    """The grouping loop of ``detect`` for blobs with neighbours (``near[i]``: the blobs whose
    being a group's middle member lets ``i`` join that group, ``i`` itself included when it
    would). A blob joins the earliest group whose middle member is near it, as OpenCV's first
    match in creation order; groups are indexed by creation, so the earliest is the smallest
    index among the groups of its near blobs."""
    r = {i: float(radius[i]) for i in blobs}
    keys: list[tuple[int, int]] = []
    members: list[list[int]] = []
    by_middle: dict[int, set[int]] = {}  # blob → the groups whose middle member it is

    def create(key, i):
        keys.append(key)
        members.append([i])
        by_middle.setdefault(i, set()).add(len(members) - 1)

    for i in blobs:
        create((0, i), i)
    for level in range(1, n_levels):
        new = []
        for i in blobs:
            candidates = [g for j in near[i] for g in by_middle.get(j, ())]
            if not candidates:
                new.append(i)
                continue
            g = min(candidates)
            m = members[g]
            old_mid = m[len(m) // 2]
            k = len(m)
            m.append(i)
            while k > 0 and r[i] < r[m[k - 1]]:
                m[k] = m[k - 1]
                k -= 1
            m[k] = i
            mid = m[len(m) // 2]
            if mid != old_mid:
                by_middle[old_mid].discard(g)
                by_middle.setdefault(mid, set()).add(g)
        for i in new:  # appended after the level's loop, as OpenCV's newCenters
            create((level, i), i)
    return [(key, m, False) for key, m in zip(keys, members, strict=True)]
