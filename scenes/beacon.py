"""Beacon geometry: the V1 and V2 target designs and their placement on the node.

Frames (all right-handed, metres)
---------------------------------
* **Beacon (global) frame**, docs/source-study.md §2: origin on the node's vertical axis at the
  height of the targets' centre lines, Z down, blue target on +X, green at +90° about
  Z, red at 180°, yellow at 270°. The floor is the plane z = +target_height.
* **Target frame** of one side: origin at the lit face of marker 1, x along the target
  normal toward the viewer, z down, y = z × x (the viewer's left). A point p_t maps to
  the beacon frame as R_z(θ) p_t + d_t (cos θ, sin θ, 0), the study's T1 (§8).

The study's reference vectors (§2) put marker 2 at +70 mm in y; here marker 2 is the one
its detector calls 2 (least azimuth, i.e. on the viewer's right, −y in a right-handed
frame with z down). The study's y axis is therefore mirrored; :mod:`pipeline` maps
between the two and documents it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from scenes.led import SIDE_COLOURS
from scenes.sourced import DATA_DIR, load_sourced

BEACON_NAMES = ("v1", "v2")
HOUSING_FINISHES = ("white", "black")

SIDE_ANGLE_RAD = {"blue": 0.0, "green": math.pi / 2, "red": math.pi, "yellow": 3 * math.pi / 2}
"""Rotation of each side's target about the beacon's Z axis (docs/source-study.md §2, §8)."""


@dataclass(frozen=True)
class Marker:
    """One LED marker of a target.

    Attributes
    ----------
    id
        The study's marker number, 1-5.
    position_m
        Centre of the lit face in the target frame, m.
    normal
        Unit normal of the lit face (the LED axis) in the target frame.
    """

    id: int
    position_m: NDArray[np.float64]
    normal: NDArray[np.float64]


@dataclass(frozen=True)
class BeaconDesign:
    """A target design (V1 or V2) with its housing dimensions, all in metres."""

    name: str
    description: str
    markers: tuple[Marker, ...]
    arm_length_m: float
    out_of_plane_m: float
    d_t_m: float
    lit_face_diameter_m: float
    housing_wall_m: float
    housing_depth_m: float
    arm_width_m: float
    node_radius_m: float
    node_height_m: float
    target_height_m: float
    lit_face_reflectance: float
    housing_reflectance: dict[str, float]
    housing_transmittance: dict[str, float]

    def __post_init__(self) -> None:
        for finish, t in self.housing_transmittance.items():
            if not 0.0 <= t <= 1.0 - self.housing_reflectance[finish]:
                raise ValueError(f"beacons.toml housing_transmittance.{finish}: expected 0 <= T <= 1 - R")

    @property
    def housing_radius_m(self) -> float:
        """Outer radius of a marker housing, m."""
        return 0.5 * self.lit_face_diameter_m + self.housing_wall_m

    @property
    def lit_face_area_m2(self) -> float:
        """Area of one lit face, m²."""
        return math.pi * (0.5 * self.lit_face_diameter_m) ** 2

    def marker(self, marker_id: int) -> Marker:
        """The marker with the study's number ``marker_id`` (1-5)."""
        return self.markers[marker_id - 1]

    def marker_positions_m(self) -> NDArray[np.float64]:
        """Lit-face centres of markers 1-5 in the target frame, shape (5, 3), m."""
        return np.stack([m.position_m for m in self.markers])

    def bounding_points_m(self) -> NDArray[np.float64]:
        """Corners of a box enclosing the target and its housings (target frame), m."""
        reach = self.arm_length_m + self.housing_radius_m + self.housing_depth_m
        x_back = -self.out_of_plane_m - self.housing_depth_m - self.arm_width_m
        xs, ys, zs = (x_back, 0.001), (-reach, reach), (-reach, reach)
        return np.array([[x, y, z] for x in xs for y in ys for z in zs])


def target_to_beacon(side: str, d_t_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Rotation matrix and translation taking target-frame points to the beacon frame."""
    if side not in SIDE_ANGLE_RAD:
        raise ValueError(f"side: expected one of {', '.join(SIDE_COLOURS)}, got {side!r}")
    t = SIDE_ANGLE_RAD[side]
    c, s = math.cos(t), math.sin(t)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot, d_t_m * np.array([c, s, 0.0])


def _markers(arm_m: float, out_m: float, in_plane_face: str) -> tuple[Marker, ...]:
    x_plane = -out_m
    # (id, in-plane direction in the target frame): 2 right (-y), 3 left (+y), 4 up (-z), 5 down (+z)
    dirs = {2: (0.0, -1.0, 0.0), 3: (0.0, 1.0, 0.0), 4: (0.0, 0.0, -1.0), 5: (0.0, 0.0, 1.0)}
    viewer = np.array([1.0, 0.0, 0.0])
    out = [Marker(1, np.zeros(3), viewer)]
    for mid, d in dirs.items():
        d = np.array(d)
        normal = viewer if in_plane_face == "viewer" else d
        out.append(Marker(mid, np.array([x_plane, 0.0, 0.0]) + arm_m * d, normal))
    return tuple(out)


@lru_cache(maxsize=1)
def load_beacons() -> dict[str, BeaconDesign]:
    """V1 and V2 from ``scenes/data/beacons.toml``."""
    values, _ = load_sourced(DATA_DIR / "beacons.toml")
    c = values["common"]
    mm = 1e-3
    designs = {}
    for name in BEACON_NAMES:
        v = values[name]
        face = v["in_plane_leds_face"]
        if face not in ("viewer", "outward"):
            raise ValueError(f"beacons.toml {name}.in_plane_leds_face: expected viewer|outward")
        designs[name] = BeaconDesign(
            name=name,
            description=v["description"],
            markers=_markers(v["arm_length_mm"] * mm, v["out_of_plane_mm"] * mm, face),
            arm_length_m=v["arm_length_mm"] * mm,
            out_of_plane_m=v["out_of_plane_mm"] * mm,
            d_t_m=c["d_t_mm"] * mm,
            lit_face_diameter_m=c["lit_face_diameter_mm"] * mm,
            housing_wall_m=c["housing_wall_mm"] * mm,
            housing_depth_m=c["housing_depth_mm"] * mm,
            arm_width_m=c["arm_width_mm"] * mm,
            node_radius_m=c["node_radius_mm"] * mm,
            node_height_m=c["node_height_mm"] * mm,
            target_height_m=c["target_height_mm"] * mm,
            lit_face_reflectance=c["lit_face_reflectance"],
            housing_reflectance=dict(values["housing_reflectance"]),
            housing_transmittance=dict(values["housing_transmittance"]),
        )
    return designs


def beacon_design(name: str) -> BeaconDesign:
    """The design called ``name`` (``v1`` or ``v2``)."""
    designs = load_beacons()
    if name not in designs:
        raise ValueError(f"beacon: expected one of {', '.join(BEACON_NAMES)}, got {name!r}")
    return designs[name]
