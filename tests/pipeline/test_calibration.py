"""Checkerboard calibration on synthetic views of a known camera; undistortion; calibration files."""

from __future__ import annotations

import json
from functools import lru_cache

import cv2
import numpy as np
import pytest

from pipeline.angles import Intrinsics, intrinsics_from_values, resize_scales
from pipeline.calibration import (
    SQUARE_M,
    Calibration,
    board_points_m,
    calibrate,
    calibration_warnings,
    check_dist_coeffs,
    corner_set_difference_px,
    distort_points,
    load_calibration,
    new_camera_matrix,
    orientation_groups,
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
    assert cal.warnings == ()  # a good set: principal point near the centre, fx ≈ fy
    again = load_calibration(cal.save(tmp_path / "cal.json"))
    assert np.array_equal(again.camera_matrix, cal.camera_matrix) and again.n_images == cal.n_images
    assert again.warnings == cal.warnings


def test_corner_search_on_a_half_size_copy(board_images):
    """``resize=0.5``: the board is found on a half-size copy, corners refined and the camera fitted at full size."""
    cal = calibrate(board_images, resize=0.5)
    assert (cal.width_px, cal.height_px) == SIZE and cal.n_images == len(board_images)
    k = cal.camera_matrix
    assert abs(k[0, 0] / K_TRUE[0, 0] - 1) < 5e-3 and abs(k[1, 1] / K_TRUE[1, 1] - 1) < 5e-3
    assert np.allclose(k[:2, 2], K_TRUE[:2, 2], atol=3.0)
    # refined at full size, the corners are the full-size search's (10⁻⁴ px): the same camera; the half-size
    # corners alone are up to 0.5 px off and move fx by ~4 px
    assert np.abs(k - calibrate(board_images).camera_matrix).max() < 0.05


def test_the_same_view_twice_is_refused(board_images):
    noisy = np.clip(board_images[2] + np.random.default_rng(1).normal(0, 2.0, board_images[2].shape), 0, 255)
    views = [*board_images[:4], noisy.astype(np.uint8)]  # other pixels, the same board pose
    with pytest.raises(
        ValueError, match=r"^images: views 2 and 4 \(image 2, image 4\) show the board in the same place"
    ):
        calibrate(views)
    with pytest.raises(ValueError, match=r"^images: views 0 and 3 \(a.png, d.png\)"):
        calibrate([*board_images[:3], board_images[0]], names=["a.png", "b.png", "c.png", "d.png"])


def test_corner_set_difference_either_numbering():
    a = board_points_m()[:, :2] * 1e4  # 48 corners, px
    assert corner_set_difference_px(a, a + np.array([3.0, 4.0])) == pytest.approx(5.0)
    assert corner_set_difference_px(a, a[::-1] + np.array([0.0, 0.5])) == pytest.approx(0.5)  # numbered from the end


def test_parallel_boards_are_refused():
    """Boards shifted and turned in their own plane but all tilted alike: one orientation, no focal length."""
    rvec = np.array([0.35, -0.2, 0.0])
    rot = cv2.Rodrigues(rvec)[0]
    views = []
    for k, (dx, dy, dz) in enumerate([(0.0, 0.0, 0.0), (0.05, -0.03, 0.06), (-0.05, 0.03, 0.12), (0.03, 0.04, -0.03)]):
        spin = cv2.Rodrigues(np.array([0.0, 0.0, 0.15 * k]))[0]  # a turn about the board's own normal
        r = cv2.Rodrigues(rot @ spin)[0].ravel()
        t = np.array([dx, dy, 0.45 + dz]) - rot @ spin @ (np.array([3.5, 2.5, 0.0]) * SQUARE_M)
        views.append(_render_board(r, t, supersample=1))
    with pytest.raises(ValueError, match=r"^images: the board has 1 distinct orientation\(s\) in 4 views"):
        calibrate(views)


def test_orientation_groups_by_plane_angle():
    def normal(ax, ay):  # board normal tilted ax° about x, then ay° about y
        rx = cv2.Rodrigues(np.radians([ax, 0.0, 0.0]))[0]
        ry = cv2.Rodrigues(np.radians([0.0, ay, 0.0]))[0]
        return ry @ rx @ [0.0, 0.0, 1.0]

    normals = [normal(0, 0), normal(4.9, 0), normal(0, 5.1), -normal(0, 0), normal(3, 4.5), normal(40, 0)]
    # angles to the first plane: 4.9°, 5.1°, 0° (the sign of a normal does not matter), 5.41°
    # (cos 3° cos 4.5°), 40°; the fifth is 3.06° (cos 3° cos 0.6°) from the third, whose group it joins
    assert orientation_groups(normals) == [[0, 1, 3], [2, 4], [5]]
    assert orientation_groups(normals, min_angle_deg=5.2) == [[0, 1, 2, 3], [4], [5]]
    assert orientation_groups(normals, min_angle_deg=5.5) == [[0, 1, 2, 3, 4], [5]]


def test_warnings_for_an_offset_principal_point_and_unequal_focal_lengths():
    w, h = SIZE
    ok = Calibration(np.array([[600.0, 0, 319.5 + 0.09 * w], [0, 600, 239.5], [0, 0, 1]]), np.zeros(5), w, h, 0.1, 9)
    assert calibration_warnings(ok) == ()
    off = Calibration(np.array([[600.0, 0, 319.5], [0, 600, 239.5 - 0.15 * h], [0, 0, 1]]), np.zeros(5), w, h, 0.1, 9)
    (warning,) = calibration_warnings(off)
    assert warning.startswith("principal point (319.5, 167.5) px is 0 % of the width and 15 % of the height")
    # the five-copies calibration: fx 380, fy 491
    odd = Calibration(np.array([[380.0, 0, 319.5], [0, 491, 239.5], [0, 0, 1]]), np.zeros(5), w, h, 0.1, 5)
    (warning,) = calibration_warnings(odd)
    assert warning.startswith("fx 380.0 px and fy 491.0 px differ by 23 %")


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"pattern": (1, 1)}, "pattern"),
        ({"pattern": (2, 6)}, "pattern"),
        ({"pattern": (8.5, 6)}, "pattern"),
        ({"pattern": (8, 6, 1)}, "pattern"),
        ({"square_m": 0.0}, "square_m"),
        ({"square_m": float("nan")}, "square_m"),
        ({"resize": 0.0}, "resize"),
        ({"resize": 1.5}, "resize"),
        ({"resize": True}, "resize"),
    ],
)
def test_bad_calibrate_arguments_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}: expected"):
        calibrate([], **kwargs)  # refused before any image is looked at


def test_a_calibration_and_intrinsics_follow_a_resize():
    """Half-size copy: projecting with the scaled calibration lands where cv2.resize moves the pixels."""
    cal = Calibration(K_TRUE, D_TRUE, *SIZE, 0.2, 12)
    half = cal.resized_to(320, 240)
    rvec, tvec = _views()[5]
    full, _ = cv2.projectPoints(board_points_m(), rvec, tvec, cal.camera_matrix, cal.dist_coeffs)
    small, _ = cv2.projectPoints(board_points_m(), rvec, tvec, half.camera_matrix, half.dist_coeffs)
    assert np.allclose((full.reshape(-1, 2) + 0.5) * 0.5 - 0.5, small.reshape(-1, 2), atol=1e-9)
    assert (half.width_px, half.height_px, half.rms_px) == (320, 240, pytest.approx(0.1))
    assert cal.resized_to(320, 200) is None  # another aspect ratio: a crop or another mode, not a resize
    # a 1280×720 camera at 50 %: the centre of the 640×360 copy, half the focal length
    intr = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720).resized_to(640, 360)
    assert intr == Intrinsics(500.0, 500.0, 319.5, 179.5, 640, 360)
    assert resize_scales((5184, 3456), (2592, 1728)) == (0.5, 0.5)
    assert resize_scales((1280, 720), (640, 480)) is None
    assert resize_scales((1281, 721), (640, 361)) is not None  # a pixel of rounding either way


def test_explicit_intrinsics_and_distortion_are_checked():
    assert intrinsics_from_values(801, 600, 700.0) == Intrinsics(700.0, 700.0, 400.0, 299.5, 801, 600)
    for kwargs, field in [({"fx": 0.0}, "fx"), ({"fx": 700.0, "fy": float("inf")}, "fy"),
                          ({"fx": 700.0, "cx": 801.0}, "cx"), ({"fx": 700.0, "cy": -1.0}, "cy")]:  # fmt: skip
        with pytest.raises(ValueError, match=rf"^{field}: expected"):
            intrinsics_from_values(801, 600, **kwargs)
    assert check_dist_coeffs([-0.1, 0.01, 0, 0]).tolist() == [-0.1, 0.01, 0.0, 0.0]
    for bad in ([0.1, 0.2, 0.3], [0.1, 0.2, 0.0, 0.0, float("nan")], "x"):
        with pytest.raises(ValueError, match=r"^dist: expected"):
            Calibration.from_intrinsics(intrinsics_from_values(640, 480, 600.0), bad)


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


def test_a_calibration_file_is_standard_json_or_not_written(tmp_path):
    """RFC 8259 has no NaN: a finite calibration is written as strict JSON, a non-finite one is refused."""
    k = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    ok = Calibration(k, np.zeros(5), 640, 480, 0.2, 10).save(tmp_path / "ok.json")
    json.loads(ok.read_text(), parse_constant=lambda name: pytest.fail(f"bare {name}"))
    with pytest.raises(ValueError, match="JSON compliant"):
        Calibration(k, np.zeros(5), 640, 480, float("nan"), 10).save(tmp_path / "nan.json")
