"""A camera turned off the render's axis: the render placed where the real lens images it.

Independent answers: a small source seen at field angle θ through an equidistant lens with its
natural relative illumination (cos θ · sin θ / θ) sends the lens cos θ of its on-axis flux (its
projected aperture), and its image centre lies at r = f·θ from the principal point.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.optics import optical_image, turned_grid
from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance
from scenes.scenario import Scenario


def disc_radiance(name: str, radius_px: float = 3.0, size: int = 40, s: int = 3) -> SpectralRadiance:
    """A uniform disc on the axis of a render grid centred on the principal point."""
    g = load_camera(name).geometry
    cx, cy = g.principal_point_px
    x0, y0 = int(cx) - size // 2, int(cy) - size // 2
    grid = PixelGrid(g.width_px, g.height_px, g.focal_length_px, g.principal_point_px, x0, y0, size, size, s)
    u, v = grid.subpixel_centres_px()
    image = ((u[None, :] - cx) ** 2 + (v[:, None] - cy) ** 2 <= radius_px**2).astype(np.float32)
    comp = RadianceComponent("led:red", image, np.asarray(spectra.illuminant_shape("D65")))
    return SpectralRadiance(grid, (comp,), {}, "test")


def centroid(img) -> tuple[float, float, float]:
    e = img.electrons_rgb.sum(axis=2)
    rows, cols = np.mgrid[0 : e.shape[0], 0 : e.shape[1]]
    return float(e.sum()), float((e * cols).sum() / e.sum()) + img.x0, float((e * rows).sum() / e.sum()) + img.y0


@pytest.mark.parametrize(("pan", "tilt"), [(40.0, 0.0), (-25.0, 15.0), (0.0, -20.0)])
def test_turned_flux_and_position_equidistant(pan, tilt):
    """Spedal 920 (equidistant, natural vignetting): flux ratio cos θ within 0.3 %, image centre at
    f·θ along the ray's azimuth within 0.15 px."""
    name = "spedal-920"
    cam = load_camera(name)
    rad = disc_radiance(name)
    on_axis, _, _ = centroid(optical_image(rad, cam, 1.0))
    sc = Scenario(camera=name, range_m=3.0, pan_deg=pan, tilt_deg=tilt)
    total, u, v = centroid(optical_image(rad, cam, 1.0, view=sc.view_rotation()))
    axis = sc.view_rotation().T @ np.array([0.0, 0.0, 1.0])  # the render's axis in the camera's frame
    theta = math.acos(axis[2])
    assert total / on_axis == pytest.approx(math.cos(theta), rel=3e-3)
    g = cam.geometry
    cx, cy = g.principal_point_px
    azimuth = math.atan2(axis[1], axis[0])
    r = g.focal_length_px * theta
    assert u == pytest.approx(cx + r * math.cos(azimuth), abs=0.15)
    assert v == pytest.approx(cy + r * math.sin(azimuth), abs=0.15)
    if tilt == 0:  # a pure pan to the right puts the beacon left of the centre, on the centre row
        assert u < cx and v == pytest.approx(cy, abs=0.05)


def test_unturned_view_is_the_render_itself():
    """The identity rotation gives the render's own crop and its electrons (to rounding)."""
    cam = load_camera("logitech-c270")
    rad = disc_radiance("logitech-c270")
    plain = optical_image(rad, cam, 1.0)
    same = optical_image(rad, cam, 1.0, view=np.eye(3))
    assert (same.x0, same.y0) == (plain.x0, plain.y0)
    np.testing.assert_allclose(same.electrons_rgb, plain.electrons_rgb, rtol=1e-9, atol=1e-12)


def test_turned_out_of_frame_is_one_line():
    cam = load_camera("logitech-c270")
    sc = Scenario(camera="logitech-c270", range_m=3.0, pan_deg=60.0)
    with pytest.raises(ValueError, match=r"pan_deg: .*outside its frame"):
        turned_grid(disc_radiance("logitech-c270").grid, cam, sc.view_rotation())
