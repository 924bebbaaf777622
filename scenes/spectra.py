"""Wavelength grid, LED emission spectra and photometric conversions.

All spectra in the project are sampled on :data:`WAVELENGTHS_NM`: 380–720 nm every
1 nm, the range of the measured camera sensitivities in ``camera_models/data/ssf`` (a
camera with an IR-cut filter sees nothing outside it). A *spectral shape* here is a
spectrum normalised to unit integral over the grid (unit nm⁻¹): a radiometric quantity
Q (W, W·sr⁻¹, W·m⁻²·sr⁻¹) with shape s(λ) has spectral density Q·s(λ) per nm.

Band exports (OpenEXR cubes) average the 1 nm spectra over :data:`BAND_EDGES_NM`,
10 nm bands centred on 380, 390, …, 720 nm, the sample points of the camera data.
"""

from __future__ import annotations

import itertools
from functools import lru_cache

import colour
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BAND_CENTRES_NM",
    "BAND_EDGES_NM",
    "K_M_LM_PER_W",
    "WAVELENGTHS_NM",
    "band_average",
    "cie1931_cmfs",
    "dominant_wavelength_nm",
    "illuminant_shape",
    "integrate_nm",
    "led_shape",
    "luminous_efficacy_lm_per_W",
    "normalise_shape",
    "peak_for_dominant_nm",
    "photopic_luminosity",
]

WAVELENGTHS_NM: NDArray[np.float64] = np.arange(380.0, 720.0 + 0.5, 1.0)
"""Spectral sample grid, nm (1 nm steps)."""

SPECTRAL_SHAPE = colour.SpectralShape(380, 720, 1)

BAND_CENTRES_NM: NDArray[np.float64] = np.arange(380.0, 720.0 + 0.5, 10.0)
"""Centres of the 10 nm export bands, nm."""

BAND_EDGES_NM: NDArray[np.float64] = np.concatenate([BAND_CENTRES_NM - 5.0, [BAND_CENTRES_NM[-1] + 5.0]])

K_M_LM_PER_W = 683.002
"""Maximum luminous efficacy of photopic vision, lm/W (CIE 018:2019; 683 lm/W at 540 THz)."""


def integrate_nm(values: NDArray[np.float64], axis: int = -1) -> NDArray[np.float64]:
    """Integrate samples on :data:`WAVELENGTHS_NM` over wavelength (trapezoid), × nm."""
    return np.trapezoid(values, WAVELENGTHS_NM, axis=axis)


def normalise_shape(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Scale a spectrum on the grid to unit integral, giving a shape in nm⁻¹."""
    values = np.asarray(values, dtype=np.float64)
    total = integrate_nm(values)
    if not np.isfinite(total) or total <= 0:
        raise ValueError("spectrum: expected a non-negative spectrum with positive integral")
    return values / total


@lru_cache(maxsize=64)
def led_shape(peak_wavelength_nm: float, fwhm_nm: float) -> NDArray[np.float64]:
    """Emission shape of a single-colour LED (Ohno 2005 model, colour-science), nm⁻¹.

    Parameters
    ----------
    peak_wavelength_nm
        Peak emission wavelength, nm.
    fwhm_nm
        Full width at half maximum, nm.
    """
    sd = colour.sd_single_led(peak_wavelength_nm, half_spectral_width=fwhm_nm, shape=SPECTRAL_SHAPE)
    out = normalise_shape(sd.values)
    out.setflags(write=False)
    return out


def dominant_wavelength_nm(shape: NDArray[np.float64]) -> float:
    """Dominant wavelength of a spectrum against the equal-energy white point, nm.

    This is how LED datasheets specify colour (CIE 1931 2° observer, resolution 1 nm).
    """
    sd = colour.SpectralDistribution(dict(zip(WAVELENGTHS_NM, shape, strict=True)))
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
        xyz = colour.sd_to_XYZ(sd, cmfs=cie1931_cmfs(), illuminant=colour.sd_ones(SPECTRAL_SHAPE))
    xy = colour.XYZ_to_xy(xyz)
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["E"]
    return float(colour.dominant_wavelength(xy, white, cmfs=cie1931_cmfs())[0])


def _dominant_wavelengths_nm(shapes: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`dominant_wavelength_nm` of many spectra at once (rows of ``shapes``), nm: their XYZ by
    one product with the colour-matching functions (the scale, which xy does not see, left out)."""
    xy = colour.XYZ_to_xy(shapes @ cie1931_cmfs().values)
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["E"]
    return np.asarray(colour.dominant_wavelength(xy, white, cmfs=cie1931_cmfs())[0], dtype=np.float64)


@lru_cache(maxsize=1)
def cie1931_cmfs() -> colour.MultiSpectralDistributions:
    """CIE 1931 2° colour-matching functions on the project's grid."""
    return colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(SPECTRAL_SHAPE)


@lru_cache(maxsize=64)
def peak_for_dominant_nm(dominant_nm: float, fwhm_nm: float) -> float:
    """Peak wavelength whose Ohno LED spectrum has the given dominant wavelength, nm.

    Datasheets quote the dominant wavelength; the LED model takes the peak. For the
    asymmetric colour-matching functions they differ by a few nm (red LEDs peak a few
    nm above their dominant wavelength, green ones below). Solved by a 0.25 nm scan,
    finer than the 1 nm resolution of the dominant wavelength itself.
    """
    candidates = np.arange(dominant_nm - 20.0, dominant_nm + 20.0 + 1e-9, 0.25)
    shapes = np.stack([colour.sd_single_led(float(p), half_spectral_width=fwhm_nm, shape=SPECTRAL_SHAPE).values
                       for p in candidates])  # fmt: skip
    errors = np.abs(_dominant_wavelengths_nm(shapes) - dominant_nm)
    best = np.flatnonzero(errors == errors.min())
    return float(np.median(candidates[best]))


def luminous_efficacy_lm_per_W(shape: NDArray[np.float64]) -> float:
    """Luminous efficacy of radiation K = K_m ∫V(λ)s(λ)dλ / ∫s(λ)dλ, lm/W."""
    v = photopic_luminosity()
    return float(K_M_LM_PER_W * integrate_nm(v * shape) / integrate_nm(shape))


@lru_cache(maxsize=1)
def photopic_luminosity() -> NDArray[np.float64]:
    """CIE 1924 photopic luminous efficiency V(λ) on the grid (dimensionless)."""
    v = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"].copy().align(SPECTRAL_SHAPE)
    return np.asarray(v.values, dtype=np.float64)


@lru_cache(maxsize=16)
def illuminant_shape(name: str) -> NDArray[np.float64]:
    """Relative spectral power of a CIE illuminant from colour-science, as a shape, nm⁻¹.

    ``name`` is a key of ``colour.SDS_ILLUMINANTS`` (e.g. ``"LED-B3"``, ``"FL2"``, ``"D65"``).
    """
    if name not in colour.SDS_ILLUMINANTS:
        raise ValueError(f"illuminant: unknown CIE illuminant {name!r}")
    sd = colour.SDS_ILLUMINANTS[name].copy().align(SPECTRAL_SHAPE)
    out = normalise_shape(np.clip(sd.values, 0.0, None))
    out.setflags(write=False)
    return out


def band_average(values: NDArray[np.float64], axis: int = -1) -> NDArray[np.float64]:
    """Average a spectrum (or array of spectra) on the 1 nm grid over the 10 nm bands.

    Returns the mean spectral density in each band of :data:`BAND_EDGES_NM`, in the same
    unit per nm as the input. The end bands are half outside the grid and average only
    the part inside it.
    """
    values = np.moveaxis(np.asarray(values, dtype=np.float64), axis, -1)
    out = np.empty((*values.shape[:-1], BAND_CENTRES_NM.size))
    for i, (lo, hi) in enumerate(itertools.pairwise(BAND_EDGES_NM)):
        sel = (WAVELENGTHS_NM >= lo) & (WAVELENGTHS_NM <= hi)
        out[..., i] = np.trapezoid(values[..., sel], WAVELENGTHS_NM[sel], axis=-1) / (
            WAVELENGTHS_NM[sel][-1] - WAVELENGTHS_NM[sel][0]
        )
    return np.moveaxis(out, -1, axis)
