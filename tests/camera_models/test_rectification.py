"""The lens's distortion in OpenCV's model: OpenCV's own projection agrees with the lens model."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.optics import RadialMapping
from camera_models.rectification import opencv_distortion


@pytest.mark.parametrize("name", ["canon-t6-18mm", "canon-t6-10mm", "logitech-c270"])
def test_opencv_projection_matches_the_lens_model(name):
    """Project rays with cv2.projectPoints and the fitted coefficients; compare with the lens
    model's own distortion of the same pinhole points (an independent code path). The
    even-power model cannot follow lensfun's ptlens curve exactly (its odd r⁴ term): the fit
    must remove at least 90 % of the distortion and state its own worst error honestly."""
    camera = load_camera(name)
    fit = opencv_distortion(camera)
    g = camera.geometry
    rng = np.random.default_rng(0)
    uv_pinhole = rng.uniform([0, 0], [g.width_px - 1, g.height_px - 1], size=(500, 2))
    truth = RadialMapping(camera).distort_points_px(uv_pinhole)
    cx, cy = g.principal_point_px
    rays = np.column_stack([(uv_pinhole - [cx, cy]) / g.focal_length_px, np.ones(len(uv_pinhole))])
    projected, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), fit.camera_matrix, fit.dist_coeffs)
    error = np.hypot(*(projected.reshape(-1, 2) - truth).T)
    distortion = np.hypot(*(truth - uv_pinhole).T)
    assert error.max() <= fit.max_error_px * 1.01 + 1e-6
    assert fit.max_error_px < 0.1 * distortion.max()
    assert fit.dist_coeffs[2] == fit.dist_coeffs[3] == 0.0
