"""The study's rectification experiment in simulation: a checkerboard through a lens model, calibrated with OpenCV.

The board is the study's (docs/source-study.md §10): 6 × 8 inner corners, 24.4 mm squares, with
a one-square white quiet zone. Its radiance is synthesised as a pinhole image (no
Mitsuba) on a grid wide enough to hold every ray the real lens brings onto the frame,
then passed through :func:`camera_models.optics.optical_image` (distortion, PSF,
relative illumination), so the lens model under test is the one every capture uses.

Poses are spread over the whole frame, corners included: the board's centre is put on
a 3 × 3 grid of image positions pushed out until the board (with its quiet zone)
touches the frame edge, the board faces the camera and is tilted ±30° about its own
axes (two tilts per position), plus two tilted views in the centre. A board seen only
near the centre constrains the distortion only near the centre; OpenCV then
extrapolates.

Calibration: ``cv2.calibrateCamera`` (the study's call) with a selectable distortion
model, or ``cv2.fisheye.calibrate`` for an equidistant (fisheye) lens. The result is
compared with the lens model's own projection r_d(θ) (sensor radius against field
angle, each model about its own principal point) over the field angles the board's
corners actually covered: the distortion curve that rectification uses, in pixels.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from camera_models.camera import Camera, load_camera
from camera_models.optics import RadialMapping, optical_image
from pipeline.calibration import PATTERN_INNER_CORNERS, SQUARE_M, board_points_m, calibrate_points, find_corners
from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance
from scenes.view import CameraGeometry

__all__ = [
    "BLACK",
    "INNER",
    "WHITE",
    "LensCalibration",
    "board_image",
    "board_poses",
    "board_radiance",
    "calibrate",
    "project_true",
    "projection_curves",
    "scaled_camera",
]

INNER = PATTERN_INNER_CORNERS
"""The study's board (docs/source-study.md §10): 8 × 6 inner corners (OpenCV's pattern size), 24.4 mm squares."""
WHITE, BLACK = 1.0, 0.05
"""Relative radiance of the white and black squares (and of the background: black)."""


def scaled_camera(name: str, k: int) -> Camera:
    """``name``'s camera with its pixel grid reduced by an integer factor ``k`` (the lens scaled with it)."""
    cam = load_camera(name)
    g = cam.geometry
    geom = CameraGeometry(
        g.name, g.description, g.width_px // k, g.height_px // k, g.pixel_pitch_um * k, g.focal_length_mm
    )
    lens = dataclasses.replace(cam.lens, blur_sigma_um=cam.lens.blur_sigma_um * k)
    return dataclasses.replace(cam, geometry=geom, lens=lens)


def project_true(camera: Camera, rvec, tvec, points_b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Where the lens model images board points (…, 3): pinhole projection, then the lens's distortion."""
    rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    pc = np.asarray(points_b, dtype=np.float64) @ rot.T + np.asarray(tvec, dtype=np.float64).ravel()
    g = camera.geometry
    cx, cy = g.principal_point_px
    f = g.focal_length_px
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([cx + f * pc[..., 0] / pc[..., 2], cy + f * pc[..., 1] / pc[..., 2]], axis=-1)
    uv[pc[..., 2] <= 0] = np.nan
    return RadialMapping(camera).distort_points_px(uv)


def _quiet_zone_outline(n: int = 24) -> NDArray[np.float64]:
    """Points along the outer edge of the white quiet zone, board frame (m)."""
    lo = -2 * SQUARE_M
    hx, hy = (INNER[0] + 1) * SQUARE_M, (INNER[1] + 1) * SQUARE_M
    t = np.linspace(0.0, 1.0, n)
    xs, ys = lo + t * (hx - lo), lo + t * (hy - lo)
    pts = np.concatenate(
        [
            np.stack([xs, np.full(n, lo)], 1),
            np.stack([xs, np.full(n, hy)], 1),
            np.stack([np.full(n, lo), ys], 1),
            np.stack([np.full(n, hx), ys], 1),
        ]
    )
    return np.concatenate([pts, np.zeros((pts.shape[0], 1))], axis=1)


def _rotation_z_to(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """Smallest rotation taking +z to ``direction`` (unit)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, direction)
    s, c = np.linalg.norm(axis), float(z @ direction)
    if s < 1e-12:
        return np.eye(3)
    rot, _ = cv2.Rodrigues(axis / s * math.atan2(s, c))
    return rot


def board_poses(camera: Camera, fill: float = 0.33, tilt_deg: float = 30.0) -> list[tuple[NDArray, NDArray]]:
    """20 board poses (rvec, tvec) spread over the frame, corners included, each fully inside the frame.

    The board spans about ``fill`` of the frame width (pinhole estimate). For each of
    the 3 × 3 image positions (centre, edge midpoints, corners) the board faces the
    camera, is tilted by ``tilt_deg`` about two different axes and rotated in-plane a
    little, and its centre is put as far toward that position as its quiet zone stays
    inside the frame (1 px margin; searched on a 21 × 21 grid of image positions); two
    more views sit in the centre, tilted the other ways.
    """
    g = camera.geometry
    mapping = RadialMapping(camera)
    cx, cy = g.principal_point_px
    f = g.focal_length_px
    board_w = (INNER[0] + 3) * SQUARE_M
    dist = f * board_w / (fill * g.width_px)
    centre_b = np.array([(INNER[0] - 1) / 2 * SQUARE_M, (INNER[1] - 1) / 2 * SQUARE_M, 0.0])
    outline = _quiet_zone_outline()
    t = math.radians(tilt_deg)
    tilts = [(t, t, 0.1), (-t, -t, -0.1), (t, -t, 0.05), (-t, t, -0.05)]
    # neighbouring positions get the other pair of tilts; the centre gets all four
    plan = [((a, b), tilts[k + 2 * ((a + b) % 2)]) for a in (-1, 0, 1) for b in (-1, 0, 1) for k in range(2)]
    plan += [((0, 0), tilts[2]), ((0, 0), tilts[3])]
    # candidate image positions of the board centre, and the unit ray to each
    fu, fv = np.meshgrid(np.linspace(-0.5, 0.5, 21), np.linspace(-0.5, 0.5, 21))
    fu, fv = fu.ravel(), fv.ravel()
    q = mapping.undistort_points_px(np.stack([cx + fu * g.width_px, cy + fv * g.height_px], axis=-1))
    rays = np.stack([(q[:, 0] - cx) / f, (q[:, 1] - cy) / f, np.ones(fu.size)], axis=-1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    out = []
    for (a, b), tilt in plan:
        r_tilt, _ = cv2.Rodrigues(np.array(tilt))
        rots = np.stack([_rotation_z_to(r) @ r_tilt for r in rays])
        tvecs = dist * rays - rots @ centre_b
        pc = np.einsum("nij,kj->nki", rots, outline) + tvecs[:, None, :]
        uv = mapping.distort_points_px(
            np.stack([cx + f * pc[..., 0] / pc[..., 2], cy + f * pc[..., 1] / pc[..., 2]], axis=-1)
        )
        ok = np.all(pc[..., 2] > 0, axis=1) & np.all(np.isfinite(uv), axis=(1, 2))
        ok &= (uv[..., 0].min(axis=1) >= 1) & (uv[..., 0].max(axis=1) <= g.width_px - 2)
        ok &= (uv[..., 1].min(axis=1) >= 1) & (uv[..., 1].max(axis=1) <= g.height_px - 2)
        if not ok.any():
            continue
        reach = a * fu + b * fv - 1e-3 * np.hypot(fu, fv)  # furthest toward (a, b); the centre itself for (0, 0)
        i = int(np.argmax(np.where(ok, reach, -np.inf)))
        rvec, _ = cv2.Rodrigues(rots[i])
        out.append((rvec.reshape(3, 1), tvecs[i].reshape(3, 1)))
    return out


def _synthesis_grid(camera: Camera, box: tuple[int, int, int, int], oversampling: int) -> PixelGrid:
    """A pixel grid holding the frame box (x0, y0, x1, y1) and the pinhole position of each of its pixels.

    The lens resamples the pinhole render at the undistorted position of every sensor
    sub-pixel, on the same grid: with barrel or fisheye distortion those lie outside
    the box, so the grid reaches beyond it (and beyond the frame where needed).
    """
    g = camera.geometry
    bx0, by0, bx1, by1 = box
    n = 64
    us, vs = np.linspace(bx0 - 0.5, bx1 - 0.5, n), np.linspace(by0 - 0.5, by1 - 0.5, n)
    edge = np.concatenate(
        [
            np.stack([us, np.full(n, by0 - 0.5)], 1),
            np.stack([us, np.full(n, by1 - 0.5)], 1),
            np.stack([np.full(n, bx0 - 0.5), vs], 1),
            np.stack([np.full(n, bx1 - 0.5), vs], 1),
        ]
    )
    und = RadialMapping(camera).undistort_points_px(edge)
    x0 = min(bx0, math.floor(np.nanmin(und[:, 0])) - 2)
    y0 = min(by0, math.floor(np.nanmin(und[:, 1])) - 2)
    x1 = max(bx1, math.ceil(np.nanmax(und[:, 0])) + 3)
    y1 = max(by1, math.ceil(np.nanmax(und[:, 1])) + 3)
    return PixelGrid(
        g.width_px, g.height_px, g.focal_length_px, g.principal_point_px, x0, y0, x1 - x0, y1 - y0, oversampling
    )


def _ramp(distance, width):
    return np.clip(0.5 + distance / (2.0 * width), 0.0, 1.0)


def board_radiance(camera: Camera, rvec, tvec, grid: PixelGrid) -> SpectralRadiance:
    """Pinhole radiance of the board at pose (rvec, tvec) on ``grid``.

    Square edges are anti-aliased (a linear ramp one sub-pixel footprint wide), the
    quiet zone is white, the background black.
    """
    g = camera.geometry
    u, v = grid.subpixel_centres_px()
    rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    cx, cy = g.principal_point_px
    f = g.focal_length_px
    d = np.stack(np.broadcast_arrays((u[None, :] - cx) / f, (v[:, None] - cy) / f, np.ones((1, 1))), axis=-1)
    d_b = d @ rot  # rows: rot.T @ d
    o_b = -rot.T @ np.asarray(tvec, dtype=np.float64).ravel()
    t = -o_b[2] / d_b[..., 2]
    x, y = o_b[0] + t * d_b[..., 0], o_b[1] + t * d_b[..., 1]
    # board-frame size of one sub-pixel (for the anti-aliasing ramp)
    w = 0.5 * (np.abs(np.gradient(x, axis=1)) + np.abs(np.gradient(x, axis=0)))
    w += 0.5 * (np.abs(np.gradient(y, axis=1)) + np.abs(np.gradient(y, axis=0)))
    w = np.maximum(0.5 * w, 1e-9)

    def square_wave(c):
        phase = c / SQUARE_M
        frac = phase - np.floor(phase)
        dist = np.minimum(frac, 1.0 - frac) * SQUARE_M
        sign = np.where(np.floor(phase) % 2 == 0, 1.0, -1.0)
        return sign * np.clip(dist / w, 0.0, 1.0)

    lo, hx, hy = -SQUARE_M, INNER[0] * SQUARE_M, INNER[1] * SQUARE_M
    inside = _ramp(np.minimum(x - lo, hx - x), w) * _ramp(np.minimum(y - lo, hy - y), w)
    blackness = 0.5 * (1.0 - square_wave(x) * square_wave(y)) * inside
    in_board = _ramp(np.minimum(x - (lo - SQUARE_M), hx + SQUARE_M - x), w)
    in_board = in_board * _ramp(np.minimum(y - (lo - SQUARE_M), hy + SQUARE_M - y), w) * (t > 0)
    image = BLACK + (WHITE - BLACK) * in_board * (1.0 - blackness)
    comp = RadianceComponent("ambient", image.astype(np.float32), spectra.illuminant_shape("D65"))
    return SpectralRadiance(grid, (comp,), {}, "synthetic")


def board_image(camera: Camera, rvec, tvec, oversampling: int = 2) -> NDArray[np.uint8]:
    """8-bit green-channel frame of the board through the lens model (white squares at ~250).

    Only the board's neighbourhood is rendered (its quiet zone's box + 8 px); the rest of
    the frame takes the median of that box's outer ring (the black background).
    """
    g = camera.geometry
    uv = project_true(camera, rvec, tvec, _quiet_zone_outline())
    m = 8
    box = (
        max(0, math.floor(np.nanmin(uv[:, 0])) - m),
        max(0, math.floor(np.nanmin(uv[:, 1])) - m),
        min(g.width_px, math.ceil(np.nanmax(uv[:, 0])) + m + 1),
        min(g.height_px, math.ceil(np.nanmax(uv[:, 1])) + m + 1),
    )
    grid = _synthesis_grid(camera, box, oversampling)
    opt = optical_image(board_radiance(camera, rvec, tvec, grid), camera, 1e-2)
    bx0, by0, bx1, by1 = box
    crop = opt.electrons_rgb[by0 - opt.y0 : by1 - opt.y0, bx0 - opt.x0 : bx1 - opt.x0, 1]
    ring = np.concatenate([crop[0], crop[-1], crop[:, 0], crop[:, -1]])
    frame = np.full((g.height_px, g.width_px), np.median(ring))
    frame[by0:by1, bx0:bx1] = crop
    return np.clip(250.0 * frame / np.percentile(crop, 99.5), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class LensCalibration:
    """What OpenCV recovered, and how it compares with the lens model.

    Attributes
    ----------
    camera
        Camera name.
    views, views_tried
        Views where the board was found / rendered.
    rms_px
        OpenCV's reprojection RMS, pixels of the calibrated image.
    K, D
        Camera matrix and distortion coefficients.
    focal_error
        (mean of fx, fy) / true paraxial focal − 1.
    covered_radius_px
        Largest distance of a detected corner from the principal point.
    curve_max_diff_px, curve_rms_diff_px
        Difference of the radial projection r_d(θ) (OpenCV's model vs the lens model),
        max and RMS over field angles up to the covered radius, pixels of the calibrated image.
    """

    camera: str
    model: str
    views: int
    views_tried: int
    rms_px: float
    K: NDArray[np.float64]
    D: NDArray[np.float64]
    focal_error: float
    covered_radius_px: float
    covered_fraction_of_half_diagonal: float
    curve_max_diff_px: float
    curve_rms_diff_px: float


def projection_curves(camera: Camera, K, D, fisheye: bool, r_max_px: float, n: int = 64):
    """(θ, r_true, r_opencv): sensor radius against field angle up to the lens model's radius ``r_max_px``.

    OpenCV's radius is measured about its own principal point and averaged over 8 azimuths
    (its fx ≠ fy and tangential terms make it slightly non-radial).
    """
    g = camera.geometry
    mapping = RadialMapping(camera)
    theta_max = float(mapping.field_angle_rad(np.array([r_max_px]))[0])
    theta = np.linspace(theta_max / n, theta_max, n)
    r_true = mapping.distorted_radius_px(g.focal_length_px * np.tan(theta))
    phi = np.arange(8) * math.pi / 4
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    obj = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1).reshape(-1, 1, 3)
    zero = np.zeros((3, 1))
    if fisheye:
        img, _ = cv2.fisheye.projectPoints(obj, zero, zero, K, D)
    else:
        img, _ = cv2.projectPoints(obj, zero, zero, K, D)
    img = img.reshape(theta.size, phi.size, 2)
    r_cv = np.hypot(img[..., 0] - K[0, 2], img[..., 1] - K[1, 2]).mean(axis=1)
    return theta, r_true, r_cv


def calibrate(camera: Camera, model: str = "rational", oversampling: int = 2, poses=None) -> LensCalibration:
    """Render the board in every pose, find it, calibrate with OpenCV and compare with the lens model.

    ``model`` is ``standard`` or ``rational`` (``cv2.calibrateCamera``) or ``fisheye``
    (``cv2.fisheye.calibrate``, 4 coefficients of θ_d = θ(1 + k1θ² + … + k4θ⁸)).
    """
    g = camera.geometry
    poses = board_poses(camera) if poses is None else poses
    objp = board_points_m(INNER, SQUARE_M)
    obj_pts, img_pts = [], []
    for rvec, tvec in poses:
        corners = find_corners(board_image(camera, rvec, tvec, oversampling), INNER)
        if corners is not None:
            obj_pts.append(objp)
            img_pts.append(corners)
    if len(obj_pts) < 5:
        raise RuntimeError(f"{camera.name}: board found in only {len(obj_pts)} of {len(poses)} views")
    rms, K, D = calibrate_points(obj_pts, img_pts, (g.width_px, g.height_px), model)
    cx, cy = g.principal_point_px
    pts = np.concatenate(img_pts).reshape(-1, 2)
    covered = float(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy).max())
    _, r_true, r_cv = projection_curves(camera, K, D, model == "fisheye", covered)
    diff = r_cv - r_true
    return LensCalibration(
        camera=camera.name,
        model=model,
        views=len(obj_pts),
        views_tried=len(poses),
        rms_px=rms,
        K=K,
        D=np.ravel(D),
        focal_error=float(0.5 * (K[0, 0] + K[1, 1]) / g.focal_length_px - 1.0),
        covered_radius_px=covered,
        covered_fraction_of_half_diagonal=covered / (0.5 * math.hypot(g.width_px, g.height_px)),
        curve_max_diff_px=float(np.abs(diff).max()),
        curve_rms_diff_px=float(np.sqrt(np.mean(diff**2))),
    )
