"""Light the lens and sensor put far from (or beside) the image point: glare, defocus, crosstalk.

Three effects the diffraction + Gaussian PSF of :func:`camera_models.optics.psf_kernel`
(which reaches ~4 px) leaves out, each a linear, shift-invariant spread of light:

* **Veiling glare** (stray light from multiple reflections between lens surfaces, surface
  and bulk scatter, the barrel and mirror box): a point source "contributes some light to
  all other sensor pixels" (Talvala et al. 2007). Its glare spread function is modelled as

      G(r) = (1 − g) · PSF_core(r) + g · T(r),   T(r) ∝ (r² + r0²)^(−p/2)  for r ≤ R,

  a fraction ``g`` of the light in a radially symmetric tail of the Harvey-Shack form
  (a power law of slope −p with a knee at r0; the form stray-light codes use for polished
  optical surfaces) truncated at radius R on the sensor. The tail's encircled energy is
  analytic (:func:`tail_encircled`), so the fraction beyond any radius is known exactly.
* **Defocus**: a thin lens of focal length f at f-number N focused at distance s images an
  object at distance d as a uniform disc (pillbox) of diameter
  c = f² |d − s| / (N d (s − f)) on the sensor (:func:`defocus_blur_diameter_m`).
* **Pixel crosstalk**: a fraction of the charge generated under one pixel's colour filter
  is collected by its neighbours (optical and carrier crosstalk): a 3×3 kernel applied to
  the *mosaic* (:func:`apply_crosstalk`), so it mixes colours as on a real Bayer sensor.

All functions are pure functions on arrays. The glare tail is wide (hundreds of pixels),
so it is applied at camera-pixel resolution by FFT convolution on the crop padded with the
kernel's radius (:func:`convolve_full`): the light it carries beyond the crop is returned
rather than silently lost, so energy can be checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

__all__ = [
    "GlareSpread",
    "OpticsEffects",
    "apply_crosstalk",
    "apply_glare",
    "convolve_full",
    "crop_centre",
    "crosstalk_kernel",
    "defocus_blur_diameter_m",
    "glare_kernel",
    "pillbox_kernel",
    "tail_density_px",
    "tail_encircled",
    "tail_fraction_beyond",
    "tail_kernel",
    "tail_profile",
]

# -- veiling glare ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GlareSpread:
    """A lens's veiling-glare tail (see module docstring).

    Attributes
    ----------
    fraction
        g: fraction of the light reaching the sensor that goes into the tail (0-1).
    knee_um
        r0: radius of the tail's knee on the sensor, µm (> 0).
    exponent
        p: the tail falls as r^(−p) beyond the knee (> 0).
    outer_radius_mm
        R: radius on the sensor beyond which the tail is cut off, mm (> r0).
    """

    fraction: float
    knee_um: float
    exponent: float
    outer_radius_mm: float

    def __post_init__(self):
        if not 0.0 <= self.fraction < 1.0:
            raise ValueError(f"glare.fraction: expected 0 <= g < 1, got {self.fraction!r}")
        if not self.knee_um > 0 or not self.exponent > 0:
            raise ValueError(f"glare: expected knee_um > 0 and exponent > 0, got {self.knee_um!r}, {self.exponent!r}")
        if not self.outer_radius_mm * 1e3 > self.knee_um:
            raise ValueError(f"glare.outer_radius_mm: expected > knee, got {self.outer_radius_mm!r}")

    def knee_px(self, pixel_pitch_um: float) -> float:
        """r0 in pixels of pitch ``pixel_pitch_um`` (µm)."""
        return self.knee_um / pixel_pitch_um

    def outer_px(self, pixel_pitch_um: float) -> float:
        """R in pixels of pitch ``pixel_pitch_um`` (µm)."""
        return self.outer_radius_mm * 1e3 / pixel_pitch_um


def tail_profile(r, *, knee: float, exponent: float) -> NDArray[np.float64]:
    """Unnormalised tail (r² + r0²)^(−p/2) at radius ``r`` (any length unit, same as ``knee``)."""
    r = np.asarray(r, dtype=np.float64)
    return (r * r + knee * knee) ** (-0.5 * exponent)


def tail_encircled(r, *, knee: float, exponent: float) -> NDArray[np.float64]:
    """∫₀^r 2πρ (ρ² + r0²)^(−p/2) dρ, closed form (units: length^(2−p) of ``r``, ``knee``).

    p ≠ 2: 2π/(2 − p) · [(r² + r0²)^(1−p/2) − r0^(2−p)];  p = 2: π ln(1 + r²/r0²).
    """
    r = np.asarray(r, dtype=np.float64)
    if abs(exponent - 2.0) < 1e-12:
        return math.pi * np.log1p((r / knee) ** 2)
    q = 1.0 - 0.5 * exponent
    return 2.0 * math.pi / (2.0 - exponent) * ((r * r + knee * knee) ** q - knee ** (2.0 * q))


def tail_fraction_beyond(radius, *, knee: float, exponent: float, outer: float) -> NDArray[np.float64]:
    """Fraction of the (normalised, truncated) tail's energy beyond ``radius`` (same unit as ``knee``, ``outer``)."""
    total = tail_encircled(outer, knee=knee, exponent=exponent)
    inside = tail_encircled(np.minimum(np.asarray(radius, dtype=np.float64), outer), knee=knee, exponent=exponent)
    return 1.0 - inside / total


def tail_density_px(r_px, *, knee_px: float, exponent: float, outer_px: float) -> NDArray[np.float64]:
    """The normalised tail T(r) per unit pixel area (∫ T dA = 1 over r ≤ R), px⁻²; 0 beyond R."""
    r = np.asarray(r_px, dtype=np.float64)
    t = tail_profile(r, knee=knee_px, exponent=exponent) / tail_encircled(outer_px, knee=knee_px, exponent=exponent)
    return np.where(r <= outer_px, t, 0.0)


def tail_kernel(
    spread: GlareSpread, pixel_pitch_um: float, *, max_radius_px: int, supersample: int = 5
) -> tuple[NDArray[np.float64], float]:
    """The glare tail on the pixel grid, cut at a disc of radius h = min(``max_radius_px``, R).

    Each pixel holds the tail's energy over the part of its area inside the disc
    (``supersample``² points per pixel, midpoint rule), rescaled so the kernel's sum is the
    exact (closed-form) energy of the unit tail within radius h. The energy beyond h, the
    far and faint part of the tail, is returned with it.

    Returns
    -------
    kernel
        (2h + 1, 2h + 1) float64, pixels of pitch ``pixel_pitch_um``.
    beyond
        Energy of the unit tail beyond radius h: 1 − kernel.sum() (to rounding).
    """
    knee, outer = spread.knee_px(pixel_pitch_um), spread.outer_px(pixel_pitch_um)
    radius = float(min(max_radius_px, outer))
    half = math.ceil(radius)
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    x = (np.arange(-half, half + 1)[:, None] + sub[None, :]).ravel()
    r = np.hypot(x[:, None], x[None, :])
    t = np.where(r <= radius, tail_profile(r, knee=knee, exponent=spread.exponent), 0.0)
    n = 2 * half + 1
    kernel = t.reshape(n, supersample, n, supersample).sum(axis=(1, 3))
    beyond = float(tail_fraction_beyond(radius, knee=knee, exponent=spread.exponent, outer=outer))
    return kernel * ((1.0 - beyond) / kernel.sum()), beyond


def glare_kernel(core: NDArray[np.float64], tail: NDArray[np.float64], fraction: float) -> NDArray[np.float64]:
    """(1 − g)·core + g·tail on the tail's (larger) grid, both centred odd squares: the whole
    glare spread function of :func:`tail_kernel` and a core PSF on the same pixel grid."""
    out = fraction * np.asarray(tail, dtype=np.float64).copy()
    h, hc = tail.shape[0] // 2, core.shape[0] // 2
    if hc > h:
        raise ValueError("glare_kernel: the core is wider than the tail")
    out[h - hc : h + hc + 1, h - hc : h + hc + 1] += (1.0 - fraction) * core
    return out


# -- defocus ------------------------------------------------------------------------------------------------------


def defocus_blur_diameter_m(
    *, focal_length_m: float, f_number: float, focus_distance_m: float, object_distance_m: float
) -> float:
    """Geometric blur-circle diameter on the sensor, m (thin lens).

    c = f² |d − s| / (N d (s − f)) for a lens of focal length f (m) at f-number N focused
    at distance s (m) viewing an object at distance d (m), both measured from the lens;
    0 when d = s.
    """
    f, n, s, d = float(focal_length_m), float(f_number), float(focus_distance_m), float(object_distance_m)
    if not (f > 0 and n > 0 and s > f and d > f):
        raise ValueError(f"defocus: expected f > 0, N > 0 and distances beyond f, got f={f}, N={n}, s={s}, d={d}")
    return f * f * abs(d - s) / (n * d * (s - f))


def pillbox_kernel(diameter_px: float, *, supersample: int = 8) -> NDArray[np.float64]:
    """Uniform disc of ``diameter_px`` (pixels of the grid it is used on), odd square, sums to 1.

    Each pixel holds the disc's area fraction over ``supersample``² points; a disc that holds
    none of them (a diameter below √2 / ``supersample``, the diagonal of the points nearest the
    centre) gives the identity kernel [[1]]: its light stays in its pixel.
    """
    radius = 0.5 * float(diameter_px)
    half = math.ceil(radius + 0.5)
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    x = (np.arange(-half, half + 1)[:, None] + sub[None, :]).ravel()
    inside = (x[:, None] ** 2 + x[None, :] ** 2 <= radius * radius).astype(np.float64)
    n = 2 * half + 1
    k = inside.reshape(n, supersample, n, supersample).sum(axis=(1, 3))
    total = k.sum()
    return k / total if total > 0 else np.ones((1, 1))


# -- pixel crosstalk ----------------------------------------------------------------------------------------------


def crosstalk_kernel(fraction: float, *, diagonal_share: float = 0.0) -> NDArray[np.float64]:
    """3×3 kernel: the pixel keeps 1 − ``fraction`` of its charge; its 4 edge neighbours share
    ``fraction`` · (1 − ``diagonal_share``), its 4 diagonal neighbours the rest. Sums to 1."""
    if not 0.0 <= fraction < 1.0 or not 0.0 <= diagonal_share <= 1.0:
        raise ValueError(f"crosstalk: expected 0 <= fraction < 1, 0 <= diagonal_share <= 1, got {fraction!r}")
    edge, diag = fraction * (1.0 - diagonal_share) / 4.0, fraction * diagonal_share / 4.0
    return np.array([[diag, edge, diag], [edge, 1.0 - fraction, edge], [diag, edge, diag]])


def apply_crosstalk(
    electrons_rgb: NDArray[np.float64], kernel: NDArray[np.float64], cfa_index: NDArray[np.integer]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Crosstalk on the mosaic, expressed on a per-channel image.

    The charge a pixel's own filter lets through, M = e[cfa], spreads by ``kernel`` into
    its neighbours whatever their filters (M' = M ⊛ k). Every channel of the result is
    e_c + (M' − M), clipped at 0, so the mosaic of the result is exactly M' and the other
    channels change by the same amount.

    Parameters
    ----------
    electrons_rgb
        (rows, cols, 3) mean electrons per pixel and channel.
    kernel
        3×3 crosstalk kernel (:func:`crosstalk_kernel`).
    cfa_index
        (rows, cols) channel of each pixel's filter (:func:`camera_models.sensor.cfa_channels`).

    Returns
    -------
    electrons
        (rows, cols, 3) with crosstalk.
    spilled
        (3,) electrons, by the channel they were generated in, that crosstalk moved out of the crop.
    """
    e = np.asarray(electrons_rgb, dtype=np.float64)
    ch = np.asarray(cfa_index).astype(np.intp)
    m = np.take_along_axis(e, ch[..., None], axis=2)[..., 0]
    spilled = np.zeros(3)
    m_new = np.zeros_like(m)
    for c in range(3):
        mc = np.where(ch == c, m, 0.0)
        full = signal.convolve2d(mc, kernel, mode="full")
        inner = full[1:-1, 1:-1]
        m_new += inner
        spilled[c] = full.sum() - inner.sum()
    return np.clip(e + (m_new - m)[..., None], 0.0, None), spilled


# -- application ----------------------------------------------------------------------------------------------------


def convolve_full(image: NDArray[np.float64], kernel: NDArray[np.float64]) -> NDArray[np.float64]:
    """``image`` ⊛ ``kernel`` on the image padded by the kernel's half-width on every side (FFT):
    shape (rows + 2h, cols + 2h); its sum is image.sum() · kernel.sum()."""
    return signal.fftconvolve(np.asarray(image, dtype=np.float64), kernel, mode="full")


def crop_centre(full: NDArray[np.float64], shape: tuple[int, int]) -> NDArray[np.float64]:
    """The central ``shape`` of a :func:`convolve_full` result (the original crop)."""
    hy, hx = (full.shape[0] - shape[0]) // 2, (full.shape[1] - shape[1]) // 2
    return full[hy : hy + shape[0], hx : hx + shape[1]]


def apply_glare(
    image: NDArray[np.float64], tail: NDArray[np.float64], fraction: float
) -> tuple[NDArray[np.float64], float]:
    """(1 − g)·image + g·(image ⊛ tail) over the crop, and the energy that left it.

    Parameters
    ----------
    image
        (rows, cols) signal per pixel (any unit: electrons, W) after the core PSF.
    tail
        Tail kernel of :func:`tail_kernel` (sums to 1 − the tail's energy beyond it).
    fraction
        g, the glare fraction.

    Returns
    -------
    inside
        (rows, cols): the glared image over the crop.
    outside
        Energy (same unit × pixels) the tail carried out of the crop: into the margin the
        kernel reaches plus the tail beyond the kernel. inside.sum() + outside = image.sum().
    """
    img = np.asarray(image, dtype=np.float64)
    if fraction == 0.0:
        return img.copy(), 0.0
    spread = convolve_full(img, tail)
    inside_tail = crop_centre(spread, img.shape)
    inside = (1.0 - fraction) * img + fraction * inside_tail
    outside = fraction * (img.sum() - inside_tail.sum())
    return inside, float(outside)


# -- switches -----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OpticsEffects:
    """Which of the effects above :func:`camera_models.optics.optical_image` applies (default none).

    Attributes
    ----------
    glare
        Apply the lens's veiling-glare tail (``LensModel.glare``).
    focus_distance_m
        Distance the lens is focused at, m; None: in focus (no defocus blur).
    object_distance_m
        Distance of the imaged object (the beacon), m, for the defocus blur; None: the
        render's ``scenario["range_m"]``.
    crosstalk
        Apply pixel crosstalk (``LensModel.crosstalk_fraction``).
    glare_radius_px
        Radius of the glare kernel actually convolved, camera pixels; the tail beyond
        it (far, faint) is counted as light leaving the crop.
    """

    glare: bool = False
    focus_distance_m: float | None = None
    object_distance_m: float | None = None
    crosstalk: bool = False
    glare_radius_px: int = 512

    @property
    def any(self) -> bool:
        """Whether any effect is on."""
        return self.glare or self.focus_distance_m is not None or self.crosstalk
