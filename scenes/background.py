"""A cheap render of the whole frame, so auto exposure meters a real frame.

The scene is rendered on the full frame at 1/``scale`` resolution (one rendered pixel
covers ``scale`` × ``scale`` camera pixels) with few samples, scaled to the scenario's
LED drive and ambient level exactly as :func:`scenes.render.render` scales its crop, and
cached in the render cache by a content key of the scene description it renders.

What is rendered (``RenderSettings.background``):

``room`` (default)
    The room without the beacon (:func:`scenes.assemble.room_spec`), seen from the
    camera of a *band representative* pose (:func:`room_scenario`): range rounded to
    :data:`RANGE_STEP` geometric steps, yaw to :data:`YAW_STEP_DEG`, camera height to
    :data:`HEIGHT_STEP_M`; every side, beacon finish, diffuser, LED drive and pose jitter
    of a band shares one render. The crop (rendered per geometry, beacon included) covers
    the beacon, so what this leaves out is the beacon's LEDs lighting the room outside the
    crop and the beacon's shadow: measured on the T6 at its manual ISO 6400, 1/60 s
    (``tests/scenes/test_direct_view.py``, docstring of ``test_room_background``), the LED
    light outside the crop is 0.0006-0.03 e⁻ per pixel on average (read noise is ~1-3 e⁻),
    the part that depends on the pose. A dark cave (no ambient light) has no room light at
    all: its background is zero and nothing is rendered.
``geometry``
    The whole scene of :func:`scenes.assemble.scene_spec` for every geometry (the
    reference; the background before issue 24), LED components included.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from scenes.assemble import room_spec, scene_spec, sensor_spec
from scenes.mitsuba_variant import select_variant
from scenes.radiance import PixelGrid, SpectralRadiance
from scenes.render import RENDER_VERSION, _scaled_component, render_unit_groups
from scenes.render_cache import RenderCache, content_key
from scenes.scenario import Scenario

__all__ = ["HEIGHT_STEP_M", "RANGE_STEP", "YAW_STEP_DEG", "background_grid", "render_background", "room_scenario"]

BACKGROUND_VERSION = 1

RANGE_STEP = 0.02
"""Range bands of the room background: ranges within ±1 % of 1.02^k m share one render
(assumed: the room's walls move by under 1 % of their distance; the studies' pose jitter,
±0.5 % in range, stays inside a band)."""
YAW_STEP_DEG = 5.0
"""Yaw bands: the camera looks at marker 1, off the room's axis by about d_t·sin(yaw)/range,
so yaw turns the room in the frame a little; ±2.5° (the jitter is ±0.5°) share a render."""
HEIGHT_STEP_M = 0.05
"""Camera-height bands, m (the jitter is ±5 mm)."""


def background_grid(scenario: Scenario, scale: int) -> PixelGrid:
    """Grid of the background render: a camera with ``scale``× larger pixels, same field of view."""
    g = scenario.geometry
    w, h = math.ceil(g.width_px / scale), math.ceil(g.height_px / scale)
    return PixelGrid(w, h, g.focal_length_px * w / g.width_px, ((w - 1) / 2, (h - 1) / 2), 0, 0, w, h, 1)


def room_scenario(scenario: Scenario) -> Scenario:
    """The band representative of ``scenario`` whose room the ``room`` background renders:
    same beacon design (its target offset places marker 1), camera, environment and seed;
    side ``red`` (the room turns with the side, the camera's view of it does not), range,
    yaw and height rounded to their bands, the camera's turn (pan, tilt) to :data:`YAW_STEP_DEG`,
    bare black-housed markers at the datasheet drive."""
    step = math.log1p(RANGE_STEP)
    range_m = math.exp(round(math.log(scenario.range_m) / step) * step)
    yaw = min(90.0, max(-90.0, YAW_STEP_DEG * round(scenario.yaw_deg / YAW_STEP_DEG)))
    height = HEIGHT_STEP_M * round(scenario.camera_height_m / HEIGHT_STEP_M)
    if abs(height) >= range_m:
        height = scenario.camera_height_m
    render = replace(scenario.render, oversampling=1)
    pan, tilt = (YAW_STEP_DEG * round(a / YAW_STEP_DEG) for a in (scenario.pan_deg, scenario.tilt_deg))
    return Scenario(
        pan_deg=min(85.0, max(-85.0, pan)),
        tilt_deg=min(85.0, max(-85.0, tilt)),
        beacon=scenario.beacon,
        side="red",
        range_m=range_m,
        yaw_deg=yaw,
        camera=scenario.camera,
        environment=scenario.environment,
        camera_height_m=height,
        render=render,
    )


def render_background(
    scenario: Scenario, cache: RenderCache | None = None, scale: int = 8, spp: int = 4
) -> SpectralRadiance:
    """Full-frame radiance at 1/``scale`` resolution (W·m⁻²·sr⁻¹ per component), cached.

    The returned grid describes the low-resolution frame (``frame_width_px`` =
    ceil(W/scale)); each of its pixels averages ``scale``² camera pixels. Components:
    ``ambient`` where the room is lit (``room`` mode), or every group of the scene
    (``geometry`` mode); none in a dark cave with ``room``.
    """
    if not isinstance(scale, int) or scale < 1:
        raise ValueError(f"scale: expected an integer >= 1, got {scale!r}")
    if not isinstance(spp, int) or spp < 1:
        raise ValueError(f"spp: expected an integer >= 1, got {spp!r}")
    variant = select_variant("mono").variant
    grid = background_grid(scenario, scale)
    seed = scenario.render.seed
    if scenario.render.background == "geometry":
        spec = scene_spec(scenario)
        spec["sensor"] = sensor_spec(scenario, turned=True)  # the whole frame is the camera's own view
        tag: tuple = ("background",)
    else:
        spec = room_spec(room_scenario(scenario))
        tag = ("background-room",)
    spec["sensor"]["film"] = [grid.width, grid.height]
    spec["sensor"]["crop"] = [0, 0, grid.width, grid.height]
    key = content_key(*tag, BACKGROUND_VERSION, RENDER_VERSION, variant, spec, spp, seed)

    def make() -> dict:
        return render_unit_groups(spec, spp, seed)

    if not any("emitter" in sh for sh in spec["shapes"]):
        unit: dict[str, np.ndarray] = {}
        from_cache = False
    else:
        unit, from_cache = cache.get_or_make(key, make) if cache is not None else (make(), False)
    components = tuple(
        _scaled_component(scenario, group, image, f"{key}:{group}") for group, image in sorted(unit.items())
    )
    return SpectralRadiance(grid, components, scenario.to_dict(), variant, from_cache)
