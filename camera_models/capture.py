"""One frame through the whole camera: render → lens → exposure → sensor → ISP → JPEG.

The crop around the beacon comes from :func:`scenes.render.render` at full detail;
the rest of the frame, when a background render (:mod:`scenes.background`) is given,
from that cheap low-resolution render (camera equation and relative illumination, no
PSF), so automatic exposure meters the whole frame and the saved image is full size.

A full-frame capture (``full=True``) puts the sensor's noise, the ISP and the JPEG on every
pixel of the frame, so its saved image has the false blobs sensor noise makes all over a
dark frame; a crop capture (``full=False``) has them only inside the crop. ``noise=False``
gives the noiseless frame (:func:`noiseless_raw`): the two then agree pixel for pixel inside
the crop, away from its edges (a check of the whole-frame path).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camera_models.camera import Camera
from camera_models.exposure import ExposureSettings, auto_exposure, manual_exposure
from camera_models.isp import ProcessedImage, process
from camera_models.isp_reference import reference_process
from camera_models.optics import (
    RadialMapping,
    camera_equation_factor_m2_sr,
    electrons_per_joule,
    optical_image,
    relative_illumination,
)
from camera_models.sensor import SensorSettings, bloom, cfa_channels, mosaic
from camera_models.sensor_paths import expose
from scenes.radiance import SpectralRadiance
from scenes.view import project

__all__ = [
    "Capture",
    "background_electrons_per_s",
    "capture",
    "frame_meter",
    "full_frame_mosaic",
    "marker_core_saturation",
    "marker_pixels",
    "noiseless_raw",
]


@dataclass(frozen=True)
class Capture:
    """What the camera produced, with the settings it chose.

    Attributes
    ----------
    raw
        Raw mosaic (DN, uint16) of the frame region ``(x0, y0)`` + shape.
    image
        The ISP's output (8-bit sRGB and JPEG bytes).
    exposure
        Exposure settings used.
    x0, y0
        Frame position of ``raw``'s top-left pixel (0, 0 for a full frame).
    saturated_fraction
        Fraction of the raw pixels at the clip level.
    """

    raw: NDArray[np.uint16]
    image: ProcessedImage
    exposure: ExposureSettings
    x0: int
    y0: int
    saturated_fraction: float


def background_electrons_per_s(background: SpectralRadiance, camera: Camera, f_number: float) -> NDArray[np.float64]:
    """Electrons per second per camera pixel and channel on the low-resolution background grid (rows, cols, 3)."""
    g = background.grid
    scale = camera.geometry.width_px / g.frame_width_px
    factor = camera_equation_factor_m2_sr(camera.lens, f_number, camera.pixel_area_m2)
    out = np.zeros((g.height, g.width, 3))
    for comp in background.components:
        if comp.spectral_shape_per_nm is None:
            continue
        out += comp.image_W_m2_sr[..., None] * (
            factor * electrons_per_joule(comp.spectral_shape_per_nm, camera.sensor.qe_rgb)
        )
    u = (np.arange(g.width) + 0.5) * scale - 0.5
    v = (np.arange(g.height) + 0.5) * scale - 0.5
    return out * relative_illumination(camera, f_number, u[None, :], v[:, None])[..., None]


def full_frame_mosaic(
    crop_e: NDArray[np.float64], x0: int, y0: int, camera: Camera, background_e: NDArray[np.float64] | None
) -> NDArray[np.float32]:
    """Full-frame mean electrons behind each pixel's own colour filter (rows, cols), e⁻.

    The background (rows, cols, 3 on its low-resolution grid) upsampled by nearest
    neighbour, the crop (rows, cols, 3 at ``x0``, ``y0``) pasted in, each pixel's channel
    picked by the CFA: :func:`camera_models.sensor.mosaic` of the full three-channel frame,
    without building it.
    """
    g, cfa = camera.geometry, camera.sensor.cfa
    out = np.zeros((g.height_px, g.width_px), dtype=np.float32)
    if background_e is not None:
        scale = math.ceil(g.width_px / background_e.shape[1])
        bg = background_e.astype(np.float32)
        ch = cfa_channels(cfa, 0, 0, 2, 2)
        for dy in range(2):
            for dx in range(2):
                rows = np.arange(dy, g.height_px, 2) // scale
                cols = np.arange(dx, g.width_px, 2) // scale
                out[dy::2, dx::2] = bg[..., ch[dy, dx]][np.ix_(rows, cols)]
    h, w = crop_e.shape[:2]
    out[y0 : y0 + h, x0 : x0 + w] = mosaic(crop_e, cfa, x0, y0)
    return out


def frame_meter(
    crop_e_per_s: NDArray[np.float64], x0: int, y0: int, camera: Camera, background_e_per_s: NDArray[np.float64] | None
):
    """``meter(exposure_s, gain)``: full-frame mean green signal as a fraction of the clip level."""
    g, s = camera.geometry, camera.sensor
    full_scale_DN = s.white_level_DN - s.black_level_DN
    crop = crop_e_per_s[..., 1].ravel()
    if background_e_per_s is not None:
        scale = g.width_px / background_e_per_s.shape[1]
        bh, bw = background_e_per_s.shape[:2]
        cu = (np.arange(bw) + 0.5) * scale
        cv = (np.arange(bh) + 0.5) * scale
        h, w = crop_e_per_s.shape[:2]
        inside = ((cu >= x0) & (cu < x0 + w))[None, :] & ((cv >= y0) & (cv < y0 + h))[:, None]
        bg = background_e_per_s[..., 1][~inside]
        bg_weight = (g.width_px * g.height_px - crop.size) / max(bg.size, 1)
    else:
        bg, bg_weight = np.zeros(0), 0.0

    def meter(exposure_s: float, gain: float) -> float:
        k = exposure_s * s.K_DN_per_e(gain) / full_scale_DN
        total = np.minimum(crop * k, 1.0).sum() + bg_weight * np.minimum(bg * k, 1.0).sum()
        return float(total / (g.width_px * g.height_px))

    return meter


def noiseless_raw(mean_electrons: NDArray[np.float64], camera: Camera, settings: SensorSettings) -> NDArray[np.uint16]:
    """Raw frame (DN, uint16) of a sensor without noise: the steps of :func:`camera_models.sensor_paths.expose`
    with every temporal and fixed-pattern term at zero.

    Each pixel's mean photo-electrons plus the mean dark charge (dark current × exposure
    time, e⁻), blooming at the full well as in the noisy sensor, × K (DN/e⁻ at the analog
    gain) + black level, rounded and clipped to [0, white level]. A check of the frame path,
    not a camera: a real sensor's saved frame always carries noise.

    Parameters
    ----------
    mean_electrons
        (rows, columns) mean photo-electrons of each pixel behind its own colour filter, e⁻.
    camera
        The camera (its sensor model).
    settings
        Exposure time (s) and analog gain.
    """
    settings.validate()
    s = camera.sensor
    mu = np.clip(mean_electrons, 0.0, None).astype(np.float32)
    mu += np.float32(s.dark_current_e_per_s * settings.exposure_s)
    dn = bloom(mu, s.full_well_e, s.blooming_fraction)
    dn *= np.float32(s.K_DN_per_e(settings.analog_gain))
    dn += np.float32(s.black_level_DN)
    top = min(s.white_level_DN, 2**s.adc_bits - 1)
    return np.clip(np.rint(dn), 0, top).astype(np.uint16)


def capture(
    radiance: SpectralRadiance,
    camera: Camera,
    seed: int,
    background: SpectralRadiance | None = None,
    exposure: ExposureSettings | None = None,
    f_number: float | None = None,
    full: bool = True,
    *,
    noise: bool = True,
    reference: bool = False,
    view: NDArray[np.float64] | None = None,
    others: Sequence[tuple[SpectralRadiance, NDArray[np.float64] | None]] = (),
) -> Capture:
    """Simulate the frame the camera records for a render.

    Parameters
    ----------
    radiance
        The render of the crop around the beacon.
    camera
        The camera.
    seed
        Seed of the sensor's temporal noise (same seed → same bytes).
    background
        Low-resolution full-frame render for metering and the rest of the frame.
    exposure
        Settings to use; default manual settings of a DSLR, auto exposure of a webcam.
    f_number
        Working f-number; default the lens's.
    full
        Produce the full frame (else only the crop).
    noise
        Sensor noise on (default); False gives the noiseless raw (:func:`noiseless_raw`), for checks.
    reference
        Use the reference implementations the fast path replaced (numpy sensor,
        :func:`camera_models.sensor.expose_numpy`; float ISP, :mod:`camera_models.isp_reference`):
        the same distributions, other random numbers; for equivalence tests and the benchmark.
    view
        The camera turned off the render's axis (:meth:`scenes.scenario.Scenario.view_rotation`;
        :func:`camera_models.optics.optical_image`); None: not turned.
    others
        Renders of further beacons in the same frame, each with its own ``view``: their light is
        added to the whole frame (light is linear); automatic exposure meters the first render and
        the background only (a few more lit faces move a frame's mean by far less than a code).
    """
    if not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")
    n = camera.lens.f_number if f_number is None else f_number
    opt = optical_image(radiance, camera, 1.0, n, view=view)  # electrons per second
    bg = background_electrons_per_s(background, camera, n) if background is not None else None
    if exposure is None:
        if camera.exposure.mode == "auto":
            exposure = auto_exposure(camera, frame_meter(opt.electrons_rgb, opt.x0, opt.y0, camera, bg))
        else:
            exposure = manual_exposure(camera)
    t = exposure.exposure_s
    if full:
        mean = full_frame_mosaic(opt.electrons_rgb * t, opt.x0, opt.y0, camera, None if bg is None else bg * t)
        for other, other_view in others:
            more = optical_image(other, camera, 1.0, n, view=other_view)
            h, w = more.electrons_rgb.shape[:2]
            mean[more.y0 : more.y0 + h, more.x0 : more.x0 + w] += mosaic(
                more.electrons_rgb * t, camera.sensor.cfa, more.x0, more.y0
            )
        x0 = y0 = 0
    else:
        if others:
            raise ValueError("others: further beacons need the whole frame (full=True)")
        x0, y0 = opt.x0, opt.y0
        mean = mosaic(opt.electrons_rgb * t, camera.sensor.cfa, x0, y0)
    settings = SensorSettings(t, exposure.analog_gain)
    if not noise:
        raw = noiseless_raw(mean, camera, settings)
    else:
        raw = expose(mean, camera.sensor, settings, seed, x0, y0, path="numpy" if reference else None)
    clip = min(camera.sensor.white_level_DN, 2**camera.sensor.adc_bits - 1)
    if reference:
        image = reference_process(raw, camera, x0, y0)
    else:
        image = process(raw, camera, x0, y0, analog_gain=exposure.analog_gain)
    return Capture(raw, image, exposure, x0, y0, float(np.mean(raw >= clip)))


def marker_pixels(camera: Camera, scenario) -> NDArray[np.float64]:
    """Where the real (distorting) lens images markers 1-5, (5, 2) camera pixels."""

    uv = project(scenario.geometry, scenario.camera_pose(), scenario.marker_positions_world_m())
    return RadialMapping(camera).distort_points_px(uv)


def marker_core_saturation(cap: Capture, camera: Camera, scenario) -> list[dict]:
    """Per marker: pixels of its lit face's image (at least the 1-px disc) and the fraction clipped in the raw.

    ``saturated_fraction`` counts every pixel of the core; ``saturated_fraction_cfa``
    splits it by colour filter (R, G, B sites of the mosaic; NaN where the core has none).
    """

    uv = marker_pixels(camera, scenario)
    depth = scenario.camera_pose().world_to_camera(scenario.marker_positions_world_m())[:, 2]
    radius_px = np.maximum(0.5 * scenario.design.lit_face_diameter_m * camera.geometry.focal_length_px / depth, 1.0)
    clip = min(camera.sensor.white_level_DN, 2**camera.sensor.adc_bits - 1)
    h, w = cap.raw.shape
    out = []
    for i, ((u, v), r) in enumerate(zip(uv, radius_px, strict=True)):
        c0 = max(math.floor(u - r) - cap.x0, 0)
        c1 = min(math.ceil(u + r) - cap.x0 + 1, w)
        r0 = max(math.floor(v - r) - cap.y0, 0)
        r1 = min(math.ceil(v + r) - cap.y0 + 1, h)
        uu, vv = np.meshgrid(np.arange(c0, max(c1, c0)) + cap.x0, np.arange(r0, max(r1, r0)) + cap.y0)
        core = (uu - u) ** 2 + (vv - v) ** 2 <= r * r
        n = int(core.sum())
        clipped = cap.raw[r0:r1, c0:c1][core] >= clip
        frac = float(np.mean(clipped)) if n else float("nan")
        ch = cfa_channels(camera.sensor.cfa, cap.x0 + c0, cap.y0 + r0, core.shape[0], core.shape[1])[core]
        by_cfa = {
            name: float(np.mean(clipped[ch == k])) if np.any(ch == k) else float("nan") for k, name in enumerate("RGB")
        }
        out.append(
            {
                "id": i + 1,
                "u": float(u),
                "v": float(v),
                "core_radius_px": float(r),
                "core_pixels": n,
                "saturated_fraction": frac,
                "saturated_fraction_cfa": by_cfa,
            }
        )
    return out
