"""pipeline.ring: the hexagon's blind zone, against a brute-force search of the plane."""

from __future__ import annotations

import math

import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.optics import RadialMapping
from pipeline.ring import STUDY_BLIND_ZONE_M, blind_zone_m, seen_by_ring


@pytest.mark.parametrize(("n", "fov_deg"), [(6, 120.0), (6, 104.6), (6, 80.0), (4, 120.0), (8, 60.0)])
def test_the_blind_zone_is_the_farthest_point_no_camera_sees(n, fov_deg):
    """On a fine polar grid, the farthest unseen point lies at the analytic distance (to the grid step)."""
    fov = math.radians(fov_deg)
    rho = blind_zone_m(n, 0.2, fov)
    radii = np.linspace(0.0, 3 * rho, 3001)
    angles = np.linspace(0.0, 2 * math.pi, 1441)
    rr, aa = np.meshgrid(radii, angles)
    points = np.stack([rr * np.cos(aa), rr * np.sin(aa)], axis=-1)
    unseen = ~seen_by_ring(points, n, 0.2, fov)
    assert rr[unseen].max() == pytest.approx(rho, abs=2 * (radii[1] - radii[0]))


def test_fields_that_never_meet_leave_the_wedges_open():
    assert blind_zone_m(6, 0.2, math.radians(60.0)) == math.inf
    with pytest.raises(ValueError, match=r"fov_rad: expected a horizontal field of view in \(0, π\)"):
        blind_zone_m(6, 0.2, 4.0)
    with pytest.raises(ValueError, match=r"n_cameras: expected an integer >= 2"):
        blind_zone_m(1, 0.2, 1.0)


def test_the_studys_hexagon_of_spedal_920_webcams():
    """The Spedal's lens (equidistant mapping: 104.6° across the frame) puts the blind zone at 0.42 m;
    the study states 507 mm, which a 93° field would give; the pinhole field (85°) would give 0.63 m."""
    spedal = load_camera("spedal-920")
    lens = math.radians(RadialMapping(spedal).horizontal_fov_deg())
    half_width_mm = 0.5 * spedal.geometry.width_px * spedal.geometry.pixel_pitch_um * 1e-3
    assert lens == pytest.approx(2 * half_width_mm / spedal.geometry.focal_length_mm, rel=1e-3)  # r = f·θ
    assert blind_zone_m(6, 0.2, lens) == pytest.approx(0.417, abs=0.002)
    assert blind_zone_m(6, 0.2, math.radians(spedal.geometry.horizontal_fov_deg)) == pytest.approx(0.628, abs=0.002)
    assert blind_zone_m(6, 0.2, math.radians(93.3)) == pytest.approx(STUDY_BLIND_ZONE_M, abs=0.005)


def test_the_ring_command_states_the_blind_zone_beside_the_studys():
    import json

    from tests.helpers.cli import assert_one_line_error, invoke

    code, out, _ = invoke(["ring", "--json"])
    record = json.loads(out)
    assert code == 0 and record["blind_zone_m"] == pytest.approx(0.417, abs=0.002)
    assert record["study_blind_zone_m"] == STUDY_BLIND_ZONE_M
    code, out, _ = invoke(["ring", "--camera", "logitech-c270", "--json"])  # 52° < 60°: the wedges stay open
    assert json.loads(out)["blind_zone_m"] is None
    code, _, err = invoke(["ring", "--cameras-n", "1"])
    assert_one_line_error(code, err, "cameras-n")


def _random_covariance(rng, scale):
    a = rng.normal(size=(3, 3)) * np.array([scale, scale, 0.02])
    return a @ a.T + np.diag([1e-4, 1e-4, 1e-6])


def test_the_fused_pose_is_never_worse_than_the_best_single_detection():
    """Synthetic detections of one instant (three cameras, covariances of different sizes and shapes),
    errors drawn from those covariances: the fused covariance lies below every single one (Loewner
    order), the fused errors scatter as it says, and their mean squared error is below the best single
    detection's on the same draws."""
    from pipeline.ring import PlanarPose, fuse

    rng = np.random.default_rng(28)
    truth = np.array([4.0, -1.5, math.radians(170.0)])
    covs = [_random_covariance(rng, s) for s in (0.05, 0.12, 0.3)]
    fused_cov = fuse([PlanarPose(*truth, c) for c in covs]).covariance
    for c in covs:
        assert np.linalg.eigvalsh(c - fused_cov).min() > -1e-12
    errors, singles = [], []
    for _ in range(4000):
        draws = [truth + rng.multivariate_normal(np.zeros(3), c) for c in covs]
        f = fuse([PlanarPose(*d, c) for d, c in zip(draws, covs, strict=True)])
        e = f.vector - truth
        e[2] = math.remainder(e[2], 2 * math.pi)
        errors.append(e)
        singles.append([np.sum((d[:2] - truth[:2]) ** 2) for d in draws])
    errors = np.array(errors)
    scale = np.sqrt(np.outer(np.diag(fused_cov), np.diag(fused_cov)))  # each entry against its own variances
    assert np.all(np.abs(np.cov(errors.T) - fused_cov) <= 0.1 * scale)  # it scatters as its covariance says
    best = min(np.mean(np.array(singles), axis=0))  # the best single camera's mean squared position error
    assert np.mean(np.sum(errors[:, :2] ** 2, axis=1)) < best


def test_headings_either_side_of_pi_fuse_to_pi_not_zero():
    from pipeline.ring import PlanarPose, fuse

    c = np.diag([0.01, 0.01, 0.001])
    f = fuse([PlanarPose(0.0, 0.0, math.radians(179.0), c), PlanarPose(0.0, 0.0, math.radians(-179.0), c)])
    assert abs(abs(f.heading_rad) - math.pi) < 1e-12
    assert np.allclose(f.covariance, c / 2)
    with pytest.raises(ValueError, match=r"estimates\[0\]\.covariance: expected a symmetric positive definite"):
        fuse([PlanarPose(0.0, 0.0, 0.0, -c)])
    with pytest.raises(ValueError, match=r"estimates: expected at least one"):
        fuse([])
