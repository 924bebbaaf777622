"""Render a scenario to spectral radiance on the camera's pixel grid.

Only the crop around the beacon is rendered, at ``oversampling``² sub-pixels per camera
pixel. The scene is loaded once; each emitter group (a side's LEDs, the ambient light)
is rendered by zeroing the other groups' (opaque) radiance parameters, and the render
loop keeps the crop out of the kernel (:func:`_render_primal`), so Dr.Jit compiles one
kernel per scene structure and block size class and reuses it for every group, range,
yaw and crop, in this process and (through its disk cache) in later ones. Renders are
cached on disk by a content hash of the scene description, render settings, Mitsuba
variant and :data:`RENDER_VERSION`; the LED drive and the ambient level are not part of
the key because they only scale the cached unit images (linearity).

With ``RenderSettings.direct = "primary"`` (the default) the LED groups are not
path-traced: their direct view comes from deterministic primary rays, all groups in one
pass, and only their scattered light from the path tracer at ``scatter_spp`` samples per
camera pixel (:mod:`scenes.direct_view`); ``direct = "path"`` is the reference.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from scenes import spectra
from scenes.assemble import (
    ceiling_radiance_W_m2_sr,
    crop_box,
    emitter_groups,
    scene_spec,
    to_mitsuba,
)
from scenes.direct_view import FaceDisc, face_discs, render_direct, render_scattered, set_film_crop, shape_groups
from scenes.mitsuba_variant import select_variant
from scenes.near_field import exit_spectral_factor
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance
from scenes.render_cache import RenderCache, content_key
from scenes.scenario import Scenario

if TYPE_CHECKING:
    import mitsuba as mi

__all__ = [
    "DIRECT_VERSION",
    "NEGLIGIBLE_UNIT_RADIANCE",
    "RENDER_VERSION",
    "pixel_grid",
    "render",
    "render_key",
    "render_unit_groups",
    "side_current_mA",
    "uses_primary_rays",
    "with_emission",
    "with_led_current",
]

log = logging.getLogger("beacon_sim")

RENDER_VERSION = 1
"""Bump when a change to the plugins or the integrator changes rendered values."""


def pixel_grid(scenario: Scenario) -> PixelGrid:
    """The pixel grid a render of ``scenario`` covers."""
    geom = scenario.geometry
    crop = crop_box(scenario)
    return PixelGrid(
        frame_width_px=geom.width_px,
        frame_height_px=geom.height_px,
        focal_length_px=geom.focal_length_px,
        principal_point_px=geom.principal_point_px,
        x0=crop.x0,
        y0=crop.y0,
        width=crop.width,
        height=crop.height,
        oversampling=scenario.render.oversampling,
    )


NEGLIGIBLE_UNIT_RADIANCE = 1e-30
"""Unit radiance (W·m⁻²·sr⁻¹ per W·sr⁻¹ of LED intensity) below which a primary-ray render
stores zero: the far tail of a cos¹⁹ beam seen edge-on reaches 1e-38 and below, where
float32 turns subnormal and the LED-drive scaling would lose its exactness. Assumed: at
1e-30 a 1 W·sr⁻¹ LED gives less than one photo-electron per 10⁹ years in any camera here."""

DIRECT_VERSION = 2
"""Bump when a change to :mod:`scenes.direct_view` changes its rendered values (2: scattered
light sampled per block of 2 × 2 camera pixels)."""


def uses_primary_rays(scenario: Scenario, variant: str) -> bool:
    """Whether ``scenario`` renders its LEDs' direct view by primary rays: ``direct =
    "primary"`` in a JIT variant (the scalar fallback, which cannot update a loaded scene's
    emitters, path-traces everything)."""
    return scenario.render.direct == "primary" and not variant.startswith("scalar")


def render_key(scenario: Scenario, variant: str, groups: list[str], spec: dict | None = None) -> str:
    """Cache key of the unit-scale render of ``groups`` of ``scenario``.

    ``spec``: ``scene_spec(scenario)`` when the caller has it (assembled once per geometry).
    ``direct = "path"`` keeps the key of the renders before :mod:`scenes.direct_view`."""
    r = scenario.render
    parts: list = [RENDER_VERSION, variant, spec if spec is not None else scene_spec(scenario), r.spp, r.seed, groups]
    if uses_primary_rays(scenario, variant):
        parts += [{"direct": r.direct, "version": DIRECT_VERSION, "scatter_spp": r.scatter_spp}]
    return content_key(*parts)


def render(
    scenario: Scenario,
    cache: RenderCache | None = None,
    groups: Sequence[str] | None = None,
) -> SpectralRadiance:
    """Spectral radiance of ``scenario`` on its pixel grid.

    Parameters
    ----------
    scenario
        What to render.
    cache
        Render cache; ``None`` renders without caching.
    groups
        Emitter groups to render (``led:red``, ``ambient`` …); default all of them.

    Returns
    -------
    SpectralRadiance
        Components ``led:<side>`` (each side's LEDs at the scenario's drive) and, in
        lit environments, ``ambient``; radiance in W·m⁻²·sr⁻¹ with spectral shapes.
    """
    variant = select_variant("mono").variant
    spec = scene_spec(scenario)
    available = emitter_groups(spec)
    groups = available if groups is None else sorted(set(groups))
    unknown = set(groups) - set(available)
    if unknown:
        raise ValueError(f"groups: expected some of {available}, got unknown {sorted(unknown)}")
    key = render_key(scenario, variant, groups, spec)

    settings = scenario.render

    def make() -> dict[str, np.ndarray]:
        t0 = time.perf_counter()
        if uses_primary_rays(scenario, variant):
            crop = crop_box(scenario)
            faces = face_discs(scenario, crop.x0, crop.y0)
            unit = render_unit_groups(
                spec,
                settings.spp,
                settings.seed,
                groups,
                faces=faces,
                scatter_spp=settings.scatter_spp,
                oversampling=settings.oversampling,
            )
        else:
            unit = render_unit_groups(spec, settings.spp, settings.seed, groups)
        log.info("rendered %s in %.1f s (%s)", list(unit), time.perf_counter() - t0, variant)
        return unit

    unit, from_cache = cache.get_or_make(key, make) if cache is not None else (make(), False)
    components = tuple(
        _scaled_component(scenario, group, image, f"{key}:{group}") for group, image in sorted(unit.items())
    )
    return SpectralRadiance(pixel_grid(scenario), components, scenario.to_dict(), variant, from_cache)


def _scaled_component(scenario: Scenario, group: str, unit_image: np.ndarray, unit_key: str) -> RadianceComponent:
    """Scale a unit render to the scenario's LED drive or ambient level."""
    if group == "ambient":
        env = scenario.env
        factor = ceiling_radiance_W_m2_sr(scenario)
        shape = env.spectral_shape()
    else:
        side = group.split(":", 1)[1]
        led = scenario.led_for(side)
        # the unit render holds radiance per W·sr⁻¹ of LED intensity at the reference
        # wavelength; the diffusers' spectral factor turns it into the band integral
        spectral_factor, _ = exit_spectral_factor(scenario.diffuser, side, led)
        exit_spectrum = led.spectral_shape * spectral_factor
        transmitted = spectra.integrate_nm(exit_spectrum)
        factor = led.radiant_intensity_W_sr(side_current_mA(scenario, side)) * transmitted
        factor *= scenario.dust_transmittance  # the LEDs' light crosses the dust to the camera
        shape = exit_spectrum / transmitted if transmitted > 0 else led.spectral_shape
    unit_image = np.asarray(unit_image, dtype=np.float32)
    unit_image.setflags(write=False)
    return RadianceComponent(group, unit_image * np.float32(factor), shape, unit_key, unit_image, float(factor))


def with_led_current(radiance: SpectralRadiance, current_mA: float) -> SpectralRadiance:
    """The same render with the LEDs driven at ``current_mA`` (light transport is linear:
    the unit renders are rescaled in memory; no scene is built and nothing is read)."""
    return with_emission(radiance, Scenario.from_dict({**radiance.scenario, "led_current_mA": current_mA}))


def with_emission(radiance: SpectralRadiance, scenario: Scenario) -> SpectralRadiance:
    """The same render with the LEDs' light of ``scenario``: its drive, its LED intensity bins
    (the :data:`scenes.data_overrides.GAIN` overrides) and the dust it crosses. Exact, as light transport is linear: the
    unit renders are rescaled in memory. ``scenario`` must differ from the render's only in those
    (``ValueError`` otherwise)."""
    rendered = Scenario.from_dict(radiance.scenario)
    if rendered.without_gains() != scenario.without_gains():
        raise ValueError("scenario: differs from the render's in more than the LEDs' drive, intensity and dust")
    components = tuple(
        _scaled_component(scenario, c.name, c.unit_image, c.unit_key) if c.unit_image is not None else c
        for c in radiance.components
    )
    return replace(radiance, components=components, scenario=scenario.to_dict())


def side_current_mA(scenario: Scenario, side: str) -> float:
    """Drive current of a side's LEDs, mA.

    The visible side runs at the scenario's current; the other sides at the same
    fraction of their own datasheet current (one dimmer setting for the whole beacon),
    capped at their absolute maximum.
    """
    if side == scenario.side:
        return scenario.current_mA
    led = scenario.led_for(side)
    fraction = scenario.current_mA / scenario.led.reference_current_mA
    return min(led.reference_current_mA * fraction, led.max_current_mA)


def render_unit_groups(
    spec: dict,
    spp: int,
    seed: int,
    groups: Sequence[str] | None = None,
    *,
    reuse_kernels: bool = True,
    faces: list[FaceDisc] | None = None,
    scatter_spp: int = 4,
    oversampling: int = 1,
) -> dict[str, np.ndarray]:
    """Render each emitter group of ``spec`` (or those in ``groups``) alone at unit scale.

    Parameters
    ----------
    spec
        Scene description (:func:`scenes.assemble.scene_spec`).
    spp
        Samples per (sub-)pixel.
    seed
        Base seed; group ``i`` (index in :func:`scenes.assemble.emitter_groups`) renders
        with seed ``seed * 7919 + i``.
    groups
        Groups to render; default all of them.
    reuse_kernels
        JIT variants: render through :func:`_render_primal`, whose kernel does not depend
        on the crop, so a new geometry reuses the kernel compiled for an earlier one (same
        pixels as ``mitsuba.render``); ``False`` renders with ``mitsuba.render``.
    faces
        The lit faces projected on the crop (:func:`scenes.direct_view.face_discs`): given,
        the LED groups (``led:*``) are the direct view by primary rays
        (:func:`scenes.direct_view.render_direct`) plus the scattered light path-traced at
        ``scatter_spp`` samples per camera pixel (:func:`scenes.direct_view.render_scattered`,
        seed as above); ``None`` path-traces them at ``spp``. ``ambient`` is path-traced.
    scatter_spp, oversampling
        Samples per camera pixel of the scattered light and sub-pixels per camera pixel
        along each axis (with ``faces``).

    Returns
    -------
    dict[str, numpy.ndarray]
        Images (float32, W·m⁻²·sr⁻¹ per unit of the group's scale: per W·sr⁻¹ of on-axis
        LED intensity, or per W·m⁻²·sr⁻¹ of ceiling radiance) keyed by group.
    """
    import drjit as dr
    import mitsuba as mi

    wanted = [(i, g) for i, g in enumerate(emitter_groups(spec)) if groups is None or g in groups]
    out: dict[str, np.ndarray] = {}
    if faces is not None and mi.variant().startswith("scalar"):
        raise ValueError(
            "direct: expected a JIT (llvm/cuda) Mitsuba variant for 'primary'; use direct='path' in scalar mode"
        )
    if mi.variant().startswith("scalar"):
        # no kernel to reuse in scalar mode, and Python plugins' parameters cannot be
        # updated there: load one scene per group with only that group's emitters
        for index, group in wanted:
            only = {
                **spec,
                "shapes": [
                    {k: v for k, v in sh.items() if k != "emitter"}
                    if "emitter" in sh and sh["emitter"]["group"] != group
                    else sh
                    for sh in spec["shapes"]
                ],
            }
            image = np.asarray(mi.render(mi.load_dict(to_mitsuba(only, spp)), seed=seed * 7919 + index, spp=spp))
            out[group] = np.ascontiguousarray(image.mean(axis=-1), dtype=np.float32)
        return out
    scene = mi.load_dict(to_mitsuba(spec, spp))
    params = mi.traverse(scene)
    by_group: dict[str, list[tuple[str, float]]] = {}
    for i, shape in enumerate(spec["shapes"]):
        if "emitter" in shape:
            prefix = f"shape_{i:04d}.emitter.radiance"
            key = prefix if prefix in params else f"{prefix}.value"
            by_group.setdefault(shape["emitter"]["group"], []).append((key, shape["emitter"]["radiance"]))
    direct: dict[str, np.ndarray] = {}
    if faces is not None:
        # one pass of primary rays for every LED group: each ray's emission goes to the
        # group of the face it hit
        led_groups = [g for _, g in wanted if g.startswith("led:")]
        for other, entries in by_group.items():
            for key, value in entries:
                params[key] = dr.opaque(mi.Float, value if other in led_groups else 0.0)
        params.update()
        crop = tuple(int(v) for v in spec["sensor"]["crop"])
        images, _ = render_direct(scene, crop, faces, shape_groups(scene, spec, led_groups))
        direct = {g: images[k] for k, g in enumerate(led_groups)} if images.shape[0] else {}
        direct.update({g: np.zeros(images.shape[1:], np.float32) for g in led_groups if g not in direct})
    for index, group in wanted:
        for other, entries in by_group.items():
            for key, value in entries:
                # opaque: a literal radiance would make each group's kernel a different one
                params[key] = dr.opaque(mi.Float, value if other == group else 0.0)
        params.update()
        group_seed = seed * 7919 + index
        if group in direct:
            scattered = render_scattered(scene, crop, oversampling, scatter_spp, group_seed, int(spec["max_depth"]))
            image = np.ascontiguousarray(direct[group] + scattered, dtype=np.float32)
            image[np.abs(image) < NEGLIGIBLE_UNIT_RADIANCE] = 0.0
            out[group] = image
            continue
        if reuse_kernels:
            image = np.asarray(_render_primal(scene, group_seed, spp))
        else:
            image = np.asarray(mi.render(scene, params, seed=group_seed, spp=spp))
        out[group] = np.ascontiguousarray(image.mean(axis=-1), dtype=np.float32)
    return out


_MIN_BLOCK_ENTRIES = 1 << 12
"""Smallest accumulation buffer of :func:`_render_primal`, in float32 entries."""


def _render_primal(scene: mi.Scene, seed: int, spp: int) -> mi.TensorXf:
    """``mitsuba.render(scene, seed=seed, spp=spp)`` with a kernel that does not depend on the crop.

    Mitsuba's ``SamplingIntegrator::render`` (JIT branch of v3.9.1, the pinned version;
    ``render_sample`` and the box-filter ``ImageBlock::put``) bakes the film's crop size
    and offset into the rendering kernel as literals, so every new geometry (new crop)
    compiles a new kernel (~150 ms with LLVM). This is the same computation, operation for
    operation, with those values opaque: the image-plane position of a sample uses opaque
    crop offset and size, and the samples accumulate into a buffer whose length is rounded
    up to a power of two (Dr.Jit's expanded scatter-reduction bakes the target's length
    into the kernel); its first ``width × height × channels`` entries are then the image
    block ``mitsuba.render`` fills. Integer arithmetic is exact and every floating-point
    operation is the same, so the pixels are identical.

    Parameters
    ----------
    scene
        Loaded ``mitsuba.Scene`` with a perspective sensor, an ``hdrfilm`` with a box
        filter and no border, and a sampling integrator without AOVs.
    seed
        Sampler seed.
    spp
        Samples per pixel (one pass).

    Returns
    -------
    mitsuba.TensorXf
        The developed film, (crop height, crop width, channels).
    """
    import drjit as dr
    import mitsuba as mi

    sensor = scene.sensors()[0]
    film, sampler, integrator = sensor.film(), sensor.sampler(), scene.integrator()
    if (
        film.sample_border()
        or not film.rfilter().is_box_filter()
        or integrator.aov_names()
        or sensor.needs_aperture_sample()
        or sensor.shutter_open_time() > 0
    ):
        raise ValueError("_render_primal: expected a box filter, no border, no AOVs, a pinhole and no shutter time")
    width, height = (int(v) for v in film.crop_size())
    if width * height * spp > 0xFFFFFFFF:
        raise ValueError("_render_primal: expected at most 2³² samples (one pass)")
    camera = mi.traverse(sensor)
    if camera["principal_point_offset_x"][0] != 0 or camera["principal_point_offset_y"][0] != 0:
        raise ValueError("_render_primal: expected the principal point at the centre of the film")
    offset_x, offset_y = (int(v) for v in film.crop_offset())
    with dr.suspend_grad():
        sampler.set_sample_count(spp)
        n_channels = film.prepare(integrator.aov_names())
        if n_channels != 4:
            raise ValueError(f"_render_primal: expected a film with channels R, G, B, W, got {n_channels} channels")
        wavefront_size = width * height * spp
        sampler.set_samples_per_wavefront(spp)
        sampler.seed(seed, wavefront_size)
        # sample index → pixel index (row-major in the crop) → pixel position in the frame
        pixel = dr.arange(mi.UInt32, wavefront_size)
        if spp & (spp - 1) == 0:
            pixel >>= dr.opaque(mi.UInt32, spp.bit_length() - 1)
        else:
            pixel //= dr.opaque(mi.UInt32, spp)
        row = pixel // dr.opaque(mi.UInt32, width)
        pos = mi.Vector2f(
            mi.Int32(pixel - row * dr.opaque(mi.UInt32, width)) + dr.opaque(mi.Int32, offset_x),
            mi.Int32(row) + dr.opaque(mi.Int32, offset_y),
        )
        # render_sample(): jittered position in [0, 1]² of the crop, then the camera ray
        scale_x, scale_y = np.float32(1.0) / np.float32(width), np.float32(1.0) / np.float32(height)
        sample_pos = pos + sampler.next_2d(True)
        adjusted_pos = dr.fma(
            sample_pos,
            mi.Vector2f(dr.opaque(mi.Float, scale_x), dr.opaque(mi.Float, scale_y)),
            mi.Vector2f(
                dr.opaque(mi.Float, -np.float32(offset_x) * scale_x),
                dr.opaque(mi.Float, -np.float32(offset_y) * scale_y),
            ),
        )
        # the perspective camera adds film size × principal point offset / crop size (zero
        # here) with the crop size as a literal: trace it with the full frame as the film's
        # crop; the camera keeps the sample-to-camera transform of the real crop
        set_film_crop(film, mi.ScalarPoint2u(0, 0), film.size())
        try:
            ray, ray_weight = sensor.sample_ray_differential(
                mi.Float(sensor.shutter_open()), mi.Float(0.0), adjusted_pos, mi.Point2f(0.5)
            )
        finally:
            set_film_crop(film, mi.ScalarPoint2u(offset_x, offset_y), mi.ScalarVector2u(width, height))
        ray.scale_differential(float(np.float32(1.0) / np.sqrt(np.float32(spp))))
        radiance, _, _ = integrator.sample(scene, sampler, ray, sensor.get_medium(), True)
        value = mi.unpolarized_spectrum(ray_weight * radiance)
        rgb = [value[0]] * 3 if mi.is_monochromatic else [value[0], value[1], value[2]]
        # ImageBlock::put() of a box filter: channels (R, G, B, W) at the pixel's index
        n_entries = width * height * n_channels
        mode = _block_reduce_mode(
            dr.backend_v(mi.Float) == dr.JitBackend.LLVM,
            n_entries,
            dr.expand_threshold(),
            dr.flag(dr.JitFlag.ScatterReduceLocal),
        )
        block = dr.zeros(mi.Float, max(_MIN_BLOCK_ENTRIES, 1 << (n_entries - 1).bit_length()))
        dr.scatter_reduce(dr.ReduceOp.Add, block, mi.ArrayXf(*rgb, mi.Float(1.0)), pixel, True, mode)
        tensor = mi.TensorXf(dr.gather(mi.Float, block, dr.arange(mi.UInt32, n_entries)), (height, width, n_channels))
        film.put_block(mi.ImageBlock(tensor, film.crop_offset()))
        return film.develop()


def _block_reduce_mode(llvm: bool, n_entries: int, expand_threshold: int, scatter_reduce_local: bool):
    """The ``drjit.ReduceMode`` that ``ReduceMode.Auto`` picks for an image block of
    ``n_entries`` floats (it decides the order of the sums, so the pixels' last bits): on
    LLVM, ``Expand`` up to Dr.Jit's expand threshold; otherwise (CUDA, larger blocks)
    ``Local`` when the ``ScatterReduceLocal`` flag is on, else ``Direct``."""
    import drjit as dr

    if llvm and n_entries <= expand_threshold:
        return dr.ReduceMode.Expand
    return dr.ReduceMode.Local if scatter_reduce_local else dr.ReduceMode.Direct
