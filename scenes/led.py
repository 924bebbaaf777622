"""LED emitters: spectrum, absolute radiant intensity and angular pattern.

An LED is described by its datasheet figures (``scenes/data/leds.toml``, the default part of each
side colour; ``scenes/data/led_parts.toml``, other parts a beacon file may name):

* spectrum: colour-science's single-LED model (Ohno 2005) with the peak wavelength that
  reproduces the datasheet's dominant wavelength, and an assumed FWHM;
* on-axis radiant intensity from the datasheet luminous intensity Iv (cd) at the test
  current: I_e = Iv / K, with K the luminous efficacy of the LED's spectrum (lm/W),
  scaled to the drive current as (I_F / I_ref)^γ;
* angular pattern I(θ)/I₀ = (1 − s) cosᵐθ + s cos θ for θ < 90°, zero behind: the lens's
  main lobe, with m chosen so that the intensity halves at the datasheet half-angle θ½
  (m = ln ½ / ln cos θ½), plus a weak Lambertian *wide* component of relative strength s
  (``wide_fraction``): chip light that the reflector cup and the dome do not focus, scattered
  in the epoxy and leaving through the dome's flanks. I(0) = I₀ for every s.

The radiant flux of such a source is Φ = I₀ [(1 − s) 2π / (m + 1) + s π]. Where a datasheet
gives both Φ and I₀, :func:`wide_fraction_for_flux` solves this for s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from scenes import spectra
from scenes.sourced import DATA_DIR, load_sourced

__all__ = [
    "HUE_BANDS_NM",
    "LED",
    "SIDE_COLOURS",
    "check_hue",
    "led_for_side",
    "led_part",
    "led_part_names",
    "led_parts",
    "load_leds",
    "side_led",
    "wide_fraction_for_flux",
]

SIDE_COLOURS = ("red", "green", "blue", "yellow")
"""Beacon side colours, in the order the study's detector tries them."""

HUE_BANDS_NM: dict[str, tuple[float, float]] = {
    "red": (610.0, 640.0),
    "green": (500.0, 540.0),
    "blue": (450.0, 480.0),
    "yellow": (583.0, 600.0),
}
"""Dominant wavelengths (nm) a side of each colour may be given (a beacon file's
``[dominant_wavelength_nm]`` table; the design search's side colour). Assumed: the bands 5 mm lamps
of each colour are sold in, around the default parts' datasheet bins (``scenes/data/leds.toml``:
red 618-630 nm, blue 465-475 nm, yellow 585-595 nm, green typical 527 nm): AlInGaP red from
red-orange (610 nm) to deep red (640 nm); InGaN green from cyan "traffic" green (500 nm) to pure
green (540 nm), leaving out AlInGaP yellow-green (560-575 nm), which would crowd yellow; InGaN
royal blue (450 nm) to blue (480 nm); AlInGaP yellow (583 nm) to amber (600 nm), short of
orange, which would crowd red. The bands keep the four colours apart as the study's tracker
names them, so a side keeps its name."""


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
    wide_fraction
        s: relative on-axis strength of the Lambertian wide component (dimensionless, 0-1).
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
    wide_fraction: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.wide_fraction < 1.0:
            raise ValueError(f"wide_fraction: expected 0 <= s < 1, got {self.wide_fraction!r}")

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

    def current_for_flux_mA(self, flux_W: float) -> float:
        """The drive current whose radiant flux is ``flux_W`` (W), mA: the inverse of
        :meth:`radiant_flux_W`, I_F = I_ref (Φ / Φ_ref)^(1/γ); not checked against the maximum."""
        if not (math.isfinite(flux_W) and flux_W > 0):
            raise ValueError(f"flux_W: expected a radiant flux > 0 W, got {flux_W!r}")
        return self.reference_current_mA * (flux_W / self.radiant_flux_W()) ** (1.0 / self.current_exponent)

    def radiant_intensity_W_sr(self, current_mA: float | None = None) -> float:
        """On-axis radiant intensity I₀ at the drive current, W·sr⁻¹."""
        current = self.reference_current_mA if current_mA is None else current_mA
        self.check_current(current)
        scale = (current / self.reference_current_mA) ** self.current_exponent
        return self.luminous_intensity_cd / self.luminous_efficacy_lm_per_W * scale

    def relative_intensity(self, theta_rad: NDArray[np.float64] | float) -> NDArray[np.float64]:
        """I(θ)/I₀ = (1 − s) cosᵐθ + s cos θ for θ < 90°, else 0 (dimensionless)."""
        c = np.clip(np.cos(np.asarray(theta_rad, dtype=np.float64)), 0.0, None)
        s = self.wide_fraction
        return np.where(c > 0.0, (1.0 - s) * c**self.cos_exponent + s * c, 0.0)

    @property
    def flux_per_intensity_sr(self) -> float:
        """Φ / I₀ = (1 − s) 2π / (m + 1) + s π, sr."""
        s = self.wide_fraction
        return (1.0 - s) * 2.0 * math.pi / (self.cos_exponent + 1.0) + s * math.pi

    def radiant_flux_W(self, current_mA: float | None = None) -> float:
        """Total radiant flux Φ = I₀ [(1 − s) 2π / (m + 1) + s π], W."""
        return self.radiant_intensity_W_sr(current_mA) * self.flux_per_intensity_sr


def wide_fraction_for_flux(flux_per_intensity_sr: float, half_angle_deg: float) -> float:
    """The wide fraction s that gives a lamp of half-angle θ½ the datasheet ratio Φ / I₀.

    Parameters
    ----------
    flux_per_intensity_sr
        Datasheet total flux over on-axis intensity, Φv / Iv (lm/cd = sr) or Φe / Ie (W/(W·sr⁻¹)).
    half_angle_deg
        Datasheet half-angle θ½, degrees.

    Returns
    -------
    float
        s (dimensionless); ``ValueError`` if the ratio is below the bare cosᵐ lobe's 2π/(m + 1)
        or above a Lambertian source's π.
    """
    m = math.log(0.5) / math.log(math.cos(math.radians(half_angle_deg)))
    lobe = 2.0 * math.pi / (m + 1.0)
    if not lobe <= flux_per_intensity_sr < math.pi:
        raise ValueError(f"flux_per_intensity_sr: expected {lobe:.4f} <= Φ/I₀ < π sr, got {flux_per_intensity_sr!r}")
    return (flux_per_intensity_sr - lobe) / (math.pi - lobe)


@lru_cache(maxsize=1)
def load_leds() -> dict[str, LED]:
    """All LEDs of ``scenes/data/leds.toml``, keyed by side colour."""
    values, _ = load_sourced(DATA_DIR / "leds.toml")
    leds = {colour: LED(colour=colour, **fields) for colour, fields in values.items()}
    missing = set(SIDE_COLOURS) - set(leds)
    if missing:
        raise ValueError(f"leds.toml: missing side colours {sorted(missing)}")
    return leds


@lru_cache(maxsize=1)
def led_parts() -> dict[str, LED]:
    """Every LED part a beacon may use, by name: the four default parts of ``scenes/data/leds.toml``
    under their colour (``red``, ``green``, ``blue``, ``yellow``), then the alternatives of
    ``scenes/data/led_parts.toml`` under their ids (e.g. ``cree-c503t-gan``, a 15° green lamp)."""
    parts = dict(load_leds())
    values, _ = load_sourced(DATA_DIR / "led_parts.toml")
    for name, fields in values.items():
        fields = dict(fields)
        colour = fields.pop("colour", None)
        if colour not in SIDE_COLOURS:
            raise ValueError(
                f"led_parts.toml: {name}.colour: expected one of {', '.join(SIDE_COLOURS)}, got {colour!r}"
            )
        parts[name] = LED(colour=colour, **fields)
    return parts


def led_part_names(colour: str) -> list[str]:
    """The parts of one colour, its default (named by the colour) first."""
    return [n for n, p in led_parts().items() if p.colour == colour]


def led_part(name: str, side: str | None = None) -> LED:
    """The LED part ``name`` (:func:`led_parts`); with ``side``, refused unless it is of that side's colour.

    Examples
    --------
    >>> led_part("cree-c503t-gan", "green").half_angle_deg
    7.5
    """
    parts = led_parts()
    if name not in parts:
        raise ValueError(f"led: expected one of {', '.join(parts)}, got {name!r}")
    if side is not None and parts[name].colour != side:
        fits = ", ".join(led_part_names(side))
        got = f"{name!r} ({parts[name].colour})"
        raise ValueError(f"led: expected a {side} part for the {side} side ({fits}), got {got}")
    return parts[name]


def check_hue(side: str, dominant_nm: float) -> float:
    """``dominant_nm`` as a float when it lies in the side colour's band (:data:`HUE_BANDS_NM`), else a
    one-line ``ValueError`` naming the side and the band.

    >>> check_hue("green", 505)
    505.0
    """
    if side not in HUE_BANDS_NM:
        raise ValueError(f"side: expected one of {', '.join(SIDE_COLOURS)}, got {side!r}")
    low, high = HUE_BANDS_NM[side]
    if isinstance(dominant_nm, bool) or not isinstance(dominant_nm, int | float) or not low <= dominant_nm <= high:
        raise ValueError(
            f"dominant_wavelength_nm.{side}: expected a {side} dominant wavelength of {low:g}-{high:g} nm, "
            f"got {dominant_nm!r}"
        )
    return float(dominant_nm)


def led_for_side(side: str) -> LED:
    """The default LED of a side's colour (``red``, ``green``, ``blue`` or ``yellow``); a beacon may
    name another part of that colour (:meth:`scenes.beacon.BeaconDesign.led`)."""
    leds = load_leds()
    if side not in leds:
        raise ValueError(f"side: expected one of {', '.join(SIDE_COLOURS)}, got {side!r}")
    return leds[side]


def side_led(side: str, part: str | None = None, dominant_nm: float | None = None) -> LED:
    """The LED of a beacon side: the ``part`` named (:func:`led_part`, of the side's colour), else the
    colour's default, at the dominant wavelength ``dominant_nm`` (nm; :func:`check_hue` is the caller's)
    if given, with the part's other figures (its luminous intensity bin included: assumed, as datasheets
    bin intensity and wavelength apart).

    >>> side_led("green", dominant_nm=512).dominant_wavelength_nm
    512.0
    """
    led = led_for_side(side) if part is None else led_part(part, side)
    return led if dominant_nm is None else replace(led, dominant_wavelength_nm=float(dominant_nm))
