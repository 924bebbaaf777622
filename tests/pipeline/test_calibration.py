"""Checkerboard calibration on synthetic views of a known camera; undistortion; calibration files."""

from __future__ import annotations

import json
from functools import lru_cache

import cv2
import numpy as np
import pytest

from pipeline.calibration import (
    SQUARE_M,
    Calibration,
    board_points_m,
    calibrate,
    distort_points,
    load_calibration,
    new_camera_matrix,
    undistort,
)

SIZE = (640, 480)
K_TRUE = np.array([[610.0, 0.0, 322.5], [0.0, 605.0, 236.0], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.21, 0.06, 0.0005, -0.0004, 0.0])


@lru_cache(maxsize=4)
def _pixel_rays(supersample: int) -> list[np.ndarray]:
    """Normalised, undistorted ray directions of every sub-pixel (the same for every view)."""
    w, h = SIZE
    offs = (np.arange(supersample) + 0.5) / supersample - 0.5
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
    rays = []
    for ou in offs:
        for ov in offs:
            pix = np.stack([(uu + ou).ravel(), (vv + ov).ravel()], 1).reshape(-1, 1, 2)
            xn = cv2.undistortPoints(pix, K_TRUE, D_TRUE, criteria=crit).reshape(-1, 2)
            rays.append(np.column_stack([xn, np.ones(len(xn))]))
    return rays


def _render_board(rvec, tvec, supersample=2):
    """Image of the 8 × 6 inner-corner board seen by (K_TRUE, D_TRUE): ray-cast every sub-pixel."""
    w, h = SIZE
    rot = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    t = np.asarray(tvec, dtype=np.float64)
    acc = np.zeros((h, w))
    for d in _pixel_rays(supersample):
        # ray λ d meets the board plane z_b = 0: (Rᵀ(λ d − t))_z = 0
        lam = (rot.T @ t)[2] / (d @ rot[:, 2])
        pb = (lam[:, None] * d - t) @ rot  # = Rᵀ(λ d − t)
        sx, sy = pb[:, 0] / SQUARE_M, pb[:, 1] / SQUARE_M
        on_board = (sx > -1) & (sx < 8) & (sy > -1) & (sy < 6)
        black = on_board & ((np.floor(sx).astype(int) + np.floor(sy).astype(int)) % 2 == 0)
        border = (sx > -2) & (sx < 9) & (sy > -2) & (sy < 7)
        acc += np.where(black, 0.05, np.where(border, 0.95, 0.4)).reshape(h, w)
    img = np.round(acc / supersample**2 * 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)


def _views():
    rng = np.random.default_rng(3)
    views = []
    for k in range(12):
        rvec = np.array([rng.uniform(-0.45, 0.45), rng.uniform(-0.45, 0.45), rng.uniform(-0.2, 0.2)])
        centre = np.array([3.5, 2.5, 0.0]) * SQUARE_M
        rot = cv2.Rodrigues(rvec)[0]
        target = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.06, 0.06), 0.42 + 0.02 * k])
        tvec = target - rot @ centre  # board centre lands at target
        views.append((rvec, tvec))
    return views


@pytest.fixture(scope="module")
def board_images():
    return [_render_board(r, t) for r, t in _views()]


def test_calibration_recovers_the_camera(board_images, tmp_path):
    cal = calibrate(board_images)
    assert cal.n_images == len(board_images)
    assert cal.rms_px < 0.3  # 8-bit, 2×2-supersampled edges
    k = cal.camera_matrix
    assert abs(k[0, 0] / K_TRUE[0, 0] - 1) < 5e-3 and abs(k[1, 1] / K_TRUE[1, 1] - 1) < 5e-3
    assert np.allclose(k[:2, 2], K_TRUE[:2, 2], atol=3.0)  # the principal point is the loosest parameter
    # distortion: compare the mapping, not the (correlated) coefficients
    # within the part of the frame the views cover (the model extrapolates poorly beyond)
    grid = np.stack(np.meshgrid(np.linspace(160, 480, 9), np.linspace(120, 360, 7)), -1).reshape(-1, 1, 2)
    # the distortion correction (pixel displacement) of each model, in pixels
    true_shift = cv2.undistortPoints(grid, K_TRUE, D_TRUE, P=K_TRUE) - grid
    got_shift = cv2.undistortPoints(grid, cal.camera_matrix, cal.dist_coeffs, P=cal.camera_matrix) - grid
    assert np.abs(true_shift).max() > 3.0  # the lens distorts noticeably there
    assert np.abs(true_shift - got_shift).max() < 0.5
    again = load_calibration(cal.save(tmp_path / "cal.json"))
    assert np.array_equal(again.camera_matrix, cal.camera_matrix) and again.n_images == cal.n_images


@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_undistort_straightens_and_points_map_back(alpha):
    cal = Calibration(K_TRUE, D_TRUE, *SIZE, 0.0, 0)
    rvec, tvec = _views()[0]
    img = _render_board(rvec, tvec)
    flat, intr = undistort(img, cal, alpha)
    new_k = new_camera_matrix(cal, alpha)
    assert np.allclose(intr.matrix(), new_k)
    # the board's corners in the undistorted image are the pinhole projection with new_k
    found, corners = cv2.findChessboardCorners(cv2.cvtColor(flat, cv2.COLOR_BGR2GRAY), (8, 6))
    assert found
    corners = cv2.cornerSubPix(
        cv2.cvtColor(flat, cv2.COLOR_BGR2GRAY), corners, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS, 0, 1e-4)
    ).reshape(-1, 2)
    pin, _ = cv2.projectPoints(board_points_m(), rvec, tvec, new_k, None)
    pin = pin.reshape(-1, 2)
    d = np.hypot(*(corners[:, None] - pin[None]).transpose(2, 0, 1)).min(axis=1)
    assert d.max() < 0.5
    # and distort_points takes them back to the original image's projection
    orig, _ = cv2.projectPoints(board_points_m(), rvec, tvec, K_TRUE, D_TRUE)
    assert np.allclose(distort_points(pin, cal, new_k), orig.reshape(-1, 2), atol=1e-6)
    # a crop undistorts to the same pixels as the full frame, away from its edges (which need
    # source pixels outside the crop)
    crop, _ = undistort(img[100:300, 200:450], cal, alpha, crop_origin_px=(200, 100))
    assert np.abs(crop[12:-12, 12:-12].astype(int) - flat[112:288, 212:438].astype(int)).max() <= 2


def test_too_few_views_and_bad_files(tmp_path):
    blank = np.full((480, 640, 3), 128, np.uint8)
    with pytest.raises(ValueError, match=r"^images: the board .* 0 view"):
        calibrate([blank, blank, blank])
    with pytest.raises(ValueError, match=r"^images\[1\]: size"):
        calibrate([blank, blank[:100]])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"camera_matrix": [[1, 0], [0, 1]]}))
    with pytest.raises(ValueError, match=r"^calibration:"):
        load_calibration(bad)
    with pytest.raises(ValueError, match=r"^calibration:"):
        load_calibration(tmp_path / "missing.json")


def test_detect_with_a_calibration_undoes_lens_distortion():
    """Markers drawn where a distorting lens puts them: with the calibration the pose is right."""
    from pipeline.angles import Intrinsics
    from pipeline.detect import detect
    from pipeline.frames import pose_from_scenario
    from scenes.scenario import Scenario
    from scenes.view import camera_geometry
    from tests.helpers.synthetic import draw_markers

    camera = "logitech-c270"
    g = camera_geometry(camera)
    k = g.intrinsics()
    dist = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    cal = Calibration(k, dist, g.width_px, g.height_px, 0.0, 0)
    sc = Scenario(camera=camera, range_m=2.0, yaw_deg=15.0)
    pose = pose_from_scenario(sc)
    # turn the camera about its centre so the target images near the top-right corner
    turn = cv2.Rodrigues(np.array([np.radians(9.0), np.radians(20.0), 0.0]))[0]
    rvec = cv2.Rodrigues(turn @ pose.cv_from_t)[0]
    tvec = turn @ pose.t_cv_m
    uv, _ = cv2.projectPoints(sc.design.marker_positions_m(), rvec, tvec, k, dist)
    uv = uv.reshape(-1, 2)
    assert uv[:, 0].max() > 1000 and uv[:, 1].min() < 200  # far off-centre, where distortion is large
    img = draw_markers((g.height_px, g.width_px), uv, (0.03, 0.06, 1.0), 1.5, peak=0.9)
    for alpha in (0.0, 1.0):
        out = detect(img, Intrinsics.from_geometry(g), calibration=cal, alpha=alpha).to_dict()
        assert out["side"] == "red", out["reason"]
        got = np.array([[m["u"], m["v"]] for m in out["markers"]])
        assert np.abs(got - uv).max() < 0.15  # reported in the original (distorted) image
        assert abs(out["range_m"] - 2.0) < 0.004
    plain = detect(img, Intrinsics.from_geometry(g)).to_dict()
    print(f"\nrange error with calibration {out['range_m'] - 2.0:+.5f} m, without {plain['range_m'] - 2.0:+.5f} m")
    assert abs(plain["range_m"] - 2.0) > 5 * abs(out["range_m"] - 2.0)
