"""Two-stage marker rendering checked against brute-force volumetric rendering.

One marker stands alone in the dark, its face toward a camera ``range_m`` away (viewed
``view_deg`` off its normal). It is rendered two ways on the same crop:

* **brute force**: the full near-field geometry (LED, housing, foam medium, paper
  sheets) in the camera's scene, path traced with ``volpath``;
* **two stage**: the marker's cached exit radiance L(r, θ) on a flat lit face.

Both are in the same unit (radiance per W·sr⁻¹ of on-axis LED intensity), so their total
flux at the camera (Σ L·Ω) and radial profiles must agree within the Monte-Carlo error
of the brute-force render.

Float precision: rays spawned from metres away carry position errors of ~10⁻⁷ of their
length, enough for paths to slip through 0.1 mm sheet stacks and zero-thickness walls
(measured: 18 % spurious light at 30° with the camera at 5 m, none at 0.1 m). So the
camera sits ``camera_distance_m`` (0.25 m) from the marker with its focal length scaled
by camera_distance / range: every pixel sees the same patch of the marker, from the same
direction, as at ``range_m``. Fluxes are reported at ``range_m`` (× (d / range)²).

Errors come from independent passes (different seeds): standard error = std over
passes / √passes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from scenes.beacon import beacon_design
from scenes.diffusers import DiffuserConfig
from scenes.led import led_for_side
from scenes.mitsuba_variant import select_variant
from scenes.near_field import NearFieldSettings, marker_emission, marker_objects, near_field_spec
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance
from scenes.render_cache import RenderCache
from scenes.shapes import disk_shape
from scenes.spectra import WAVELENGTHS_NM
from scenes.view import camera_geometry

__all__ = [
    "Comparison",
    "MarkerView",
    "PassStats",
    "brute_force_scene",
    "compare",
    "flux_and_profile",
    "relative_rms_error",
    "render_passes",
    "two_stage_scene",
]


@dataclass(frozen=True)
class MarkerView:
    """One marker seen by one camera (see module docstring)."""

    config: DiffuserConfig = field(default_factory=lambda: DiffuserConfig(True, 1, "matched"))
    side: str = "red"
    housing: str = "white"
    range_m: float = 5.0
    view_deg: float = 10.0
    camera: str = "canon-t6-18mm"
    half_px: int = 10
    oversampling: int = 4
    camera_distance_m: float = 0.25

    @property
    def focal_scale(self) -> float:
        """Focal-length factor that keeps the pixel footprint of ``range_m``."""
        return self.camera_distance_m / self.range_m

    def grid(self) -> PixelGrid:
        """The crop around the marker's image (it projects to the principal point)."""
        g = camera_geometry(self.camera)
        cx, cy = (round(c) for c in g.principal_point_px)
        n = 2 * self.half_px
        return PixelGrid(
            g.width_px,
            g.height_px,
            g.focal_length_px * self.focal_scale,
            g.principal_point_px,
            cx - self.half_px,
            cy - self.half_px,
            n,
            n,
            self.oversampling,
        )


def _scene(view: MarkerView, objects: dict, spp: int, integrator: str) -> dict:
    import mitsuba as mi

    g, grid = camera_geometry(view.camera), view.grid()
    s = view.oversampling
    t = math.radians(view.view_deg)
    eye = view.camera_distance_m * np.array([math.sin(t), 0.0, math.cos(t)])
    pixel_format = "luminance" if mi.variant().endswith("mono") else "rgb"
    return {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": 2048, "rr_depth": 256},
        "sensor": {
            "type": "perspective",
            "fov_axis": "x",
            "near_clip": 1e-3,
            "fov": math.degrees(2 * math.atan(g.width_px / (2 * g.focal_length_px * view.focal_scale))),
            "to_world": mi.ScalarTransform4f().look_at(eye.tolist(), [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            "film": {
                "type": "hdrfilm",
                "width": g.width_px * s,
                "height": g.height_px * s,
                "crop_offset_x": grid.x0 * s,
                "crop_offset_y": grid.y0 * s,
                "crop_width": grid.width * s,
                "crop_height": grid.height * s,
                "pixel_format": pixel_format,
                "rfilter": {"type": "box"},
                "sample_border": False,
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
        **objects,
    }


def brute_force_scene(view: MarkerView, spp: int) -> dict:
    """The whole volumetric marker in the camera's scene."""
    design, led = beacon_design("v2"), led_for_side(view.side)
    spec = near_field_spec(design, led, view.housing, view.config, view.side)
    return _scene(view, marker_objects(spec), spp, "volpath")


def two_stage_scene(view: MarkerView, spp: int, near: NearFieldSettings, cache: RenderCache | None) -> dict:
    """The marker's lit face with its cached exit radiance."""
    import mitsuba as mi

    design, led = beacon_design("v2"), led_for_side(view.side)
    emission = marker_emission(design, led, view.housing, view.config, view.side, cache, near)
    face = disk_shape(np.zeros(3), np.array([0.0, 0.0, 1.0]), emission.radius_m, "black")
    objects = {
        "mat_black": {"type": "diffuse", "id": "mat_black", "reflectance": 0.0},
        "face": {
            "type": "disk",
            "to_world": mi.ScalarTransform4f(np.asarray(face["matrix"])),
            "bsdf": {"type": "ref", "id": "mat_black"},
            "emitter": {
                "type": "marker_face",
                "radiance": 1.0,
                "exponent": 0.0,
                "profile": {
                    "type": "bitmap",
                    "data": mi.TensorXf(emission.texture()),
                    "raw": True,
                    "filter_type": "bilinear",
                    "wrap_mode": "clamp",
                },
            },
        },
    }
    return _scene(view, objects, spp, "path")


@dataclass(frozen=True)
class PassStats:
    """Per-pass results of one method: images (passes, rows, cols) and timings."""

    images: NDArray[np.float64]
    seconds_per_pass: float
    spp_per_pass: int


def render_passes(scene_dict: dict, passes: int, seed0: int = 0) -> PassStats:
    """Render ``passes`` independent passes of a scene (kernel compiled once, not timed)."""
    import mitsuba as mi

    select_variant("mono")
    scene = mi.load_dict(scene_dict)
    spp = scene_dict["sensor"]["sampler"]["sample_count"]
    np.asarray(mi.render(scene, seed=10_000 + seed0, spp=1))  # warm-up: compile the kernel
    images, t0 = [], time.perf_counter()
    for k in range(passes):
        images.append(np.asarray(mi.render(scene, seed=seed0 + k), dtype=np.float64).mean(axis=-1))
    return PassStats(np.array(images), (time.perf_counter() - t0) / passes, spp)


def flux_and_profile(view: MarkerView, images: NDArray[np.float64], ring_px: float = 0.5, max_px: float = 8.0):
    """Per pass: irradiance at the pupil (Σ L·Ω, per W·sr⁻¹) and the radial profile
    (mean radiance in rings of ``ring_px`` camera pixels around the marker's centre)."""
    grid = view.grid()
    dummy = SpectralRadiance(
        grid, (RadianceComponent("x", images[0].astype(np.float32), np.ones_like(WAVELENGTHS_NM)),), {}, ""
    )
    omega = dummy.subpixel_solid_angle_sr()
    u, v = grid.subpixel_centres_px()
    cx, cy = grid.principal_point_px
    r = np.hypot(u[None, :] - cx, v[:, None] - cy)
    edges = np.arange(0.0, max_px + 1e-9, ring_px)
    idx = np.digitize(r, edges) - 1
    flux = np.array([np.sum(img * omega) for img in images]) * view.focal_scale**2  # at range_m
    profile = np.array([[img[idx == j].mean() for j in range(edges.size - 1)] for img in images])
    return flux, profile, edges


def relative_rms_error(images: NDArray[np.float64], reference: NDArray[np.float64]) -> float:
    """RMS over the marker (reference > 1 % of its peak) of one pass's relative error."""
    mask = reference > 0.01 * reference.max()
    err = (images[:, mask] - reference[mask]) / reference[mask]
    return float(np.sqrt(np.mean(err**2)))


@dataclass(frozen=True)
class Comparison:
    """Two-stage vs brute force: fluxes (per W·sr⁻¹) with standard errors, profiles."""

    flux_two_stage: float
    flux_two_stage_se: float
    flux_brute_force: float
    flux_brute_force_se: float
    profile_two_stage: NDArray[np.float64]
    profile_two_stage_se: NDArray[np.float64]
    profile_brute_force: NDArray[np.float64]
    profile_brute_force_se: NDArray[np.float64]
    ring_edges_px: NDArray[np.float64]
    chi2: float
    dof: int

    @property
    def flux_z(self) -> float:
        """Flux difference in units of its combined standard error."""
        se = math.hypot(self.flux_two_stage_se, self.flux_brute_force_se)
        return (self.flux_two_stage - self.flux_brute_force) / se

    def to_dict(self) -> dict:
        """JSON-able summary."""
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()} | {
            "flux_z": self.flux_z
        }


def compare(
    view: MarkerView,
    brute_spp: int,
    brute_passes: int,
    near: NearFieldSettings,
    near_seeds: int = 4,
    cache: RenderCache | None = None,
) -> Comparison:
    """Render both ways and compare flux and radial profile (see module docstring).

    The two-stage result's own uncertainty comes from its near-field render: it is
    repeated with ``near_seeds`` independent seeds, and the far render (noise-free apart
    from anti-aliasing) is averaged over those.
    """
    fluxes, profiles = [], []
    for k in range(near_seeds):
        settings = NearFieldSettings(near.spp, near.film_px, near.radial_bins, near.foam_angles_deg, near.seed + k)
        ts = render_passes(two_stage_scene(view, 16, settings, cache), 2, seed0=100 * k)
        f, p, edges = flux_and_profile(view, ts.images)
        fluxes.append(f.mean())
        profiles.append(p.mean(axis=0))
    fluxes, profiles = np.array(fluxes), np.array(profiles)
    bf = render_passes(brute_force_scene(view, brute_spp), brute_passes)
    fb, pb, edges = flux_and_profile(view, bf.images)
    sqrt_n, sqrt_k = math.sqrt(brute_passes), math.sqrt(near_seeds)
    p_ts, p_ts_se = profiles.mean(axis=0), profiles.std(axis=0, ddof=1) / sqrt_k
    p_bf, p_bf_se = pb.mean(axis=0), pb.std(axis=0, ddof=1) / sqrt_n
    var = p_ts_se**2 + p_bf_se**2
    used = (var > 0) & (p_ts > 0.02 * p_ts.max())
    chi2 = float(np.sum((p_ts[used] - p_bf[used]) ** 2 / var[used]))
    return Comparison(
        float(fluxes.mean()),
        float(fluxes.std(ddof=1) / sqrt_k),
        float(fb.mean()),
        float(fb.std(ddof=1) / sqrt_n),
        p_ts,
        p_ts_se,
        p_bf,
        p_bf_se,
        edges,
        chi2,
        int(used.sum()),
    )
