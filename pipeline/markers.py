"""What a tracker reports, and how five image points are numbered as markers 1..5.

Numbering (the study's detector numbering = the project's marker ids): 1 centre (out of
plane), 2 the viewer's right, 3 the viewer's left, 4 top, 5 bottom.

* :func:`number_study` is the study's rule (docs/source-study.md §5.6): highest in the image is 4,
  lowest is 5, the other three by increasing azimuth (positive left) are 2, 1, 3. The
  study calls 4 the "greatest elevation" while its elevation is positive *downward*;
  the project reads "highest" as top of the image (least elevation), as its marker
  table requires. The rule breaks when yaw pushes marker 1 past marker 2 or 3 in
  azimuth (V2: yaw > atan(70/46) = 56.7°) and, like any up/down rule, at about 45° of
  camera roll.
* :func:`cross_candidates` is the project's rule: the four outer markers are the two
  diagonals of a convex quadrilateral (the arms 2–3 and 4–5), the fifth point is 1; the
  more horizontal diagonal is 2–3 (2 on the right), the other 4–5 (4 on top). It holds
  for any roll below 45° and needs no ordering by azimuth; the better tracker picks among
  the candidates by fitting the target geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.failures import Failure

__all__ = ["Blob", "TrackResult", "cross_candidates", "cross_candidates_many", "number_study"]


@dataclass
class Blob:
    """A bright blob found by a tracker.

    Attributes
    ----------
    u, v
        Centroid in full-resolution, full-frame pixels.
    area_px
        Area in the processed image, px.
    colour
        Colour class, or None when it could not be told.
    flux
        Background-subtracted intensity sum (0 for the study's binary masks).
    saturated_fraction
        Share of the blob's pixels with a clipped channel.
    chroma
        (r, g) chromaticity, or None.
    """

    u: float
    v: float
    area_px: float
    colour: str | None = None
    flux: float = 0.0
    saturated_fraction: float = 0.0
    chroma: tuple[float, float] | None = None

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "u": round(float(self.u), 4),
            "v": round(float(self.v), 4),
            "area_px": float(self.area_px),
            "colour": self.colour,
            "flux": float(self.flux),
            "saturated_fraction": round(float(self.saturated_fraction), 4),
            "chroma": None if self.chroma is None else [round(float(c), 4) for c in self.chroma],
        }


@dataclass
class TrackResult:
    """A tracker's answer for one image.

    Attributes
    ----------
    side
        Colour of the side found, or None.
    uv
        (5, 2) full-resolution pixels of markers 1..5, or None when no target.
    reason
        Why there is no target (or what is doubtful about it), else None.
    failure
        The code of ``reason`` when there is no complete answer, else None.
    blobs
        Every blob found (for diagnostics).
    notes
        Extra findings: merged or lost markers, colour doubts.
    azimuth_rad, elevation_rad
        The tracker's angles of markers 1..5 (the study's formula for the study's tracker).
    """

    side: str | None
    uv: NDArray[np.float64] | None
    reason: str | None = None
    blobs: list[Blob] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    azimuth_rad: NDArray[np.float64] | None = None
    elevation_rad: NDArray[np.float64] | None = None
    failure: Failure | None = None

    @property
    def found(self) -> bool:
        """True when five markers were numbered."""
        return self.uv is not None


def number_study(azimuth_rad, elevation_rad) -> NDArray[np.int64]:
    """The study's numbering: indices of markers 1..5 among five points (see module doc)."""
    az = np.asarray(azimuth_rad, dtype=np.float64)
    el = np.asarray(elevation_rad, dtype=np.float64)
    if az.shape != (5,) or el.shape != (5,):
        raise ValueError("markers: expected 5 azimuths and 5 elevations")
    top = int(np.argmin(el))
    bottom = int(np.argmax(el))
    if top == bottom:
        raise ValueError("markers: cannot tell top from bottom")
    rest = [i for i in range(5) if i not in (top, bottom)]
    two, one, three = sorted(rest, key=lambda i: az[i])
    return np.array([one, two, three, top, bottom])


def cross_candidates(uv) -> list[NDArray[np.int64]]:
    """Every plausible numbering of five points as a cross: each point as marker 1 in turn.

    For each choice of centre, the other four are ordered by angle about their mean and
    opposite ones paired; returns index arrays (markers 1..5) for the choices where the
    two diagonals cross (a convex quadrilateral).
    """
    pts = np.asarray(uv, dtype=np.float64)
    return list(cross_candidates_many(pts[None])[1])


def cross_candidates_many(points) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """:func:`cross_candidates` of many five-point sets at once, shape (S, 5, 2).

    Returns (set index, numbering) of every candidate, ordered by set and then by the
    centre's index, as the one-set function lists them; the arithmetic is the same, so
    the results are identical.
    """
    pts = np.asarray(points, dtype=np.float64)
    sets = np.arange(len(pts))
    found = []
    for centre in range(5):
        others = np.array([i for i in range(5) if i != centre])
        q = pts[:, others]
        rel = q - q.mean(axis=1, keepdims=True)
        order = np.argsort(np.arctan2(rel[..., 1], rel[..., 0]), axis=1)
        ring = others[order]  # (S, 4) point indices around the centre
        at = [pts[sets, ring[:, k]] for k in range(4)]
        cross = _segments_cross(at[0], at[2], at[1], at[3])
        dir1, dir2 = at[2] - at[0], at[3] - at[1]
        first_horizontal = np.abs(dir1[:, 0]) * np.abs(dir2[:, 1]) >= np.abs(dir1[:, 1]) * np.abs(dir2[:, 0])
        hor = np.where(first_horizontal[:, None], ring[:, [0, 2]], ring[:, [1, 3]])
        ver = np.where(first_horizontal[:, None], ring[:, [1, 3]], ring[:, [0, 2]])
        hx = pts[sets[:, None], hor, 0]
        vy = pts[sets[:, None], ver, 1]
        swap_h = ~(-hx[:, 0] <= -hx[:, 1])  # a stable sort by -x keeps the pair's order on ties
        swap_v = ~(vy[:, 0] <= vy[:, 1])  # … and by y
        two, three = np.where(swap_h, hor[:, 1], hor[:, 0]), np.where(swap_h, hor[:, 0], hor[:, 1])
        four, five = np.where(swap_v, ver[:, 1], ver[:, 0]), np.where(swap_v, ver[:, 0], ver[:, 1])
        numbered = np.stack([np.full(len(pts), centre), two, three, four, five], axis=1)
        found.append((np.flatnonzero(cross), numbered[cross]))
    which = np.concatenate([w for w, _ in found])
    numbered = np.concatenate([n for _, n in found]).reshape(-1, 5)
    order = np.argsort(which, kind="stable")  # by set, then by centre
    return which[order], numbered[order]


def _segments_cross(a, b, c, d):
    """Whether segments ab and cd cross properly (points (..., 2))."""

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    return (orient(a, b, c) * orient(a, b, d) < 0) & (orient(c, d, a) * orient(c, d, b) < 0)
