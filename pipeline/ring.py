"""The camera ring's coverage: where around the robot no camera of the ring sees (its blind zone).

The source study's ring (docs/source-study.md §4.7, §8): N cameras on a circle of radius r about
the robot's centre, each facing straight outward, adjacent ones 2π/N apart (the study's six
Spedal 920 webcams at r = 200 mm). Near the ring, between two adjacent cameras, lies a wedge that
neither field of view reaches; the wedge closes where the two cameras' facing edges cross, on the
bisector between them. With a horizontal field φ (> 2π/N, else the wedges never close) that
point lies

    ρ = r · sin(φ/2) / sin(φ/2 − π/N)

from the centre: every point farther than ρ is seen by at least one camera, and a beacon nearer
than ρ may be seen by none. The field φ must be the lens's (its radial mapping,
:meth:`camera_models.optics.RadialMapping.horizontal_fov_deg`), not the pinhole's: a wide-angle
webcam's barrel distortion widens it. The study states a blind zone to 507 mm for its hexagon.

Example
-------
>>> round(blind_zone_m(6, 0.2, math.radians(120.0)), 4)
0.3464
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["STUDY_BLIND_ZONE_M", "blind_zone_m", "seen_by_ring"]

STUDY_BLIND_ZONE_M = 0.507
"""The blind zone the study states for its hexagon of Spedal 920 webcams, m (docs/source-study.md §4.7)."""


def _check(n_cameras: int, radius_m: float, fov_rad: float) -> None:
    if isinstance(n_cameras, bool) or not isinstance(n_cameras, int) or n_cameras < 2:
        raise ValueError(f"n_cameras: expected an integer >= 2, got {n_cameras!r}")
    if not (math.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"radius_m: expected a ring radius > 0 m, got {radius_m!r}")
    if not 0 < fov_rad < math.pi:
        raise ValueError(f"fov_rad: expected a horizontal field of view in (0, π) rad, got {fov_rad!r}")


def blind_zone_m(n_cameras: int, radius_m: float, fov_rad: float) -> float:
    """How far from the ring's centre the blind wedges between adjacent cameras reach, m (module
    docstring); ∞ when the fields of adjacent cameras never meet (φ ≤ 2π/N)."""
    _check(n_cameras, radius_m, fov_rad)
    gap = fov_rad / 2 - math.pi / n_cameras
    return math.inf if gap <= 0 else radius_m * math.sin(fov_rad / 2) / math.sin(gap)


def seen_by_ring(points_xy: np.ndarray, n_cameras: int, radius_m: float, fov_rad: float) -> np.ndarray:
    """Whether each point (…, 2) of the robot's horizontal plane (m, ring centre at the origin) lies in
    the horizontal field of at least one camera: in front of it and within ±φ/2 of its axis (camera k
    at angle 2πk/N, facing outward)."""
    _check(n_cameras, radius_m, fov_rad)
    p = np.asarray(points_xy, dtype=float)
    seen = np.zeros(p.shape[:-1], dtype=bool)
    for k in range(n_cameras):
        a = 2 * math.pi * k / n_cameras
        axis = np.array([math.cos(a), math.sin(a)])
        d = p - radius_m * axis
        along = d @ axis
        across = d @ np.array([-axis[1], axis[0]])
        seen |= (along > 0) & (np.abs(np.arctan2(across, along)) <= fov_rad / 2)
    return seen
