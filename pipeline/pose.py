"""Better pose estimators: PnP (SQPnP + Levenberg–Marquardt) with covariance, and full QUEST.

* :func:`pnp_pose` (the ``best`` estimator): OpenCV's SQPnP gives the global minimum of
  its algebraic cost for the five non-coplanar markers (EPnP and ITERATIVE are unreliable
  on five points in a near-planar cross), then ``solvePnPRefineLM`` minimises the
  reprojection error — the maximum-likelihood estimate under independent Gaussian
  centroid noise, which reaches the Cramér–Rao bound (:mod:`pipeline.crlb`) when the
  noise is small against the target's image. Covariance σ²(JᵀJ)⁻¹ at the solution.
* :func:`quest_pose`: the study's structure (inverse perspective + vector QUEST) with
  exact pinhole rays, the geometric Newton start and full QUEST (Newton on the
  characteristic equation, sequential rotations); an ablation showing how much of the
  study's error comes from its start, angle formula and Gibbs shortcut.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics, cv_to_study, pinhole_rays_cv
from pipeline.crlb import PoseBound, bound_from_covariance, pose_covariance, project_points
from pipeline.frames import Pose
from pipeline.pnp import solve_pnp
from pipeline.thesis_pose import thesis_pose_from_vectors
from scenes.beacon import BeaconDesign

__all__ = ["PoseEstimate", "pnp_pose", "quest_pose"]

_LM_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12)


@dataclass(frozen=True)
class PoseEstimate:
    """An estimated pose with its uncertainty.

    Attributes
    ----------
    pose
        Camera pose relative to the target.
    covariance
        6×6 covariance of (ω, t) for the assumed centroid noise (rad², m²).
    bound
        Range / attitude / position σ derived from ``covariance``.
    reprojection_rms_px
        RMS reprojection residual over the markers, px.
    method
        Which estimator produced it.
    """

    pose: Pose
    covariance: NDArray[np.float64]
    bound: PoseBound
    reprojection_rms_px: float
    method: str


def _check_uv(uv) -> NDArray[np.float64]:
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape != (5, 2) or not np.all(np.isfinite(uv)):
        raise ValueError(f"markers: expected 5 finite (u, v) pixel pairs, got shape {uv.shape}")
    return uv


def pnp_pose(uv, design: BeaconDesign, intrinsics: Intrinsics, sigma_px: float = 0.3) -> PoseEstimate:
    """SQPnP (EPnP where SQPnP refuses a distant target: :func:`pipeline.pnp.solve_pnp`) then
    Levenberg–Marquardt on markers 1..5.

    Parameters
    ----------
    uv
        (5, 2) undistorted pixel centroids of markers 1..5, px.
    design
        Beacon design (target-frame marker positions).
    intrinsics
        Pinhole intrinsics of the image the centroids come from.
    sigma_px
        Assumed centroid noise for the covariance, px.
    """
    uv = _check_uv(uv)
    obj = design.marker_positions_m()
    k = intrinsics.matrix()
    solved = solve_pnp(obj, uv, k, criteria=_LM_CRITERIA)
    if solved is None:
        raise ValueError("markers: PnP found no pose (degenerate marker positions)")
    rvec, tvec = solved
    pose = Pose(cv2.Rodrigues(rvec)[0], tvec.reshape(3))
    return _estimate(pose, uv, obj, intrinsics, sigma_px, "sqpnp+lm")


def _estimate(pose, uv, obj, intrinsics, sigma_px, method) -> PoseEstimate:
    cov = pose_covariance(obj, pose, intrinsics, sigma_px)
    res = project_points(obj, pose, intrinsics) - uv
    return PoseEstimate(pose, cov, bound_from_covariance(cov, pose), float(np.sqrt(np.mean(res**2))), method)


def quest_pose(
    uv, design: BeaconDesign, intrinsics: Intrinsics, sigma_px: float = 0.3, weights=(0.25, 0.25, 0.25, 0.25)
) -> PoseEstimate:
    """Inverse perspective (geometric start) + full QUEST on exact pinhole rays."""
    uv = _check_uv(uv)
    r_cs = cv_to_study(pinhole_rays_cv(uv[:, 0], uv[:, 1], intrinsics))
    res = thesis_pose_from_vectors(r_cs, design, start="geometric", weights=weights, full_quest=True)
    if res.pose is None:
        raise ValueError(f"markers: {res.reason}")
    return _estimate(res.pose, uv, design.marker_positions_m(), intrinsics, sigma_px, "ip+quest")
