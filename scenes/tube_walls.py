"""The lava tube around one beacon as a render sees it: side walls, ceiling and a rough, sloped floor.

A beacon of the traverse stands in a tube (:class:`scenes.tube.Tube` is its floor plan). Its frame
is rendered with the tube's own surfaces instead of the dark environment's box around the
camera-beacon line (:func:`scenes.assemble.environment_shapes`): the straight stretch of tube
through the beacon along the tube's axis where the beacon stands (its tangent: around a bend the
walls near the beacon, which its light reaches first, are where the tube has them, and those
farther off are not), the walls ``left_m`` and ``right_m`` from the beacon's axis, the ceiling
``height_m`` above the floor, the floor rising by ``slope_deg`` along the axis, and the floor's
height varying about its plane as a Gaussian random field over the tube's floor plan
(:func:`rough_heights`): one floor per tube, so every render that shows a piece of it shows the same
piece (``floor_x_m``, ``floor_y_m``, ``floor_heading_deg`` place the beacon's stretch on the plan).
The stretch runs :data:`OPEN_END_M` beyond the beacon and the camera and is open there: the light
the tube beyond would return is left out (in the dark only the LEDs light the walls, and what their
basalt returns from farther is smaller still). Walls, ceiling and floor are the dark environment's
basalt, or grey of the tube's own ``reflectance`` (a dusty tube: 0.15-0.28 in RELAB's powder spectra,
as issue 28 reports them, against 0.05-0.10 for fresh basalt; their red slope is not modelled).

Directions are in the scenario's target frame (x out of the lit side, z down; a yaw turns the
camera from x toward y), so ``axis_deg`` is measured like ``yaw_deg``; left and right are seen
from above, looking along the axis.

Example
-------
>>> walls = TubeWalls(axis_deg=90.0, left_m=0.5, right_m=7.5, floor_rms_m=0.05)
>>> walls.validate()
>>> [round(float(v), 12) for v in walls.axis()]
[0.0, 1.0, 0.0]
>>> h = rough_heights(np.array([0.0, 0.1, 5.0]), np.zeros(3), rms_m=0.05, correlation_m=0.4, seed=1)
>>> h.shape, bool(abs(h).max() < 0.25)
((3,), True)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scenes.shapes import rect_shape
from scenes.sourced import DATA_DIR, load_sourced

__all__ = [
    "FLOOR_MODES",
    "MAX_FLOOR_VERTICES",
    "OPEN_END_M",
    "TubeWalls",
    "heightfield_mesh",
    "rough_heights",
    "tube_defaults",
    "tube_wall_shapes",
]

OPEN_END_M = 5.0
"""How far the rendered stretch of tube runs beyond the beacon and beyond the camera, m (assumed:
an LED's light reaching a basalt wall (ρ ≈ 0.07) 5 m away and coming back is under 1e-4 of what
reaches the camera directly at the traverse's ranges)."""

FLOOR_MODES = 1024
"""Cosine modes summed for the rough floor (:func:`rough_heights`): the field's covariance at any lag
is then within ~1/√1024 ≈ 3 % of the target's, and its values Gaussian to the central limit."""

MAX_FLOOR_VERTICES = 250_000
"""The rough floor's grid is coarsened (its spacing raised above a quarter of the correlation
length) to stay under this many vertices."""


def tube_defaults() -> dict[str, float]:
    """The tube's height and floor of ``scenes/data/tube.toml`` (``height_m``, ``floor_rms_m``,
    ``floor_correlation_m``), each with its provenance there."""
    return dict(load_sourced(DATA_DIR / "tube.toml")[0])


@dataclass(frozen=True)
class TubeWalls:
    """The tube around a beacon (lengths in m, angles in degrees; module docstring for the frame).

    Attributes
    ----------
    axis_deg
        The tube's axis (the direction of travel) in the target frame's horizontal plane, from the
        lit side's outward normal toward the target's y (as ``yaw_deg``).
    left_m, right_m
        Beacon axis to the wall on the left and on the right of the axis, seen from above (> 0).
    height_m
        Floor to ceiling, perpendicular to the floor (> 0).
    slope_deg
        The floor's rise along the axis, degrees in (−45, 45); the beacon stands upright on it.
    floor_rms_m
        Root-mean-square height of the floor about its plane (0: flat).
    floor_correlation_m
        The lag at which the floor heights' autocorrelation falls to 1/e.
    floor_seed
        Seed of the tube's floor (one field over its floor plan).
    floor_x_m, floor_y_m, floor_heading_deg
        Where the beacon's foot lies on the floor plan (m) and the axis's heading there (degrees,
        counter-clockwise seen from above): the stretch's floor is the plan's field there.
    reflectance
        Diffuse reflectance of walls, ceiling and floor (grey, in (0, 1)); None: the environment's.
    """

    axis_deg: float = 0.0
    left_m: float = 4.0
    right_m: float = 4.0
    height_m: float = 5.0
    slope_deg: float = 0.0
    floor_rms_m: float = 0.0
    floor_correlation_m: float = 0.5
    floor_seed: int = 0
    floor_x_m: float = 0.0
    floor_y_m: float = 0.0
    floor_heading_deg: float = 0.0
    reflectance: float | None = None

    def validate(self) -> None:
        """One-line errors naming the field (prefixed ``tube_walls.``)."""
        for name in ("left_m", "right_m", "height_m", "floor_correlation_m"):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ValueError(f"tube_walls.{name}: expected a length > 0 m, got {value!r}")
        for name in ("axis_deg", "floor_x_m", "floor_y_m", "floor_heading_deg"):
            if not _finite(getattr(self, name)):
                raise ValueError(f"tube_walls.{name}: expected a finite number, got {getattr(self, name)!r}")
        if not (_finite(self.slope_deg) and abs(self.slope_deg) < 45):
            raise ValueError(f"tube_walls.slope_deg: expected an angle in (-45, 45) degrees, got {self.slope_deg!r}")
        if not (_finite(self.floor_rms_m) and 0 <= self.floor_rms_m < self.height_m / 4):
            raise ValueError(
                f"tube_walls.floor_rms_m: expected a height >= 0 m and below a quarter of height_m, "
                f"got {self.floor_rms_m!r}"
            )
        if not (isinstance(self.floor_seed, int) and not isinstance(self.floor_seed, bool) and self.floor_seed >= 0):
            raise ValueError(f"tube_walls.floor_seed: expected an integer >= 0, got {self.floor_seed!r}")
        if self.reflectance is not None and not (_finite(self.reflectance) and 0 < self.reflectance < 1):
            raise ValueError(f"tube_walls.reflectance: expected a reflectance in (0, 1), got {self.reflectance!r}")

    def axis(self) -> NDArray[np.float64]:
        """Unit vector of the axis in the target frame (horizontal)."""
        a = math.radians(self.axis_deg)
        return np.array([math.cos(a), math.sin(a), 0.0])

    def right(self) -> NDArray[np.float64]:
        """Unit vector toward the right wall in the target frame (horizontal; z is down)."""
        a = math.radians(self.axis_deg)
        return np.array([-math.sin(a), math.cos(a), 0.0])

    def to_dict(self) -> dict:
        """Plain-data form (``reflectance`` left out when None, so the walls of the environment's
        basalt keep the form, and the render keys, they had before it existed)."""
        d = dataclasses.asdict(self)
        if d["reflectance"] is None:
            del d["reflectance"]
        return d

    @classmethod
    def coerce(cls, value: TubeWalls | dict | None) -> TubeWalls | None:
        """A :class:`TubeWalls` from itself, its :meth:`to_dict` form, or None; unknown fields are
        one-line errors."""
        if value is None or isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise ValueError(f"tube_walls: expected a table of the tube's walls, got {type(value).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(value) - names)
        if unknown:
            raise ValueError(f"tube_walls.{unknown[0]}: unknown field (expected {', '.join(sorted(names))})")
        return cls(**value)


def rough_heights(
    x_m: NDArray[np.float64],
    y_m: NDArray[np.float64],
    *,
    rms_m: float,
    correlation_m: float,
    seed: int,
    modes: int = FLOOR_MODES,
) -> NDArray[np.float64]:
    """Heights of a rough floor at plan points (x, y), m: a stationary Gaussian random field.

    The field is a sum of ``modes`` random cosines, h(p) = σ √(2/M) Σ cos(k_m · p + φ_m), with
    wave vectors k_m drawn from the normal distribution N(0, 2/ℓ² I) and phases φ_m uniform, so that
    its covariance is σ² E[cos(k · r)] = σ² exp(−|r|²/ℓ²) (the normal's characteristic function): it
    falls to 1/e at the lag ℓ = ``correlation_m`` (spectral synthesis; Shinozuka & Deodatis 1991,
    Appl. Mech. Rev. 44(4), 191). Defined everywhere on the plan by the seed alone, so every render
    that shows a piece of the floor shows the same piece. Lava-flow surfaces are self-affine rather
    than Gaussian-correlated over wide bands of scale (Shepard et al. 2001, J. Geophys. Res.
    106(E12), 32777); one scale is what a render of LED light scattered by the floor resolves.

    Parameters
    ----------
    x_m, y_m
        Plan coordinates, m (same shape).
    rms_m
        Root-mean-square height σ, m (0: a flat floor).
    correlation_m
        1/e autocorrelation length ℓ, m (> 0).
    seed
        Seed of the modes.
    modes
        Number of cosines M.
    """
    x, y = np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
    if rms_m == 0:
        return np.zeros(np.broadcast_shapes(x.shape, y.shape))
    rng = np.random.default_rng(seed)
    k = rng.normal(0.0, math.sqrt(2.0) / correlation_m, size=(modes, 2))
    phase = rng.uniform(0.0, 2 * math.pi, size=modes)
    out = np.empty(np.broadcast_shapes(x.shape, y.shape))
    flat_x, flat_y, flat = np.broadcast_to(x, out.shape).ravel(), np.broadcast_to(y, out.shape).ravel(), out.ravel()
    for i in range(0, flat.size, 4096):  # in chunks: a modes × chunk table at a time
        arg = np.outer(k[:, 0], flat_x[i : i + 4096]) + np.outer(k[:, 1], flat_y[i : i + 4096]) + phase[:, None]
        flat[i : i + 4096] = np.cos(arg).sum(axis=0)
    return out * (rms_m * math.sqrt(2.0 / modes))


def heightfield_mesh(spec: dict) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """Vertices (n × 3, m) and triangles (m × 3 vertex indices) of a ``heightfield`` shape of a
    scene spec: the grid ``s`` × ``c`` (ranges, m) along the unit vectors ``e_s`` and ``e_c`` from
    ``origin``, each point raised along ``normal`` by :func:`rough_heights` at its place on the
    floor plan (``plan``: the origin's plan point (m) and the heading of ``e_s`` there, degrees; c
    runs to the right of it)."""
    (s0, s1), (c0, c1) = spec["s"], spec["c"]
    spacing = float(spec["spacing_m"])
    ns, nc = max(2, math.ceil((s1 - s0) / spacing) + 1), max(2, math.ceil((c1 - c0) / spacing) + 1)
    s, c = np.linspace(s0, s1, ns)[:, None], np.linspace(c0, c1, nc)[None, :]
    x0, y0, heading = spec["plan"]
    cos_h, sin_h = math.cos(math.radians(heading)), math.sin(math.radians(heading))
    h = rough_heights(
        x0 + s * cos_h + c * sin_h,
        y0 + s * sin_h - c * cos_h,
        rms_m=float(spec["rms_m"]),
        correlation_m=float(spec["correlation_m"]),
        seed=int(spec["seed"]),
    )
    origin, e_s, e_c, normal = (np.asarray(spec[k], dtype=np.float64) for k in ("origin", "e_s", "e_c", "normal"))
    points = origin + s[:, :, None] * e_s + c[:, :, None] * e_c + h[:, :, None] * normal
    idx = np.arange(ns * nc, dtype=np.uint32).reshape(ns, nc)
    a, b, cc, d = idx[:-1, :-1], idx[1:, :-1], idx[:-1, 1:], idx[1:, 1:]
    faces = np.concatenate([np.stack([a, b, cc], -1).reshape(-1, 3), np.stack([b, d, cc], -1).reshape(-1, 3)])
    return points.reshape(-1, 3).astype(np.float32), faces


def _floor_spacing_m(walls: TubeWalls, length_m: float) -> float:
    """The rough floor's grid spacing for a stretch ``length_m`` long: a quarter of the correlation
    length, coarser where that would exceed :data:`MAX_FLOOR_VERTICES`; a flat floor needs none."""
    width = walls.left_m + walls.right_m
    if walls.floor_rms_m == 0:
        return max(length_m, width)
    fine = walls.floor_correlation_m / 4
    return max(fine, math.sqrt(length_m * width / MAX_FLOOR_VERTICES))


def tube_wall_shapes(
    walls: TubeWalls, *, target_rotation: NDArray[np.float64], floor_z_m: float, camera_position_m: NDArray[np.float64]
) -> list[dict]:
    """The tube's surfaces around a beacon as shapes of a scene spec, in the beacon frame (z down;
    the beacon's axis through the origin, its foot at ``floor_z_m``): the floor (a ``heightfield``,
    :func:`heightfield_mesh`), the ceiling and the two side walls, from :data:`OPEN_END_M` behind
    the beacon or the camera, whichever is farther back along the axis, to as far beyond the other.

    ``target_rotation`` takes target-frame directions to the beacon frame; ``camera_position_m`` is
    the camera's centre in the beacon frame. A camera outside the walls, or below the floor or
    above the ceiling where it stands, is a one-line error.
    """
    axis, right = target_rotation @ walls.axis(), target_rotation @ walls.right()
    up = np.array([0.0, 0.0, -1.0])
    slope = math.radians(walls.slope_deg)
    e_s = math.cos(slope) * axis + math.sin(slope) * up  # along the floor, rising with the slope
    normal = np.cross(right, e_s)  # the floor's normal, pointing up (right × along, z down)
    foot = np.array([0.0, 0.0, floor_z_m])
    rel = np.asarray(camera_position_m, dtype=np.float64) - foot
    s_cam, c_cam, n_cam = float(rel @ e_s), float(rel @ right), float(rel @ normal)
    if not -walls.left_m < c_cam < walls.right_m:
        raise ValueError(
            f"tube_walls: the camera stands {c_cam:+.3f} m across the axis, outside the walls "
            f"(-{walls.left_m:g} to +{walls.right_m:g} m)"
        )
    if not 0 < n_cam < walls.height_m:
        raise ValueError(
            f"tube_walls: the camera is {n_cam:.3f} m above the floor, outside the tube's height "
            f"(0 to {walls.height_m:g} m)"
        )
    s0, s1 = min(0.0, s_cam) - OPEN_END_M, max(0.0, s_cam) + OPEN_END_M
    c0, c1 = -walls.left_m, walls.right_m
    half_s, mid_s = (s1 - s0) / 2, (s0 + s1) / 2
    half_c, mid_c, half_h = (c1 - c0) / 2, (c0 + c1) / 2, walls.height_m / 2
    centre = foot + mid_s * e_s + mid_c * right + half_h * normal
    floor = {
        "type": "heightfield",
        "origin": foot.tolist(),
        "e_s": e_s.tolist(),
        "e_c": right.tolist(),
        "normal": normal.tolist(),
        "s": [s0, s1],
        "c": [c0, c1],
        "spacing_m": _floor_spacing_m(walls, s1 - s0),
        "rms_m": walls.floor_rms_m,
        "correlation_m": walls.floor_correlation_m,
        "seed": walls.floor_seed,
        "plan": [walls.floor_x_m, walls.floor_y_m, walls.floor_heading_deg],
        "material": "floor",
    }
    return [
        floor,
        rect_shape(centre + half_h * normal, e_s, right, half_s, half_c, "wall"),  # ceiling
        rect_shape(centre + (c0 - mid_c) * right, e_s, normal, half_s, half_h, "wall"),  # left wall
        rect_shape(centre + (c1 - mid_c) * right, e_s, normal, half_s, half_h, "wall"),  # right wall
    ]


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False
