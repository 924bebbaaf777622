"""A cheap render of the whole frame, so auto exposure meters a real frame.

The scene of :func:`scenes.assemble.scene_spec` is rendered on the full frame at
1/``scale`` resolution (one rendered pixel covers ``scale`` × ``scale`` camera pixels)
with few samples, scaled to the scenario's LED drive and ambient level exactly as
:func:`scenes.render.render` scales its crop, and cached in the render cache by a
content key of the modified scene description.
"""

from __future__ import annotations

import math

from scenes.assemble import scene_spec
from scenes.mitsuba_variant import select_variant
from scenes.radiance import PixelGrid, SpectralRadiance
from scenes.render import RENDER_VERSION, _scaled_component, render_unit_groups
from scenes.render_cache import RenderCache, content_key
from scenes.scenario import Scenario

BACKGROUND_VERSION = 1


def background_grid(scenario: Scenario, scale: int) -> PixelGrid:
    """Grid of the background render: a camera with ``scale``× larger pixels, same field of view."""
    g = scenario.geometry
    w, h = math.ceil(g.width_px / scale), math.ceil(g.height_px / scale)
    return PixelGrid(w, h, g.focal_length_px * w / g.width_px, ((w - 1) / 2, (h - 1) / 2), 0, 0, w, h, 1)


def render_background(
    scenario: Scenario, cache: RenderCache | None = None, scale: int = 8, spp: int = 4
) -> SpectralRadiance:
    """Full-frame radiance at 1/``scale`` resolution (W·m⁻²·sr⁻¹ per component), cached.

    The returned grid describes the low-resolution frame (``frame_width_px`` =
    ceil(W/scale)); each of its pixels averages ``scale``² camera pixels.
    """
    if not isinstance(scale, int) or scale < 1:
        raise ValueError(f"scale: expected an integer >= 1, got {scale!r}")
    if not isinstance(spp, int) or spp < 1:
        raise ValueError(f"spp: expected an integer >= 1, got {spp!r}")
    variant = select_variant("mono").variant
    spec = scene_spec(scenario)
    grid = background_grid(scenario, scale)
    spec["sensor"]["film"] = [grid.width, grid.height]
    spec["sensor"]["crop"] = [0, 0, grid.width, grid.height]
    seed = scenario.render.seed
    key = content_key("background", BACKGROUND_VERSION, RENDER_VERSION, variant, spec, spp, seed)

    def make() -> dict:
        return render_unit_groups(spec, spp, seed)

    unit, from_cache = cache.get_or_make(key, make) if cache is not None else (make(), False)
    components = tuple(
        _scaled_component(scenario, group, image, f"{key}:{group}") for group, image in sorted(unit.items())
    )
    return SpectralRadiance(grid, components, scenario.to_dict(), variant, from_cache)
