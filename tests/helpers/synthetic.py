"""Synthetic marker images without rendering: coloured blobs at projected marker positions.

Used by the tests (known truth) and handy for trying the trackers. A blob is a Gaussian
spot or an area-sampled disc of a given colour; a peak above the full-scale value clips,
giving the white, saturated core of an over-exposed LED with a coloured fringe.
"""

from __future__ import annotations

import colorsys

import numpy as np
from numpy.typing import NDArray

from pipeline.frames import Pose, pose_from_scenario
from scenes.scenario import Scenario
from scenes.view import project


def marker_pixels(
    camera: str, range_m: float, yaw_deg: float, beacon: str = "v2", camera_height_m: float = 0.0
) -> tuple[NDArray[np.float64], Pose]:
    """Full-frame pixels (5, 2) of markers 1..5 and the true pose, for the scenario convention."""
    sc = Scenario(beacon=beacon, camera=camera, range_m=range_m, yaw_deg=yaw_deg, camera_height_m=camera_height_m)
    return project(sc.geometry, sc.camera_pose(), sc.marker_positions_world_m()), pose_from_scenario(sc)


def hsv_to_bgr(h: float, s: float, v: float) -> tuple[float, float, float]:
    """OpenCV-scaled HSV (H 0–180, S and V 0–255) to BGR in [0, 1]."""
    r, g, b = colorsys.hsv_to_rgb(h / 180.0, s / 255.0, v / 255.0)
    return (b, g, r)


def _profile(du: NDArray, dv: NDArray, kind: str, size_px: float, supersample: int) -> NDArray:
    if kind == "gaussian":
        return np.exp(-(du**2 + dv**2) / (2.0 * size_px**2))
    if kind == "disc":
        offs = (np.arange(supersample) + 0.5) / supersample - 0.5
        cover = np.zeros_like(du)
        for ou in offs:
            for ov in offs:
                cover += ((du + ou) ** 2 + (dv + ov) ** 2) <= size_px**2
        return cover / supersample**2
    raise ValueError(f"profile: expected 'gaussian' or 'disc', got {kind!r}")


def draw_markers(
    shape_hw: tuple[int, int],
    uv,
    colour_bgr,
    size_px: float,
    peak: float = 1.0,
    profile: str = "gaussian",
    background: float = 0.0,
    noise_sigma: float = 0.0,
    dtype=np.uint8,
    rng: np.random.Generator | None = None,
    supersample: int = 8,
    origin_px: tuple[float, float] = (0.0, 0.0),
) -> NDArray:
    """An image with one blob per point of ``uv``.

    Parameters
    ----------
    shape_hw
        Image height and width, px.
    uv
        (n, 2) blob centres in full-frame pixels.
    colour_bgr
        Blob colour, BGR in [0, 1] (one colour for all, or (n, 3)).
    size_px
        Gaussian σ or disc radius, px.
    peak
        Peak value in units of full scale; > 1 clips (saturated core).
    profile
        ``gaussian`` or ``disc`` (area-sampled).
    background, noise_sigma
        Background level and Gaussian noise σ, units of full scale.
    dtype
        uint8, uint16 or float32 (in [0, 1]).
    rng
        Random generator for the noise.
    supersample
        Sub-samples per pixel axis for discs.
    origin_px
        Full-frame pixel of the image's top-left pixel (for crops).
    """
    h, w = shape_hw
    img = np.full((h, w, 3), float(background), dtype=np.float64)
    pts = np.asarray(uv, dtype=np.float64).reshape(-1, 2) - np.asarray(origin_px, dtype=np.float64)
    cols = np.broadcast_to(np.asarray(colour_bgr, dtype=np.float64), (len(pts), 3))
    reach = int(np.ceil(5 * size_px if profile == "gaussian" else size_px + 2))
    for (pu, pv), col in zip(pts, cols, strict=True):
        u_lo, u_hi = max(0, int(pu) - reach), min(w, int(pu) + reach + 2)
        v_lo, v_hi = max(0, int(pv) - reach), min(h, int(pv) + reach + 2)
        if u_lo >= u_hi or v_lo >= v_hi:
            continue
        du = np.arange(u_lo, u_hi)[None, :] - pu
        dv = np.arange(v_lo, v_hi)[:, None] - pv
        prof = _profile(du + 0 * dv, dv + 0 * du, profile, size_px, supersample)
        img[v_lo:v_hi, u_lo:u_hi] += peak * prof[..., None] * col
    if noise_sigma > 0:
        img += (rng or np.random.default_rng(0)).normal(scale=noise_sigma, size=img.shape)
    img = np.clip(img, 0.0, 1.0)
    if dtype == np.uint8:
        return np.round(img * 255).astype(np.uint8)
    if dtype == np.uint16:
        return np.round(img * 65535).astype(np.uint16)
    return img.astype(np.float32)
