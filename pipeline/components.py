"""8-connected components of a sparse binary mask from its pixel list, without a full-frame label image.

A dark whole frame's mask holds a few hundred pixels in 18 Mpx; OpenCV's labelling writes a
label for every pixel (~120 ms on the T6's frame on the 2-core machine), the pixel list costs
a few ms (``cv2.findNonZero``). Both trackers use it.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["MAX_POINT_PIXELS", "components", "group_bounds"]


MAX_POINT_PIXELS = 200_000
"""Pixels above the threshold up to which :func:`components` labels them as a point set
(assumed: beyond this OpenCV's labelling of the whole mask is as fast)."""


def components(mask: NDArray[np.uint8]):
    """8-connected components of a 0/1 mask: (x, y, label) of its pixels grouped by label, and per
    label (x0, y0, width, height, area), labels numbered in raster order of their first pixel;
    None when the mask is empty.

    A sparse mask (a dark frame's tens of blobs) is labelled from its pixel list, linking each
    pixel to its right, lower-left, lower and lower-right neighbours (scipy's connected
    components), without a full-frame label image; a dense one by OpenCV.
    """
    pts = cv2.findNonZero(mask)
    if pts is None:
        return None
    pts = pts.reshape(-1, 2).astype(np.int64)
    if len(pts) > MAX_POINT_PIXELS:
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        ys, xs = np.nonzero(labels)
        label = labels[ys, xs] - 1
        stats = stats[1:].astype(np.int64)
    else:
        w = mask.shape[1] + 2  # a spare column each side: no wrap-around between rows
        xs, ys = pts[:, 0], pts[:, 1]
        key = ys * w + (xs + 1)  # raster order (findNonZero's order)
        links = []
        for off in (1, w - 1, w, w + 1):
            j = np.searchsorted(key, key + off)
            hit = (j < len(key)) & (key[np.minimum(j, len(key) - 1)] == key + off)
            links.append(np.stack([np.nonzero(hit)[0], j[hit]]))
        edges = np.concatenate(links, axis=1)
        graph = csr_matrix((np.ones(edges.shape[1], bool), (edges[0], edges[1])), shape=(len(key), len(key)))
        _, raw = connected_components(graph, directed=False)
        first = np.full(raw.max() + 1, len(key))
        np.minimum.at(first, raw, np.arange(len(key)))
        rank = np.empty_like(first)
        rank[np.argsort(first)] = np.arange(len(first))
        label = rank[raw]
    order = np.argsort(label, kind="stable")
    xs, ys, label = xs[order], ys[order], label[order]
    n = int(label.max()) + 1
    area = np.bincount(label, minlength=n)
    x0, y0, x1, y1 = group_bounds(label, n, xs, ys, xs, ys)
    return xs, ys, label, np.stack([x0, y0, x1 - x0 + 1, y1 - y0 + 1, area], axis=1)


def group_bounds(
    group: NDArray[np.integer],
    n: int,
    x0: NDArray[np.integer],
    y0: NDArray[np.integer],
    x1: NDArray[np.integer],
    y1: NDArray[np.integer],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Inclusive bounding box (x0, y0, x1, y1) of each of ``n`` groups of boxes, px: box k
    (inclusive corners ``x0[k], y0[k]`` to ``x1[k], y1[k]``; a pixel is a box with equal
    corners) belongs to group ``group[k]``. An empty group keeps (int64 max, int64 max, -1, -1)."""
    bx0, by0 = np.full(n, np.iinfo(np.int64).max), np.full(n, np.iinfo(np.int64).max)
    bx1, by1 = np.full(n, -1), np.full(n, -1)
    np.minimum.at(bx0, group, x0)
    np.minimum.at(by0, group, y0)
    np.maximum.at(bx1, group, x1)
    np.maximum.at(by1, group, y1)
    return bx0, by0, bx1, by1
