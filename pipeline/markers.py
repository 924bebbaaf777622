"""What a tracker reports, and how five image points are numbered as markers 1..5.

Numbering (the study's detector numbering = the project's marker ids): 1 centre (out of
plane), 2 the viewer's right, 3 the viewer's left, 4 top, 5 bottom.

* :func:`number_study` is the study's rule (THESIS_FACTS §5.6): highest in the image is 4,
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
    out = []
    for centre in range(5):
        others = [i for i in range(5) if i != centre]
        q = pts[others]
        ang = np.arctan2(*(q - q.mean(axis=0)).T[::-1])
        ring = [others[i] for i in np.argsort(ang)]
        d1, d2 = (ring[0], ring[2]), (ring[1], ring[3])
        if not _segments_cross(pts[d1[0]], pts[d1[1]], pts[d2[0]], pts[d2[1]]):
            continue
        dir1, dir2 = pts[d1[1]] - pts[d1[0]], pts[d2[1]] - pts[d2[0]]
        hor, ver = (d1, d2) if abs(dir1[0]) * abs(dir2[1]) >= abs(dir1[1]) * abs(dir2[0]) else (d2, d1)
        two, three = sorted(hor, key=lambda i: -pts[i, 0])
        four, five = sorted(ver, key=lambda i: pts[i, 1])
        out.append(np.array([centre, two, three, four, five]))
    return out


def _segments_cross(a, b, c, d) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    return orient(a, b, c) * orient(a, b, d) < 0 and orient(c, d, a) * orient(c, d, b) < 0
