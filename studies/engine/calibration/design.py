"""Space-filling designs in the unit cube, and inside a region given by a membership test.

Points come from scipy's scrambled Sobol' sequence (Owen scrambling, seeded; Sobol' 1967, "On the
distribution of points in a cube and the approximate evaluation of integrals"), drawn in blocks of
powers of two so the sequence keeps its balance. A wave's design in the not-ruled-out region is a
**greedy maximin** subset of the Sobol' points that pass the test (farthest-point selection:
Gonzalez 1985, "Clustering to minimize the maximum intercluster distance"): the region may be a
thin or curved part of the cube, where the first n filtered Sobol' points can cluster.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist
from scipy.stats import qmc

__all__ = ["RegionSample", "maximin_subset", "sample_region", "sobol"]


def sobol(n: int, dim: int, *, seed: int) -> np.ndarray:
    """``n`` points (n, dim) of a scrambled Sobol' sequence; ``n`` must be a power of 2."""
    if n < 1 or n & (n - 1):
        raise ValueError(f"n: expected a power of 2, got {n!r}")
    return qmc.Sobol(dim, scramble=True, seed=seed).random_base2(int(np.log2(n)))


def maximin_subset(points: np.ndarray, n: int) -> np.ndarray:
    """Indices of ``n`` of ``points`` chosen greedily to be far apart (the first point, then each
    next the one farthest from those chosen). Deterministic; all indices if ``n >= len(points)``."""
    m = len(points)
    if n >= m:
        return np.arange(m)
    chosen = [0]
    nearest = cdist(points, points[:1]).ravel()
    for _ in range(n - 1):
        i = int(np.argmax(nearest))
        chosen.append(i)
        nearest = np.minimum(nearest, cdist(points, points[i : i + 1]).ravel())
    return np.array(chosen)


@dataclass(frozen=True, eq=False)
class RegionSample:
    """Sobol' points drawn until enough passed a region's test.

    Attributes
    ----------
    points
        (k, d) the points that passed, in Sobol' order.
    n_drawn
        How many were drawn (``k / n_drawn`` estimates the region's volume fraction).
    """

    points: np.ndarray
    n_drawn: int


def sample_region(
    inside: Callable[[np.ndarray], np.ndarray],
    dim: int,
    *,
    n_wanted: int,
    seed: int,
    block: int = 4096,
    max_points: int = 2**18,
) -> RegionSample:
    """Sobol' points that pass ``inside`` (a function of (n, d) points returning (n,) booleans),
    drawn in blocks until ``n_wanted`` have passed or ``max_points`` were drawn."""
    engine = qmc.Sobol(dim, scramble=True, seed=seed)
    kept: list[np.ndarray] = []
    n_drawn = n_kept = 0
    while n_kept < n_wanted and n_drawn < max_points:
        q = engine.random(block)
        n_drawn += block
        q = q[inside(q)]
        kept.append(q)
        n_kept += len(q)
    return RegionSample(np.vstack(kept) if kept else np.empty((0, dim)), n_drawn)
