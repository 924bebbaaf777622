"""Radiometry of rendered emitters against closed-form answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance
from scenes.render import render_unit_groups
from scenes.shapes import disk_shape
from scenes.spectra import WAVELENGTHS_NM

pytestmark = pytest.mark.usefixtures("mitsuba_variant")


def _spec(shapes, film, crop, fov_x_deg, max_depth=2):
    """Camera at the origin looking along +x, image-up along -z (world Z down)."""
    return {
        "sensor": {
            "position": [0.0, 0.0, 0.0],
            "target": [1.0, 0.0, 0.0],
            "up": [0.0, 0.0, -1.0],
            "fov_x_deg": fov_x_deg,
            "film": film,
            "crop": crop,
        },
        "materials": {"black": 0.0},
        "shapes": shapes,
        "max_depth": max_depth,
    }


def _emitter(radiance, exponent):
    return {"type": "marker_face", "group": "led:test", "radiance": radiance, "exponent": exponent}


@pytest.mark.parametrize("tilt_deg", [0.0, 30.0])
@pytest.mark.parametrize("exponent", [0.0, 4.0])
def test_extended_emitter_pixel_radiance(tilt_deg, exponent):
    """A disc filling the view: every pixel sees L(θ) = L₀ cos^e θ, θ to the disc normal."""
    L0, n_px, fov = 3.7, 48, 8.0
    t = math.radians(tilt_deg)
    normal = np.array([-math.cos(t), math.sin(t), 0.0])
    disc = disk_shape(np.array([1.0, 0.0, 0.0]), normal, 0.25, "black", _emitter(L0, exponent))
    image = render_unit_groups(_spec([disc], [n_px, n_px], [0, 0, n_px, n_px], fov), 16, 1)["led:test"]
    # analytic: direction of each pixel centre through the pinhole
    f = (n_px / 2) / math.tan(math.radians(fov / 2))
    c = np.arange(n_px) + 0.5 - n_px / 2
    right, down = np.meshgrid(c / f, c / f)
    d = np.stack([np.ones_like(right), right, down], axis=-1)  # world: x forward, y right, z down
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    expected = L0 * (d @ -normal) ** exponent
    assert np.allclose(image, expected, rtol=0.01), np.abs(image / expected - 1).max()


@pytest.mark.parametrize("view_deg", [0.0, 12.0])
def test_point_like_marker_flux_matches_inverse_square_law(view_deg):
    """Σ L·Ω over the image of a small cos^m source = I(θ)/R² (its irradiance at the pupil)."""
    from scenes.view import camera_geometry

    geom = camera_geometry("canon-t6-18mm")
    m, i0, r_face, distance = 19.99, 0.0258, 1.5e-3, 5.0
    t = math.radians(view_deg)
    normal = np.array([-math.cos(t), math.sin(t), 0.0])
    area = math.pi * r_face**2
    disc = disk_shape(np.array([distance, 0.0, 0.0]), normal, r_face, "black", _emitter(i0 / area, m - 1))
    s, half = 4, 12
    x0, y0 = geom.width_px // 2 - half, geom.height_px // 2 - half
    fov = math.degrees(2 * math.atan(geom.width_px / (2 * geom.focal_length_px)))
    spec = _spec([disc], [geom.width_px * s, geom.height_px * s], [x0 * s, y0 * s, 2 * half * s, 2 * half * s], fov)
    image = render_unit_groups(spec, 64, 2)["led:test"]
    grid = PixelGrid(
        geom.width_px, geom.height_px, geom.focal_length_px, geom.principal_point_px, x0, y0, 2 * half, 2 * half, s
    )
    rad = SpectralRadiance(grid, (RadianceComponent("led:test", image, np.ones_like(WAVELENGTHS_NM)),), {}, "")
    measured = rad.irradiance_at_pupil_W_m2(*geom.principal_point_px, radius_px=half)
    expected = i0 * math.cos(t) ** m / distance**2
    assert measured == pytest.approx(expected, rel=0.02)
