"""Veiling glare, defocus and pixel crosstalk (camera_models/glare.py) against independent answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, ndimage, signal

from camera_models.camera import load_camera
from camera_models.glare import (
    GlareSpread,
    OpticsEffects,
    apply_crosstalk,
    apply_glare,
    convolve_full,
    crop_centre,
    crosstalk_kernel,
    defocus_blur_diameter_m,
    glare_kernel,
    pillbox_kernel,
    tail_encircled,
    tail_fraction_beyond,
    tail_kernel,
)
from camera_models.optics import _UNIT_OPTICS, optical_image
from camera_models.sensor import cfa_channels
from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance

SPREAD = GlareSpread(fraction=0.02, knee_um=10.0, exponent=2.0, outer_radius_mm=1.0)  # R = 232.6 px at 4.3 µm
PITCH_UM = 4.3


@pytest.mark.parametrize("p", [1.5, 2.0, 2.7])
def test_encircled_energy_matches_numerical_integral(p):
    """The closed-form ∫ 2πr (r² + r0²)^(−p/2) dr equals quad's integral."""
    for r in (0.5, 3.0, 40.0, 700.0):
        ref, _ = integrate.quad(lambda x: 2 * math.pi * x * (x * x + 2.3**2) ** (-p / 2), 0.0, r, limit=200)
        assert float(tail_encircled(r, knee=2.3, exponent=p)) == pytest.approx(ref, rel=1e-10)


def test_tail_kernel_energy_and_fraction_outside_radius():
    """The kernel plus the analytic energy beyond it is 1; the fraction beyond R in the kernel
    equals the analytic integral (pixelisation of the circle is the only difference)."""
    kernel, beyond = tail_kernel(SPREAD, PITCH_UM, max_radius_px=100)
    assert kernel.sum() + beyond == pytest.approx(1.0, abs=1e-12)
    knee, outer = SPREAD.knee_px(PITCH_UM), SPREAD.outer_px(PITCH_UM)
    ln = math.log1p((100 / knee) ** 2) / math.log1p((outer / knee) ** 2)  # p = 2: energy within 100 px
    assert beyond == pytest.approx(1.0 - ln, rel=1e-12)
    h = kernel.shape[0] // 2
    yy, xx = np.mgrid[-h : h + 1, -h : h + 1]
    for radius in (10.0, 30.0, 60.0):
        outside = kernel[np.hypot(xx, yy) > radius].sum() + beyond
        expected = float(tail_fraction_beyond(radius, knee=knee, exponent=2.0, outer=outer))
        assert outside == pytest.approx(expected, rel=5e-3), radius


def test_combined_kernel_sums_to_one_and_point_source_keeps_its_energy():
    """(1 − g) core + g tail sums to 1 − g·beyond; a point source on a padded grid keeps its
    total to 1e-9 (the crop plus what glare carries out of it)."""
    core = np.outer(*(2 * [signal.windows.gaussian(9, 1.2)]))
    core /= core.sum()
    tail, beyond = tail_kernel(SPREAD, PITCH_UM, max_radius_px=SPREAD.outer_px(PITCH_UM) + 1)
    assert beyond == pytest.approx(0.0, abs=1e-15)  # the kernel holds the whole tail
    full_kernel = glare_kernel(core, tail, SPREAD.fraction)
    assert full_kernel.sum() == pytest.approx(1.0, abs=1e-12)
    image = np.zeros((61, 61))
    image[30, 30] = 1.0e6
    padded = convolve_full(image, full_kernel)
    assert padded.sum() == pytest.approx(1.0e6, rel=1e-9)
    inside, outside = apply_glare(image, tail, SPREAD.fraction)
    assert inside.sum() + outside == pytest.approx(1.0e6, rel=1e-9)
    # what left the 61 × 61 crop lies between the tail beyond its inscribed and its circumscribed circle
    knee, outer = SPREAD.knee_px(PITCH_UM), SPREAD.outer_px(PITCH_UM)
    lo = SPREAD.fraction * float(tail_fraction_beyond(30.5 * math.sqrt(2), knee=knee, exponent=2.0, outer=outer))
    hi = SPREAD.fraction * float(tail_fraction_beyond(30.5, knee=knee, exponent=2.0, outer=outer))
    assert lo < outside / 1.0e6 < hi


def test_fft_application_equals_direct_convolution():
    rng = np.random.default_rng(4)
    image = rng.uniform(0.0, 1.0, (37, 23))
    small = GlareSpread(fraction=0.05, knee_um=6.0, exponent=2.5, outer_radius_mm=0.06)
    tail, _ = tail_kernel(small, PITCH_UM, max_radius_px=40)
    direct = signal.convolve2d(image, tail, mode="full")
    fft = convolve_full(image, tail)
    assert np.max(np.abs(fft - direct)) <= 1e-10 * np.max(np.abs(direct))
    inside, _ = apply_glare(image, tail, small.fraction)
    same = ndimage.convolve(image, tail, mode="constant", cval=0.0)
    ref = (1 - small.fraction) * image + small.fraction * same
    assert np.max(np.abs(inside - ref)) <= 1e-10 * np.max(ref)
    assert np.array_equal(crop_centre(fft, image.shape).shape, image.shape)


def test_defocus_diameter_thin_lens_by_hand():
    """f = 18 mm, N = 3.5, focus 2 m, object 5 m: c = 0.018² · 3 / (3.5 · 5 · 1.982) = 28.02 µm."""
    c = defocus_blur_diameter_m(focal_length_m=0.018, f_number=3.5, focus_distance_m=2.0, object_distance_m=5.0)
    assert c == pytest.approx(0.018**2 * 3.0 / (3.5 * 5.0 * 1.982), rel=1e-12)
    assert c == pytest.approx(28.02e-6, rel=1e-3)
    # the same from image distances: blur = aperture · |v_d − v_s| / v_d (thin-lens equation 1/v = 1/f − 1/u)
    f, a = 0.018, 0.018 / 3.5
    v_s, v_d = 1 / (1 / f - 1 / 2.0), 1 / (1 / f - 1 / 5.0)
    assert c == pytest.approx(a * abs(v_d - v_s) / v_d, rel=1e-12)
    assert defocus_blur_diameter_m(focal_length_m=0.018, f_number=3.5, focus_distance_m=5.0, object_distance_m=5.0) == 0
    with pytest.raises(ValueError, match=r"^defocus"):
        defocus_blur_diameter_m(focal_length_m=0.018, f_number=3.5, focus_distance_m=0.01, object_distance_m=5.0)


def test_pillbox_is_a_normalised_disc_of_the_right_area():
    k = pillbox_kernel(20.0, supersample=16)
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    assert k[k.shape[0] // 2, k.shape[1] // 2] * math.pi * 10.0**2 == pytest.approx(1.0, rel=2e-3)  # interior
    assert np.count_nonzero(k) * 1.0 == pytest.approx(math.pi * 10.5**2, rel=0.05)  # the disc plus its rim
    assert np.array_equal(pillbox_kernel(0.0), np.ones((1, 1)))


@pytest.mark.parametrize("supersample", [4, 8])
def test_pillbox_of_any_small_diameter_is_finite_and_keeps_the_light(supersample):
    """A disc smaller than the diagonal of the sample points nearest the centre (√2/ss) holds none:
    the identity; from there on it holds the four central points of the centre pixel. (Diameters
    between 1/ss and √2/ss once gave 0/0, a NaN kernel, and a frame that could not be exposed.)"""
    edge = math.sqrt(2.0) / supersample
    for d in np.linspace(0.0, 3.0, 601):
        k = pillbox_kernel(d, supersample=supersample)
        assert np.isfinite(k).all() and k.sum() == pytest.approx(1.0, abs=1e-12)
        if d < edge * (1 - 1e-9):
            assert np.array_equal(k, np.ones((1, 1)))
        elif d < 2.0 / supersample:  # still inside the centre pixel only
            assert k[k.shape[0] // 2, k.shape[1] // 2] == pytest.approx(1.0)


def test_crosstalk_keeps_energy_and_mixes_the_mosaic():
    k = crosstalk_kernel(0.04, diagonal_share=0.2)
    assert k.sum() == pytest.approx(1.0, abs=1e-15) and k[1, 1] == pytest.approx(0.96)
    rng = np.random.default_rng(1)
    e = rng.uniform(0.0, 100.0, (20, 30, 3))
    cfa = cfa_channels("RGGB", 3, 5, 20, 30)
    out, spilled = apply_crosstalk(e, k, cfa)
    m = np.take_along_axis(e, cfa[..., None].astype(np.intp), axis=2)[..., 0]
    m_out = np.take_along_axis(out, cfa[..., None].astype(np.intp), axis=2)[..., 0]
    assert m_out.sum() + spilled.sum() == pytest.approx(m.sum(), rel=1e-12)
    ref = ndimage.convolve(m, k, mode="constant", cval=0.0)  # mosaic spread by the kernel, independently
    assert np.allclose(m_out, ref, rtol=1e-12, atol=1e-9)


def _spot(camera_name: str) -> SpectralRadiance:
    g = load_camera(camera_name).geometry
    cx, cy = (int(c) for c in g.principal_point_px)
    grid = PixelGrid(g.width_px, g.height_px, g.focal_length_px, g.principal_point_px, cx - 40, cy - 40, 80, 80, 2)
    image = np.zeros(grid.shape, np.float32)
    image[78:82, 78:82] = 5.0e4
    shape = np.asarray(spectra.led_shape(630.0, 20.0))
    return SpectralRadiance(grid, (RadianceComponent("led:red", image, shape),), {"range_m": 5.0}, "synthetic")


def test_all_switches_off_is_the_plain_path_bit_for_bit():
    cam = load_camera("canon-t6-18mm")
    rad = _spot("canon-t6-18mm")
    plain = optical_image(rad, cam, 1 / 60, 3.5)
    off = optical_image(rad, cam, 1 / 60, 3.5, effects=OpticsEffects())
    assert np.array_equal(plain.electrons_rgb, off.electrons_rgb) and off.spilled_electrons_rgb is None
    # in focus (d = s) is no defocus either
    focused = optical_image(rad, cam, 1 / 60, 3.5, effects=OpticsEffects(focus_distance_m=5.0))
    assert np.array_equal(plain.electrons_rgb, focused.electrons_rgb)


def test_unit_render_cache_keys_on_defocus():
    """A cached unit render (linear stages done once) must not serve a defocused request, nor the reverse."""
    cam = load_camera("canon-t6-18mm")
    rad = _spot("canon-t6-18mm")
    comp = rad.components[0]
    unit = RadianceComponent(comp.name, comp.image_W_m2_sr, comp.spectral_shape_per_nm, "test-unit", comp.image_W_m2_sr)
    cached = SpectralRadiance(rad.grid, (unit,), rad.scenario, rad.variant)
    _UNIT_OPTICS.clear()
    plain = optical_image(cached, cam, 1 / 60, 3.5).electrons_rgb
    blurred = optical_image(cached, cam, 1 / 60, 3.5, effects=OpticsEffects(focus_distance_m=2.0)).electrons_rgb
    fresh = optical_image(rad, cam, 1 / 60, 3.5, effects=OpticsEffects(focus_distance_m=2.0)).electrons_rgb
    assert np.allclose(blurred, fresh, rtol=1e-12, atol=0) and not np.allclose(plain, blurred)
    assert plain.sum() == pytest.approx(blurred.sum(), rel=1e-3)  # defocus moves light, keeps it (spot well inside)


def test_glare_radius_of_a_point_source_follows_the_tail_in_closed_form():
    """A point source through core + tail: beyond the core the image is g·I·T(r), so the radius where it
    falls to 1e-5 of the peak solves g·c·(r² + r0²)^(−p/2) = 1e-5·peak (c: the tail's normalisation)."""
    knee = SPREAD.knee_px(PITCH_UM)
    outer = SPREAD.outer_px(PITCH_UM)
    core = np.outer(*(2 * [signal.windows.gaussian(9, 1.0)]))
    core /= core.sum()
    tail, _ = tail_kernel(SPREAD, PITCH_UM, max_radius_px=200)
    image = np.zeros((401, 401))
    image[200, 200] = 1.0
    inside, _ = apply_glare(convolve_full(image, core)[4:-4, 4:-4], tail, SPREAD.fraction)
    peak = inside.max()
    profile = inside[200, 200:]
    measured = np.argmax(profile < 1e-5 * peak)  # first pixel along the row below 1e-5 of the peak
    c = 1.0 / float(tail_encircled(outer, knee=knee, exponent=2.0))
    r_expected = math.sqrt(SPREAD.fraction * c / (1e-5 * peak) - knee**2)
    assert abs(measured - r_expected) <= 1.0, (measured, r_expected)
    assert r_expected > 5 * 4  # far beyond the 9-px core: the tail sets it
    without = convolve_full(image, core)[4:-4, 4:-4][200, 200:]
    assert np.argmax(without < 1e-5 * without.max()) <= 5  # the core alone ends at its 9-px edge


def test_glare_on_spreads_light_and_accounts_for_it():
    cam = load_camera("canon-t6-18mm")
    rad = _spot("canon-t6-18mm")
    plain = optical_image(rad, cam, 1 / 60, 3.5)
    glared = optical_image(rad, cam, 1 / 60, 3.5, effects=OpticsEffects(glare=True))
    total = plain.electrons_rgb.sum(axis=(0, 1))
    assert np.allclose(glared.electrons_rgb.sum(axis=(0, 1)) + glared.spilled_electrons_rgb, total, rtol=1e-6)
    corner = (0, 0, 0)
    assert glared.electrons_rgb[corner] > 1e3 * max(plain.electrons_rgb[corner], 1e-12)
    with pytest.raises(ValueError, match=r"^object_distance_m"):
        optical_image(
            SpectralRadiance(rad.grid, rad.components, {}, "x"), cam, 1 / 60, effects=OpticsEffects(focus_distance_m=2)
        )
