"""Airborne dust between camera and beacon: a homogeneous attenuating medium (Beer–Lambert).

Dust of extinction coefficient σ (m⁻¹) passes T = exp(−σ d) of the light that crosses d metres of
it. Visibility is the usual way to state σ: Koschmieder's law gives the distance V at which a black
object's contrast against the sky falls to a threshold ε as V = −ln ε / σ; with Koschmieder's
ε = 2 % (1924) σ V = 3.912, with the WMO's 5 % for the meteorological optical range 2.996. Light the
dust scatters *into* the view (a veil, a halo around each marker) is not modelled: with it a marker
would lose more contrast, so ranges found with dust are upper bounds. Against Mitsuba's homogeneous
medium (tests/scenes/test_dust.py) the direct view is exp(−σ d) within 1 % and the veil beside a lit
disc is under 1 % of its radiance at 5-10 m visibility.

>>> round(extinction_per_m(10.0), 4), round(transmittance(extinction_per_m(10.0), 10.0), 3)
(0.3912, 0.02)
"""

from __future__ import annotations

import math

__all__ = ["KOSCHMIEDER_CONTRAST", "extinction_per_m", "transmittance", "visual_range_m"]

KOSCHMIEDER_CONTRAST = 0.02
"""Contrast threshold of Koschmieder's visual range (Koschmieder 1924, Beiträge zur Physik der freien
Atmosphäre 12: 33-53, 171-181): σ V = −ln 0.02 = 3.912."""


def extinction_per_m(visual_range_m: float) -> float:
    """Extinction coefficient (m⁻¹) of dust with Koschmieder visual range ``visual_range_m`` (m)."""
    if not visual_range_m > 0:
        raise ValueError(f"visual_range_m: expected a distance > 0 m, got {visual_range_m!r}")
    return -math.log(KOSCHMIEDER_CONTRAST) / visual_range_m


def visual_range_m(extinction: float) -> float:
    """Koschmieder visual range (m) of dust with extinction coefficient ``extinction`` (m⁻¹; inf in clear air)."""
    return math.inf if extinction == 0 else -math.log(KOSCHMIEDER_CONTRAST) / extinction


def transmittance(extinction: float, distance_m: float) -> float:
    """Fraction of light that crosses ``distance_m`` (m) of dust of extinction ``extinction`` (m⁻¹)."""
    return math.exp(-extinction * distance_m)
