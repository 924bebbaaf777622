"""Diffusers: printer paper (white or dyed) and closed-cell foam.

Paper
-----
A sheet is thin (0.1 mm) compared with the marker (12 mm), so it is modelled as a
surface that reflects R₁ and transmits T₁ diffusely (Lambertian on both sides), the
rest being absorbed. Stacking N such sheets with multiple reflections between them is
the *adding* method for diffuse layers, which for identical Kubelka–Munk layers gives
exactly the KM result for N-fold thickness: transmittance falls roughly as
1/(1 + N·SX) for weak absorption, not as T₁ᴺ. The sheet's KM scattering SX and
absorption KX follow from (R₁, T₁) by KM inversion; a dyed sheet keeps SX and adds a dye
absorption K_dye(λ)X derived from a measured reflectance spectrum (see the data file).

Foam
----
Closed-cell foam is a homogeneous scattering medium filling the housing's aperture,
described by its reduced optical depth τ' = σs(1 − g)t, anisotropy g (Henyey–Greenstein
phase function) and single-scattering albedo. The renderer uses the real extinction
σt = τ'/((1 − g)t): an isotropic medium with the reduced coefficient would give the same
diffuse transmission but let e^(−τ') of the LED's beam through unscattered, a hot spot
a real foam does not have.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import colour
import numpy as np
from numpy.typing import NDArray

from scenes import spectra
from scenes.led import SIDE_COLOURS
from scenes.sourced import DATA_DIR, load_sourced

__all__ = [
    "MAX_PAPER_SHEETS",
    "DiffuserConfig",
    "Foam",
    "Paper",
    "adding",
    "colour_module_patch",
    "default_foam",
    "foam_optical_depth_from_transmittance",
    "foam_transmittance_diffusion",
    "km_invert",
    "km_layer",
    "paper",
    "stack",
]

PAPER_COLOURS = ("white", "matched", *SIDE_COLOURS)
MAX_PAPER_SHEETS = 5


# -- Kubelka–Munk -----------------------------------------------------------------------
def km_layer(sx, kx):
    """Diffuse reflectance and transmittance of a Kubelka–Munk layer.

    Parameters
    ----------
    sx, kx
        Scattering S·X and absorption K·X of the layer (dimensionless, X its thickness).

    Returns
    -------
    R, T
        Diffuse reflectance and transmittance (no interface reflections).
    """
    sx, kx = np.asarray(sx, dtype=np.float64), np.asarray(kx, dtype=np.float64)
    a = 1.0 + kx / sx
    b = np.sqrt(a * a - 1.0)
    bsx = b * sx
    denom = a * np.sinh(bsx) + b * np.cosh(bsx)
    return np.sinh(bsx) / denom, b / denom


def km_invert(r, t):
    """S·X and K·X of the KM layer with diffuse reflectance ``r`` and transmittance ``t``."""
    r, t = np.asarray(r, dtype=np.float64), np.asarray(t, dtype=np.float64)
    a = (1.0 + r * r - t * t) / (2.0 * r)
    b = np.sqrt(a * a - 1.0)
    sx = np.arctanh(b * r / (1.0 - a * r)) / b  # SX = (1/b) arcoth((1 − aR)/(bR))
    return sx, sx * (a - 1.0)


def adding(r1, t1, r2, t2):
    """Diffuse reflectance and transmittance of layer 1 on top of layer 2 (light enters
    through layer 1; both layers symmetric), with all inter-reflections."""
    inter = 1.0 / (1.0 - r1 * r2)
    return r1 + t1 * t1 * r2 * inter, t1 * t2 * inter


def stack(r1, t1, n: int):
    """R and T of ``n`` identical diffuse sheets by repeated adding (n = 0 is no sheet)."""
    r, t = np.zeros_like(np.asarray(r1, float)), np.ones_like(np.asarray(t1, float))
    for _ in range(n):
        r, t = adding(r, t, r1, t1)
    return r, t


# -- paper -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Paper:
    """One sheet's optics on :data:`scenes.spectra.WAVELENGTHS_NM`.

    Attributes
    ----------
    colour
        ``white`` or a dye colour.
    reflectance, transmittance
        Diffuse reflectance R₁(λ) and transmittance T₁(λ) of one sheet (dimensionless).
    thickness_m
        Sheet thickness, m.
    """

    colour: str
    reflectance: NDArray[np.float64]
    transmittance: NDArray[np.float64]
    thickness_m: float

    def at(self, wavelength_nm: float) -> tuple[float, float]:
        """(R₁, T₁) at one wavelength (linear interpolation)."""
        return (
            float(np.interp(wavelength_nm, spectra.WAVELENGTHS_NM, self.reflectance)),
            float(np.interp(wavelength_nm, spectra.WAVELENGTHS_NM, self.transmittance)),
        )


@lru_cache(maxsize=1)
def _paper_data() -> dict:
    values, _ = load_sourced(DATA_DIR / "diffusers.toml")
    return values


@lru_cache(maxsize=32)
def paper(colour: str, sheet_transmittance: float | None = None) -> Paper:
    """The sheet optics for ``colour`` (``white``, ``red``, ``green``, ``blue``, ``yellow``).

    ``sheet_transmittance``: the white sheet's T₁ instead of the data file's (the sheet
    reflectance stays the file's; T₁ + R₁ ≤ 1, :meth:`DiffuserConfig.validate`).
    """
    p = _paper_data()["paper"]
    r1 = p["sheet_reflectance"]
    t1 = p["sheet_transmittance"] if sheet_transmittance is None else sheet_transmittance
    sx, kx_white = km_invert(r1, t1)
    n = spectra.WAVELENGTHS_NM.size
    if colour == "white":
        r, t = np.full(n, r1), np.full(n, t1)
    else:
        patches = p["dye_patch"]
        if colour not in patches:
            raise ValueError(f"paper_colour: expected one of {', '.join(PAPER_COLOURS)}, got {colour!r}")
        sd = colour_module_patch(p["dye_reference"], patches[colour])
        r_inf = np.clip(sd, 1e-4, 0.999)
        k_over_s = (1.0 - r_inf) ** 2 / (2.0 * r_inf)
        # The patch's K/S has a non-selective floor (its grey/black component and
        # substrate); a dyed paper has only the selective part, on top of the fibre's own.
        selective = k_over_s - k_over_s.min()
        kx = kx_white + selective * sx
        r, t = km_layer(np.full(n, sx), kx)
    return Paper(colour, np.asarray(r), np.asarray(t), p["thickness_mm"] * 1e-3)


def colour_module_patch(dataset: str, patch: str) -> NDArray[np.float64]:
    """Reflectance of a colour-science ColorChecker patch on the project grid."""
    sd = colour.SDS_COLOURCHECKERS[dataset][patch].copy()
    with colour.utilities.suppress_warnings(colour_runtime_warnings=True):
        sd = sd.interpolate(colour.SpectralShape(380, 720, 1))
    return np.asarray(sd.values, dtype=np.float64)


# -- foam ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Foam:
    """Closed-cell foam slab: thickness (m), reduced optical depth, HG anisotropy g, albedo."""

    thickness_m: float
    reduced_optical_depth: float
    anisotropy: float
    single_scattering_albedo: float

    @property
    def sigma_t_per_m(self) -> float:
        """Extinction coefficient σt = τ' / ((1 − g) t), m⁻¹ (absorption is tiny)."""
        return self.reduced_optical_depth / ((1.0 - self.anisotropy) * self.thickness_m)


@lru_cache(maxsize=32)
def default_foam(reduced_optical_depth: float | None = None, thickness_mm: float | None = None) -> Foam:
    """The foam of ``scenes/data/diffusers.toml``, with its reduced optical depth τ' and thickness
    (mm) replaced where given."""
    f = _paper_data()["foam"]
    tau = f["reduced_optical_depth"] if reduced_optical_depth is None else reduced_optical_depth
    thickness_mm = f["thickness_mm"] if thickness_mm is None else thickness_mm
    return Foam(thickness_mm * 1e-3, tau, f["anisotropy"], f["single_scattering_albedo"])


def foam_transmittance_diffusion(reduced_optical_depth: float, albedo: float = 1.0) -> float:
    """Diffuse transmittance of a foam slab under diffuse light, diffusion estimate.

    Two-flux (KM) slab with S·X = (3/4)τ' and K·X = 2(1 − ω)τ'/… : for a conservative
    medium T = 1 / (1 + ¾τ'). A quick estimate for planning; the near-field renderer
    gives the value for the real housing.
    """
    sx = 0.75 * reduced_optical_depth
    kx = max(2.0 * (1.0 - albedo) * reduced_optical_depth, 1e-12)
    return float(km_layer(sx, kx)[1])


def foam_optical_depth_from_transmittance(transmittance: float, albedo: float = 1.0) -> float:
    """Invert :func:`foam_transmittance_diffusion`: τ' from a measured diffuse transmittance.

    How to measure: photograph one marker square-on with and without its foam at the
    same exposure (no paper), sum the marker's raw signal above background in each, and
    take the ratio as the foam's transmittance.
    """
    if not 0.0 < transmittance < 1.0:
        raise ValueError(f"transmittance: expected a value in (0, 1), got {transmittance!r}")
    lo, hi = 1e-6, 1e4
    for _ in range(200):  # bisection: T decreases monotonically with τ'
        mid = math.sqrt(lo * hi)
        if foam_transmittance_diffusion(mid, albedo) > transmittance:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


# -- a marker's diffuser configuration -------------------------------------------------
@dataclass(frozen=True)
class DiffuserConfig:
    """Foam on/off, number of paper sheets and their colour (``matched`` = side colour), and the
    materials' unknowns where a scenario replaces the data file's values
    (:mod:`scenes.data_overrides`; None: the file's).

    Attributes
    ----------
    foam, paper_sheets, paper_colour
        The stack in front of every LED.
    foam_reduced_optical_depth
        τ' of the foam disc (dimensionless).
    foam_thickness_mm
        Thickness of the foam disc, mm.
    sheet_transmittance
        Diffuse transmittance T₁ of one white sheet (a dyed sheet keeps its dye on top).
    """

    foam: bool = False
    paper_sheets: int = 0
    paper_colour: str = "white"
    foam_reduced_optical_depth: float | None = None
    foam_thickness_mm: float | None = None
    sheet_transmittance: float | None = None

    def validate(self) -> None:
        """Raise ``ValueError`` naming the bad field."""
        if not isinstance(self.foam, bool):
            raise ValueError(f"foam: expected true or false, got {self.foam!r}")
        if not isinstance(self.paper_sheets, int) or not 0 <= self.paper_sheets <= MAX_PAPER_SHEETS:
            raise ValueError(f"paper_sheets: expected an integer 0-{MAX_PAPER_SHEETS}, got {self.paper_sheets!r}")
        if self.paper_colour not in PAPER_COLOURS:
            raise ValueError(f"paper_colour: expected one of {', '.join(PAPER_COLOURS)}, got {self.paper_colour!r}")
        r1 = _paper_data()["paper"]["sheet_reflectance"]
        if self.sheet_transmittance is not None and not 0.0 < self.sheet_transmittance < 1.0 - r1 - 1e-9:
            raise ValueError(
                f"data.diffusers.paper.sheet_transmittance: expected 0 < T < 1 - R = {1.0 - r1:.2f} (R: the sheet "
                "reflectance of scenes/data/diffusers.toml; a sheet absorbs some light), "
                f"got {self.sheet_transmittance!r}"
            )

    def foam_optics(self) -> Foam:
        """The foam disc's optics."""
        return default_foam(self.foam_reduced_optical_depth, self.foam_thickness_mm)

    def sheet(self, side: str) -> Paper:
        """One sheet's optics on a side."""
        return paper(self.paper_colour_for(side), self.sheet_transmittance)

    @property
    def is_bare(self) -> bool:
        """No foam and no paper: the LED is seen directly."""
        return not self.foam and self.paper_sheets == 0

    def paper_colour_for(self, side: str) -> str:
        """The actual paper colour on a side (resolves ``matched``)."""
        return side if self.paper_colour == "matched" else self.paper_colour
