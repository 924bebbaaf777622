"""Frame conventions: study ↔ project mappings, attitude angles, T1·T2·T3, and the study's pose on exact rays."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.angles import Intrinsics, cv_to_study, pinhole_angles, pinhole_rays_cv, study_angles, study_unit_vectors
from pipeline.crlb import project_points
from pipeline.frames import (
    CS_FROM_CV,
    RING_RADIUS_M,
    S_FROM_T,
    Pose,
    beacon_from_target,
    cv_from_robot,
    global_pose,
    invert,
    pose_from_scenario,
    ring_angle_rad,
)
from pipeline.messages import LEDPoints
from pipeline.thesis_pose import reference_vectors_s, thesis_pose, thesis_pose_from_vectors
from scenes.beacon import beacon_design
from scenes.scenario import Scenario
from scenes.view import CameraPose, camera_geometry, project


def test_frames_are_proper_rotations():
    for m in (CS_FROM_CV, S_FROM_T):
        assert np.allclose(m @ m.T, np.eye(3)) and np.isclose(np.linalg.det(m), 1.0)


def test_study_reference_vectors_in_frame_s():
    """v2, v3 exactly as the study's; v4, v5 with the z sign that makes 4 the top marker."""
    v = reference_vectors_s(beacon_design("v2"))
    study = np.array([[46, -70, 0], [46, 70, 0], [46, 0, -70], [46, 0, 70]], dtype=float)
    assert np.allclose(v, study / np.linalg.norm(study, axis=1, keepdims=True), atol=1e-12)


def test_study_unit_vector_is_the_pinhole_ray_only_on_the_axes():
    intr = Intrinsics.from_geometry(camera_geometry("canon-t6-18mm"))
    w, h = intr.width_px, intr.height_px
    # pixels on the centre row: the study's r is exactly the pinhole ray (up to its half-pixel centre)
    u = np.array([0.0, 1000.0, 4000.0])
    v = np.full(3, h / 2)
    a, b = study_angles(u, v, (w, h), intr)
    exact = cv_to_study(pinhole_rays_cv(u + (intr.cx - w / 2), v + (intr.cy - h / 2), intr))
    assert np.allclose(study_unit_vectors(a, b), exact, atol=1e-15)
    # a corner: lateral component stretched by 1/cos β
    a, b = study_angles(np.array([0.0]), np.array([0.0]), (w, h), intr)
    r = study_unit_vectors(a, b)[0]
    assert math.isclose(-r[1] / -r[0], math.tan(a[0]) / math.cos(b[0]), rel_tol=1e-12)
    ray = cv_to_study(pinhole_rays_cv(np.array([intr.cx - w / 2]), np.array([intr.cy - h / 2]), intr))[0]
    err = math.acos(np.clip(r @ ray, -1, 1))
    print(f"\nstudy unit vector vs pinhole ray at the T6 + 18 mm corner: {err * 1e3:.2f} mrad")
    assert err > 1e-3
    # the study's angles are the pinhole angles half a pixel off: its centre is W/2, not (W − 1)/2
    aa, bb = pinhole_angles(np.array([100.0]), np.array([200.0]), intr)
    a2, b2 = study_angles(np.array([100.0 + 0.5]), np.array([200.0 + 0.5]), (w, h), intr)
    assert np.allclose([aa[0], bb[0]], [a2[0], b2[0]], atol=1e-15)


@pytest.mark.parametrize(("yaw", "height"), [(0.0, 0.0), (20.0, 0.0), (-35.0, 0.8), (10.0, -0.5)])
def test_pose_from_scenario_projects_like_camera_models_and_gives_scenario_angles(yaw, height):
    sc = Scenario(side="green", range_m=4.0, yaw_deg=yaw, camera_height_m=height, camera="logitech-c270")
    pose = pose_from_scenario(sc)
    intr = Intrinsics.from_geometry(sc.geometry)
    uv = project(sc.geometry, sc.camera_pose(), sc.marker_positions_world_m())
    assert np.allclose(project_points(sc.design.marker_positions_m(), pose, intr), uv, atol=1e-9)
    assert math.isclose(pose.range_m, 4.0, rel_tol=1e-12)
    y, p, r = (math.degrees(a) for a in pose.attitude_rad())
    assert math.isclose(y, yaw, abs_tol=1e-9)
    assert math.isclose(p, -math.degrees(math.asin(height / 4.0)), abs_tol=1e-9)  # looking down = negative pitch
    assert abs(r) < 1e-9
    g = global_pose(sc.side, pose, sc.design.d_t_m)
    assert np.allclose([g.x_m, g.y_m, g.z_m], sc.camera_pose().position_m, atol=1e-12)
    assert math.isclose(math.degrees(g.pitch_rad), p, abs_tol=1e-9)


def test_square_on_pose_has_identity_quaternion():
    pose = pose_from_scenario(Scenario(range_m=3.0, yaw_deg=0.0))
    assert np.allclose(pose.quaternion_wxyz(), (1, 0, 0, 0), atol=1e-12)


def test_ring_angles_and_camera_to_robot_transform():
    assert [round(math.degrees(ring_angle_rad(c)), 9) for c in range(6)] == [180, 240, 300, 360, 420, 480]
    for c in range(6):
        robot_from_cv = invert(cv_from_robot(c))
        centre = robot_from_cv[:3, 3]
        forward = robot_from_cv[:3, :3] @ np.array([0.0, 0.0, 1.0])
        phi = math.radians(60 * c)
        assert np.allclose(centre, RING_RADIUS_M * np.array([math.cos(phi), math.sin(phi), 0.0]), atol=1e-15)
        assert np.allclose(forward, [math.cos(phi), math.sin(phi), 0.0], atol=1e-15)  # faces outward
        assert np.allclose(robot_from_cv[:3, :3] @ [0.0, 1.0, 0.0], [0, 0, -1])  # image down = robot down


def test_t1_t2_t3_chain_recovers_a_known_robot_pose():
    """Place a robot (FLU) in the beacon frame, see the yellow target with ring camera 2, recover it."""
    design = beacon_design("v2")
    robot_yaw = math.radians(-130.0)
    # robot FLU in the beacon (Z down) frame: level, heading robot_yaw about beacon Z
    flu_to_frd = np.diag([1.0, -1.0, -1.0])
    beacon_from_robot = np.eye(4)
    beacon_from_robot[:3, :3] = Rotation.from_euler("z", robot_yaw).as_matrix() @ flu_to_frd
    beacon_from_robot[:3, 3] = [0.4, -3.1, 0.05]
    cam = 2
    beacon_from_cv = beacon_from_robot @ invert(cv_from_robot(cam))
    t_from_cv = invert(beacon_from_target("yellow", design.d_t_m)) @ beacon_from_cv
    pose = Pose(t_from_cv[:3, :3].T, invert(t_from_cv)[:3, 3])
    g = global_pose("yellow", pose, design.d_t_m, camera_index=cam)
    assert np.allclose([g.x_m, g.y_m, g.z_m], beacon_from_robot[:3, 3], atol=1e-12)
    assert math.isclose(g.yaw_rad, robot_yaw, abs_tol=1e-12)
    assert abs(g.pitch_rad) < 1e-12 and abs(g.roll_rad) < 1e-12

    # the same through the study's messages: exact lines of sight as azimuth/elevation
    intr = Intrinsics.from_geometry(camera_geometry("logitech-c270"))
    p_cv = design.marker_positions_m() @ pose.cv_from_t.T + pose.t_cv_m
    assert np.all(p_cv[:, 2] > 0)
    r_cs = cv_to_study(p_cv / np.linalg.norm(p_cv, axis=1, keepdims=True))
    res = thesis_pose_from_vectors(r_cs, design)
    assert res.pose is not None and all(res.converged)
    g2 = global_pose("yellow", res.pose, design.d_t_m, camera_index=cam)
    assert np.allclose([g2.x_m, g2.y_m, g2.z_m], beacon_from_robot[:3, 3], atol=1e-9)
    assert math.isclose(g2.yaw_rad, robot_yaw, abs_tol=1e-9)
    del intr


@pytest.mark.parametrize("side", ["red", "green", "blue", "yellow"])
@pytest.mark.parametrize("cam", range(6))
def test_every_ring_camera_and_side_recovers_the_robots_global_pose(cam, side):
    """Issue 28: a level robot placed so that ring camera ``cam`` sees ``side``'s target from 3 m at
    an angle; noise-free lines of sight through the study's own pose solver and T1·T2·T3 give the
    robot's position and heading in the beacon frame to 1e-9 (heading read off the robot's forward
    axis, independently of global_pose's Euler convention)."""
    design = beacon_design("v2")
    turn = math.radians(-20.0 + 7.0 * cam)  # the camera's yaw off the target's normal
    # the camera in the target frame T (x toward the viewer, z down): 3 m out, facing the target
    z_cv = -np.array([math.cos(turn), math.sin(turn), 0.0])
    y_cv = np.array([0.0, 0.0, 1.0])  # image down = target down: a level camera
    t_from_cv = np.eye(4)
    t_from_cv[:3, :3] = np.column_stack([np.cross(y_cv, z_cv), y_cv, z_cv])
    t_from_cv[:3, 3] = [3.0 * math.cos(turn), 3.0 * math.sin(turn), -0.05]
    beacon_from_robot = beacon_from_target(side, design.d_t_m) @ t_from_cv @ cv_from_robot(cam)
    forward = beacon_from_robot[:3, :3] @ np.array([1.0, 0.0, 0.0])
    heading = math.atan2(forward[1], forward[0])
    pose = Pose(t_from_cv[:3, :3].T, invert(t_from_cv)[:3, 3])
    p_cv = design.marker_positions_m() @ pose.cv_from_t.T + pose.t_cv_m
    assert np.all(p_cv[:, 2] > 0)  # every marker in front of the camera
    solved = thesis_pose_from_vectors(cv_to_study(p_cv / np.linalg.norm(p_cv, axis=1, keepdims=True)), design)
    assert solved.pose is not None and all(solved.converged)
    for estimate in (pose, solved.pose):
        g = global_pose(side, estimate, design.d_t_m, camera_index=cam)
        assert np.allclose([g.x_m, g.y_m, g.z_m], beacon_from_robot[:3, 3], atol=1e-9)
        assert abs(math.remainder(g.yaw_rad - heading, 2 * math.pi)) < 1e-9
        assert abs(g.pitch_rad) < 1e-9 and abs(g.roll_rad) < 1e-9


@pytest.mark.parametrize("yaw", [0.0, 15.0, 30.0])
def test_thesis_pose_from_led_points_on_exact_angles(yaw):
    """LEDPoints built from exact lines of sight (as (α, β) with r = study formula) give the true pose."""
    sc = Scenario(range_m=3.0, yaw_deg=yaw, camera_height_m=0.3)
    pose = pose_from_scenario(sc)
    p_cv = sc.design.marker_positions_m() @ pose.cv_from_t.T + pose.t_cv_m
    r = cv_to_study(p_cv / np.linalg.norm(p_cv, axis=1, keepdims=True))
    # invert r = (−cos α cos β, −sin α, −cos α sin β)
    alpha = np.arcsin(-r[:, 1])
    beta = np.arctan2(-r[:, 2], -r[:, 0])
    res = thesis_pose(LEDPoints(0, "red", tuple(alpha), tuple(beta)), sc.design)
    assert res.message is not None
    assert math.isclose(res.message.range_m, 3.0, rel_tol=1e-9)
    assert Rotation.from_matrix(res.pose.cv_from_t @ pose.cv_from_t.T).magnitude() < 1e-9
    assert np.allclose(res.pose.t_cv_m, pose.t_cv_m, atol=1e-9)


def test_camera_pose_look_at_matches_pose_convention():
    pose = Pose.from_camera_pose(CameraPose.look_at([2.0, 0.5, 0.0], [0.0, 0.0, 0.0]).rotation, [2.0, 0.5, 0.0])
    assert np.allclose(pose.camera_position_t_m(), [2.0, 0.5, 0.0])
