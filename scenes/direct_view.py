"""The lit faces seen straight from the camera, by deterministic primary rays.

Every surface the camera sees in a dark scene is either an emitter (a marker's lit face
with its near-field exit radiance L(r, θ), a glowing housing wall) or grey diffuse
stone, paint and plastic lit by those emitters. The first part, the *direct view*, is
the emitted radiance at the first surface a camera ray meets: no path to sample, only a
pixel footprint to integrate. This module integrates it with a fixed pattern of primary
rays (stratum centres, no random numbers), so the image has no Monte-Carlo noise:

1. every rendered sub-pixel gets one ray through its centre (:data:`BASE_SAMPLES`);
2. sub-pixels whose 3 × 3 neighbourhood is not flat (an edge of a face, of its texture or
   of a glowing housing wall runs near them) and the sub-pixels around every lit face's
   projected disc are rendered again with ``n``² rays at the centres of an n × n grid of
   strata, ``n`` chosen so that the smallest facing lit face spans at least
   :data:`SAMPLES_ACROSS_FACE` rays across its projected minor axis (at least 2).

One pass serves every emitter group at once: each ray's radiance goes to the group of the
shape it hit.

Counting regular-grid points inside a disc of radius R (in grid spacings) gives its area
within ~1 % (worst of 300 random offsets: 1.0 % at R = 24, 0.9 % at R = 16; standard
deviation 0.2-0.3 %, the Gauss circle problem) and its centroid within 0.03-0.04 spacings
(standard deviation), measured with numpy for this module; at 48 rays across a face both
are far inside the 1 % flux and 0.05 px centroid the renders are checked against
(``tests/scenes/test_direct_view.py``).

The light the room, the beacon body and the housings scatter (~0.07 % of the marker flux,
measured in ``tests/scenes/test_direct_view.py``) is left to Mitsuba's path tracer with
the directly seen emitters hidden (``hide_emitters``), at a few samples per camera pixel:
:func:`render_scattered`. The two add up to the full path-traced image
(direct + scattered = all paths; a conservation check in the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from scenes.beacon import SIDE_ANGLE_RAD, target_to_beacon
from scenes.scenario import Scenario

if TYPE_CHECKING:
    import mitsuba as mi

__all__ = [
    "BASE_SAMPLES",
    "EDGE_TOLERANCE",
    "MAX_SAMPLES",
    "SAMPLES_ACROSS_FACE",
    "FaceDisc",
    "face_discs",
    "refine_samples",
    "render_direct",
    "render_scattered",
    "set_film_crop",
    "shape_groups",
]

BASE_SAMPLES = 1
"""Rays per sub-pixel along each axis everywhere (its centre); sub-pixels near an edge get more."""
SAMPLES_ACROSS_FACE = 48
"""Rays across the smallest facing lit face's projected minor axis (radius 24 spacings:
area within ~1 % worst case, 0.2 % typical; see the module docstring)."""
MAX_SAMPLES = 64
"""Most rays per refined sub-pixel along each axis (a face 0.75 sub-pixels across still
spans 48 rays)."""
SCATTER_BLOCK_PX = 2
"""Camera pixels per side of a block of the scattered light's samples (assumed: that light,
~0.07 % of a marker's flux, spreads over the housing, the beacon body and the room, so
averaging it over 2 × 2 pixels moves no centroid by more than ~0.07 % of a pixel, while it
quarters the path-traced samples, the largest share of a new geometry's render)."""
EDGE_TOLERANCE = 1e-4
"""A sub-pixel is refined where its 3 × 3 neighbourhood's centre radiances differ by more
than this fraction of the brightest (assumed: far below the 1 % flux accuracy asked of a marker, and far
above float32 rounding)."""


@dataclass(frozen=True)
class FaceDisc:
    """A lit face's projection on the rendered crop.

    Attributes
    ----------
    x, y
        Centre, sub-pixels from the crop's top-left corner (continuous: the first
        sub-pixel spans [0, 1)).
    radius
        Projected radius (the disc's semi-major axis), sub-pixels.
    minor_axis
        Projected minor axis (diameter × |cos θ|), sub-pixels.
    facing
        Whether it faces the camera well enough to be a marker a detector measures.
    """

    x: float
    y: float
    radius: float
    minor_axis: float
    facing: bool


FACING_COS = 0.25
"""A lit face of the visible side seen within acos(0.25) ≈ 75.5° of its normal sets the
refinement (beyond that it is a sliver the detectors do not measure; it is still refined,
at the rate the others set)."""


def face_discs(scenario: Scenario, crop_x0_px: int, crop_y0_px: int) -> list[FaceDisc]:
    """Every lit face of the beacon (all four sides) projected on the crop whose top-left
    camera pixel is (``crop_x0_px``, ``crop_y0_px``), in sub-pixels (pinhole camera, as rendered)."""
    design, geom, s = scenario.design, scenario.geometry, scenario.render.oversampling
    pose = scenario.render_pose()
    cx, cy = geom.principal_point_px
    f = geom.focal_length_px
    r_face = design.lit_face_diameter_m / 2
    out: list[FaceDisc] = []
    for side in SIDE_ANGLE_RAD:
        rot, trans = target_to_beacon(side, design.d_t_m)
        points = design.marker_positions_m() @ rot.T + trans
        normals = np.stack([m.normal for m in design.markers]) @ rot.T
        pc = pose.world_to_camera(points)
        to_camera = pose.position_m - points
        cos = np.sum(normals * to_camera, axis=1) / np.linalg.norm(to_camera, axis=1)
        for (xc, yc, zc), c in zip(pc, cos, strict=True):
            if zc <= 0:
                continue
            u, v, radius = cx + f * xc / zc, cy + f * yc / zc, r_face * f / zc
            out.append(
                FaceDisc(
                    x=(u + 0.5 - crop_x0_px) * s,
                    y=(v + 0.5 - crop_y0_px) * s,
                    radius=radius * s,
                    minor_axis=2 * radius * s * abs(float(c)),
                    facing=side == scenario.side and c > FACING_COS,
                )
            )
    return out


def refine_samples(faces: list[FaceDisc]) -> int:
    """Rays per refined sub-pixel along each axis: enough that the smallest facing face
    spans :data:`SAMPLES_ACROSS_FACE` rays, between :data:`BASE_SAMPLES` and :data:`MAX_SAMPLES`."""
    sizes = [f.minor_axis for f in faces if f.facing and f.minor_axis > 0]
    if not sizes:
        return BASE_SAMPLES
    return int(min(MAX_SAMPLES, max(BASE_SAMPLES, math.ceil(SAMPLES_ACROSS_FACE / min(sizes)))))


def _emitted(
    scene: mi.Scene, crop: tuple[int, int, int, int], x: NDArray, y: NDArray
) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """Radiance emitted toward the camera by the first surface on the rays through film
    positions (``x``, ``y``) (sub-pixels of the full film, continuous), W·m⁻²·sr⁻¹, and the
    registry id of the shape each ray hit (0: none)."""
    import drjit as dr
    import mitsuba as mi

    sensor = scene.sensors()[0]
    film = sensor.film()
    offset_x, offset_y, width, height = crop
    position = mi.Point2f(
        mi.Float(((x - offset_x) / width).astype(np.float32)), mi.Float(((y - offset_y) / height).astype(np.float32))
    )
    # as in scenes.render._render_primal: the camera keeps the real crop's sample-to-camera
    # transform; the film's crop is the full frame while the ray is made, so no crop size
    # becomes a literal of the kernel
    set_film_crop(film, mi.ScalarPoint2u(0, 0), film.size())
    try:
        with dr.suspend_grad():
            ray, weight = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), position, mi.Point2f(0.5))
            si = scene.ray_intersect(ray)
            valid = si.is_valid()
            value = dr.select(valid, weight * si.emitter(scene).eval(si, valid), 0.0)
            shape = dr.select(valid, dr.reinterpret_array(mi.UInt32, si.shape), 0)
            dr.eval(value, shape)
            out = np.asarray(mi.unpolarized_spectrum(value)[0], dtype=np.float32)
            ids = np.asarray(shape, dtype=np.uint32)
    finally:
        set_film_crop(film, mi.ScalarPoint2u(offset_x, offset_y), mi.ScalarVector2u(width, height))
    return out, ids


def set_film_crop(film: mi.Film, offset: mi.ScalarPoint2u, size: mi.ScalarVector2u) -> None:
    """Set a ``mitsuba.Film``'s crop window (offset and size in film pixels) without
    notifying its sensor (whose sample-to-camera transform keeps the crop it was made with)."""
    import mitsuba as mi

    params = mi.traverse(film)
    params["crop_offset"] = offset
    params["crop_size"] = size
    params.update()


def _stratum_offsets(n: int) -> NDArray[np.float64]:
    """Centres of an n × n grid of strata of the unit square, (n², 2)."""
    c = (np.arange(n) + 0.5) / n
    gx, gy = np.meshgrid(c, c)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def _sample_subpixels(
    scene: mi.Scene, crop: tuple[int, int, int, int], rows: NDArray, cols: NDArray, n: int, group_of: NDArray[np.int32]
) -> NDArray[np.float32]:
    """Mean radiance of each emitter group over the n × n stratum centres of the sub-pixels
    (rows, cols) of the crop, (groups, len); ``group_of`` maps a shape's registry id to its
    group's index (−1: no group)."""
    offsets = _stratum_offsets(n)
    n_groups = int(group_of.max()) + 1 if group_of.size else 0
    out = np.zeros((n_groups, rows.size), dtype=np.float32)
    chunk = max(1, (1 << 22) // (n * n))  # at most 4 M rays per kernel launch
    for i in range(0, rows.size, chunk):
        x = crop[0] + cols[i : i + chunk, None] + offsets[None, :, 0]
        y = crop[1] + rows[i : i + chunk, None] + offsets[None, :, 1]
        value, ids = _emitted(scene, crop, x.ravel(), y.ravel())
        group = group_of[np.minimum(ids, group_of.size - 1)]
        which = np.repeat(np.arange(x.shape[0]), n * n)
        hit = (group >= 0) & (value != 0)
        flat = np.bincount(
            group[hit] * x.shape[0] + which[hit], weights=value[hit], minlength=n_groups * x.shape[0]
        ).reshape(n_groups, x.shape[0])
        out[:, i : i + chunk] = flat / (n * n)
    return out


def shape_groups(scene: mi.Scene, spec: dict, groups: list[str]) -> NDArray[np.int32]:
    """Registry id of each of ``scene``'s shapes → index in ``groups`` of its emitter's
    group (−1 for shapes without one or of another group); shapes are named
    ``shape_<index in spec["shapes"]>`` (:func:`scenes.assemble.to_mitsuba`)."""
    import drjit as dr
    import mitsuba as mi

    shapes = scene.shapes()
    ids = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()), dtype=np.int64)
    table = np.full(int(ids.max()) + 1 if ids.size else 1, -1, dtype=np.int32)
    for shape, registry_id in zip(shapes, ids, strict=True):
        name = shape.id()
        if not name.startswith("shape_"):
            continue
        emitter = spec["shapes"][int(name.split("_", 1)[1])].get("emitter")
        if emitter is not None and emitter["group"] in groups:
            table[registry_id] = groups.index(emitter["group"])
    return table


def render_direct(
    scene: mi.Scene, crop: tuple[int, int, int, int], faces: list[FaceDisc], group_of: NDArray[np.int32]
) -> tuple[NDArray[np.float32], dict]:
    """The direct view of the active emitters on the crop, noise-free, split by group.

    Parameters
    ----------
    scene
        Loaded Mitsuba scene (its sensor's film holds the crop), with the emitters of
        every group wanted at their unit radiance.
    crop
        (x0, y0, width, height) of the crop, film sub-pixels.
    faces
        Projected lit faces (where to refine whatever pass 1 sees).
    group_of
        Shape registry id → group index (:func:`shape_groups`).

    Returns
    -------
    images, info
        (groups, height, width) float32 radiance, W·m⁻²·sr⁻¹ per unit of each group's
        scale; ``info``: rays per refined sub-pixel along each axis, refined sub-pixels,
        rays traced.
    """
    _, _, width, height = crop
    rows, cols = np.divmod(np.arange(width * height), width)
    n0 = BASE_SAMPLES
    base = _sample_subpixels(scene, crop, rows, cols, n0, group_of)
    images = base.reshape(-1, height, width)
    total = images.sum(axis=0)
    n = refine_samples(faces)
    peak = float(total.max()) if total.size else 0.0
    refine = np.zeros((height, width), dtype=bool)
    if peak > 0:
        # a sub-pixel differs from a neighbour: an edge of a face (or of its texture) runs near it
        spread = ndimage.maximum_filter(total, size=3) - ndimage.minimum_filter(total, size=3)
        refine = spread > EDGE_TOLERANCE * peak
    vv, uu = np.mgrid[0:height, 0:width]
    for f in faces:
        # every sub-pixel that the face's disc (plus one sub-pixel) may touch
        r = f.radius + 1.5
        y0, y1 = max(0, math.floor(f.y - r)), min(height, math.ceil(f.y + r))
        x0, x1 = max(0, math.floor(f.x - r)), min(width, math.ceil(f.x + r))
        if y1 > y0 and x1 > x0:
            near = (uu[y0:y1, x0:x1] + 0.5 - f.x) ** 2 + (vv[y0:y1, x0:x1] + 0.5 - f.y) ** 2 <= r * r
            refine[y0:y1, x0:x1] |= near
    rays = rows.size * n0 * n0
    n = max(n, 2 * n0)  # refined sub-pixels always get more rays than the rest
    if refine.any():
        rr, cc = np.nonzero(refine)
        images[:, rr, cc] = _sample_subpixels(scene, crop, rr, cc, n, group_of)
        rays += rr.size * n * n
    info = {"refine_samples": n, "refined_subpixels": int(refine.sum()), "rays": rays}
    return images.astype(np.float32), info


def render_scattered(
    scene: mi.Scene,
    crop: tuple[int, int, int, int],
    oversampling: int,
    spp: int,
    seed: int,
    max_depth: int,
    *,
    block_px: int = SCATTER_BLOCK_PX,
) -> NDArray[np.float32]:
    """Light scattered toward the camera (every path but the directly seen emission), on the crop.

    Mitsuba's ``path`` integrator with ``hide_emitters`` (a camera ray that meets an
    emitter gets none of its emission; the emitters still light the scene) and
    ``max_depth`` path vertices, at ``spp`` samples jittered over each *block* of
    ``block_px`` × ``block_px`` camera pixels (``oversampling``² sub-pixels each; blocks
    at the crop's right and bottom edges cover what is left of it): each block's mean is
    spread evenly over its sub-pixels, which keeps every block's flux unbiased and blurs
    the scattered light by at most a block (see :data:`SCATTER_BLOCK_PX`).

    Parameters
    ----------
    scene
        Loaded Mitsuba scene.
    crop
        (x0, y0, width, height) in film sub-pixels; width and height multiples of ``oversampling``.
    oversampling
        Sub-pixels per camera pixel along each axis.
    spp
        Samples per block of camera pixels.
    seed
        Sampler seed.
    max_depth
        Longest path (Mitsuba's ``max_depth``).
    block_px
        Camera pixels per block side (1: one block per camera pixel).

    Returns
    -------
    numpy.ndarray
        (height, width) float32, W·m⁻²·sr⁻¹ per unit of the emitters' scale.
    """
    import drjit as dr
    import mitsuba as mi

    offset_x, offset_y, width, height = crop
    s = oversampling
    pw, ph = width // s, height // s
    if pw * s != width or ph * s != height:
        raise ValueError(f"crop: expected a size in whole camera pixels of {s} sub-pixels, got {width} × {height}")
    b = int(block_px)
    bw, bh = -(-pw // b), -(-ph // b)
    # each block's extent in camera pixels (the last column and row of blocks may be narrower)
    block_w = np.minimum(b, pw - b * np.arange(bw)).astype(np.float32)
    block_h = np.minimum(b, ph - b * np.arange(bh)).astype(np.float32)
    integrator = mi.load_dict({"type": "path", "max_depth": int(max_depth), "hide_emitters": True})
    sampler = mi.load_dict({"type": "independent", "sample_count": int(spp)})
    n = bw * bh * spp
    sensor = scene.sensors()[0]
    film = sensor.film()
    with dr.suspend_grad():
        sampler.set_samples_per_wavefront(spp)
        sampler.seed(seed, n)
        block = dr.arange(mi.UInt32, n) // dr.opaque(mi.UInt32, spp)
        row = block // dr.opaque(mi.UInt32, bw)
        col = block - row * dr.opaque(mi.UInt32, bw)
        jitter = sampler.next_2d()
        extent_x = dr.gather(mi.Float, mi.Float(block_w), col)
        extent_y = dr.gather(mi.Float, mi.Float(block_h), row)
        # film position (crop-relative, normalised) of a point jittered over the block
        position = mi.Point2f(
            (mi.Float(col) * b + jitter.x * extent_x) * dr.opaque(mi.Float, s / width),
            (mi.Float(row) * b + jitter.y * extent_y) * dr.opaque(mi.Float, s / height),
        )
        set_film_crop(film, mi.ScalarPoint2u(0, 0), film.size())
        try:
            ray, weight = sensor.sample_ray(mi.Float(0.0), mi.Float(0.5), position, mi.Point2f(0.5))
        finally:
            set_film_crop(film, mi.ScalarPoint2u(offset_x, offset_y), mi.ScalarVector2u(width, height))
        radiance, _, _ = integrator.sample(scene, sampler, ray, sensor.get_medium(), True)
        value = np.asarray(mi.unpolarized_spectrum(weight * radiance)[0], dtype=np.float64)
    per_block = value.reshape(bh, bw, spp).mean(axis=2)
    # below float32's smallest normal number: zero (a subnormal keeps too few bits to be
    # scaled by the LED drive exactly)
    per_block[np.abs(per_block) < np.finfo(np.float32).tiny] = 0.0
    per_block = per_block.astype(np.float32)
    return np.repeat(np.repeat(per_block, b * s, axis=0)[:height], b * s, axis=1)[:, :width]
