"""The viewing camera as the scene needs it: the pixel grid of a camera + lens, its pose
and pinhole projection.

The camera files live with the camera models (``camera_models/data/<name>.toml``, or a
user's file, see :mod:`scenes.hardware`); the scene reads only their ``[geometry]`` table
here, so a scenario can name its camera without the scene importing the camera models (the later stage).

Pixel coordinates follow OpenCV: (u, v) from the top-left, the centre of the top-left
pixel at (0, 0), u to the right, v down. The principal point is the image centre,
((W − 1)/2, (H − 1)/2). Camera frame: x right, y down, z along the optical axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from scenes.hardware import PACKAGE_DIRS, HardwareFile, hardware_names, hardware_source
from scenes.sourced import DataFileError, Fields, loads_sourced

__all__ = [
    "CAMERA_DATA_DIR",
    "MAX_PIXELS",
    "MAX_SIDE_PX",
    "MIN_PIXEL_PITCH_UM",
    "CameraGeometry",
    "CameraPose",
    "camera_geometry",
    "camera_names",
    "geometry_from_fields",
    "project",
]

CAMERA_DATA_DIR = PACKAGE_DIRS["camera"]
"""The camera files: one TOML per camera + lens (the camera models read the rest of each)."""


@dataclass(frozen=True)
class CameraGeometry:
    """Pixel grid and focal length of a camera + lens.

    Attributes
    ----------
    name, description
        Identifier (``canon-t6-18mm``) and a human description.
    width_px, height_px
        Full-frame size of the saved image, pixels.
    pixel_pitch_um
        Pixel pitch on the sensor, µm.
    focal_length_mm
        Effective focal length, mm.
    """

    name: str
    description: str
    width_px: int
    height_px: int
    pixel_pitch_um: float
    focal_length_mm: float

    @property
    def focal_length_px(self) -> float:
        """Focal length in pixels, f / p."""
        return self.focal_length_mm * 1e3 / self.pixel_pitch_um

    @property
    def principal_point_px(self) -> tuple[float, float]:
        """Principal point (cx, cy), pixels (image centre, OpenCV convention)."""
        return (self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0

    @property
    def horizontal_fov_deg(self) -> float:
        """Full horizontal field of view of the pinhole model, degrees."""
        return math.degrees(2 * math.atan(self.width_px / (2 * self.focal_length_px)))

    @property
    def diagonal_fov_deg(self) -> float:
        """Full diagonal field of view of the pinhole model, degrees."""
        diag = math.hypot(self.width_px, self.height_px)
        return math.degrees(2 * math.atan(diag / (2 * self.focal_length_px)))

    def intrinsics(self) -> NDArray[np.float64]:
        """3×3 camera matrix K (pixels)."""
        cx, cy = self.principal_point_px
        f = self.focal_length_px
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    def pixel_solid_angle_sr(self, u: NDArray[np.float64], v: NDArray[np.float64]):
        """Solid angle seen by the pixel at (u, v) through the pinhole, sr.

        Ω = (p/f)² cos³φ with φ the angle off the optical axis.
        """
        cx, cy = self.principal_point_px
        f = self.focal_length_px
        r2 = ((np.asarray(u) - cx) ** 2 + (np.asarray(v) - cy) ** 2) / f**2
        return (1.0 / f**2) * (1.0 + r2) ** -1.5


@dataclass(frozen=True)
class CameraPose:
    """Where a camera is and where it looks, in the beacon (world) frame.

    Attributes
    ----------
    position_m
        Centre of projection, m.
    rotation
        3×3 matrix whose rows are the camera's x (right), y (down) and z (forward) axes
        expressed in the world frame: p_cam = rotation @ (p_world − position_m).
    """

    position_m: NDArray[np.float64]
    rotation: NDArray[np.float64]

    @classmethod
    def look_at(cls, position_m, target_m, up=(0.0, 0.0, -1.0)) -> CameraPose:
        """A camera at ``position_m`` looking at ``target_m`` with image-up along ``up``."""
        position = np.asarray(position_m, dtype=np.float64)
        forward = np.asarray(target_m, dtype=np.float64) - position
        forward /= np.linalg.norm(forward)
        down = -np.asarray(up, dtype=np.float64)
        right = np.cross(down, forward)
        if np.linalg.norm(right) < 1e-9:
            raise ValueError("camera pose: viewing direction parallel to 'up'")
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        return cls(position, np.stack([right, down, forward]))

    def turned(self, pan_deg: float, tilt_deg: float, up=(0.0, 0.0, -1.0)) -> CameraPose:
        """The same camera with its optical axis turned, no roll: ``pan_deg`` toward the camera's
        right about ``up`` (clockwise seen from above), then ``tilt_deg`` up, both from this pose's
        axis in azimuth and elevation about ``up``; a point on this pose's axis then appears
        ``pan_deg`` left of and ``tilt_deg`` below the new axis.

        >>> pose = CameraPose.look_at((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
        >>> np.round(pose.turned(90.0, 0.0).rotation[2], 12) + 0.0  # now looking along world +y
        array([0., 1., 0.])
        """
        u = -np.asarray(up, dtype=np.float64)  # "down" in the world frame
        u /= np.linalg.norm(u)
        forward = self.rotation[2]
        elevation = math.asin(float(np.clip(-forward @ u, -1.0, 1.0)))
        horizontal = forward + math.sin(elevation) * u  # forward's part perpendicular to up
        if np.linalg.norm(horizontal) < 1e-9:
            raise ValueError("camera pose: cannot pan a camera that looks straight up or down")
        east = horizontal / np.linalg.norm(horizontal)
        right = np.cross(u, east)  # the camera's right at zero roll
        pan, el = math.radians(pan_deg), elevation + math.radians(tilt_deg)
        if abs(el) >= math.pi / 2:
            raise ValueError(f"tilt_deg: the turned axis would point straight up or down ({math.degrees(el):.1f}°)")
        heading = math.cos(pan) * east + math.sin(pan) * right
        direction = math.cos(el) * heading - math.sin(el) * u
        return CameraPose.look_at(self.position_m, self.position_m + direction, up)

    def world_to_camera(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points (…, 3) from the world frame to the camera frame, m."""
        return (np.asarray(points_m) - self.position_m) @ self.rotation.T


def project(geometry: CameraGeometry, pose: CameraPose, points_m) -> NDArray[np.float64]:
    """Pinhole projection of world points (…, 3) to pixel coordinates (…, 2)."""
    pc = pose.world_to_camera(points_m)
    if np.any(pc[..., 2] <= 0):
        raise ValueError("project: a point lies behind the camera")
    cx, cy = geometry.principal_point_px
    f = geometry.focal_length_px
    return np.stack([cx + f * pc[..., 0] / pc[..., 2], cy + f * pc[..., 1] / pc[..., 2]], axis=-1)


def camera_names() -> list[str]:
    """Names of every camera: the package's own files, then the user's (:mod:`scenes.hardware`)."""
    return hardware_names("camera")


def camera_geometry(name: str) -> CameraGeometry:
    """Geometry of the camera called ``name`` (e.g. ``canon-t6-18mm``); one-line errors."""
    return _geometry_from_source(hardware_source("camera", name))


MAX_SIDE_PX = 20_000
"""Largest image width or height, pixels: above the largest image sensors made (Phase One IQ4
150MP, 14204 × 10652 px; Canon's 250 MP APS-H prototype, 19580 × 12600 px)."""

MAX_PIXELS = 250_000_000
"""Largest width × height, pixels (the 250 MP prototype above): a whole-frame capture holds
several arrays of that many pixels, so a larger grid would only exhaust the memory."""

MIN_PIXEL_PITCH_UM = 0.5
"""Smallest pixel pitch, µm: below the smallest pixels made (0.56 µm, Samsung ISOCELL HP3, 2022)."""


@lru_cache(maxsize=32)
def _geometry_from_source(source: HardwareFile) -> CameraGeometry:
    values, _ = loads_sourced(source.text, source.label)
    top = Fields(values, f"camera file {source.label}")
    geometry = geometry_from_fields(top)
    top.check_known(within="geometry.")
    return geometry


def geometry_from_fields(top: Fields) -> CameraGeometry:
    """The :class:`CameraGeometry` of a camera file's fields (its ``name``, ``description`` and
    ``[geometry]``), every field checked with a one-line error naming it and its bounds."""
    g = top.table("geometry")
    size = f"<= {MAX_SIDE_PX} px: the largest image sensors made are 14204 x 10652 px"
    width = g.number("width_px", integer=True, minimum=16, maximum=MAX_SIDE_PX, reason=size)
    height = g.number("height_px", integer=True, minimum=16, maximum=MAX_SIDE_PX, reason=size)
    if width * height > MAX_PIXELS:
        raise DataFileError(
            f"{g.file}: geometry.height_px: expected width_px x height_px <= {MAX_PIXELS:.3g} pixels (above the "
            f"largest image sensors made), got {width} x {height} = {width * height:.3g}"
        )
    pitch = g.number(
        "pixel_pitch_um",
        minimum=MIN_PIXEL_PITCH_UM,
        maximum=100.0,
        reason="the smallest pixels made are 0.56 um, the largest near 100 um",
    )
    if g.has("focal_length_mm"):
        focal = g.number("focal_length_mm", positive=True, maximum=10_000.0)
        if g.has("diagonal_fov_deg"):  # the published figure the focal length came from (checked, not used)
            g.number("diagonal_fov_deg", positive=True, maximum=179.0)
    else:  # from the diagonal field of view of a rectilinear lens
        half_diag_mm = 0.5 * math.hypot(width, height) * pitch * 1e-3
        fov = g.number("diagonal_fov_deg", positive=True, maximum=179.0)
        focal = half_diag_mm / math.tan(math.radians(fov) / 2)
    return CameraGeometry(top.text("name"), top.text("description", default=""), width, height, pitch, focal)
