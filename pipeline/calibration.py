"""Checkerboard camera calibration and undistortion (docs/source-study.md §10).

The study calibrated with a board of 6 × 8 inner corners and 24.4 mm squares, 46 to 299
photos, OpenCV ``calibrateCamera``, and undistorted with alpha 0 (only valid pixels,
cropped) and alpha 1 (all source pixels kept, black borders). Here:

* :func:`find_corners` finds the inner corners (``findChessboardCorners`` +
  ``cornerSubPix``) and :func:`calibrate_points` fits a distortion model to corner sets
  (``standard`` k1, k2, p1, p2, k3 as the study; ``rational``; ``fisheye``);
* :func:`calibrate` does both on photos (the study's model) and returns a :class:`Calibration`;
* :meth:`Calibration.save` / :func:`load_calibration` use a JSON file;
* :func:`undistort` remaps an image (full frame or a crop) with
  ``getOptimalNewCameraMatrix(alpha)`` and returns the new intrinsics, and
  :func:`distort_points` maps pixels of the undistorted image back to the original.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics
from pipeline.image_io import as_bgr, load_image, to_uint8

PATTERN_INNER_CORNERS = (8, 6)
"""Inner corners per row and per column of the study's board (6 × 8)."""

SQUARE_M = 0.0244
"""Square size of the study's board, m."""


@dataclass(frozen=True)
class Calibration:
    """Result of a checkerboard calibration.

    Attributes
    ----------
    camera_matrix
        3×3 K, px.
    dist_coeffs
        (k1, k2, p1, p2, k3).
    width_px, height_px
        Image size the calibration applies to, px.
    rms_px
        RMS reprojection error over all corners, px.
    n_images
        Views used.
    pattern, square_m
        Board inner corners (per row, per column) and square size, m.
    """

    camera_matrix: NDArray[np.float64]
    dist_coeffs: NDArray[np.float64]
    width_px: int
    height_px: int
    rms_px: float
    n_images: int
    pattern: tuple[int, int] = PATTERN_INNER_CORNERS
    square_m: float = SQUARE_M

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.reshape(-1).tolist(),
            "width_px": self.width_px,
            "height_px": self.height_px,
            "rms_px": self.rms_px,
            "n_images": self.n_images,
            "pattern": list(self.pattern),
            "square_m": self.square_m,
        }

    def save(self, path: str | Path) -> Path:
        """Write the calibration file (JSON)."""
        p = Path(path)
        p.write_text(json.dumps(self.to_dict(), indent=2))
        return p

    def intrinsics(self) -> Intrinsics:
        """The calibrated pinhole part (distortion not included)."""
        return Intrinsics.from_matrix(self.camera_matrix, self.width_px, self.height_px)


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration file written by :meth:`Calibration.save`; errors name ``calibration``."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
        k = np.array(d["camera_matrix"], dtype=np.float64)
        dist = np.array(d["dist_coeffs"], dtype=np.float64)
        cal = Calibration(
            k, dist, int(d["width_px"]), int(d["height_px"]), float(d["rms_px"]), int(d["n_images"]),
            tuple(d.get("pattern", PATTERN_INNER_CORNERS)), float(d.get("square_m", SQUARE_M)),
        )  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"calibration: cannot read {p} ({type(exc).__name__}: {exc})") from None
    if k.shape != (3, 3) or not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise ValueError(f"calibration: bad camera_matrix in {p}")
    if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise ValueError(f"calibration: bad dist_coeffs in {p}")
    return cal


def board_points_m(pattern=PATTERN_INNER_CORNERS, square_m: float = SQUARE_M) -> NDArray[np.float32]:
    """Inner-corner positions on the board plane (z = 0), shape (n, 3), m."""
    cols, rows = pattern
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return grid


_CORNER_FLAGS = (
    cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE,
    cv2.CALIB_CB_ADAPTIVE_THRESH,
)
"""``findChessboardCorners`` flags, tried in turn: histogram normalisation helps unevenly lit
photos, but on evenly lit (rendered) boards it loses some steeply tilted views that the
adaptive threshold alone finds (12 against 15 of the lens-calibration experiment's 20 T6 views)."""


def find_corners(image, pattern=PATTERN_INNER_CORNERS) -> NDArray[np.float32] | None:
    """Sub-pixel inner corners of the board in an image, (n, 1, 2) in OpenCV's order, or None.

    (``findChessboardCornersSB`` finds boards as reliably on rendered boards but its corners
    are ~6× less accurate there: 0.15 px RMS against 0.025 px.)
    """
    bgr, _ = as_bgr(image)
    if bgr is None:
        return None
    grey = cv2.cvtColor(to_uint8(bgr), cv2.COLOR_BGR2GRAY)
    for flags in _CORNER_FLAGS:
        found, corners = cv2.findChessboardCorners(grey, pattern, flags=flags)
        if found:
            break
    else:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria)


def calibrate(images, pattern=PATTERN_INNER_CORNERS, square_m: float = SQUARE_M) -> Calibration:
    """Calibrate from checkerboard images (arrays or file paths).

    Raises ``ValueError`` naming ``images`` when the views differ in size or fewer than
    three show the whole board.
    """
    obj, img_pts, size = [], [], None
    for k, item in enumerate(images):
        image = load_image(item) if isinstance(item, str | Path) else item
        bgr, reason = as_bgr(image)
        if bgr is None:
            raise ValueError(f"images[{k}]: {reason}")
        this = (bgr.shape[1], bgr.shape[0])
        if size is not None and this != size:
            raise ValueError(f"images[{k}]: size {this[0]}×{this[1]} differs from image 0's {size[0]}×{size[1]}")
        size = this
        corners = find_corners(bgr, pattern)
        if corners is not None:
            obj.append(board_points_m(pattern, square_m))
            img_pts.append(corners)
    if len(obj) < 3:
        board = f"{pattern[0]}×{pattern[1]} inner corners"
        raise ValueError(f"images: the board ({board}) was found in {len(obj)} view(s), need at least 3")
    rms, k, dist = calibrate_points(obj, img_pts, size)
    return Calibration(k, dist, size[0], size[1], rms, len(obj), tuple(pattern), square_m)


CV_MODELS = {
    "standard": 0,  # k1, k2, p1, p2, k3: calibrateCamera's default (the study's)
    "rational": cv2.CALIB_RATIONAL_MODEL,  # + k4, k5, k6 (radial ratio of sixth-order polynomials)
}
"""``cv2.calibrateCamera`` flags of each distortion model (``fisheye`` is ``cv2.fisheye.calibrate``)."""


def calibrate_points(
    object_points: list[NDArray], image_points: list[NDArray], size: tuple[int, int], model: str = "standard"
) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """Fit a camera model to corner sets: (reprojection RMS px, camera matrix K, distortion coefficients).

    ``model``: ``standard`` or ``rational`` (``cv2.calibrateCamera``), or ``fisheye``
    (``cv2.fisheye.calibrate``, θ_d = θ(1 + k1θ² + … + k4θ⁸)). ``size`` is (width, height), px.
    """
    if model not in (*CV_MODELS, "fisheye"):
        raise ValueError(f"model: expected standard, rational or fisheye, got {model!r}")
    if model == "fisheye":
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-12)
        rms, k, dist, _, _ = cv2.fisheye.calibrate(
            # OpenCV 5.0's fisheye.calibrate accepts only (1, N, C) float32 point sets
            [o.reshape(1, -1, 3).astype(np.float32) for o in object_points],
            [c.reshape(1, -1, 2).astype(np.float32) for c in image_points],
            size,
            np.eye(3),
            np.zeros((4, 1)),
            flags=cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW,  # OpenCV 5: shared calib flags
            criteria=crit,
        )
    elif model == "standard":
        rms, k, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    else:
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-12)
        rms, k, dist, _, _ = cv2.calibrateCamera(
            object_points, image_points, size, None, None, flags=CV_MODELS[model], criteria=crit
        )
    return float(rms), np.asarray(k, dtype=np.float64), np.asarray(dist, dtype=np.float64).reshape(-1)


def new_camera_matrix(cal: Calibration, alpha: float) -> NDArray[np.float64]:
    """``getOptimalNewCameraMatrix`` for the full frame: alpha 0 keeps only valid pixels, 1 keeps all."""
    if not (math.isfinite(alpha) and 0.0 <= alpha <= 1.0):
        raise ValueError(f"alpha: expected a value in [0, 1], got {alpha!r}")
    size = (cal.width_px, cal.height_px)
    new_k, _ = cv2.getOptimalNewCameraMatrix(cal.camera_matrix, cal.dist_coeffs, size, alpha, size)
    return new_k


def undistort(image, cal: Calibration, alpha: float = 0.0, crop_origin_px=(0, 0)) -> tuple[NDArray, Intrinsics]:
    """Undistort a full frame or a crop of it; returns the image and the new full-frame intrinsics.

    The crop keeps its place in the frame: its pixels are the undistorted frame's pixels
    at the same full-frame coordinates.
    """
    new_k = new_camera_matrix(cal, alpha)
    h, w = image.shape[:2]
    u0, v0 = crop_origin_px
    intr = Intrinsics.from_matrix(new_k, cal.width_px, cal.height_px)
    if (w, h, u0, v0) == (cal.width_px, cal.height_px, 0, 0):
        maps = cv2.initUndistortRectifyMap(cal.camera_matrix, cal.dist_coeffs, None, new_k, (w, h), cv2.CV_32FC1)
        return cv2.remap(image, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), intr
    # a crop: the map for its own pixels only, in the undistorted full frame
    uu, vv = np.meshgrid(np.arange(u0, u0 + w, dtype=np.float64), np.arange(v0, v0 + h, dtype=np.float64))
    src = distort_points(np.stack([uu.ravel(), vv.ravel()], 1), cal, new_k)
    map_u = (src[:, 0] - u0).reshape(h, w).astype(np.float32)
    map_v = (src[:, 1] - v0).reshape(h, w).astype(np.float32)
    return cv2.remap(image, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), intr


def distort_points(uv_undistorted, cal: Calibration, new_k: NDArray[np.float64]) -> NDArray[np.float64]:
    """Original-image pixels (n, 2) of pixels in the image undistorted with ``new_k``."""
    uv = np.asarray(uv_undistorted, dtype=np.float64).reshape(-1, 2)
    xn = (uv[:, 0] - new_k[0, 2]) / new_k[0, 0]
    yn = (uv[:, 1] - new_k[1, 2]) / new_k[1, 1]
    pts = np.stack([xn, yn, np.ones_like(xn)], 1)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cal.camera_matrix, cal.dist_coeffs)
    return proj.reshape(-1, 2)
