"""Monte-Carlo of the pose estimators with exact correspondences and Gaussian centroid noise.

For one camera, range and yaw, the five markers' exact pixels get independent Gaussian
noise of σ px in u and v; each estimator runs on the same noisy pixels and its range
and attitude errors are compared with the Cramér–Rao bound (:mod:`pipeline.crlb`):

* ``best``: :func:`pipeline.pose.pnp_pose` (SQPnP + LM);
* ``quest``: inverse perspective (geometric start) + full QUEST on pinhole rays;
* ``thesis``: the study's chain — pixels resized as its tracker does (50 % for the T6),
  its angle formula and unit vectors, Newton from (100, 500, 1000) mm, Gibbs QUEST with
  weights (0.05, 0.05, 0.45, 0.45). Trials with no finite answer count as failures.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.angles import (
    Intrinsics,
    cv_to_study,
    pinhole_rays_cv,
    resized_pixel,
    study_angles,
    study_unit_vectors,
)
from pipeline.crlb import pose_crlb, project_points
from pipeline.frames import pose_from_scenario
from pipeline.pose import pnp_pose
from pipeline.thesis_pose import STUDY_WEIGHTS, attitude_and_pose, thesis_ranges
from scenes.scenario import Scenario
from scenes.view import camera_geometry

__all__ = ["pose_error_trials"]

ESTIMATORS = ("best", "quest", "thesis")


def pose_error_trials(
    camera: str, range_m: float, yaw_deg: float, sigma_px: float, n_trials: int, seed: int = 0, beacon: str = "v2"
) -> dict:
    """RMS range and attitude errors of each estimator beside the Cramér–Rao bound.

    Returns
    -------
    dict
        ``crlb_range_m``, ``crlb_attitude_rad`` and per estimator
        ``{name: {"rms_range_m", "rms_attitude_rad", "range_ratio", "attitude_ratio",
        "bias_range_m", "failures"}}`` (ratios = RMS / CRLB).
    """
    sc = Scenario(beacon=beacon, camera=camera, range_m=range_m, yaw_deg=yaw_deg)
    geometry = camera_geometry(camera)
    intr = Intrinsics.from_geometry(geometry)
    pose = pose_from_scenario(sc)
    pts = sc.design.marker_positions_m()
    uv0 = project_points(pts, pose, intr)
    bound = pose_crlb(pts, pose, intr, sigma_px)
    scale = 0.5 if geometry.width_px >= 3000 else 1.0
    processed = (round(geometry.width_px * scale), round(geometry.height_px * scale))
    rng = np.random.default_rng(seed)
    noisy = uv0[None] + rng.normal(scale=sigma_px, size=(n_trials, *uv0.shape))
    estimates = {k: [] for k in ESTIMATORS}
    for uv in noisy:
        try:
            estimates["best"].append(pnp_pose(uv, sc.design, intr, sigma_px).pose)
        except ValueError:
            estimates["best"].append(None)
    # the two vector-QUEST chains share their Newton step, run for all trials at once
    ur, vr = resized_pixel(noisy[..., 0], noisy[..., 1], scale)
    r_study = study_unit_vectors(*study_angles(ur, vr, processed, intr))
    r_exact = cv_to_study(pinhole_rays_cv(noisy[..., 0], noisy[..., 1], intr))
    for name, r_all, start, weights, full in (
        ("thesis", r_study, "study", STUDY_WEIGHTS, False),
        ("quest", r_exact, "geometric", (0.25,) * 4, True),
    ):
        ranges = thesis_ranges(r_all, sc.design, start=start).ranges_m
        for r, rg in zip(r_all, ranges, strict=True):
            estimates[name].append(attitude_and_pose(r, rg, sc.design, weights, full))
    errs = {k: ([], []) for k in ESTIMATORS}
    failures = dict.fromkeys(ESTIMATORS, 0)
    for name, ests in estimates.items():
        for est in ests:
            if est is None or not np.isfinite(est.range_m):
                failures[name] += 1
                continue
            errs[name][0].append(est.range_m - range_m)
            errs[name][1].append(Rotation.from_matrix(est.cv_from_t @ pose.cv_from_t.T).magnitude())
    out = {"crlb_range_m": bound.range_m, "crlb_attitude_rad": bound.attitude_rad}
    for name, (er, ea) in errs.items():
        er, ea = np.array(er), np.array(ea)
        rms_r = float(np.sqrt(np.mean(er**2))) if er.size else float("nan")
        rms_a = float(np.sqrt(np.mean(ea**2))) if ea.size else float("nan")
        out[name] = {
            "rms_range_m": rms_r,
            "rms_attitude_rad": rms_a,
            "range_ratio": rms_r / bound.range_m,
            "attitude_ratio": rms_a / bound.attitude_rad,
            "bias_range_m": float(er.mean()) if er.size else float("nan"),
            "failures": failures[name],
        }
    return out
