"""PnP on a distant target: OpenCV's SQPnP refuses a small spread of points, the fallback does not.

The projections are exact pinhole projections of V2's five markers (scenes.view.project); the
independent answer is the pose they were made from.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.angles import Intrinsics
from pipeline.pnp import solve_pnp
from pipeline.pose import pnp_pose
from pipeline.tracker import _fit
from scenes.scenario import Scenario
from scenes.view import project

V2 = Scenario(camera="canon-t6-18mm").design
OBJ = V2.marker_positions_m()


def _view(range_m: float, yaw_deg: float):
    s = Scenario(camera="canon-t6-18mm", range_m=range_m, yaw_deg=yaw_deg)
    uv = project(s.geometry, s.camera_pose(), s.marker_positions_world_m())
    return uv, Intrinsics.from_geometry(s.geometry).matrix()


def test_sqpnp_refuses_v2_beyond_about_19_m():
    """The limit the fallback exists for (if OpenCV lifts it, this test says so)."""
    uv, k = _view(25.0, 0.0)
    with pytest.raises(cv2.error, match="point_coordinate_variance"):
        cv2.solvePnP(OBJ, uv, k, None, flags=cv2.SOLVEPNP_SQPNP)


@pytest.mark.parametrize("range_m", [2.0, 10.0, 19.0, 25.0, 40.0])
@pytest.mark.parametrize("yaw_deg", [0.0, 30.0])
def test_the_pose_is_recovered_at_every_range(range_m, yaw_deg):
    uv, k = _view(range_m, yaw_deg)
    rvec, tvec = solve_pnp(OBJ, uv, k)
    camera = -cv2.Rodrigues(rvec)[0].T @ tvec.reshape(3)
    assert np.linalg.norm(camera) == pytest.approx(range_m, rel=1e-6)
    assert np.degrees(np.arctan2(camera[1], camera[0])) == pytest.approx(yaw_deg, abs=1e-4)
    assert _fit(uv, V2, k) < 1e-3  # the best tracker's fit accepts it (RMS, px)


def test_the_pnp_estimator_works_at_30_m_with_noise():
    uv, _ = _view(30.0, 15.0)
    rng = np.random.default_rng(5)
    s = Scenario(camera="canon-t6-18mm", range_m=30.0, yaw_deg=15.0)
    estimate = pnp_pose(uv + rng.normal(0.0, 0.3, uv.shape), V2, Intrinsics.from_geometry(s.geometry))
    assert np.linalg.norm(estimate.pose.t_cv_m) == pytest.approx(30.0, rel=0.05)


def test_coincident_points_have_no_pose():
    uv = np.full((5, 2), 100.0)
    assert solve_pnp(OBJ, uv, np.array([[1000.0, 0, 50], [0, 1000.0, 50], [0, 0, 1]])) is None
