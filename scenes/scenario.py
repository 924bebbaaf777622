"""A scenario: everything that decides what the camera sees, validated.

Pose convention
---------------
``range_m`` is the distance from the camera's centre of projection to the lit face of
marker 1. ``yaw_deg`` is the camera's azimuth about the target's vertical axis, seen
from marker 1: 0 faces the target squarely, positive puts the camera toward the
target's +y (the viewer's left), which is the same as turning the beacon by −yaw about
its vertical (Z-down) axis with the camera fixed. ``camera_height_m`` raises the camera
above marker 1 (positive up). The camera looks at marker 1 with its image-up along −Z, unless
``pan_deg`` or ``tilt_deg`` turn it: the camera's axis then points ``pan_deg`` to its right
(clockwise seen from above) and ``tilt_deg`` up from the direction to marker 1, with no roll, so
the beacon appears off the image centre (:meth:`Scenario.camera_pose`). The render is made from
the unturned pose (:meth:`Scenario.render_pose`), where the beacon sits on the axis, and the
camera models place it in the turned camera's frame (:meth:`Scenario.view_rotation`): a pan
changes what the lens does to the beacon's light (distortion, vignetting), not the render.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

import numpy as np

from scenes import dust
from scenes.beacon import HOUSING_FINISHES, BeaconDesign, beacon_design, target_to_beacon
from scenes.data_overrides import GAIN, check_data_overrides, data_path
from scenes.diffusers import DiffuserConfig
from scenes.environment import Environment, environment
from scenes.led import LED, led_for_side
from scenes.tube_walls import TubeWalls, tube_wall_shapes
from scenes.view import CameraGeometry, CameraPose, camera_geometry

__all__ = ["MAX_RANGE_M", "RenderSettings", "Scenario", "ScenarioError"]

MAX_RANGE_M = 10_000.0
"""Longest camera-to-beacon range a scenario accepts, m: at 10 km a beacon under a metre
across subtends less than 0.1 mrad, under one pixel of any camera modelled (and ranges
near 1e154 m overflowed the squared distances of the geometry)."""


class ScenarioError(ValueError):
    """Bad input: the message names the field and what was expected, in one line."""


@dataclass(frozen=True)
class RenderSettings:
    """How a scenario is rendered.

    Attributes
    ----------
    spp
        Samples per oversampled pixel.
    oversampling
        Rendered pixels per camera pixel along each axis.
    seed
        Sampler seed; the same seed renders identical bytes.
    margin_px
        Camera pixels added around the beacon's projected bounding box.
    led_max_depth, ambient_max_depth
        Path lengths for the LED component (direct view + stray light off the housing
        and environment) and the ambient component (room inter-reflections).
    crop
        ``beacon``: the region covering all four targets (what a detector may see);
        ``target``: only the target facing the camera (faster).
    near_field_spp
        Samples per pixel of the near-field marker renders (diffusers), cached per
        configuration.
    direct
        How the LEDs' light is rendered: ``primary`` (default), the lit faces' direct view
        by deterministic primary rays (:mod:`scenes.direct_view`, no Monte-Carlo noise)
        plus the light the room, beacon and housings scatter, path-traced at
        ``scatter_spp``; ``path``, everything path-traced at ``spp`` (the reference, and
        the renders before issue 24). The ambient light is path-traced at ``spp`` in both;
        the scalar fallback variant path-traces everything.
    scatter_spp
        With ``direct = "primary"``: path-traced samples per *camera* pixel of the
        scattered LED light (~0.07 % of the marker flux).
    background
        The low-resolution whole-frame background (:mod:`scenes.background`): ``room``
        (default), the room without the beacon, rendered once per camera, environment and
        band of range, yaw and camera height; ``geometry``, the whole scene rendered for
        every geometry (the reference, and the backgrounds before issue 24).
    """

    spp: int = 16
    oversampling: int = 3
    seed: int = 0
    margin_px: int = 12
    led_max_depth: int = 4
    ambient_max_depth: int = 6
    crop: str = "beacon"
    near_field_spp: int = 1024
    direct: str = "primary"
    scatter_spp: int = 1
    background: str = "room"

    DIRECT_MODES = ("primary", "path")
    """Values of :attr:`direct`."""
    BACKGROUND_MODES = ("room", "geometry")
    """Values of :attr:`background`."""
    MAX_SPP = 65536
    """Monte-Carlo noise falls as 1/√spp: at 2^16 samples it is 1/256 of one sample's, far
    below any sensor's shot noise, while the work (crop × oversampling² × spp) keeps growing."""
    MAX_OVERSAMPLING = 8
    """The lens blur (Airy disk ≈ 2.44 λ N ≈ 5 µm at f/3.5) spans about a pixel, so sub-pixels
    finer than 1/8 pixel resolve nothing more, and memory grows as oversampling²: the T6's full
    18 MP frame at 8² is 1.1e9 sub-pixels, 4.6 GB per float32 image."""
    MAX_SEED = (2**32 - 64) // 7919
    """Mitsuba's sampler seed is a 32-bit unsigned integer and each light group renders with
    seed × 7919 + group (``scenes.render``), so larger seeds fail inside the render."""
    LIMIT_REASONS = (
        ("spp", " (noise falls as 1/√spp; beyond 2^16 only the work grows)"),
        ("oversampling", " (finer than the lens blur; memory grows as oversampling²)"),
    )
    """Why :meth:`validate` bounds a setting, appended to its one-line error."""

    def validate(self) -> None:
        """Raise :class:`ScenarioError` for impossible settings."""
        limits = {
            "spp": self.MAX_SPP,
            "oversampling": self.MAX_OVERSAMPLING,
            "led_max_depth": 64,
            "ambient_max_depth": 64,
            "near_field_spp": 2**20,
            "scatter_spp": self.MAX_SPP,
        }
        for name, most in limits.items():
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= most:
                raise ScenarioError(
                    f"{name}: expected an integer in [1, {most}]{dict(self.LIMIT_REASONS).get(name, '')}, got {v!r}"
                )
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or not 0 <= self.seed <= self.MAX_SEED:
            raise ScenarioError(
                f"seed: expected an integer in [0, {self.MAX_SEED}] (renderer seeds are 32-bit), got {self.seed!r}"
            )
        if self.direct not in self.DIRECT_MODES:
            raise ScenarioError(f"direct: expected one of {', '.join(self.DIRECT_MODES)}, got {self.direct!r}")
        if self.background not in self.BACKGROUND_MODES:
            raise ScenarioError(
                f"background: expected one of {', '.join(self.BACKGROUND_MODES)}, got {self.background!r}"
            )
        if self.crop not in ("beacon", "target"):
            raise ScenarioError(f"crop: expected 'beacon' or 'target', got {self.crop!r}")
        if not isinstance(self.margin_px, int) or self.margin_px < 0:
            raise ScenarioError(f"margin_px: expected an integer >= 0, got {self.margin_px!r}")


@dataclass(frozen=True)
class Scenario:
    """Beacon, side, LED drive, environment, camera and pose.

    Attributes
    ----------
    beacon
        ``v1`` or ``v2``.
    side
        Side colour facing the camera: ``red``, ``green``, ``blue`` or ``yellow``.
    range_m
        Camera to marker 1, m (> 0).
    yaw_deg
        Camera azimuth about the target's vertical axis, degrees in [−90, 90].
    camera
        Camera name; here it supplies the pixel grid.
    environment
        ``dark``, ``dark-room`` or ``lit-room``.
    led_current_mA
        LED drive current, mA; ``None`` means the datasheet test current.
    camera_height_m
        Camera height above marker 1, m.
    pan_deg, tilt_deg
        The camera's optical axis turned from marker 1, degrees in (−90, 90): ``pan_deg`` to the
        camera's right (the beacon appears left of the image centre), ``tilt_deg`` up (the beacon
        appears below it); 0, 0: looking at marker 1.
    housing
        Housing finish, ``white`` or ``black``.
    foam, paper_sheets, paper_colour
        Diffusers in front of every LED: foam disc on/off, 0-5 sheets of paper, paper
        colour (``white``, ``matched`` = each side's own colour, or a fixed colour).
    render
        Render settings.
    data
        Values of the scene data files replaced for this scenario, ``(path, value)`` pairs
        sorted by path (a mapping is accepted): the LEDs' intensity bin, the foam, the paper,
        the lit face, the housing walls' leak (:data:`scenes.data_overrides.DATA_PATHS`); empty:
        the files' values.
    dust_extinction_per_m
        Extinction coefficient σ of airborne dust between camera and beacon, m⁻¹ (0: clear air):
        the beacon's light reaches the camera attenuated by T = exp(−σ · range_m)
        (:mod:`scenes.dust`; :attr:`dust_transmittance`); the light it scatters into the view is
        not modelled. σ = 0.39 m⁻¹ is 10 m Koschmieder visibility. Only where nothing but the
        LEDs lights the scene (the room's light would need the medium rendered).
    """

    beacon: str = "v2"
    side: str = "red"
    range_m: float = 5.0
    yaw_deg: float = 0.0
    camera: str = "canon-t6-18mm"
    environment: str = "dark"
    led_current_mA: float | None = None
    camera_height_m: float = 0.0
    pan_deg: float = 0.0
    tilt_deg: float = 0.0
    housing: str = "black"
    foam: bool = False
    paper_sheets: int = 0
    paper_colour: str = "white"
    render: RenderSettings = field(default_factory=RenderSettings)
    data: tuple[tuple[str, float], ...] = ()
    dust_extinction_per_m: float = 0.0
    tube_walls: TubeWalls | None = None

    def __post_init__(self) -> None:
        try:  # checked, and as the canonical sorted tuple of (path, value) (a mapping or JSON's lists in)
            object.__setattr__(self, "data", check_data_overrides(self.data, beacon=str(self.beacon)))
            object.__setattr__(self, "tube_walls", TubeWalls.coerce(self.tube_walls))
        except (TypeError, ValueError) as exc:
            raise ScenarioError(str(exc)) from None
        self.validate()

    # -- validation -------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`ScenarioError` naming the first bad field."""
        try:
            beacon_design(self.beacon)
            led = beacon_design(self.beacon).led(self.side)
            camera_geometry(self.camera)
            environment(self.environment)
        except ScenarioError:
            raise
        except ValueError as exc:
            raise ScenarioError(str(exc)) from None
        if not _finite(self.range_m) or not 0 < self.range_m <= MAX_RANGE_M:
            raise ScenarioError(f"range_m: expected a distance > 0 m and <= {MAX_RANGE_M:g} m, got {self.range_m!r}")
        if not _finite(self.yaw_deg) or abs(self.yaw_deg) > 90:
            raise ScenarioError(f"yaw_deg: expected an angle in [-90, 90] degrees, got {self.yaw_deg!r}")
        if not _finite(self.camera_height_m) or abs(self.camera_height_m) >= self.range_m:
            raise ScenarioError(
                f"camera_height_m: expected |height| < range_m ({self.range_m} m), got {self.camera_height_m!r}"
            )
        for name in ("pan_deg", "tilt_deg"):
            value = getattr(self, name)
            if not _finite(value) or abs(value) >= 90:
                raise ScenarioError(f"{name}: expected an angle in (-90, 90) degrees, got {value!r}")
        if not _finite(self.dust_extinction_per_m) or self.dust_extinction_per_m < 0:
            raise ScenarioError(
                "dust_extinction_per_m: expected an extinction coefficient >= 0 per m, "
                f"got {self.dust_extinction_per_m!r}"
            )
        if self.dust_extinction_per_m > 0 and environment(self.environment).has_ambient:
            raise ScenarioError(
                f"dust_extinction_per_m: dust only in an environment without ambient light (dark), not "
                f"{self.environment!r} (its room light would need the medium rendered)"
            )
        if self.housing not in HOUSING_FINISHES:
            raise ScenarioError(f"housing: expected one of {', '.join(HOUSING_FINISHES)}, got {self.housing!r}")
        try:
            self.diffuser.validate()
        except ValueError as exc:
            raise ScenarioError(str(exc)) from None
        if self.led_current_mA is not None:
            try:
                led.check_current(float(self.led_current_mA))
            except (TypeError, ValueError) as exc:
                raise ScenarioError(str(exc)) from None
        try:
            self.design  # noqa: B018  (the overrides' own checks: e.g. a leak beyond 1 - the housing's reflectance)
        except ValueError as exc:
            raise ScenarioError(f"data: {exc}") from None
        self.render.validate()
        if self.tube_walls is not None:
            if self.env.kind != "cave":
                raise ScenarioError(f"tube_walls: a tube's walls only in a cave environment, not {self.environment!r}")
            try:
                self.tube_walls.validate()
                self.tube_shapes()  # the camera inside the walls
            except ValueError as exc:
                raise ScenarioError(str(exc)) from None

    def tube_shapes(self) -> list[dict]:
        """The surfaces of :attr:`tube_walls` as scene-spec shapes in the beacon frame
        (:func:`scenes.tube_walls.tube_wall_shapes`; ValueError where the camera stands outside them)."""
        return tube_wall_shapes(
            self.tube_walls,
            target_rotation=self.target_to_world()[0],
            floor_z_m=self.design.target_height_m,
            camera_position_m=self.render_pose().position_m,
        )

    # -- derived ----------------------------------------------------------------------
    @property
    def diffuser(self) -> DiffuserConfig:
        """The diffuser configuration of every marker (with the foam and paper of :attr:`data`)."""
        return DiffuserConfig(
            self.foam,
            self.paper_sheets,
            self.paper_colour,
            foam_reduced_optical_depth=self._data("diffusers.foam.reduced_optical_depth"),
            foam_thickness_mm=self._data("diffusers.foam.thickness_mm"),
            sheet_transmittance=self._data("diffusers.paper.sheet_transmittance"),
        )

    @property
    def design(self) -> BeaconDesign:
        """The beacon design (with the lit face and housing leaks of :attr:`data`)."""
        design = beacon_design(self.beacon)
        prefix = f"beacons.{self.beacon}."
        mine = {p.removeprefix(prefix): v for p, v in self.data if p.startswith(prefix)}
        if not mine:
            return design
        changes: dict = {}
        if "lit_face_diameter_mm" in mine:
            changes["lit_face_diameter_m"] = mine["lit_face_diameter_mm"] * 1e-3
        leaks = {k.split(".", 1)[1]: v for k, v in mine.items() if k.startswith("housing_transmittance.")}
        if leaks:
            changes["housing_transmittance"] = {**design.housing_transmittance, **leaks}
        return dataclasses.replace(design, **changes)

    @property
    def led(self) -> LED:
        """The LED of the visible side."""
        return self.led_for(self.side)

    def led_for(self, side: str) -> LED:
        """The LED of a side: the beacon's part (:meth:`scenes.beacon.BeaconDesign.led`) with the
        intensity bin of :attr:`data`. The bin (``leds.<side>.luminous_intensity_cd``) is the default
        part's; another part takes it as the same ratio to its own typical intensity (assumed: the
        delivered rank relative to the typical is what varies, and 5 mm lamps' ranks span similar
        ratios, scenes/data/leds.toml and led_parts.toml)."""
        led = beacon_design(self.beacon).led(side)
        cd = self._data(f"leds.{side}.luminous_intensity_cd")
        if cd is None:
            return led
        default = led_for_side(side)
        if led == default:
            return dataclasses.replace(led, luminous_intensity_cd=cd)
        ratio = cd / default.luminous_intensity_cd
        return dataclasses.replace(led, luminous_intensity_cd=led.luminous_intensity_cd * ratio)

    def _data(self, path: str) -> float | None:
        return dict(self.data).get(path)

    def without_gains(self) -> Scenario:
        """This scenario at the datasheet drive and without the overrides that only scale the LEDs'
        light (:data:`scenes.data_overrides.GAIN`): what a unit render depends on."""
        kept = tuple((p, v) for p, v in self.data if data_path(p)[0].acts != GAIN)
        return dataclasses.replace(self, led_current_mA=None, data=kept, dust_extinction_per_m=0.0)

    @property
    def dust_transmittance(self) -> float:
        """Fraction of the beacon's light that crosses the dust to the camera, exp(−σ · range_m).

        >>> round(Scenario(range_m=10.0, dust_extinction_per_m=0.3912).dust_transmittance, 4)
        0.02
        """
        return dust.transmittance(self.dust_extinction_per_m, self.range_m)

    @property
    def geometry(self) -> CameraGeometry:
        """The camera's pixel grid."""
        return camera_geometry(self.camera)

    @property
    def env(self) -> Environment:
        """The environment."""
        return environment(self.environment)

    @property
    def current_mA(self) -> float:
        """LED drive current, mA."""
        return self.led.reference_current_mA if self.led_current_mA is None else float(self.led_current_mA)

    def target_to_world(self):
        """Rotation and translation from this side's target frame to the beacon frame."""
        return target_to_beacon(self.side, self.design.d_t_m)

    def camera_position_target_m(self) -> np.ndarray:
        """Camera centre in the target frame, m."""
        yaw = math.radians(self.yaw_deg)
        horizontal = math.sqrt(self.range_m**2 - self.camera_height_m**2)
        return np.array([horizontal * math.cos(yaw), horizontal * math.sin(yaw), -self.camera_height_m])

    def render_pose(self) -> CameraPose:
        """The pose the beacon is rendered from, in the beacon frame: at the camera, looking at
        marker 1, image-up along −Z (the camera itself when it is not turned)."""
        rot, trans = self.target_to_world()
        position = rot @ self.camera_position_target_m() + trans
        return CameraPose.look_at(position, trans)

    @property
    def turned(self) -> bool:
        """Whether the camera's axis is turned off marker 1 (``pan_deg`` or ``tilt_deg`` not 0)."""
        return self.pan_deg != 0 or self.tilt_deg != 0

    def camera_pose(self) -> CameraPose:
        """The camera's pose in the beacon frame: :meth:`render_pose` turned by ``pan_deg`` and
        ``tilt_deg`` (:meth:`scenes.view.CameraPose.turned`)."""
        pose = self.render_pose()
        return pose.turned(self.pan_deg, self.tilt_deg) if self.turned else pose

    def view_rotation(self) -> np.ndarray | None:
        """Rotation (3 × 3) taking a direction in the camera's frame to the render's camera frame
        (:meth:`render_pose`), or None when the camera is not turned."""
        if not self.turned:
            return None
        return self.render_pose().rotation @ self.camera_pose().rotation.T

    def marker_positions_world_m(self) -> np.ndarray:
        """Lit-face centres of markers 1-5 in the beacon frame, shape (5, 3), m."""
        rot, trans = self.target_to_world()
        return self.design.marker_positions_m() @ rot.T + trans

    # -- identity ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain-data form (JSON-able); ``data`` as a mapping, left out when empty, and ``pan_deg``,
        ``tilt_deg`` and ``dust_extinction_per_m`` left out at 0 and ``tube_walls`` when None (so
        scenarios without them keep the keys they had before they existed)."""
        out = dataclasses.asdict(self)
        out.pop("data")
        if self.data:
            out["data"] = dict(self.data)
        for name in ("pan_deg", "tilt_deg", "dust_extinction_per_m", "tube_walls"):  # left out at 0: keys kept
            if not out[name]:
                out.pop(name)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> Scenario:
        """Inverse of :meth:`to_dict`."""
        data = dict(data)
        render = RenderSettings(**data.pop("render", {}))
        return cls(render=render, **data)

    def to_json(self) -> str:
        """Canonical JSON (sorted keys)."""
        return json.dumps(self.to_dict(), sort_keys=True)


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False
