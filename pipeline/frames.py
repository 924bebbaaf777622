"""Frames and the transforms between them: one consistent set for the whole pipeline.

See ``pipeline/CONVENTIONS.md`` for the derivation. In short (all right-handed):

* **T**, our target frame (``scenes.beacon``): origin at marker 1's lit face, x toward the
  viewer, y the viewer's left, z down.
* **cv**, the camera frame of OpenCV and ``scenes.view``: x right, y down, z
  forward.
* **Cs**, the study's camera frame, as its unit-vector formula defines it (docs/source-study.md
  §5.7): X backward (out of the camera), Y right, Z up.
* **S**, the study's target frame made right-handed: x toward the viewer, y the viewer's
  right, z up; S = T turned 180° about x. With it a camera facing the target squarely
  has A = I (QUEST's Gibbs shortcut is far from its 180° singularity).
* **F**, the facing frame used for the reported attitude: F = T turned 180° about z (x
  into the target, y the viewer's right, z down); **B**, the camera body frame: x
  forward, y right, z down. The camera attitude in the target frame is the Z-Y-X Euler
  angles of B in F, so a camera facing the target squarely has yaw = pitch = roll = 0
  and ``yaw_deg`` equals the scenario's yaw (camera azimuth toward the target's +y).
* **R**, the robot frame of the study's camera ring (docs/source-study.md §8): x forward, y left,
  z up (ROS convention). This is the frame in which the study's T3 rotation about Z by
  θ_c is exactly the camera-to-robot rotation; the reported robot attitude uses the
  body frame x forward, y right, z down.

Homogeneous transforms are named ``a_from_b``: ``p_a = a_from_b @ p_b``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pipeline.messages import GlobalPos
from scenes.beacon import target_to_beacon

__all__ = [
    "B_FROM_CV",
    "CS_FROM_CV",
    "FRD_FROM_FLU",
    "F_FROM_T",
    "RING_RADIUS_M",
    "S_FROM_T",
    "Pose",
    "beacon_from_target",
    "cv_from_robot",
    "euler_zyx",
    "global_pose",
    "homogeneous",
    "invert",
    "pose_from_scenario",
    "ring_angle_rad",
]

CS_FROM_CV = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Study camera frame (X back, Y right, Z up) from the OpenCV camera frame."""

S_FROM_T = np.diag([1.0, -1.0, -1.0])
"""Study target frame (x toward viewer, y viewer's right, z up) from our target frame."""

F_FROM_T = np.diag([-1.0, -1.0, 1.0])
"""Facing frame (x into the target, y viewer's right, z down) from our target frame."""

B_FROM_CV = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""Camera body frame (x forward, y right, z down) from the OpenCV camera frame."""

FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])
"""Robot body frame (x forward, y right, z down) from the robot ring frame (x forward, y left, z up)."""

RING_RADIUS_M = 0.2
"""Distance from the ring centre to each camera, m (docs/source-study.md §4)."""


def homogeneous(rotation: NDArray[np.float64], translation: NDArray[np.float64]) -> NDArray[np.float64]:
    """4×4 transform from a 3×3 rotation and a translation."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def invert(transform: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of a rigid 4×4 transform."""
    rot = transform[:3, :3]
    return homogeneous(rot.T, -rot.T @ transform[:3, 3])


def euler_zyx(rotation: NDArray[np.float64]) -> tuple[float, float, float]:
    """Yaw, pitch, roll (rad) of R = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    yaw, pitch, roll = Rotation.from_matrix(rotation).as_euler("ZYX")
    return float(yaw), float(pitch), float(roll)


@dataclass(frozen=True)
class Pose:
    """Camera pose relative to a target, in OpenCV form.

    Attributes
    ----------
    cv_from_t
        3×3 rotation taking target-frame (T) vectors into the camera frame (cv).
    t_cv_m
        Marker 1 (the target origin) in the camera frame, m: p_cv = cv_from_t @ p_T + t_cv_m.
    """

    cv_from_t: NDArray[np.float64]
    t_cv_m: NDArray[np.float64]

    @property
    def range_m(self) -> float:
        """Camera centre to marker 1, m."""
        return float(np.linalg.norm(self.t_cv_m))

    def camera_position_t_m(self) -> NDArray[np.float64]:
        """Camera centre in the target frame, m."""
        return -self.cv_from_t.T @ self.t_cv_m

    def attitude_rad(self) -> tuple[float, float, float]:
        """Camera yaw, pitch, roll in the target frame (B in F, Z-Y-X), rad; 0 facing squarely."""
        return euler_zyx(self.attitude_matrix())

    def t_from_cv(self) -> NDArray[np.float64]:
        """4×4 transform from the camera frame to the target frame (the study's T2)."""
        return invert(homogeneous(self.cv_from_t, self.t_cv_m))

    def attitude_matrix(self) -> NDArray[np.float64]:
        """Rotation of the camera body frame B in the facing frame F (identity facing squarely)."""
        return F_FROM_T @ self.cv_from_t.T @ B_FROM_CV.T

    def quaternion_wxyz(self) -> tuple[float, float, float, float]:
        """Unit quaternion (w, x, y, z) of :meth:`attitude_matrix` (Hamilton, active), w ≥ 0."""
        x, y, z, w = Rotation.from_matrix(self.attitude_matrix()).as_quat()
        sign = 1.0 if w >= 0 else -1.0
        return (sign * w, sign * x, sign * y, sign * z)

    @classmethod
    def from_camera_pose(cls, camera_rotation: NDArray[np.float64], camera_position_t_m) -> Pose:
        """From a ``CameraPose``-style rotation (rows = camera axes in T) and position in T."""
        rot = np.asarray(camera_rotation, dtype=np.float64)
        return cls(rot, -rot @ np.asarray(camera_position_t_m, dtype=np.float64))


def pose_from_scenario(scenario) -> Pose:
    """True camera pose of a :class:`scenes.scenario.Scenario` relative to its target."""
    rot, trans = scenario.target_to_world()
    cam = scenario.camera_pose()
    cam_rot_t = cam.rotation @ rot  # rows: camera axes in T
    return Pose.from_camera_pose(cam_rot_t, rot.T @ (cam.position_m - trans))


def beacon_from_target(side: str, d_t_m: float) -> NDArray[np.float64]:
    """The study's T1: 4×4 transform from a side's target frame (T) to the beacon frame."""
    rot, trans = target_to_beacon(side, d_t_m)
    return homogeneous(rot, trans)


def ring_angle_rad(camera_index: int, n_cameras: int = 6) -> float:
    """The study's θ_c = C·((N−2)·π/2)/N + π (docs/source-study.md §8).

    Equals 2π·C/N + π only for N = 6 (it is half the polygon's interior angle), so other
    ring sizes get the wrong spacing: kept as the study wrote it.
    """
    if isinstance(camera_index, bool) or not isinstance(camera_index, int | np.integer):
        raise ValueError(f"camera: expected an integer, got {camera_index!r}")
    if not 0 <= camera_index < n_cameras:
        raise ValueError(f"camera: expected 0..{n_cameras - 1}, got {camera_index}")
    return camera_index * ((n_cameras - 2) * math.pi / 2) / n_cameras + math.pi


def cv_from_robot(camera_index: int, n_cameras: int = 6, radius_m: float = RING_RADIUS_M) -> NDArray[np.float64]:
    """The study's T3: 4×4 transform from the ring frame R (x fwd, y left, z up) to camera C's cv frame.

    In the study camera frame (X back, Y right, Z up) the camera's rotation into R is
    Rz(θ_c) and the ring centre sits at (radius, 0, 0), i.e. behind the camera: exactly
    the study's numbers, read as "robot seen from the camera" (the rotation transposed).
    Camera C faces outward at azimuth θ_c − π, counter-clockwise seen from above.
    """
    theta = ring_angle_rad(camera_index, n_cameras)
    c, s = math.cos(theta), math.sin(theta)
    r_from_cs = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cs_from_r = homogeneous(r_from_cs.T, np.array([radius_m, 0.0, 0.0]))
    cv_from_cs = homogeneous(CS_FROM_CV.T, np.zeros(3))
    return cv_from_cs @ cs_from_r


def global_pose(side: str, pose: Pose, d_t_m: float, camera_index: int | None = None, n_cameras: int = 6) -> GlobalPos:
    """T1·T2·T3: the robot's (or, without ``camera_index``, the camera's) pose in the beacon frame.

    Parameters
    ----------
    side
        Colour of the side seen (selects T1).
    pose
        Camera pose relative to that side's target.
    d_t_m
        Beacon centre to marker 1, m.
    camera_index
        Camera number C on the study's ring; ``None`` reports the camera itself (body
        frame x forward along the optical axis, y right, z down).
    n_cameras
        Ring size N.
    """
    beacon_from_cv = beacon_from_target(side, d_t_m) @ pose.t_from_cv()
    if camera_index is None:
        body = beacon_from_cv[:3, :3] @ B_FROM_CV.T
        position = beacon_from_cv[:3, 3]
    else:
        beacon_from_r = beacon_from_cv @ cv_from_robot(camera_index, n_cameras)
        body = beacon_from_r[:3, :3] @ FRD_FROM_FLU.T
        position = beacon_from_r[:3, 3]
    yaw, pitch, roll = euler_zyx(body)
    return GlobalPos(*(float(p) for p in position), yaw, pitch, roll)
