"""Pixels to angles and lines of sight: the study's formula and the exact pinhole.

The study (docs/source-study.md §5.7), with W × H the processed image, N × M the full sensor
resolution, p the pixel pitch and f the focal length::

    α = atan(((W/2 − u)/(W/2)) · (N/2)·p / f)     azimuth, positive to the left
    β = atan(((v − H/2)/(H/2)) · (M/2)·p / f)     elevation, positive downward
    r = (−cos α cos β, −sin α, −cos α sin β)       in its camera frame Cs (X back, Y right, Z up)

Weaknesses kept in :func:`study_angles` / :func:`study_unit_vectors` and documented:

* The image centre is taken at W/2, H/2; with OpenCV pixel centres (top-left pixel at
  (0, 0)) it is (W − 1)/2, (H − 1)/2, a half-pixel bias in the processed image (one full
  pixel after the T6's 50 % resize).
* r is not the pinhole ray: its lateral/forward ratio is tan α / cos β instead of
  tan α, so an off-axis marker's azimuth is stretched by 1/cos β (8 % at the T6 + 18 mm's
  top edge, < 10⁻⁵ near the centre).
* f/p stands for the focal length in pixels, so one value serves both axes and lens
  distortion is ignored (the study undistorted images separately, if at all).

The exact pinhole version (:func:`pinhole_angles`, :func:`pinhole_rays_cv`) uses the
principal point and the focal lengths of an :class:`Intrinsics` and returns true rays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.frames import CS_FROM_CV
from scenes.view import CameraGeometry

__all__ = [
    "Intrinsics",
    "cv_to_study",
    "full_pixel",
    "intrinsics_from_values",
    "pinhole_angles",
    "pinhole_rays_cv",
    "resize_scales",
    "resized_pixel",
    "study_angles",
    "study_unit_vectors",
]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a full-resolution frame, pixels (OpenCV convention).

    Attributes
    ----------
    fx, fy
        Focal lengths, px.
    cx, cy
        Principal point, px (top-left pixel centre at (0, 0)).
    width_px, height_px
        Frame size, px.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width_px: int
    height_px: int

    @classmethod
    def from_geometry(cls, geometry: CameraGeometry) -> Intrinsics:
        """Nominal intrinsics of a camera model (no distortion)."""
        cx, cy = geometry.principal_point_px
        f = geometry.focal_length_px
        return cls(f, f, cx, cy, geometry.width_px, geometry.height_px)

    @classmethod
    def from_matrix(cls, k: NDArray[np.float64], width_px: int, height_px: int) -> Intrinsics:
        """From a 3×3 camera matrix."""
        return cls(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), int(width_px), int(height_px))

    def matrix(self) -> NDArray[np.float64]:
        """3×3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def resized(self, scale_x: float, scale_y: float | None = None) -> Intrinsics:
        """The intrinsics of this frame resized by ``scale_x`` (and ``scale_y``, default the same).

        Pixel centres are aligned as in ``cv2.resize``: the focal lengths scale with the
        image and the principal point maps like a pixel centre, c' = (c + 0.5)·s − 0.5 px.
        The new frame is round(W·s_x) × round(H·s_y) px.
        """
        sy = scale_x if scale_y is None else scale_y
        return Intrinsics(
            self.fx * scale_x,
            self.fy * sy,
            (self.cx + 0.5) * scale_x - 0.5,
            (self.cy + 0.5) * sy - 0.5,
            max(1, round(self.width_px * scale_x)),
            max(1, round(self.height_px * sy)),
        )

    def resized_to(self, width_px: int, height_px: int) -> Intrinsics | None:
        """The intrinsics of a resized copy of this frame that is ``width_px`` × ``height_px``, or None.

        None when that size is not the frame resized by one factor (the aspect ratios
        differ by more than a pixel of rounding): a crop or another sensor mode, whose
        intrinsics cannot be told from this frame's. The scales are taken per axis
        (W'/W, H'/H), as a resize to an exact size does.
        """
        scales = resize_scales((self.width_px, self.height_px), (width_px, height_px))
        if scales is None:
            return None
        out = self.resized(*scales)
        return Intrinsics(out.fx, out.fy, out.cx, out.cy, int(width_px), int(height_px))


def resize_scales(frame_px: tuple[int, int], image_px: tuple[int, int]) -> tuple[float, float] | None:
    """Per-axis scales (W'/W, H'/H) when ``image_px`` (W', H') is ``frame_px`` (W, H) resized by one factor, else None.

    One factor s gives round(W·s) × round(H·s); a pixel of slack on each axis allows for
    programs that floor or ceil instead of rounding.
    """
    (w0, h0), (w1, h1) = frame_px, image_px
    if min(w0, h0, w1, h1) < 1:
        return None
    lo = max((w1 - 1) / w0, (h1 - 1) / h0)
    hi = min((w1 + 1) / w0, (h1 + 1) / h0)
    return (w1 / w0, h1 / h0) if lo <= hi else None


def intrinsics_from_values(
    width_px: int, height_px: int, fx: float, fy: float | None = None, cx: float | None = None, cy: float | None = None
) -> Intrinsics:
    """Pinhole intrinsics of a whole ``width_px`` × ``height_px`` image from given values.

    Parameters
    ----------
    width_px, height_px
        Image size, px.
    fx
        Horizontal focal length, px (> 0).
    fy
        Vertical focal length, px; None means ``fx`` (square pixels).
    cx, cy
        Principal point, px (top-left pixel centre at (0, 0)); None means the image centre
        ((W − 1)/2, (H − 1)/2). It must lie in the image.

    Raises
    ------
    ValueError
        Naming the field (``fx``, ``fy``, ``cx`` or ``cy``) when a value is not finite,
        a focal length is not positive, or the principal point is outside the image.
    """
    fy = fx if fy is None else fy
    cx = (width_px - 1) / 2.0 if cx is None else cx
    cy = (height_px - 1) / 2.0 if cy is None else cy
    for name, value in (("fx", fx), ("fy", fy)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a focal length > 0 px, got {value!r}")
    for name, value, size in (("cx", cx, width_px), ("cy", cy, height_px)):
        if not (math.isfinite(value) and -0.5 <= value <= size - 0.5):
            raise ValueError(f"{name}: expected a principal point in the image, -0.5 to {size - 0.5} px, got {value!r}")
    return Intrinsics(float(fx), float(fy), float(cx), float(cy), int(width_px), int(height_px))


def study_angles(u, v, processed_size_px: tuple[int, int], intrinsics: Intrinsics) -> tuple[NDArray, NDArray]:
    """The study's azimuth and elevation (rad) of processed-image pixels (u, v).

    Parameters
    ----------
    u, v
        Pixel coordinates in the processed (possibly resized) image, px.
    processed_size_px
        (W, H) of the processed image, px.
    intrinsics
        Full-resolution intrinsics; only fx, fy (= f/p) and the full size (N, M) are used,
        the principal point is the study's W/2, H/2.
    """
    w, h = processed_size_px
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    alpha = np.arctan((w / 2 - u) / (w / 2) * (intrinsics.width_px / 2) / intrinsics.fx)
    beta = np.arctan((v - h / 2) / (h / 2) * (intrinsics.height_px / 2) / intrinsics.fy)
    return alpha, beta


def study_unit_vectors(alpha, beta) -> NDArray[np.float64]:
    """The study's r = (−cos α cos β, −sin α, −cos α sin β) in its camera frame Cs, shape (…, 3)."""
    alpha = np.asarray(alpha, dtype=np.float64)
    beta = np.asarray(beta, dtype=np.float64)
    return np.stack([-np.cos(alpha) * np.cos(beta), -np.sin(alpha), -np.cos(alpha) * np.sin(beta)], axis=-1)


def pinhole_angles(u, v, intrinsics: Intrinsics) -> tuple[NDArray, NDArray]:
    """Azimuth atan((cx − u)/fx) (positive left) and elevation atan((v − cy)/fy) (positive down), rad.

    Same definition as the study's angles, with the true principal point.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    return np.arctan((intrinsics.cx - u) / intrinsics.fx), np.arctan((v - intrinsics.cy) / intrinsics.fy)


def pinhole_rays_cv(u, v, intrinsics: Intrinsics) -> NDArray[np.float64]:
    """Unit lines of sight of pixels (u, v) in the OpenCV camera frame, shape (…, 3)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    ray = np.stack([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)], -1)
    return ray / np.linalg.norm(ray, axis=-1, keepdims=True)


def cv_to_study(vectors_cv: NDArray[np.float64]) -> NDArray[np.float64]:
    """Vectors (…, 3) from the OpenCV camera frame to the study's camera frame Cs."""
    return np.asarray(vectors_cv) @ CS_FROM_CV.T


def resized_pixel(u_full, v_full, scale: float) -> tuple[NDArray, NDArray]:
    """Where full-resolution pixel (u, v) lands after resizing by ``scale`` (pixel centres aligned, as cv2.resize)."""
    return (np.asarray(u_full) + 0.5) * scale - 0.5, (np.asarray(v_full) + 0.5) * scale - 0.5


def full_pixel(u_resized, v_resized, scale: float) -> tuple[NDArray, NDArray]:
    """Inverse of :func:`resized_pixel`."""
    return (np.asarray(u_resized) + 0.5) / scale - 0.5, (np.asarray(v_resized) + 0.5) / scale - 0.5
