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
