"""The camera ring: where around the robot no camera sees (its blind zone), and one instant's
detections by its cameras fused into one pose.

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

At one instant several cameras may see beacons, each detection giving the robot's pose in the
beacon frame with a covariance (:class:`PlanarPose`: position and heading in the horizontal
plane). :func:`fuse` combines them by their information (the best linear unbiased estimate of
independent estimates: P⁻¹ = Σ Pᵢ⁻¹, x = P Σ Pᵢ⁻¹ xᵢ, headings unwrapped about the most certain
one), so the fused covariance is never larger than any single one's.

Example
-------
>>> round(blind_zone_m(6, 0.2, math.radians(120.0)), 4)
0.3464
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["STUDY_BLIND_ZONE_M", "PlanarPose", "blind_zone_m", "fuse", "seen_by_ring"]

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


@dataclass(frozen=True)
class PlanarPose:
    """A robot pose estimate in the beacon frame's horizontal plane.

    Attributes
    ----------
    x_m, y_m
        Position, m.
    heading_rad
        Heading about the vertical, rad.
    covariance
        3×3 covariance of (x, y, heading), m² and rad² (symmetric positive definite).
    """

    x_m: float
    y_m: float
    heading_rad: float
    covariance: NDArray[np.float64]

    @property
    def vector(self) -> NDArray[np.float64]:
        """(x, y, heading)."""
        return np.array([self.x_m, self.y_m, self.heading_rad])


def fuse(estimates: Sequence[PlanarPose]) -> PlanarPose:
    """The information-weighted fusion of independent estimates of one pose (module docstring); the
    heading is returned in (−π, π]. ValueError, one line, without estimates or with a covariance that
    is not symmetric positive definite."""
    if not estimates:
        raise ValueError("estimates: expected at least one pose estimate")
    info = []
    for i, e in enumerate(estimates):
        c = np.asarray(e.covariance, dtype=float)
        if c.shape != (3, 3) or not np.allclose(c, c.T) or np.linalg.eigvalsh(c).min() <= 0:
            raise ValueError(f"estimates[{i}].covariance: expected a symmetric positive definite 3×3 matrix")
        info.append(np.linalg.inv(c))
    anchor = estimates[int(np.argmax([np.linalg.det(m) for m in info]))].heading_rad  # the most certain
    total = np.sum(info, axis=0)
    weighted = np.zeros(3)
    for e, m in zip(estimates, info, strict=True):
        v = e.vector
        v[2] = anchor + math.remainder(v[2] - anchor, 2 * math.pi)  # unwrapped about the anchor
        weighted += m @ v
    covariance = np.linalg.inv(total)
    x, y, heading = covariance @ weighted
    return PlanarPose(float(x), float(y), math.remainder(float(heading), 2 * math.pi), (covariance + covariance.T) / 2)
