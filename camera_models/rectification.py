"""The lens's distortion in OpenCV's parametrisation: what an ideal checkerboard calibration
of the camera would find, for rectifying its images as the source study did
(docs/source-study.md §10: OpenCV ``calibrateCamera``, undistortion with alpha 0 and 1).

OpenCV's standard model maps normalised pinhole coordinates x (radius r = |x|) to
distorted ones x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) (no tangential terms for a centred
lens). :func:`opencv_distortion` fits k1, k2, k3 by linear least squares to the camera's
own radial mapping (:class:`camera_models.optics.RadialMapping`) from the centre to the
frame's corner, with the camera's paraxial focal length and principal point as K; the fit's
worst radial error over the frame says how well that model can describe the lens. (A
calibration from photos adds corner-detection and pose errors on top:
``beacon-sim lens-calibration`` measures those.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camera_models.camera import Camera
from camera_models.optics import RadialMapping

__all__ = ["OpenCVDistortion", "opencv_distortion"]


@dataclass(frozen=True)
class OpenCVDistortion:
    """Camera matrix and distortion coefficients in OpenCV's standard model.

    Attributes
    ----------
    camera_matrix
        3×3 K, px (the fitted focal length, the principal point at the frame centre).
    dist_coeffs
        (k1, k2, p1, p2, k3), p1 = p2 = 0.
    width_px, height_px
        Frame size, px.
    max_error_px
        Largest radial difference between the fitted model and the lens over the frame, px.
    """

    camera_matrix: NDArray[np.float64]
    dist_coeffs: NDArray[np.float64]
    width_px: int
    height_px: int
    max_error_px: float


def opencv_distortion(camera: Camera, samples: int = 400) -> OpenCVDistortion:
    """Fit OpenCV's k1, k2, k3 to ``camera``'s radial mapping out to the frame's corner."""
    g = camera.geometry
    f = g.focal_length_px
    r_d = np.linspace(0.0, 0.5 * math.hypot(g.width_px, g.height_px), samples + 1)[1:]
    r_u = RadialMapping(camera).undistorted_radius_px(r_d)
    ok = np.isfinite(r_u)
    x, x_d = r_u[ok] / f, r_d[ok] / f
    basis = np.stack([x, x**3, x**5, x**7], axis=1)
    (a1, a3, a5, a7), *_ = np.linalg.lstsq(basis, x_d, rcond=None)
    fitted = basis @ np.array([a1, a3, a5, a7])
    cx, cy = g.principal_point_px
    k = np.array([[a1 * f, 0.0, cx], [0.0, a1 * f, cy], [0.0, 0.0, 1.0]])
    dist = np.array([a3 / a1, a5 / a1, 0.0, 0.0, a7 / a1])
    return OpenCVDistortion(k, dist, g.width_px, g.height_px, float(np.max(np.abs(fitted - x_d)) * f))
