"""Cramér–Rao lower bound of the camera pose from the marker centroids.

Model: each marker's centroid is its pinhole projection plus independent Gaussian noise
of standard deviation σ (px) in u and in v. The pose parameters are θ = (ω, t): ω a
small rotation applied on the left of R (p_cv = exp([ω]×) R p_T + t, rad, camera frame)
and t the target origin (marker 1) in the camera frame (m). With J = ∂(u, v)/∂θ, the
Fisher information is JᵀJ/σ² and any unbiased estimator has Cov(θ̂) ⪰ σ² (JᵀJ)⁻¹.
Derived quantities use first-order propagation (delta method):

* range |t|: gradient t/|t| on t;
* attitude: RMS rotation-angle error √tr Σ_ωω (frame independent), and per axis of the
  target frame (about x_T ≈ roll, y_T ≈ pitch, z_T ≈ yaw);
* camera position in the target frame c = −Rᵀt: ∂c/∂ω = −Rᵀ[t]×, ∂c/∂t = −Rᵀ; the
  lateral position is c_y (across the target normal, horizontal).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics
from pipeline.frames import Pose, pose_from_scenario
from scenes.view import camera_geometry

__all__ = [
    "PoseBound",
    "bound_from_covariance",
    "planar_covariance",
    "pose_covariance",
    "pose_crlb",
    "project_points",
    "projection_jacobian",
    "scenario_crlb",
]


def _skew(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def projection_jacobian(points_t_m, pose: Pose, intrinsics: Intrinsics) -> NDArray[np.float64]:
    """∂(u_1, v_1, …, u_n, v_n)/∂(ω, t), shape (2n, 6), px/rad and px/m."""
    pts = np.asarray(points_t_m, dtype=np.float64).reshape(-1, 3)
    rp = pts @ pose.cv_from_t.T
    x = rp + pose.t_cv_m
    jac = np.zeros((2 * len(pts), 6))
    for k, (rpk, (px, py, pz)) in enumerate(zip(rp, x, strict=True)):
        fx, fy = intrinsics.fx, intrinsics.fy
        dproj = np.array([[fx / pz, 0.0, -fx * px / pz**2], [0.0, fy / pz, -fy * py / pz**2]])
        jac[2 * k : 2 * k + 2, :3] = dproj @ (-_skew(rpk))  # d(exp(ω×) R p)/dω = −[R p]×
        jac[2 * k : 2 * k + 2, 3:] = dproj
    return jac


def project_points(points_t_m, pose: Pose, intrinsics: Intrinsics) -> NDArray[np.float64]:
    """Pinhole pixels (n, 2) of target-frame points under ``pose``."""
    x = np.asarray(points_t_m, dtype=np.float64).reshape(-1, 3) @ pose.cv_from_t.T + pose.t_cv_m
    if np.any(x[:, 2] <= 0):
        raise ValueError("project_points: a point lies behind the camera")
    u = intrinsics.cx + intrinsics.fx * x[:, 0] / x[:, 2]
    return np.stack([u, intrinsics.cy + intrinsics.fy * x[:, 1] / x[:, 2]], axis=1)


@dataclass(frozen=True)
class PoseBound:
    """Cramér–Rao bound (standard deviations) of the pose and derived quantities.

    Attributes
    ----------
    covariance
        6×6 bound on Cov(ω, t), rad² / m².
    range_m
        σ of the range to marker 1, m.
    attitude_rad
        RMS rotation-angle error √tr Σ_ωω, rad.
    attitude_axes_rad
        σ of the rotation about the target's x, y, z axes (≈ roll, pitch, yaw), rad.
    position_t_m
        σ of the camera position in the target frame (x along the normal, y lateral, z vertical), m.
    """

    covariance: NDArray[np.float64]
    range_m: float
    attitude_rad: float
    attitude_axes_rad: NDArray[np.float64]
    position_t_m: NDArray[np.float64]

    @property
    def lateral_m(self) -> float:
        """σ of the camera's lateral position (target y), m."""
        return float(self.position_t_m[1])


def pose_covariance(points_t_m, pose: Pose, intrinsics: Intrinsics, sigma_px: float) -> NDArray[np.float64]:
    """σ²(JᵀJ)⁻¹ at ``pose``, 6×6 (ω rad, t m)."""
    if not (math.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sigma_px: expected a noise > 0 px, got {sigma_px!r}")
    jac = projection_jacobian(points_t_m, pose, intrinsics)
    return sigma_px**2 * np.linalg.inv(jac.T @ jac)


def bound_from_covariance(cov: NDArray[np.float64], pose: Pose) -> PoseBound:
    """Range, attitude and position σ from a 6×6 (ω, t) covariance at ``pose``."""
    t = pose.t_cv_m
    g = t / np.linalg.norm(t)
    rot = pose.cv_from_t
    att_t = rot.T @ cov[:3, :3] @ rot
    jc = np.hstack([-rot.T @ _skew(t), -rot.T])
    cov_c = jc @ cov @ jc.T
    return PoseBound(
        covariance=cov,
        range_m=float(np.sqrt(g @ cov[3:, 3:] @ g)),
        attitude_rad=float(np.sqrt(np.trace(cov[:3, :3]))),
        attitude_axes_rad=np.sqrt(np.diag(att_t)),
        position_t_m=np.sqrt(np.diag(cov_c)),
    )


def planar_covariance(cov: NDArray[np.float64], pose: Pose) -> NDArray[np.float64]:
    """3×3 covariance of the camera's horizontal pose in the target frame from a 6×6 (ω, t) one:
    its position (x along the normal, y lateral; m) and its rotation about the target's vertical z
    (rad), in the target frame's own axes (z down: a positive angle turns x toward y)."""
    t, rot = pose.t_cv_m, pose.cv_from_t
    position = np.hstack([-rot.T @ _skew(t), -rot.T])[:2]  # ∂c/∂(ω, t), the x and y rows
    about_z = np.hstack([rot.T[2], np.zeros(3)])  # the z component of the rotation Rᵀω, in T
    j = np.vstack([position, about_z])
    out = j @ cov @ j.T
    return (out + out.T) / 2


def pose_crlb(points_t_m, pose: Pose, intrinsics: Intrinsics, sigma_px: float) -> PoseBound:
    """Cramér–Rao bound for ``pose`` given the target points, intrinsics and centroid noise σ (px)."""
    return bound_from_covariance(pose_covariance(points_t_m, pose, intrinsics, sigma_px), pose)


def scenario_crlb(scenario, sigma_px: float) -> PoseBound:
    """Cramér–Rao bound for a :class:`scenes.scenario.Scenario` (its beacon, camera and pose)."""
    intr = Intrinsics.from_geometry(camera_geometry(scenario.camera))
    return pose_crlb(scenario.design.marker_positions_m(), pose_from_scenario(scenario), intr, sigma_px)
