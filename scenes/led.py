"""LED emitters: spectrum, absolute radiant intensity and angular pattern.

An LED is described by its datasheet figures (``scenes/data/leds.toml``):

* spectrum: colour-science's single-LED model (Ohno 2005) with the peak wavelength that
  reproduces the datasheet's dominant wavelength, and an assumed FWHM;
* on-axis radiant intensity from the datasheet luminous intensity Iv (cd) at the test
  current: I_e = Iv / K, with K the luminous efficacy of the LED's spectrum (lm/W),
  scaled to the drive current as (I_F / I_ref)^γ;
* angular pattern I(θ) = I₀ cosᵐθ for θ < 90°, zero behind, with m chosen so that the
  intensity halves at the datasheet half-angle θ½: m = ln ½ / ln cos θ½.

The radiant flux of such a source is Φ = 2π I₀ / (m + 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from scenes import spectra
from scenes.sourced import DATA_DIR, load_sourced

SIDE_COLOURS = ("red", "green", "blue", "yellow")
"""Beacon side colours, in the order the study's detector tries them."""


@dataclass(frozen=True)
class LED:
    """One LED type, from its datasheet.

    Attributes
    ----------
    colour
        Side colour it is used for.
    part
        Part description.
    dominant_wavelength_nm, fwhm_nm
        Dominant wavelength and spectral full width at half maximum, nm.
    luminous_intensity_cd
        On-axis luminous intensity at ``reference_current_mA``, cd.
    reference_current_mA, max_current_mA
        Datasheet test current and absolute maximum DC current, mA.
    half_angle_deg
        Off-axis angle at which the intensity halves (θ½), degrees.
    current_exponent
        γ in Iv ∝ I_F^γ.
    lens_diameter_mm
        Diameter of the LED package's lens, mm.
    """

    colour: str
    part: str
    dominant_wavelength_nm: float
    fwhm_nm: float
    luminous_intensity_cd: float
    reference_current_mA: float
    max_current_mA: float
    half_angle_deg: float
    current_exponent: float
    lens_diameter_mm: float

    @property
    def cos_exponent(self) -> float:
        """m in I(θ) = I₀ cosᵐθ, from the half-angle (dimensionless)."""
        return math.log(0.5) / math.log(math.cos(math.radians(self.half_angle_deg)))

    @cached_property
    def peak_wavelength_nm(self) -> float:
        """Peak wavelength of the model spectrum that has the datasheet λD, nm."""
        return spectra.peak_for_dominant_nm(self.dominant_wavelength_nm, self.fwhm_nm)

    @property
    def spectral_shape(self) -> NDArray[np.float64]:
        """Normalised emission spectrum on :data:`scenes.spectra.WAVELENGTHS_NM`, nm⁻¹."""
        return spectra.led_shape(self.peak_wavelength_nm, self.fwhm_nm)

    @cached_property
    def luminous_efficacy_lm_per_W(self) -> float:
        """Luminous efficacy of the emitted radiation, lm/W."""
        return spectra.luminous_efficacy_lm_per_W(self.spectral_shape)

    def check_current(self, current_mA: float) -> None:
        """Raise ``ValueError`` unless 0 < current ≤ the absolute maximum."""
        if not (math.isfinite(current_mA) and 0.0 < current_mA <= self.max_current_mA):
            raise ValueError(
                f"led_current_mA: expected 0 < current <= {self.max_current_mA:g} mA "
                f"for the {self.colour} LED, got {current_mA!r}"
            )

    def radiant_intensity_W_sr(self, current_mA: float | None = None) -> float:
        """On-axis radiant intensity I₀ at the drive current, W·sr⁻¹."""
        current = self.reference_current_mA if current_mA is None else current_mA
        self.check_current(current)
        scale = (current / self.reference_current_mA) ** self.current_exponent
        return self.luminous_intensity_cd / self.luminous_efficacy_lm_per_W * scale

    def relative_intensity(self, theta_rad: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """I(θ)/I₀ = cosᵐθ for θ < 90°, else 0 (dimensionless)."""
        c = np.cos(np.asarray(theta_rad, dtype=np.float64))
        return np.where(c > 0.0, np.clip(c, 0.0, None) ** self.cos_exponent, 0.0)

    def radiant_flux_W(self, current_mA: float | None = None) -> float:
        """Total radiant flux Φ = 2π I₀ / (m + 1), W."""
        return 2.0 * math.pi * self.radiant_intensity_W_sr(current_mA) / (self.cos_exponent + 1.0)


@lru_cache(maxsize=1)
def load_leds() -> dict[str, LED]:
    """All LEDs of ``scenes/data/leds.toml``, keyed by side colour."""
    values, _ = load_sourced(DATA_DIR / "leds.toml")
    leds = {colour: LED(colour=colour, **fields) for colour, fields in values.items()}
    missing = set(SIDE_COLOURS) - set(leds)
    if missing:
        raise ValueError(f"leds.toml: missing side colours {sorted(missing)}")
    return leds


def led_for_side(side: str) -> LED:
    """The LED used on a beacon side (``red``, ``green``, ``blue`` or ``yellow``)."""
    leds = load_leds()
    if side not in leds:
        raise ValueError(f"side: expected one of {', '.join(SIDE_COLOURS)}, got {side!r}")
    return leds[side]
