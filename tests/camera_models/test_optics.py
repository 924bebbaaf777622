"""Lens model: camera equation, relative illumination and distortion against lensfun."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.optics import RadialMapping, optical_image, relative_illumination
from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance

CAMERAS = ["canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920"]


def uniform_radiance(name: str, x0: int, y0: int, size: int = 32, s: int = 2, L: float = 0.5) -> SpectralRadiance:
    g = load_camera(name).geometry
    grid = PixelGrid(g.width_px, g.height_px, g.focal_length_px, g.principal_point_px, x0, y0, size, size, s)
    shape = spectra.illuminant_shape("D65")
    comp = RadianceComponent("ambient", np.full(grid.shape, L, dtype=np.float32), np.asarray(shape))
    return SpectralRadiance(grid, (comp,), {}, "test")


@pytest.mark.parametrize("name", CAMERAS)
def test_camera_equation_at_centre(name):
    """Uniform radiance L gives π L T t A /(4N²) ∫ shape QE λ/hc dλ electrons on the axis (independent sum)."""
    cam = load_camera(name)
    g = cam.geometry
    cx, cy = g.principal_point_px
    L, t = 0.5, 1e-3
    rad = uniform_radiance(name, int(cx) - 16, int(cy) - 16, L=L)
    img = optical_image(rad, cam, t).electrons_rgb
    h_c = 6.62607015e-34 * 299792458.0
    lam = spectra.WAVELENGTHS_NM
    shape = spectra.illuminant_shape("D65")
    area = (g.pixel_pitch_um * 1e-6) ** 2
    for c in range(3):
        integrand = shape * cam.sensor.qe_rgb[c] * lam * 1e-9 / h_c
        spectral = float(np.sum((integrand[1:] + integrand[:-1]) / 2))  # trapezoid, 1 nm
        expected = math.pi * L * cam.lens.transmittance * t * area / (4 * cam.lens.f_number**2) * spectral
        got = img[16, 16, c]
        assert got == pytest.approx(expected, rel=0.01), (name, c, got, expected)


def _lensfun(cam):
    lensfunpy = pytest.importorskip("lensfunpy")
    db = lensfunpy.Database()
    body = next(c for c in db.find_cameras("Canon") if c.model == cam.lens.lensfun_camera)
    lens = db.find_lenses(body, "Canon", cam.lens.lensfun_lens.removeprefix("Canon "))[0]
    g = cam.geometry
    mod = lensfunpy.Modifier(lens, body.crop_factor, g.width_px, g.height_px)
    mod.initialize(cam.geometry.focal_length_mm, cam.lens.f_number, 1000.0, scale=1.0, pixel_format=np.float32)
    return mod


@pytest.mark.parametrize("name", ["canon-t6-18mm", "canon-t6-10mm"])
def test_vignetting_matches_lensfun_toward_corners(name):
    """Our relative illumination equals 1 / lensfun's vignetting correction along the diagonal."""
    cam = load_camera(name)
    g = cam.geometry
    mod = _lensfun(cam)
    ones = np.ones((g.height_px, g.width_px, 3), np.float32)
    assert mod.apply_color_modification(ones)
    cx, cy = g.principal_point_px
    for frac in (0.25, 0.5, 0.75, 0.97):
        u, v = round(cx * (1 - frac)), round(cy * (1 - frac))
        ours = float(relative_illumination(cam, cam.lens.f_number, u, v))
        theirs = 1.0 / float(ones[v, u, 1])
        assert ours == pytest.approx(theirs, rel=0.01), (frac, ours, theirs)
    # and the full optical path shows it in the corner: electrons / centre electrons. The uniform field
    # is given on the sensor grid, so distortion (which would look outside it in the corner) is turned off.
    cam = dataclasses.replace(cam, lens=dataclasses.replace(cam.lens, distortion_terms=(0.0, 0.0, 0.0)))
    corner = optical_image(uniform_radiance(name, 0, 0), cam, 1e-3).electrons_rgb[16, 16, 1]
    centre = optical_image(uniform_radiance(name, int(cx) - 16, int(cy) - 16), cam, 1e-3).electrons_rgb[16, 16, 1]
    assert corner / centre == pytest.approx(1.0 / float(ones[16, 16, 1]), rel=0.02)
    assert corner / centre < 0.6  # wide open: strong fall-off, as lensfun says


@pytest.mark.parametrize("name", ["canon-t6-18mm", "canon-t6-10mm"])
def test_distortion_matches_lensfun(name):
    """Pinhole → sensor mapping agrees with lensfun's geometry map to < 0.3 px over the frame."""
    cam = load_camera(name)
    g = cam.geometry
    mod = _lensfun(cam)
    src = mod.apply_geometry_distortion()  # for each corrected (pinhole) pixel, where the lens imaged it
    ys, xs = np.meshgrid(np.linspace(0, g.height_px - 1, 9).astype(int), np.linspace(0, g.width_px - 1, 9).astype(int))
    pin = np.stack([xs.ravel(), ys.ravel()], axis=-1).astype(float)
    mapping = RadialMapping(cam)
    centre = np.array(g.principal_point_px)
    # lensfun's corrected image is a pinhole of focal f / m0 (its models fix r = 1, not the axis scale)
    corrected = centre + (pin - centre) / mapping.paraxial_magnification
    inside = np.all((corrected >= 0) & (corrected <= [g.width_px - 1, g.height_px - 1]), axis=1)
    pin, corrected = pin[inside], corrected[inside]
    ours = mapping.distort_points_px(pin)
    fy, fx = corrected[:, 1], corrected[:, 0]
    theirs = np.stack(
        [
            np.array([np.interp(x, np.arange(g.width_px), src[round(y), :, 0]) for x, y in zip(fx, fy, strict=False)]),
            np.array([np.interp(y, np.arange(g.height_px), src[:, round(x), 1]) for x, y in zip(fx, fy, strict=False)]),
        ],
        axis=-1,
    )
    assert np.max(np.abs(ours - theirs)) < 0.3
    back = mapping.undistort_points_px(ours)
    assert np.max(np.abs(back - pin)) < 1e-3


def test_natural_relative_illumination_analytic():
    """Without lensfun data: cos⁴θ for a distortion-free lens, cos θ · sin θ / θ for an equidistant one."""
    c270 = load_camera("logitech-c270")
    rectilinear = dataclasses.replace(c270, lens=dataclasses.replace(c270.lens, distortion_terms=(0.0,)))
    g = c270.geometry
    theta = math.atan(math.hypot(g.width_px / 2, g.height_px / 2) / g.focal_length_px)
    assert float(relative_illumination(rectilinear, 2.4, -0.5, -0.5)) == pytest.approx(math.cos(theta) ** 4, rel=2e-3)
    spedal = load_camera("spedal-920")
    g = spedal.geometry
    theta = math.hypot(g.width_px / 2, g.height_px / 2) / g.focal_length_px  # r = f θ
    assert math.degrees(2 * theta) == pytest.approx(120.0, abs=0.2)
    expected = math.cos(theta) * math.sin(theta) / theta
    assert float(relative_illumination(spedal, 2.0, -0.5, -0.5)) == pytest.approx(expected, rel=2e-3)
