"""The lens: distortion, point-spread function, relative illumination, camera equation.

Input is a render's oversampled radiance (:class:`scenes.radiance.SpectralRadiance`),
output the mean photo-electrons each pixel of the crop would collect for each colour
channel (before the colour filter array picks one per pixel and before noise).

Order: distortion (resample the pinhole render at the undistorted position of each
distorted sub-pixel) → PSF (polychromatic Airy diffraction ⊗ Gaussian aberration,
defocus and low-pass-filter blur) → relative illumination → bin s×s sub-pixels →
camera equation

    E = π L T V(r) / (4 N²)        (irradiance on the sensor, W·m⁻²)

Optional effects (:class:`camera_models.glare.OpticsEffects`, all off by default, which
gives exactly the output of the plain path): defocus (a pillbox convolved into the PSF),
then, on the summed camera-pixel image, the lens's veiling-glare tail and pixel crosstalk.

where V is lensfun's measured relative illumination when the lens has lensfun data
(it already contains the natural cos⁴ fall-off and mechanical vignetting, so no cos⁴θ
is applied on top) and the lens's natural relative illumination cos θ · dΩ/dA
(cos⁴θ for a distortion-free lens) otherwise. Electrons per pixel for channel c are

    e_c = Σ_k  L̄_k · (π T t A_pix / (4 N²)) · ∫ shape_k(λ) QE_c(λ) λ/(h c) dλ

with the spectral integral done once per component, never per pixel.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage, signal, special

from camera_models.camera import Camera, LensModel
from camera_models.glare import (
    OpticsEffects,
    apply_crosstalk,
    apply_glare,
    crosstalk_kernel,
    defocus_blur_diameter_m,
    pillbox_kernel,
    tail_kernel,
)
from camera_models.sensor import cfa_channels
from scenes import spectra
from scenes.radiance import PixelGrid, SpectralRadiance

__all__ = [
    "C_LIGHT_M_S",
    "H_PLANCK_J_S",
    "OpticalImage",
    "RadialMapping",
    "airy_intensity",
    "camera_equation_factor_m2_sr",
    "check_f_number",
    "distortion_resample",
    "electrons_per_joule",
    "optical_image",
    "photons_per_joule",
    "psf_kernel",
    "relative_illumination",
    "turned_grid",
]

H_PLANCK_J_S = 6.62607015e-34
"""Planck constant, J·s (SI 2019, exact)."""
C_LIGHT_M_S = 299792458.0
"""Speed of light in vacuum, m/s (exact)."""


def photons_per_joule(wavelength_nm: NDArray[np.float64]) -> NDArray[np.float64]:
    """λ/(h c): photons per joule at each wavelength."""
    return np.asarray(wavelength_nm) * 1e-9 / (H_PLANCK_J_S * C_LIGHT_M_S)


def electrons_per_joule(shape_per_nm: NDArray[np.float64], qe: NDArray[np.float64]) -> NDArray[np.float64]:
    """∫ shape(λ) QE_c(λ) λ/(hc) dλ for each channel of ``qe`` (3, n): electrons per joule."""
    return spectra.integrate_nm(shape_per_nm[None, :] * qe * photons_per_joule(spectra.WAVELENGTHS_NM)[None, :])


def check_f_number(f_number: float) -> float:
    """Validate an f-number (> 0.5, finite); return it as float."""
    try:
        n = float(f_number)
    except (TypeError, ValueError):
        n = float("nan")
    if not math.isfinite(n) or n < 0.5:
        raise ValueError(f"f_number: expected an f-number >= 0.5, got {f_number!r}")
    return n


def camera_equation_factor_m2_sr(lens: LensModel, f_number: float, pixel_area_m2: float) -> float:
    """π T A_pix / (4 N²): pixel power per unit radiance at the image centre, W per (W·m⁻²·sr⁻¹)."""
    return math.pi * lens.transmittance * pixel_area_m2 / (4.0 * check_f_number(f_number) ** 2)


# -- distortion ----------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RadialMapping:
    """Radial lens mapping between undistorted (pinhole) and distorted (sensor) radii, pixels."""

    camera: Camera

    @property
    def _norm_px(self) -> float:
        g = self.camera.geometry
        return 0.5 * min(g.width_px, g.height_px) / self.camera.lens.distortion_scale

    @property
    def paraxial_magnification(self) -> float:
        """lensfun's image scale on the axis, dr_d/dr_c at 0 (1 − a − b − c, or 1 − k1)."""
        lens = self.camera.lens
        if lens.distortion_model == "ptlens":
            return 1.0 - sum(lens.distortion_terms)
        if lens.distortion_model == "poly3":
            return 1.0 - lens.distortion_terms[0]
        return 1.0

    def distorted_radius_px(self, r_u_px: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sensor radius of a point whose pinhole image lies at radius ``r_u_px``."""
        lens, r_u = self.camera.lens, np.asarray(r_u_px, dtype=np.float64)
        if lens.distortion_model == "equidistant":
            f = self.camera.geometry.focal_length_px
            return f * np.arctan(r_u / f)
        # lensfun's models keep r = 1 fixed, so their paraxial magnification is m0 ≠ 1: lensfun's
        # corrected image is a pinhole of focal f / m0. Ours has the lens's paraxial focal f.
        r_c = r_u / self.paraxial_magnification
        x = r_c / self._norm_px
        if lens.distortion_model == "ptlens":
            a, b, c = lens.distortion_terms
            return r_c * (a * x**3 + b * x**2 + c * x + 1.0 - a - b - c)
        if lens.distortion_model == "poly3":
            (k1,) = lens.distortion_terms
            return r_c * (1.0 - k1 + k1 * x**2)
        raise ValueError(f"distortion.model: expected ptlens, poly3 or equidistant, got {lens.distortion_model!r}")

    def horizontal_fov_deg(self) -> float:
        """Full horizontal field of view through the lens (its mapping, not the pinhole's), degrees:
        twice the field angle whose image falls on the frame's left and right edges."""
        g = self.camera.geometry
        r_u = float(self.undistorted_radius_px(np.array([0.5 * g.width_px]))[0])
        return math.degrees(2 * math.atan(r_u / g.focal_length_px)) if math.isfinite(r_u) else 180.0

    def _table(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        g = self.camera.geometry
        r_max_d = 0.5 * math.hypot(g.width_px, g.height_px) * 1.6
        if self.camera.lens.distortion_model == "equidistant":
            f = g.focal_length_px
            r_u = f * np.tan(np.linspace(0.0, min(r_max_d / f, 0.499 * math.pi), 20001))
        else:
            r_u = np.linspace(0.0, r_max_d * 1.5, 20001)
        r_d = self.distorted_radius_px(r_u)
        if np.any(np.diff(r_d) <= 0):
            keep = np.concatenate([[True], np.cumsum(np.diff(r_d) <= 0) == 0])
            r_u, r_d = r_u[keep], r_d[keep]
        return r_u, r_d

    def undistorted_radius_px(self, r_d_px: NDArray[np.float64]) -> NDArray[np.float64]:
        """Pinhole radius of the point imaged at sensor radius ``r_d_px`` (inverse by table)."""
        r_u, r_d = self._table()
        return np.interp(np.asarray(r_d_px, dtype=np.float64), r_d, r_u, right=np.nan)

    def distort_points_px(self, uv_px: NDArray[np.float64]) -> NDArray[np.float64]:
        """Pinhole pixel positions (…, 2) → where the real lens images them (…, 2)."""
        cx, cy = self.camera.geometry.principal_point_px
        uv = np.asarray(uv_px, dtype=np.float64)
        d = uv - np.array([cx, cy])
        r_u = np.hypot(d[..., 0], d[..., 1])
        scale = np.where(r_u > 0, self.distorted_radius_px(r_u) / np.where(r_u > 0, r_u, 1.0), 1.0)
        return np.array([cx, cy]) + d * scale[..., None]

    def undistort_points_px(self, uv_px: NDArray[np.float64]) -> NDArray[np.float64]:
        """Sensor pixel positions (…, 2) → pinhole positions (…, 2)."""
        cx, cy = self.camera.geometry.principal_point_px
        uv = np.asarray(uv_px, dtype=np.float64)
        d = uv - np.array([cx, cy])
        r_d = np.hypot(d[..., 0], d[..., 1])
        safe = np.where(r_d > 0, r_d, 1.0)
        scale = np.where(r_d > 0, self.undistorted_radius_px(r_d) / safe, 1.0)
        return np.array([cx, cy]) + d * scale[..., None]

    def field_angle_rad(self, r_d_px: NDArray[np.float64]) -> NDArray[np.float64]:
        """Angle off the optical axis of the ray imaged at sensor radius ``r_d_px``."""
        return np.arctan(self.undistorted_radius_px(r_d_px) / self.camera.geometry.focal_length_px)


def relative_illumination(camera: Camera, f_number: float, u_px, v_px) -> NDArray[np.float64]:
    """Relative illumination V at sensor positions (u, v) (1 on the axis).

    With lensfun data: the 'pa' model V = 1 + k1 r² + k2 r⁴ + k3 r⁶ (r = 1 at the
    half-diagonal, rescaled by the crop-factor ratio like the distortion), interpolated
    linearly in 1/N between the lensfun apertures and clamped outside them. Without:
    the natural value cos θ · sin θ / (ρ ρ′) of the lens's mapping ρ(θ) = r_d/f.
    """
    g, lens = camera.geometry, camera.lens
    cx, cy = g.principal_point_px
    r_d = np.hypot(np.asarray(u_px, dtype=np.float64) - cx, np.asarray(v_px, dtype=np.float64) - cy)
    if lens.vignetting:
        n = check_f_number(f_number)
        r = r_d / (0.5 * math.hypot(g.width_px, g.height_px) / lens.distortion_scale)

        def pa(e):
            return 1.0 + e.k1 * r**2 + e.k2 * r**4 + e.k3 * r**6

        entries = lens.vignetting
        if n <= entries[0].f_number:
            return pa(entries[0])
        if n >= entries[-1].f_number:
            return pa(entries[-1])
        for lo, hi in itertools.pairwise(entries):
            if lo.f_number <= n <= hi.f_number:
                w = (1 / lo.f_number - 1 / n) / (1 / lo.f_number - 1 / hi.f_number)
                return (1 - w) * pa(lo) + w * pa(hi)
    mapping = RadialMapping(camera)
    f = g.focal_length_px
    theta = np.linspace(0.0, mapping.field_angle_rad(np.array([r_d.max() * 1.01 + 2.0]))[0], 4001)
    rho = mapping.distorted_radius_px(f * np.tan(theta)) / f
    drho = np.gradient(rho, theta)
    with np.errstate(invalid="ignore", divide="ignore"):
        ri = np.where(theta > 0, np.cos(theta) * np.sin(theta) / (rho * drho), 1.0)
    ri[0] = 1.0
    return np.interp(mapping.field_angle_rad(r_d), theta, ri)


# -- point-spread function ----------------------------------------------------------------------------------------


def airy_intensity(r_m: NDArray[np.float64], wavelength_m: float, f_number: float) -> NDArray[np.float64]:
    """Airy pattern [2 J1(x)/x]², x = π r / (λ N); 1 at the centre."""
    x = np.pi * np.asarray(r_m) / (wavelength_m * f_number)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(x > 1e-9, (2.0 * special.j1(x) / np.where(x > 1e-9, x, 1.0)) ** 2, 1.0)
    return out


def psf_kernel(
    camera: Camera, f_number: float, spectral_weight: NDArray[np.float64], oversampling: int
) -> NDArray[np.float64]:
    """Polychromatic PSF on the oversampled grid (sums to 1), odd square array.

    ``spectral_weight`` (on ``WAVELENGTHS_NM``) weights each wavelength's Airy pattern
    (shape × QE × λ: the electrons it produces); the result is convolved with the
    Gaussian blur of ``lens.blur_sigma_um``. Each sub-pixel integrates the Airy pattern
    over 3×3 points.
    """
    n = check_f_number(f_number)
    pitch_m = camera.geometry.pixel_pitch_um * 1e-6
    sub_m = pitch_m / oversampling
    w = np.asarray(spectral_weight, dtype=np.float64)
    lam_nm = spectra.WAVELENGTHS_NM[::10]
    w10 = np.add.reduceat(w, np.arange(0, w.size, 10))[: lam_nm.size]
    if w10.sum() <= 0:
        w10 = np.ones_like(lam_nm)
    w10 = w10 / w10.sum()
    lam_eff = float(np.sum(w10 * lam_nm)) * 1e-9
    sigma_m = camera.lens.blur_sigma_um * 1e-6
    radius_m = max(4.0 * sigma_m, 6.0 * 1.22 * lam_eff * n, 1.5 * pitch_m)
    half = math.ceil(radius_m / sub_m)
    offsets = (np.arange(-half, half + 1)) * sub_m
    fine = (np.array([-1.0, 0.0, 1.0]) / 3.0) * sub_m
    xx = (offsets[:, None] + fine[None, :]).ravel()
    rr = np.hypot(xx[:, None], xx[None, :])
    airy = np.zeros_like(rr)
    for wk, lam in zip(w10, lam_nm, strict=True):
        if wk > 1e-6:
            airy += wk * airy_intensity(rr, lam * 1e-9, n) / (lam * 1e-9) ** 2
    size = offsets.size
    airy = airy.reshape(size, 3, size, 3).sum(axis=(1, 3))
    if sigma_m > 0:
        g = np.exp(-0.5 * (offsets / sigma_m) ** 2)
        kernel = signal.fftconvolve(airy, np.outer(g, g), mode="same")
    else:
        kernel = airy
    kernel = np.clip(kernel, 0.0, None)
    return kernel / kernel.sum()


# -- the whole optical path -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OpticalImage:
    """Mean photo-electrons per pixel and channel over a crop of the frame.

    Attributes
    ----------
    electrons_rgb
        (height, width, 3) float64: electrons a pixel would collect behind each colour
        filter during the exposure (before noise and clipping).
    x0, y0
        Frame position of the crop's top-left pixel, camera pixels.
    spilled_electrons_rgb
        (3,) electrons per channel that the glare tail and crosstalk carried out of the
        crop (so electrons_rgb.sum() + spilled = the total without them); None when
        neither effect is on.
    """

    electrons_rgb: NDArray[np.float64]
    x0: int
    y0: int
    spilled_electrons_rgb: NDArray[np.float64] | None = None


def _pinhole_rays(uv_px: NDArray[np.float64], grid: PixelGrid) -> NDArray[np.float64]:
    """Directions (…, 3) in the camera frame of pinhole pixel positions (…, 2) (z = 1)."""
    cx, cy = grid.principal_point_px
    f = grid.focal_length_px
    return np.stack([(uv_px[..., 0] - cx) / f, (uv_px[..., 1] - cy) / f, np.ones(uv_px.shape[:-1])], axis=-1)


def _pinhole_pixels(rays: NDArray[np.float64], grid: PixelGrid) -> NDArray[np.float64]:
    """Pinhole pixel positions (…, 2) of directions (…, 3); NaN for a direction behind the camera."""
    cx, cy = grid.principal_point_px
    f = grid.focal_length_px
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(rays[..., 2] > 1e-9, rays[..., 2], np.nan)
        return np.stack([cx + f * rays[..., 0] / z, cy + f * rays[..., 1] / z], axis=-1)


def turned_grid(grid: PixelGrid, camera: Camera, view: NDArray[np.float64]) -> PixelGrid:
    """The crop of the frame a render on ``grid`` covers once the camera is turned off the render's
    axis: ``view`` (3 × 3) takes a direction in the camera's frame to the render's
    (:meth:`scenes.scenario.Scenario.view_rotation`). The render's border, every sub-pixel of it,
    mapped through ``view`` and the real lens into the frame: the box around it, clipped to the
    frame, same oversampling.

    Raises
    ------
    ValueError
        When the render falls behind the camera or outside its frame.
    """
    s = grid.oversampling
    u, v = grid.subpixel_centres_px()
    border = np.concatenate(
        [
            np.stack([u, np.full(u.size, v[0])], axis=-1),
            np.stack([u, np.full(u.size, v[-1])], axis=-1),
            np.stack([np.full(v.size, u[0]), v], axis=-1),
            np.stack([np.full(v.size, u[-1]), v], axis=-1),
        ]
    )
    pinhole = _pinhole_pixels(_pinhole_rays(border, grid) @ np.asarray(view), grid)  # rows: d_cam = viewᵀ d_render
    if not np.all(np.isfinite(pinhole)):
        raise ValueError("pan_deg: the beacon lies behind the turned camera (|turn| too large)")
    mapping = RadialMapping(camera)
    uv = mapping.distort_points_px(pinhole)
    back = mapping.undistort_points_px(uv)  # beyond the lens's one-to-one field the mapping folds back
    if not np.all(np.hypot(*(back - pinhole).T) < 0.5):
        raise ValueError(f"pan_deg: the turned {camera.name} does not see the beacon: it falls outside its frame")
    x0 = max(0, math.floor(float(uv[:, 0].min()) + 0.5))  # the pixel each border sub-pixel falls in
    y0 = max(0, math.floor(float(uv[:, 1].min()) + 0.5))
    x1 = min(grid.frame_width_px, math.floor(float(uv[:, 0].max()) + 0.5) + 1)
    y1 = min(grid.frame_height_px, math.floor(float(uv[:, 1].max()) + 0.5) + 1)
    if x1 <= x0 or y1 <= y0 or not np.all(np.isfinite(uv)):
        raise ValueError(f"pan_deg: the turned {camera.name} does not see the beacon: it falls outside its frame")
    return replace(grid, x0=x0, y0=y0, width=x1 - x0, height=y1 - y0, oversampling=s)


def distortion_resample(
    image: NDArray[np.float32],
    grid: PixelGrid,
    camera: Camera,
    *,
    out: PixelGrid | None = None,
    view: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Resample a pinhole render onto the distorted sensor, bilinear.

    Each output sub-pixel centre (on ``out``, default the render's own ``grid``) is mapped to its
    undistorted position and, for a camera turned off the render's axis by ``view`` (see
    :func:`turned_grid`), along its ray into the render's camera; radiance is conserved along rays,
    so values are taken, not rescaled. Outside the render: 0.
    """

    out = grid if out is None else out
    u, v = out.subpixel_centres_px()
    uu, vv = np.meshgrid(u, v)
    und = RadialMapping(camera).undistort_points_px(np.stack([uu, vv], axis=-1))
    if view is not None:
        und = _pinhole_pixels(_pinhole_rays(und, grid) @ np.asarray(view).T, grid)
    s = grid.oversampling
    # sub-pixel index of camera-pixel coordinate p: (p - x0 + 0.5) * s - 0.5
    col = (und[..., 0] - grid.x0 + 0.5) * s - 0.5
    row = (und[..., 1] - grid.y0 + 0.5) * s - 0.5
    coords = np.stack([np.nan_to_num(row, nan=-1e9), np.nan_to_num(col, nan=-1e9)])
    return ndimage.map_coordinates(np.asarray(image, dtype=np.float64), coords, order=1, mode="constant", cval=0.0)


def optical_image(
    radiance: SpectralRadiance,
    camera: Camera,
    exposure_s: float,
    f_number: float | None = None,
    *,
    effects: OpticsEffects | None = None,
    view: NDArray[np.float64] | None = None,
) -> OpticalImage:
    """Mean electrons per pixel and channel for a render seen through ``camera``'s lens.

    Parameters
    ----------
    radiance
        The render (oversampled radiance components on the camera's pixel grid).
    camera
        The camera (lens and sensor QE are used).
    exposure_s
        Exposure time, s (> 0).
    f_number
        Working f-number; default the lens's.
    effects
        Defocus, veiling glare and pixel crosstalk to apply (default: the camera's
        ``effects``, which are none unless a task switches them on).
    view
        For a camera turned off the render's axis: the rotation (3 × 3) from the camera's frame to
        the render's (:meth:`scenes.scenario.Scenario.view_rotation`); the image is then made on the
        crop of the frame where the turned camera sees the render (:func:`turned_grid`), with the
        distortion and relative illumination of that place. None: the render's own crop.
    """
    if not math.isfinite(exposure_s) or exposure_s <= 0:
        raise ValueError(f"exposure_s: expected a time > 0 s, got {exposure_s!r}")
    n = camera.lens.f_number if f_number is None else check_f_number(f_number)
    source = radiance.grid
    grid = source if view is None else turned_grid(source, camera, view)
    turn = None if view is None else (tuple(np.round(np.asarray(view), 12).ravel().tolist()), grid)
    effects = camera.effects if effects is None else effects
    defocus_subpx = _defocus_subpixels(radiance, camera, n, effects)
    factor = camera_equation_factor_m2_sr(camera.lens, n, camera.pixel_area_m2) * exposure_s
    u, v = grid.subpixel_centres_px()
    ri = None

    def illumination():
        nonlocal ri
        if ri is None:
            ri = relative_illumination(camera, n, u[None, :], v[:, None])
        return ri

    out = np.zeros((grid.height, grid.width, 3))
    for comp in radiance.components:
        if comp.spectral_shape_per_nm is None or not np.any(comp.image_W_m2_sr):
            continue
        if comp.unit_key is not None and comp.unit_image is not None:
            # linear in radiance: the lens's work on the unit render is done once and rescaled
            cache_key = (comp.unit_key, camera.name, n, source)
            if turn is not None:
                cache_key += (("view", turn),)
            if defocus_subpx > 0:  # the only effect applied per component (glare and crosstalk act on the sum)
                cache_key += (("defocus_subpx", defocus_subpx),)
            binned = _UNIT_OPTICS.get(cache_key)
            if binned is None:
                binned = _lens_image(
                    comp.unit_image, comp.spectral_shape_per_nm, source, camera, n, illumination(), defocus_subpx,
                    out=grid, view=view,
                )  # fmt: skip
                _UNIT_OPTICS[cache_key] = binned
                while len(_UNIT_OPTICS) > 32:
                    _UNIT_OPTICS.pop(next(iter(_UNIT_OPTICS)))
            out += binned * (comp.scale * factor)
        else:
            out += (
                _lens_image(
                    comp.image_W_m2_sr,
                    comp.spectral_shape_per_nm,
                    source,
                    camera,
                    n,
                    illumination(),
                    defocus_subpx,
                    out=grid,
                    view=view,
                )
                * factor
            )
    if not (effects.glare or effects.crosstalk):
        return OpticalImage(out, grid.x0, grid.y0)
    spilled = np.zeros(3)
    if effects.glare:
        spread = camera.lens.glare
        if spread is None:
            raise ValueError(f"glare: camera {camera.name!r} has no [optics.glare] data")
        tail, _ = _tail_kernel(spread, camera.geometry.pixel_pitch_um, int(effects.glare_radius_px))
        for c in range(3):
            out[..., c], spilled[c] = apply_glare(out[..., c], tail, spread.fraction)
    if effects.crosstalk:
        kernel = crosstalk_kernel(camera.lens.crosstalk_fraction, diagonal_share=camera.lens.crosstalk_diagonal_share)
        cfa = cfa_channels(camera.sensor.cfa, grid.x0, grid.y0, grid.height, grid.width)
        out, lost = apply_crosstalk(out, kernel, cfa)
        spilled += lost
    return OpticalImage(out, grid.x0, grid.y0, spilled)


def _defocus_subpixels(radiance: SpectralRadiance, camera: Camera, n: float, effects: OpticsEffects) -> float:
    """Defocus blur-circle diameter in rendered sub-pixels (0 when in focus or not asked for)."""
    if effects.focus_distance_m is None:
        return 0.0
    d = effects.object_distance_m
    if d is None:
        d = (radiance.scenario or {}).get("range_m")
    if d is None:
        raise ValueError("object_distance_m: defocus needs the object's distance (none given, none in the render)")
    pitch_m = camera.geometry.pixel_pitch_um * 1e-6
    c_m = defocus_blur_diameter_m(
        focal_length_m=camera.geometry.focal_length_px * pitch_m,
        f_number=n,
        focus_distance_m=effects.focus_distance_m,
        object_distance_m=float(d),
    )
    diameter = c_m / pitch_m * radiance.grid.oversampling
    return diameter if pillbox_kernel(diameter).size > 1 else 0.0


@functools.lru_cache(maxsize=8)
def _tail_kernel(spread, pixel_pitch_um: float, radius_px: int):
    return tail_kernel(spread, pixel_pitch_um, max_radius_px=radius_px)


_UNIT_OPTICS: dict[tuple, NDArray[np.float64]] = {}
"""Lens images of unit renders (see :func:`optical_image`), most recent 32."""


def _lens_image(
    image, shape_per_nm, source, camera: Camera, n: float, ri, defocus_subpx: float = 0.0, *, out=None, view=None
):
    """Distortion (from the render on ``source`` to the crop ``out``, turned by ``view``: see
    :func:`distortion_resample`), PSF per channel (with a defocus pillbox of ``defocus_subpx``
    sub-pixels' diameter when > 0), relative illumination and binning of one radiance image:
    (height, width, 3) electrons per pixel of ``out`` per unit of the camera-equation factor."""
    grid = source if out is None else out
    s = grid.oversampling
    qe = camera.sensor.qe_rgb
    image = distortion_resample(image, source, camera, out=grid, view=view)
    e_per_j = electrons_per_joule(shape_per_nm, qe)
    out = np.empty((grid.height, grid.width, 3))
    for c in range(3):
        weight = shape_per_nm * qe[c] * spectra.WAVELENGTHS_NM
        psf = psf_kernel(camera, n, weight, s)
        if defocus_subpx > 0:
            psf = signal.fftconvolve(psf, pillbox_kernel(defocus_subpx), mode="full")
            psf = np.clip(psf, 0.0, None) / np.clip(psf, 0.0, None).sum()
        blurred = signal.fftconvolve(image, psf, mode="same")
        out[..., c] = (np.clip(blurred, 0.0, None) * ri).reshape(grid.height, s, grid.width, s).mean(axis=(1, 3))
        out[..., c] *= e_per_j[c]
    return out
