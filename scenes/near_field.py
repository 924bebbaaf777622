"""Near-field marker model: the light leaving a marker's front face.

A marker is an LED (5 mm lamp, cosᵐ pattern, lens 6 mm behind the face) in a
cylindrical housing (inner radius = lit-face radius, 15 mm deep, printed walls), behind
an optional foam disc (a homogeneous scattering medium, ``volpath``) and 0–5 paper
sheets at the face (``diffuse_sheet`` surfaces 0.1 mm apart). This module renders that
small scene once per configuration, with many samples, and reduces it to the exit
radiance L(r, θ) on the face plane: radius r from the centre, viewing angle θ from the
normal, azimuthally averaged (the marker is axisymmetric). The beacon-scale render then
uses L(r, θ) as the texture of the marker's lit face (:mod:`scenes.plugins`), so a far
render needs few samples per pixel (the *two-stage* method).

Units: L per W·sr⁻¹ of the LED's on-axis intensity, i.e. W·m⁻²·sr⁻¹ / (W·sr⁻¹) = m⁻².

Spectra: sheets are rendered at one reference wavelength, the centroid of the light the
stack transmits; the exit spectrum is the LED's times the stack's 1-D transmittance
T_N(λ)/T_N(λ_ref) (adding method), assuming the spatial pattern does not change across
the LED's 20–35 nm band. White paper and foam are grey, so for them this is exact.

Views: with paper in front the exit light is Lambertian by construction (the front
sheet transmits diffusely), so one view (θ = 0) gives the whole table; foam alone needs
several angles.

Housing leak: the bore's wall is a ``diffuse_sheet`` with the printed wall's diffuse
reflectance R and transmittance T (``scenes/data/beacons/*.toml``), so light that reaches
the wall partly leaks out through it. :func:`housing_leak` renders the housing from the
side and returns the mean (Lambertian) radiance leaving its outer wall, which the
beacon-scale scene puts on the housing's cylinder as a second emitter of the side's group.
The housing's back is the arm's mount (V1) or elbow (V2) and stays opaque.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scenes import spectra
from scenes.beacon import BeaconDesign
from scenes.diffusers import DiffuserConfig, stack
from scenes.led import LED
from scenes.mitsuba_variant import select_variant
from scenes.render_cache import RenderCache, content_key
from scenes.shapes import disk_shape

__all__ = [
    "CLEARANCE_M",
    "LED_BODY_REFLECTANCE",
    "LED_DEPTH_M",
    "STATS",
    "MarkerEmission",
    "NearFieldSettings",
    "NearFieldStats",
    "exit_spectral_factor",
    "housing_leak",
    "marker_emission",
    "marker_objects",
    "near_field_spec",
]

log = logging.getLogger("beacon_sim")

NEAR_FIELD_VERSION = 3
LED_DEPTH_M = 6.0e-3
"""Front of the LED lens behind the face: room for 5 sheets (0.5 mm), 5 mm foam, 0.5 mm air."""
FOAM_TOP_M = -0.5e-3
SHEET_PITCH_M = 1.0e-4
CLEARANCE_M = 5.0e-5
"""The foam is this much narrower than the housing bore so its boundary (a medium
interface) never coincides with the wall."""
LED_BODY_REFLECTANCE = 0.5
"""Assumed diffuse reflectance of the LED's epoxy body and lead frame seen from the front."""


@dataclass(frozen=True)
class NearFieldSettings:
    """Sampling of the near-field render."""

    spp: int = 1024
    film_px: int = 48
    radial_bins: int = 12
    foam_angles_deg: tuple[float, ...] = (0.0, 20.0, 40.0, 55.0, 70.0, 82.0)
    seed: int = 0


@dataclass(frozen=True)
class MarkerEmission:
    """Exit radiance of one marker configuration.

    Attributes
    ----------
    profile_per_m2
        L(θ_i, r_j) per W·sr⁻¹ of LED on-axis intensity at the reference wavelength, m⁻²;
        rows: θ at ``theta_deg`` (bin centres of 0-90°), columns: radial bin centres.
    theta_deg
        Viewing-angle bin centres, degrees (one row: Lambertian).
    radius_m
        Lit-face radius, m.
    spectral_factor
        Exit spectrum relative to the LED's at the reference wavelength, on
        ``WAVELENGTHS_NM`` (1 for grey diffusers).
    reference_wavelength_nm
        Wavelength the sheets were rendered at, nm.
    from_cache
        Whether it came from the cache.
    """

    profile_per_m2: NDArray[np.float64]
    theta_deg: NDArray[np.float64]
    radius_m: float
    spectral_factor: NDArray[np.float64]
    reference_wavelength_nm: float
    from_cache: bool = False

    @property
    def radial_edges_m(self) -> NDArray[np.float64]:
        """Edges of the radial bins, m."""
        return np.linspace(0.0, self.radius_m, self.profile_per_m2.shape[1] + 1)

    def intensity_per_W_sr(self, theta_deg: float) -> float:
        """Radiant intensity of the face toward θ per W·sr⁻¹ of LED intensity (ratio).

        I(θ) = cos θ ∫ L(r, θ) 2πr dr at the table's angles, interpolated between them
        in log(I/cos θ) (exact for a Gaussian-like lobe such as cosᵐ, and never above
        the true value for a log-concave one); a one-row table is Lambertian.
        """
        edges = self.radial_edges_m
        areas = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
        per_cos = self.profile_per_m2 @ areas  # I(θ_i) / cos θ_i
        c = math.cos(math.radians(theta_deg))
        if per_cos.size == 1:
            return float(c * per_cos[0])
        if np.all(per_cos > 0):
            return float(c * math.exp(np.interp(theta_deg, self.theta_deg, np.log(per_cos))))
        return float(c * np.interp(theta_deg, self.theta_deg, per_cos))

    def exit_flux_per_W_sr(self) -> float:
        """Total flux leaving the face per W·sr⁻¹ of LED intensity, W/(W·sr⁻¹) = sr.

        Φ = 2π ∫ I(θ) sin θ dθ over the hemisphere (trapezoid over 0-90° in 0.5° steps).
        """
        t = np.radians(np.arange(0.0, 90.0 + 1e-9, 0.5))
        i = np.array([self.intensity_per_W_sr(math.degrees(x)) for x in t])
        return float(2 * np.pi * np.trapezoid(i * np.sin(t), t))

    def texture(self) -> NDArray[np.float32]:
        """The (θ, r) table as a bitmap for the ``marker_face`` emitter, shape (rows, cols, 1)."""
        return self.profile_per_m2.astype(np.float32)[..., None]


def exit_spectral_factor(config: DiffuserConfig, side: str, led: LED) -> tuple[NDArray[np.float64], float]:
    """Spectral factor T_N(λ)/T_N(λ_ref) of the sheets and the reference wavelength, nm."""
    if config.paper_sheets == 0:
        return np.ones_like(spectra.WAVELENGTHS_NM), float(led.peak_wavelength_nm)
    sheet = config.sheet(side)
    _, t_n = stack(sheet.reflectance, sheet.transmittance, config.paper_sheets)
    weight = led.spectral_shape * t_n
    if spectra.integrate_nm(weight) <= 0:
        return np.zeros_like(t_n), float(led.peak_wavelength_nm)
    lam_ref = float(spectra.integrate_nm(weight * spectra.WAVELENGTHS_NM) / spectra.integrate_nm(weight))
    t_ref = float(np.interp(lam_ref, spectra.WAVELENGTHS_NM, t_n))
    return t_n / t_ref, lam_ref


def near_field_spec(design: BeaconDesign, led: LED, housing: str, config: DiffuserConfig, side: str) -> dict:
    """Plain-data description of the near-field scene (face at z = 0, normal +z, metres)."""
    r_face = design.lit_face_diameter_m / 2
    depth = design.housing_depth_m
    r_led = led.lens_diameter_mm * 1e-3 / 2
    r_in = r_face - CLEARANCE_M
    up = np.array([0.0, 0.0, 1.0])
    led_emitter = {
        "type": "marker_face",
        "group": "led",
        "radiance": 1.0 / (math.pi * r_led**2),
        "exponent": led.cos_exponent - 1.0,
    }
    if led.wide_fraction > 0:
        led_emitter["wide"] = led.wide_fraction
    shapes: list[dict] = [
        {
            "type": "cylinder",
            "p0": [0.0, 0.0, -depth],
            "p1": [0.0, 0.0, 0.0],
            "radius": r_face,
            "material": "housing_wall",
        },
        disk_shape(np.array([0.0, 0.0, -depth]), up, r_face, "housing"),
        disk_shape(
            np.array([0.0, 0.0, -LED_DEPTH_M]),
            up,
            r_led,
            "led_body",
            led_emitter,
        ),
        {
            "type": "cylinder",
            "p0": [0.0, 0.0, -depth],
            "p1": [0.0, 0.0, -LED_DEPTH_M],
            "radius": r_led,
            "material": "led_body",
        },
    ]
    _, lam_ref = exit_spectral_factor(config, side, led)
    if config.paper_sheets:
        r1, t1 = config.sheet(side).at(lam_ref)
        for k in range(config.paper_sheets):
            # sheets fill the bore (their edges meet the wall; no gap for light to bypass them)
            shapes.append(disk_shape(np.array([0.0, 0.0, -k * SHEET_PITCH_M]), up, r_face, "sheet"))
    else:
        r1 = t1 = 0.0
    medium = None
    if config.foam:
        foam = config.foam_optics()
        z0, z1 = FOAM_TOP_M - foam.thickness_m, FOAM_TOP_M
        medium = {"sigma_t_per_m": foam.sigma_t_per_m, "albedo": foam.single_scattering_albedo, "g": foam.anisotropy}
        shapes += [
            {
                "type": "cylinder",
                "p0": [0.0, 0.0, z0],
                "p1": [0.0, 0.0, z1],
                "radius": r_in,
                "material": "null",
                "interior": "foam",
            },
            {**disk_shape(np.array([0.0, 0.0, z1]), up, r_in, "null"), "interior": "foam"},
            {**disk_shape(np.array([0.0, 0.0, z0]), -up, r_in, "null"), "interior": "foam"},
        ]
    return {
        "materials": {"housing": design.housing_reflectance[housing], "led_body": LED_BODY_REFLECTANCE},
        "housing_wall": {
            "reflectance": design.housing_reflectance[housing],
            "transmittance": design.housing_transmittance[housing],
        },
        "sheet": {"reflectance": r1, "transmittance": t1},
        "medium": medium,
        "shapes": shapes,
        "radius_m": r_face,
    }


def marker_objects(spec: dict, to_world: NDArray[np.float64] | None = None, prefix: str = "") -> dict:
    """Mitsuba dictionary entries (materials, medium, shapes) of a near-field spec,
    optionally moved by the 4×4 matrix ``to_world`` (the marker's pose in a larger scene)."""
    import mitsuba as mi

    m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64)
    scale = float(np.cbrt(abs(np.linalg.det(m[:3, :3]))))
    out: dict = {
        f"{prefix}mat_housing": {
            "type": "twosided",
            "id": f"{prefix}mat_housing",
            "bsdf": {"type": "diffuse", "reflectance": spec["materials"]["housing"]},
        },
        f"{prefix}mat_led_body": {
            "type": "twosided",
            "id": f"{prefix}mat_led_body",
            "bsdf": {"type": "diffuse", "reflectance": spec["materials"]["led_body"]},
        },
        f"{prefix}mat_sheet": {"type": "diffuse_sheet", "id": f"{prefix}mat_sheet", **spec["sheet"]},
        f"{prefix}mat_housing_wall": {
            "type": "diffuse_sheet",
            "id": f"{prefix}mat_housing_wall",
            **spec["housing_wall"],
        },
        f"{prefix}mat_null": {"type": "null", "id": f"{prefix}mat_null"},
    }
    if spec["medium"]:
        out[f"{prefix}foam"] = {
            "type": "homogeneous",
            "id": f"{prefix}foam",
            "sigma_t": spec["medium"]["sigma_t_per_m"] / scale,
            "albedo": spec["medium"]["albedo"],
            "phase": {"type": "hg", "g": spec["medium"]["g"]},
        }
    for i, sh in enumerate(spec["shapes"]):
        d: dict = {"type": sh["type"], "bsdf": {"type": "ref", "id": f"{prefix}mat_{sh['material']}"}}
        if "matrix" in sh:
            d["to_world"] = mi.ScalarTransform4f(m @ np.asarray(sh["matrix"]))
        if sh["type"] == "cylinder":
            p0 = (m @ np.array([*sh["p0"], 1.0]))[:3]
            p1 = (m @ np.array([*sh["p1"], 1.0]))[:3]
            d.update(p0=p0.tolist(), p1=p1.tolist(), radius=sh["radius"] * scale)
        if "interior" in sh:
            d["interior"] = {"type": "ref", "id": f"{prefix}{sh['interior']}"}
        if "emitter" in sh:
            e = {k: v for k, v in sh["emitter"].items() if k != "group"}
            if e.get("type") == "marker_face":
                e["radiance"] = e["radiance"] / scale**2
            d["emitter"] = e
        out[f"{prefix}shape_{i:03d}"] = d
    return out


def _to_mitsuba(spec: dict, settings: NearFieldSettings, view_deg: float) -> dict:
    import mitsuba as mi

    half = spec["radius_m"] * 1.02
    t = math.radians(view_deg)
    eye = 0.1 * np.array([math.sin(t), 0.0, math.cos(t)])
    sensor_xf = mi.ScalarTransform4f().look_at(eye.tolist(), [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]).scale([half, half, 1.0])
    pixel_format = "luminance" if mi.variant().endswith("mono") else "rgb"
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 2048, "rr_depth": 256},
        "sensor": {
            "type": "orthographic",
            "to_world": sensor_xf,
            "near_clip": 1e-4,
            "far_clip": 1.0,
            "film": {
                "type": "hdrfilm",
                "width": settings.film_px,
                "height": settings.film_px,
                "pixel_format": pixel_format,
                "rfilter": {"type": "box"},
                "sample_border": False,
            },
            "sampler": {"type": "independent", "sample_count": settings.spp},
        },
        **marker_objects(spec),
    }


def _radial_profile(image: NDArray[np.float64], radius_m: float, view_deg: float, bins: int) -> NDArray[np.float64]:
    """Average an orthographic view over rings of the face plane (see module docstring)."""
    n = image.shape[0]
    half = radius_m * 1.02
    a = ((np.arange(n) + 0.5) / n * 2 - 1) * half
    A, B = np.meshgrid(a, a)  # film x (across the tilt), film y
    t = math.radians(view_deg)
    # a pixel's ray meets the face plane at (A / cos θ, B) in the face's own coordinates
    r = np.hypot(A / math.cos(t), B)
    edges = np.linspace(0.0, radius_m, bins + 1)
    idx = np.digitize(r, edges) - 1
    out = np.zeros(bins)
    for j in range(bins):
        sel = idx == j
        out[j] = image[sel].mean() if np.any(sel) else 0.0
    return out


@dataclass
class NearFieldStats:
    """How many near-field configurations were rendered (not served from cache)."""

    renders: int = 0


STATS = NearFieldStats()


def marker_emission(
    design: BeaconDesign,
    led: LED,
    housing: str,
    config: DiffuserConfig,
    side: str,
    cache: RenderCache | None = None,
    settings: NearFieldSettings | None = None,
) -> MarkerEmission:
    """Exit radiance of a marker (rendered once, then cached).

    The beacon-scale render uses the analytic LED for bare markers; rendering a bare
    marker here is how the near-field machinery is checked against that analytic LED.
    """
    settings = settings or NearFieldSettings()
    variant = select_variant("mono").variant
    spec = near_field_spec(design, led, housing, config, side)
    angles = (0.0,) if config.paper_sheets else settings.foam_angles_deg
    if config.is_bare:  # the LED's cos^20 beam needs fine angles near the axis
        angles = (0.0, 4.0, 8.0, 12.0, 16.0, 20.0, 25.0, 30.0, 40.0, 60.0, 82.0)
    factor, lam_ref = exit_spectral_factor(config, side, led)
    key = content_key(
        "near-field",
        NEAR_FIELD_VERSION,
        variant,
        spec,
        angles,
        settings.spp,
        settings.film_px,
        settings.radial_bins,
        settings.seed,
    )
    paper = config.paper_colour_for(side)
    label = f"near-field render ({side}, foam={config.foam}, {config.paper_sheets} sheets, {paper})"
    profile, from_cache = _cached(cache, key, "profile", label, lambda: _render_profile(spec, settings, angles))
    return MarkerEmission(profile, np.asarray(angles, dtype=np.float64), spec["radius_m"], factor, lam_ref, from_cache)


def housing_leak(
    design: BeaconDesign,
    led: LED,
    housing: str,
    config: DiffuserConfig,
    side: str,
    cache: RenderCache | None = None,
    settings: NearFieldSettings | None = None,
) -> float:
    """Mean radiance leaving a housing's outer wall per W·sr⁻¹ of LED on-axis intensity, m⁻².

    The near-field scene is viewed from the side, orthographically, across the housing's
    axis. The wall transmits diffusely, so every pixel over the wall shows the (Lambertian)
    exit radiance at its height; the mean over the wall's central band is the area mean L̄
    at the bore radius. Referred to the housing's outer radius by flux conservation
    (× r_bore / r_outer), it is the radiance of the beacon-scale housing cylinder. Zero for
    an opaque wall (T = 0); rendered once per configuration, then cached.
    """
    if design.housing_transmittance[housing] <= 0.0:
        return 0.0
    settings = settings or NearFieldSettings()
    variant = select_variant("mono").variant
    spec = near_field_spec(design, led, housing, config, side)
    key = content_key("housing-leak", NEAR_FIELD_VERSION, variant, spec, settings.spp, settings.film_px, settings.seed)
    label = f"housing-leak render ({side}, {housing} housing)"
    leak, _ = _cached(cache, key, "leak", label, lambda: [_render_leak(spec, design.housing_depth_m, settings)])
    return float(leak[0]) * spec["radius_m"] / design.housing_radius_m


def _cached(cache: RenderCache | None, key: str, name: str, label: str, render) -> tuple[NDArray[np.float64], bool]:
    """The array ``name`` stored under ``key``, or ``render()`` run, counted, logged and
    stored; and whether it came from the cache."""

    def make() -> dict[str, NDArray[np.float64]]:
        t0 = time.perf_counter()
        value = np.asarray(render(), dtype=np.float64)
        STATS.renders += 1
        log.info("%s in %.1f s", label, time.perf_counter() - t0)
        return {name: value}

    stored, from_cache = (cache if cache is not None else RenderCache()).get_or_make(key, make)
    return stored[name], from_cache


def _render_leak(spec: dict, depth_m: float, settings: NearFieldSettings) -> float:
    """Mean exit radiance of the bore's wall seen from the side (see :func:`housing_leak`), m⁻²."""
    import mitsuba as mi

    r = spec["radius_m"]
    half = 1.05 * max(r, depth_m / 2)
    zc = -depth_m / 2
    scene_dict = _to_mitsuba(spec, settings, 0.0)
    scene_dict["sensor"]["to_world"] = (
        mi.ScalarTransform4f().look_at([0.1, 0.0, zc], [0.0, 0.0, zc], [0.0, 0.0, 1.0]).scale([half, half, 1.0])
    )
    image = np.asarray(mi.render(mi.load_dict(scene_dict), seed=settings.seed), dtype=np.float64).mean(axis=-1)
    n = image.shape[0]
    a = ((np.arange(n) + 0.5) / n * 2 - 1) * half
    across, height = np.meshgrid(a, a)  # film x (across the axis), film y (along it, about zc)
    band = (np.abs(across) < 0.7 * r) & (np.abs(height) < 0.45 * depth_m)
    return float(image[band].mean())


def _render_profile(spec: dict, settings: NearFieldSettings, angles: tuple[float, ...]) -> NDArray[np.float64]:
    import mitsuba as mi

    rows = []
    for k, view in enumerate(angles):
        scene = mi.load_dict(_to_mitsuba(spec, settings, view))
        image = np.asarray(mi.render(scene, seed=settings.seed * 101 + k), dtype=np.float64).mean(axis=-1)
        rows.append(_radial_profile(image, spec["radius_m"], view, settings.radial_bins))
    return np.array(rows)
