"""Checkerboard camera calibration and undistortion (docs/source-study.md §10).

The study calibrated with a board of 6 × 8 inner corners and 24.4 mm squares, 46 to 299
photos, OpenCV ``calibrateCamera``, and undistorted with alpha 0 (only valid pixels,
cropped) and alpha 1 (all source pixels kept, black borders). Here:

* :func:`find_corners` finds the inner corners (``findChessboardCorners`` +
  ``cornerSubPix``) and :func:`calibrate_points` fits a distortion model to corner sets
  (``standard`` k1, k2, p1, p2, k3 as the study; ``rational``; ``fisheye``);
* :func:`calibrate` does both on photos (the study's model) and returns a :class:`Calibration`;
  it refuses degenerate sets (the same view twice, too few board orientations) and warns
  about implausible results (principal point far from the centre, fx ≠ fy);
* :meth:`Calibration.save` / :func:`load_calibration` use a JSON file;
* :func:`undistort` remaps an image (full frame or a crop) with
  ``getOptimalNewCameraMatrix(alpha)`` and returns the new intrinsics, and
  :func:`distort_points` maps pixels of the undistorted image back to the original.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics
from pipeline.image_io import as_bgr, load_image, to_uint8

__all__ = [
    "ASPECT_WARN",
    "CV_MODELS",
    "DIST_COEFF_COUNTS",
    "DUPLICATE_MIN_PX",
    "DUPLICATE_REL",
    "MIN_ORIENTATIONS",
    "MIN_ORIENTATION_DEG",
    "PATTERN_INNER_CORNERS",
    "PRINCIPAL_POINT_WARN",
    "SQUARE_M",
    "Calibration",
    "board_normals",
    "board_points_m",
    "calibrate",
    "calibrate_points",
    "calibration_warnings",
    "check_dist_coeffs",
    "check_pattern",
    "corner_set_difference_px",
    "distort_points",
    "find_corners",
    "load_calibration",
    "new_camera_matrix",
    "orientation_groups",
    "undistort",
]

PATTERN_INNER_CORNERS = (8, 6)
"""Inner corners per row and per column of the study's board (6 × 8)."""

SQUARE_M = 0.0244
"""Square size of the study's board, m."""

DIST_COEFF_COUNTS = (4, 5, 8, 12, 14)
"""Lengths of an OpenCV distortion vector: (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, τx, τy]]]])."""

DUPLICATE_REL = 0.01
"""Two views whose corners differ by less than this fraction of the board's diagonal in the
image (RMS over the corners, and at least :data:`DUPLICATE_MIN_PX`) are the same view:
the same photo twice, or two shots without moving the board or the camera."""

DUPLICATE_MIN_PX = 0.5
"""Floor of the duplicate tolerance, px (corner noise of two shots of a still board is ~0.1 px)."""

MIN_ORIENTATION_DEG = 5.0
"""Board planes whose normals differ by less than this count as one orientation, degrees."""

MIN_ORIENTATIONS = 3
"""Distinct board orientations needed: parallel boards (any translation, any turn in their
own plane, e.g. all facing the camera squarely) leave the focal length undetermined
(Zhang 2000, §3.3); three orientations pin down the focal lengths and the principal point."""

PRINCIPAL_POINT_WARN = 0.10
"""Warn when the principal point is farther than this fraction of the width (height) from the centre."""

ASPECT_WARN = 0.05
"""Warn when fx and fy differ by more than this fraction (pixels of almost every camera are square)."""


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
    warnings
        One-line doubts about the result (see :func:`calibrate`).
    """

    camera_matrix: NDArray[np.float64]
    dist_coeffs: NDArray[np.float64]
    width_px: int
    height_px: int
    rms_px: float
    n_images: int
    pattern: tuple[int, int] = PATTERN_INNER_CORNERS
    square_m: float = SQUARE_M
    warnings: tuple[str, ...] = ()

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
            "warnings": list(self.warnings),
        }

    def save(self, path: str | Path) -> Path:
        """Write the calibration file (JSON)."""
        p = Path(path)
        p.write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False))  # standard JSON: every field is finite
        return p

    def intrinsics(self) -> Intrinsics:
        """The calibrated pinhole part (distortion not included)."""
        return Intrinsics.from_matrix(self.camera_matrix, self.width_px, self.height_px)

    def resized_to(self, width_px: int, height_px: int) -> Calibration | None:
        """This calibration for a resized copy of its frame (``width_px`` × ``height_px``), or None.

        The camera matrix scales as :meth:`pipeline.angles.Intrinsics.resized_to` does; the
        distortion coefficients act on normalised coordinates and are unchanged; the RMS
        scales with the image. None when the size is not the frame resized by one factor.
        """
        intr = self.intrinsics().resized_to(width_px, height_px)
        if intr is None:
            return None
        rms = self.rms_px * width_px / self.width_px
        return Calibration(
            intr.matrix(), self.dist_coeffs.copy(), int(width_px), int(height_px), rms, self.n_images,
            self.pattern, self.square_m, self.warnings,
        )  # fmt: skip

    @classmethod
    def from_intrinsics(cls, intrinsics: Intrinsics, dist_coeffs) -> Calibration:
        """A calibration from known values (no fit: RMS 0, no views), e.g. a lens's published distortion.

        Raises ``ValueError`` naming ``dist`` when the coefficients are not 4, 5, 8, 12 or 14 finite numbers.
        """
        dist = check_dist_coeffs(dist_coeffs)
        return cls(intrinsics.matrix(), dist, intrinsics.width_px, intrinsics.height_px, 0.0, 0)


def check_dist_coeffs(values, field: str = "dist") -> NDArray[np.float64]:
    """OpenCV distortion coefficients as a float array, or ``ValueError`` naming ``field``."""
    try:
        dist = np.asarray(values, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{field}: expected numbers k1,k2,p1,p2[,k3], got {values!r}") from None
    if dist.size not in DIST_COEFF_COUNTS or not np.all(np.isfinite(dist)):
        counts = ", ".join(map(str, DIST_COEFF_COUNTS))
        raise ValueError(f"{field}: expected {counts} finite coefficients (k1,k2,p1,p2[,k3]), got {dist.tolist()}")
    return dist


def check_pattern(pattern) -> tuple[int, int]:
    """A board's inner corners (per row, per column) as integers of at least 3 (OpenCV's minimum)."""
    try:
        cols, rows = (int(p) for p in pattern)
        ok = (cols, rows) == tuple(pattern)
    except (TypeError, ValueError):
        ok = False
    if not ok or not (3 <= cols <= 200 and 3 <= rows <= 200):
        raise ValueError(f"pattern: expected inner corners per row and per column, 3 to 200 each, got {pattern!r}")
    return cols, rows


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
            tuple(str(w) for w in d.get("warnings", ())),
        )  # fmt: skip
    except RecursionError:
        raise ValueError(f"calibration: cannot read {p} (JSON nested too deep for a calibration file)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"calibration: cannot read {p} ({type(exc).__name__}: {exc})") from None
    if k.shape != (3, 3) or not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise ValueError(f"calibration: bad camera_matrix in {p}")
    if dist.size not in DIST_COEFF_COUNTS or not np.all(np.isfinite(dist)):
        raise ValueError(f"calibration: bad dist_coeffs in {p}")
    if cal.width_px < 1 or cal.height_px < 1:
        raise ValueError(f"calibration: bad image size {cal.width_px}×{cal.height_px} px in {p}")
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


def calibrate(
    images,
    pattern=PATTERN_INNER_CORNERS,
    square_m: float = SQUARE_M,
    *,
    resize: float | None = None,
    names: Sequence[str] | None = None,
) -> Calibration:
    """Calibrate from checkerboard images (arrays or file paths), the study's model.

    Parameters
    ----------
    images
        BGR arrays or image files, all the same size.
    pattern
        Inner corners per row and per column (at least 3 each).
    square_m
        Square size, m.
    resize
        Search for the board on a copy resized by this factor in (0, 1] (faster on large
        photos); the corners are then refined, and the camera calibrated, at full size.
        None or 1: full size.
    names
        What to call each image in messages (default: file names, or ``image k``).

    Returns
    -------
    Calibration
        With ``warnings`` when the principal point lies more than 10 % of the width
        (height) from the centre, or fx and fy differ by more than 5 %.

    Raises
    ------
    ValueError
        One line naming the field: ``pattern``, ``square_m``, ``resize``;
        ``images[k]`` for an unreadable image or one of another size; ``images`` when
        fewer than three views show the whole board, when two views are the same
        (corner sets within 1 % of the board's size, e.g. the same photo twice), or when
        the board has fewer than :data:`MIN_ORIENTATIONS` orientations 5° apart.
    """
    pattern = check_pattern(pattern)
    if not 0 < _number(square_m) < math.inf:
        raise ValueError(f"square_m: expected a square size > 0 m, got {square_m!r}")
    _check_resize(resize)
    images = list(images)
    labels = list(names) if names is not None else [_label(item, k) for k, item in enumerate(images)]
    found: list[tuple[int, NDArray[np.float32]]] = []
    size = None
    for k, item in enumerate(images):
        image = load_image(item) if isinstance(item, str | Path) else item
        bgr, reason = as_bgr(image)
        if bgr is None:
            raise ValueError(f"images[{k}]: {reason}")
        this = (bgr.shape[1], bgr.shape[0])
        if size is not None and this != size:
            raise ValueError(f"images[{k}]: size {this[0]}×{this[1]} differs from image 0's {size[0]}×{size[1]}")
        size = this
        corners = _find_corners_resized(bgr, pattern, resize)
        if corners is not None:
            found.append((k, corners))
    if len(found) < 3:
        board = f"{pattern[0]}×{pattern[1]} inner corners"
        raise ValueError(f"images: the board ({board}) was found in {len(found)} view(s), need at least 3")
    _refuse_duplicates(found, labels)
    obj = [board_points_m(pattern, square_m) for _ in found]
    img_pts = [c for _, c in found]
    try:
        rms, k, dist = calibrate_points(obj, img_pts, size)
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"images: OpenCV could not calibrate from these {len(found)} views ({detail})") from None
    # the board planes seen with the fitted lens, or with a nominal one when the fit is degenerate
    plausible = _plausible_camera(k, size)
    groups = orientation_groups(
        board_normals(obj, img_pts, k if plausible else _nominal_k(size), dist if plausible else np.zeros(5))
    )
    if len(groups) < MIN_ORIENTATIONS:
        raise ValueError(
            f"images: the board has {len(groups)} distinct orientation(s) in {len(found)} views (board planes at "
            f"least {MIN_ORIENTATION_DEG:g}° apart; need {MIN_ORIENTATIONS}): tilt the board differently, "
            "e.g. ±30° about each of its axes, not only shifted or turned in its own plane"
        )
    cal = Calibration(k, dist, size[0], size[1], rms, len(found), pattern, float(square_m))
    return replace(cal, warnings=calibration_warnings(cal))


def _label(item, k: int) -> str:
    return Path(item).name if isinstance(item, str | Path) else f"image {k}"


def _number(value) -> float:
    """``value`` as a float, or NaN when it is not a real number (bools included)."""
    if isinstance(value, bool | str):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _check_resize(resize: float | None) -> None:
    if resize is None:
        return
    if not 0 < _number(resize) <= 1:
        raise ValueError(f"resize: expected a scale in (0, 1], got {resize!r}")


def _find_corners_resized(bgr: NDArray, pattern: tuple[int, int], resize: float | None) -> NDArray[np.float32] | None:
    """:func:`find_corners`, searching on a copy resized by ``resize`` and refining at full size."""
    if resize is None or resize == 1:
        return find_corners(bgr, pattern)
    small = cv2.resize(to_uint8(bgr), None, fx=resize, fy=resize, interpolation=cv2.INTER_AREA)
    corners = find_corners(small, pattern)
    if corners is None:
        return None
    full = ((corners.astype(np.float64) + 0.5) / resize - 0.5).astype(np.float32)  # pixel centres aligned
    grey = cv2.cvtColor(to_uint8(bgr), cv2.COLOR_BGR2GRAY)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(grey, full, (5, 5), (-1, -1), criteria)


def corner_set_difference_px(a: NDArray, b: NDArray) -> float:
    """RMS distance between two views' corners, px, in the same order or reversed.

    A board with an even number of corners per row and column looks the same turned by
    180°, so OpenCV may number the same corners from either end.
    """
    pa, pb = np.asarray(a, np.float64).reshape(-1, 2), np.asarray(b, np.float64).reshape(-1, 2)
    same = np.sqrt(np.mean(np.sum((pa - pb) ** 2, axis=1)))
    turned = np.sqrt(np.mean(np.sum((pa - pb[::-1]) ** 2, axis=1)))
    return float(min(same, turned))


def _refuse_duplicates(found: list[tuple[int, NDArray]], labels: list[str]) -> None:
    for i, (ka, ca) in enumerate(found):
        diag = float(np.hypot(*np.ptp(ca.reshape(-1, 2), axis=0)))
        tol = max(DUPLICATE_MIN_PX, DUPLICATE_REL * diag)
        for kb, cb in found[i + 1 :]:
            d = corner_set_difference_px(ca, cb)
            if d < tol:
                raise ValueError(
                    f"images: views {ka} and {kb} ({labels[ka]}, {labels[kb]}) show the board in the same place "
                    f"(corners {d:.2f} px RMS apart, under {tol:.2f} px): a repeated view adds nothing; remove one"
                )


def _nominal_k(size: tuple[int, int]) -> NDArray[np.float64]:
    """A normal lens for a ``size`` (W, H) px image: f = max(W, H) px (53° across), principal point at the centre."""
    f = float(max(size))
    return np.array([[f, 0.0, (size[0] - 1) / 2], [0.0, f, (size[1] - 1) / 2], [0.0, 0.0, 1.0]])


def _plausible_camera(k: NDArray[np.float64], size: tuple[int, int]) -> bool:
    """A fitted K that is a camera at all: f of 0.1 to 20 image sizes, nearly square pixels, centre in the image."""
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    if not np.all(np.isfinite(k)) or fx <= 0 or fy <= 0:
        return False
    ok_f = all(0.1 <= f / max(size) <= 20.0 for f in (fx, fy)) and abs(fx / fy - 1) < 0.5
    return bool(ok_f and 0 <= cx <= size[0] and 0 <= cy <= size[1])


def board_normals(object_points, image_points, k: NDArray[np.float64], dist: NDArray[np.float64]) -> NDArray:
    """Unit normals (n, 3) of the board plane in each view, camera frame (``solvePnP`` with K and dist).

    The iterative solver (homography start, Levenberg–Marquardt), not IPPE: on a board
    nearly facing the camera IPPE may return the mirror pose, ~2° off.
    """
    normals = []
    for obj, img in zip(object_points, image_points, strict=True):
        _, rvec, _ = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        normals.append(cv2.Rodrigues(rvec)[0][:, 2])
    return np.asarray(normals)


def orientation_groups(normals, min_angle_deg: float = MIN_ORIENTATION_DEG) -> list[list[int]]:
    """Views grouped by board orientation: a view joins the first group whose first view's
    plane is within ``min_angle_deg`` (the sign of a normal is ignored)."""
    groups: list[list[int]] = []
    cos_min = math.cos(math.radians(min_angle_deg))
    n = np.asarray(normals, dtype=np.float64)
    for i, v in enumerate(n):
        for g in groups:
            if abs(float(n[g[0]] @ v)) >= cos_min:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def calibration_warnings(cal: Calibration) -> tuple[str, ...]:
    """One-line doubts about a calibration: principal point far from the centre, fx ≠ fy."""
    k = cal.camera_matrix
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    out = []
    dx, dy = cx - (cal.width_px - 1) / 2, cy - (cal.height_px - 1) / 2
    if abs(dx) > PRINCIPAL_POINT_WARN * cal.width_px or abs(dy) > PRINCIPAL_POINT_WARN * cal.height_px:
        out.append(
            f"principal point ({cx:.1f}, {cy:.1f}) px is {100 * abs(dx) / cal.width_px:.0f} % of the width and "
            f"{100 * abs(dy) / cal.height_px:.0f} % of the height from the centre (usually under "
            f"{100 * PRINCIPAL_POINT_WARN:.0f} %): the views may not constrain it; add tilted views near the corners"
        )
    if abs(fx / fy - 1) > ASPECT_WARN:
        out.append(
            f"fx {fx:.1f} px and fy {fy:.1f} px differ by {100 * abs(fx / fy - 1):.0f} % (pixels are square on "
            "almost every camera): the views may not constrain the focal length; add views tilted about each axis"
        )
    return tuple(out)


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
