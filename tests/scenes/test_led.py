"""LED model: angular pattern, flux, spectrum and photometry against independent answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from scenes import spectra
from scenes.led import load_leds

LEDS = load_leds()


@pytest.mark.parametrize("colour", list(LEDS))
def test_intensity_halves_at_half_angle(colour):
    led = LEDS[colour]
    assert led.relative_intensity(math.radians(led.half_angle_deg)) == pytest.approx(0.5, rel=1e-12)
    assert led.relative_intensity(math.radians(95.0)) == 0.0


@pytest.mark.parametrize("colour", list(LEDS))
def test_flux_is_the_sphere_integral_of_the_pattern(colour):
    led = LEDS[colour]
    i0 = led.radiant_intensity_W_sr()
    # independent: numerical integral of I(θ) over the sphere, 2π ∫ I(θ) sin θ dθ
    flux, _ = integrate.quad(
        lambda t: 2 * math.pi * i0 * float(led.relative_intensity(t)) * math.sin(t),
        0,
        math.pi,
        points=[math.radians(led.half_angle_deg)],
        limit=200,
    )
    assert led.radiant_flux_W() == pytest.approx(flux, rel=1e-6)


@pytest.mark.parametrize("colour", list(LEDS))
def test_model_spectrum_has_datasheet_dominant_wavelength(colour):
    led = LEDS[colour]
    assert spectra.dominant_wavelength_nm(led.spectral_shape) == pytest.approx(led.dominant_wavelength_nm, abs=1.0)
    assert spectra.integrate_nm(led.spectral_shape) == pytest.approx(1.0, rel=1e-9)


def test_luminous_efficacy_of_a_555nm_line_is_683_lm_per_W():
    # independent: the definition of the candela / lumen (V(555 nm) = 1.0000)
    line = spectra.led_shape(555.0, 1.0)
    assert spectra.luminous_efficacy_lm_per_W(line) == pytest.approx(683.0, rel=2e-3)


def test_radiant_intensity_follows_datasheet_candela_and_current():
    led = LEDS["red"]
    k = led.luminous_efficacy_lm_per_W
    assert led.radiant_intensity_W_sr() == pytest.approx(led.luminous_intensity_cd / k, rel=1e-12)
    half = led.radiant_intensity_W_sr(led.reference_current_mA / 2)
    assert half / led.radiant_intensity_W_sr() == pytest.approx(0.5**led.current_exponent, rel=1e-12)


@pytest.mark.parametrize("current", [0.0, -5.0, 1e6, float("nan")])
def test_impossible_current_is_rejected(current):
    with pytest.raises(ValueError, match="led_current_mA: expected 0 < current"):
        LEDS["blue"].radiant_intensity_W_sr(current)


def test_band_average_conserves_the_integral_inside_the_grid():
    shape = spectra.led_shape(525.0, 30.0)
    bands = spectra.band_average(shape)
    widths = np.diff(np.clip(spectra.BAND_EDGES_NM, 380, 720))
    assert np.sum(bands * widths) == pytest.approx(1.0, rel=2e-3)


def test_the_alternative_parts_reproduce_their_sheet():
    """Cree CLD-CT939.000: C503T-GAN (green) and -BAN (blue) are 15° lamps binned 12000-64600 and
    3000-16800 mcd at 20 mA; the catalogue's intensity is each range's geometric mean, to the sheet's
    three figures."""
    from scenes.led import led_part, led_part_names

    gan, ban = led_part("cree-c503t-gan", "green"), led_part("cree-c503t-ban", "blue")
    assert gan.half_angle_deg == ban.half_angle_deg == 7.5
    assert gan.luminous_intensity_cd == pytest.approx(math.sqrt(12.0 * 64.6), rel=1e-3)
    assert ban.luminous_intensity_cd == pytest.approx(math.sqrt(3.0 * 16.8), rel=1e-3)
    assert gan.relative_intensity(math.radians(7.5)) == pytest.approx(0.5, rel=1e-12)
    assert led_part_names("green") == ["green", "cree-c503t-gan"] and led_part_names("red") == ["red"]
    # same drive, 3.3x the on-axis intensity, but a beam a quarter the solid angle: less flux than the 30° part
    ratio = gan.radiant_flux_W(2.0) / LEDS["green"].radiant_flux_W(2.0)
    lobe = {n: 2 * math.pi / (led.cos_exponent + 1) for n, led in (("gan", gan), ("gcn", LEDS["green"]))}
    assert ratio == pytest.approx(27.84 / 8.38 * lobe["gan"] / lobe["gcn"], rel=1e-3)
    with pytest.raises(ValueError, match=r"led: expected a green part for the green side \(green, cree-c503t-gan\), "
                       r"got 'cree-c503t-ban' \(blue\)"):  # fmt: skip
        led_part("cree-c503t-ban", "green")
    with pytest.raises(ValueError, match=r"led: expected one of red, green, .*, got 'nope'"):
        led_part("nope")


@pytest.mark.parametrize("colour", list(LEDS))
def test_the_current_for_a_flux_inverts_the_drive_law(colour):
    led = LEDS[colour]
    for current in (0.5, 2.0, 13.0):
        assert led.current_for_flux_mA(led.radiant_flux_W(current)) == pytest.approx(current, rel=1e-12)
    with pytest.raises(ValueError, match=r"flux_W: expected a radiant flux > 0 W, got 0"):
        led.current_for_flux_mA(0)


def test_the_peak_search_measures_dominant_wavelengths_as_colour_science_does():
    """peak_for_dominant_nm measures its candidates' dominant wavelengths at once (one product with the
    colour-matching functions); each equals colour-science's own sd_to_XYZ path (dominant_wavelength_nm)
    for LED spectra across the four colours' bands and widths."""
    rng = np.random.default_rng(3)
    peaks, widths = rng.uniform(440.0, 650.0, 60), rng.uniform(12.0, 40.0, 60)
    shapes = np.stack([spectra.led_shape(float(p), float(w)) for p, w in zip(peaks, widths, strict=True)])
    one_by_one = [spectra.dominant_wavelength_nm(s) for s in shapes]
    assert spectra._dominant_wavelengths_nm(shapes).tolist() == one_by_one
