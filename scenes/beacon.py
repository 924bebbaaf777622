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

from scenes.hardware import HardwareFile, hardware_names, hardware_source
from scenes.led import HUE_BANDS_NM, LED, SIDE_COLOURS, led_part, side_led
from scenes.sourced import DataFileError, Fields, loads_sourced

__all__ = [
    "HOUSING_FINISHES",
    "SIDE_ANGLE_RAD",
    "BeaconDesign",
    "Marker",
    "beacon_design",
    "beacon_names",
    "beacon_template",
    "load_beacons",
    "target_to_beacon",
]

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
    led_parts: tuple[tuple[str, str], ...] = ()
    """(side, part name) of the sides whose LEDs are not their colour's default part
    (:func:`scenes.led.led_part`); the file's ``[leds]`` table."""
    led_dominant_nm: tuple[tuple[str, float], ...] = ()
    """(side, dominant wavelength, nm) of the sides whose LEDs are given another colour within their
    colour's band (:data:`scenes.led.HUE_BANDS_NM`); the file's ``[dominant_wavelength_nm]`` table."""

    def __post_init__(self) -> None:
        for finish, t in self.housing_transmittance.items():
            if not 0.0 <= t <= 1.0 - self.housing_reflectance[finish] + 1e-12:  # (float rounding of 1 - R)
                raise ValueError(f"beacon {self.name}: housing_transmittance.{finish}: expected 0 <= T <= 1 - R")

    @property
    def housing_radius_m(self) -> float:
        """Outer radius of a marker housing, m."""
        return 0.5 * self.lit_face_diameter_m + self.housing_wall_m

    @property
    def lit_face_area_m2(self) -> float:
        """Area of one lit face, m²."""
        return math.pi * (0.5 * self.lit_face_diameter_m) ** 2

    def led(self, side: str) -> LED:
        """The LED part of a side: the one the file names (``[leds]``), else the colour's default; at
        the dominant wavelength the file gives the side (``[dominant_wavelength_nm]``), if any, with the
        part's other figures (its luminous intensity bin included: assumed, as datasheets bin
        intensity and wavelength apart)."""
        return side_led(side, dict(self.led_parts).get(side), dict(self.led_dominant_nm).get(side))

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


def beacon_names() -> list[str]:
    """Names of every beacon: the package's own files, then the user's (:mod:`scenes.hardware`)."""
    return hardware_names("beacon")


def load_beacons() -> dict[str, BeaconDesign]:
    """Every beacon design by name (V1, V2 and the user's files)."""
    return {name: beacon_design(name) for name in beacon_names()}


def beacon_design(name: str) -> BeaconDesign:
    """The design called ``name`` (``v1``, ``v2`` or a user's file); one-line errors."""
    return _design_from_source(hardware_source("beacon", name))


@lru_cache(maxsize=16)
def _design_from_source(source: HardwareFile) -> BeaconDesign:
    """Load and check a beacon file's contents (``scenes/data/beacons/v2.toml`` shows the form):
    every field is checked with a one-line error naming it; a field nothing reads (a misspelt
    key) is an error naming the nearest field that exists."""
    values, _ = loads_sourced(source.text, source.label)
    f = Fields(values, f"beacon file {source.label}")
    mm = 1e-3
    arm = f.number("arm_length_mm", positive=True, maximum=2000.0) * mm
    out = f.number("out_of_plane_mm", minimum=0.0, maximum=2000.0) * mm
    face = f.text("in_plane_leds_face", choices=("viewer", "outward"))
    reflectance = f.table("housing_reflectance")
    transmittance = f.table("housing_transmittance")
    r = {k: reflectance.number(k, minimum=0.0, maximum=1.0) for k in HOUSING_FINISHES}
    t = {k: transmittance.number(k, minimum=0.0, maximum=1.0 - r[k]) for k in HOUSING_FINISHES}
    lit_face = f.number("lit_face_diameter_mm", positive=True, maximum=200.0) * mm
    if 0.5 * lit_face >= arm:
        raise DataFileError(f"{f.file}: arm_length_mm: expected more than the lit-face radius, got {arm / mm:g}")
    d_t = f.number("d_t_mm", positive=True, maximum=5000.0) * mm
    depth = f.number("housing_depth_mm", positive=True, maximum=500.0) * mm
    arm_width = f.number("arm_width_mm", positive=True, maximum=200.0) * mm
    # the node's enclosure stands on the beacon's axis behind the four targets: its radius must
    # clear the backs of their housings and arms (else the targets sit inside it)
    clear_mm = (d_t - out - depth - arm_width) / mm
    if clear_mm <= 0:
        raise DataFileError(
            f"{f.file}: d_t_mm: expected more than out_of_plane_mm + housing_depth_mm + arm_width_mm "
            f"({(out + depth + arm_width) / mm:g}: the targets' backs must lie in front of the axis), got {d_t / mm:g}"
        )
    node_radius = (
        f.number(
            "node_radius_mm",
            positive=True,
            maximum=clear_mm,
            reason="d_t_mm - out_of_plane_mm - housing_depth_mm - arm_width_mm: the node must stand behind "
            "the targets' backs",
        )
        * mm
    )
    design = BeaconDesign(
        name=f.text("name"),
        description=f.text("description", default=""),
        markers=_markers(arm, out, face),
        arm_length_m=arm,
        out_of_plane_m=out,
        d_t_m=d_t,
        lit_face_diameter_m=lit_face,
        housing_wall_m=f.number("housing_wall_mm", positive=True, maximum=50.0) * mm,
        housing_depth_m=depth,
        arm_width_m=arm_width,
        node_radius_m=node_radius,
        node_height_m=f.number("node_height_mm", positive=True, maximum=10_000.0) * mm,
        target_height_m=f.number("target_height_mm", positive=True, maximum=10_000.0) * mm,
        lit_face_reflectance=f.number("lit_face_reflectance", minimum=0.0, maximum=1.0),
        housing_reflectance=r,
        housing_transmittance=t,
        led_parts=_led_parts(f),
        led_dominant_nm=_led_hues(f),
    )
    f.check_known()
    return design


def _led_parts(f: Fields) -> tuple[tuple[str, str], ...]:
    """The ``[leds]`` table (side = part name), checked: a side colour, a known part of that colour."""
    if not f.has("leds"):
        return ()
    table = f.table("leds")
    out = []
    for side in sorted(table.values):
        if side not in SIDE_COLOURS:
            raise DataFileError(f"{f.file}: leds.{side}: expected a side colour ({', '.join(SIDE_COLOURS)})")
        name = table.text(side)
        try:
            led_part(name, side)
        except ValueError as exc:
            raise DataFileError(f"{f.file}: leds.{side}: {str(exc).removeprefix('led: ')}") from None
        out.append((side, name))
    return tuple(out)


def _led_hues(f: Fields) -> tuple[tuple[str, float], ...]:
    """The ``[dominant_wavelength_nm]`` table (side = nm), checked: a side colour, a wavelength in its band."""
    if not f.has("dominant_wavelength_nm"):
        return ()
    table = f.table("dominant_wavelength_nm")
    out = []
    for side in sorted(table.values):
        if side not in SIDE_COLOURS:
            raise DataFileError(
                f"{f.file}: dominant_wavelength_nm.{side}: expected a side colour ({', '.join(SIDE_COLOURS)})"
            )
        low, high = HUE_BANDS_NM[side]
        why = f"the band of {side} 5 mm lamps, scenes.led.HUE_BANDS_NM"
        out.append((side, table.number(side, minimum=low, maximum=high, reason=why)))
    return tuple(out)


def beacon_template(like: str = "v2") -> str:
    """A complete beacon file to copy and edit: the beacon ``like``'s file, named ``my-beacon``."""
    lines = hardware_source("beacon", like).text.splitlines()
    out = [
        f"# A beacon file for beacon-sim, made from '{like}' (beacon-sim beacons --template --like {like}).",
        "# Edit every value for your beacon; give each number a `source` or an `assumed` note.",
        "# Use it with --beacon-file FILE. Each side's LED is its colour's default part unless a",
        '# [leds] table names another of that colour (e.g. green = "cree-c503t-gan"; the parts are in',
        "# scenes/data/leds.toml and led_parts.toml), at its datasheet colour unless a",
        "# [dominant_wavelength_nm] table gives another within the colour's band (e.g. green = { value =",
        '# 505.0, source = "its datasheet" }; the bands: scenes.led.HUE_BANDS_NM). Drive and diffusers are set per run',
        "# (--led-current-ma, --foam, --paper-sheets, --paper-colour).",
    ]
    for line in lines:
        if line.startswith("name ="):
            out.append('name = "my-beacon"')
        elif line.startswith("description ="):
            out.append(f'description = "my beacon (from the template of {like})"')
        else:
            out.append(line)
    return "\n".join(out) + "\n"
