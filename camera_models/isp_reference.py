"""The ISP as it was computed before issue 24, in float: the reference the 16-bit OpenCV path of
:func:`camera_models.isp.process` is held to (tests) and timed against (``beacon-sim bench``).

demosaic (float, :func:`camera_models.isp.demosaic`) → × white-balance gains → highlight
mode (clip, unclip, blend) → camera RGB to linear sRGB → tone curve → 8-bit codes.
"""

from __future__ import annotations

import numpy as np

from camera_models.isp import (
    ProcessedImage,
    blend_highlights,
    camera_to_srgb_matrix,
    demosaic,
    encode_8bit,
    saved_image,
    white_balance_gains,
)

__all__ = ["reference_process", "reference_rgb8"]


def reference_rgb8(raw: np.ndarray, camera, x0: int = 0, y0: int = 0, gains: np.ndarray | None = None) -> np.ndarray:
    """8-bit RGB of a raw mosaic by the float32 path, in blocks of 256 rows as it ran
    (noise reduction and sharpening off)."""
    s, isp = camera.sensor, camera.isp
    g = (white_balance_gains(raw, camera, x0, y0) if gains is None else gains).astype(np.float32)
    matrix_t = camera_to_srgb_matrix(camera).T.astype(np.float32)
    out = np.empty((*raw.shape, 3), np.uint8)
    scale = np.float32(1.0 / (isp.white_level_DN(s) - s.black_level_DN))
    linear = (raw.astype(np.float32) - np.float32(s.black_level_DN)) * scale
    rgb_all = demosaic(linear, s.cfa, x0, y0)
    del linear
    for r0 in range(0, raw.shape[0], 256):
        rgb = rgb_all[r0 : r0 + 256] * g
        if isp.highlight == "clip":
            np.clip(rgb, 0.0, 1.0, out=rgb)
        elif isp.highlight == "blend":
            blend_highlights(rgb, 1.0)
        out[r0 : r0 + 256] = encode_8bit(rgb @ matrix_t, isp.tone_curve, isp.tone_contrast)
    return out


def reference_process(raw: np.ndarray, camera, x0: int = 0, y0: int = 0) -> ProcessedImage:
    """:func:`camera_models.isp.process` by the float path (noise reduction and sharpening must be off)."""
    if camera.isp.noise_reduction != "none" or camera.isp.sharpening_amount > 0.0:
        raise ValueError("isp: the reference path has no noise reduction or sharpening; use process()")
    rgb8 = reference_rgb8(raw, camera, x0, y0)
    return saved_image(np.ascontiguousarray(rgb8[..., ::-1]), camera, white_balance_gains(raw, camera, x0, y0))
