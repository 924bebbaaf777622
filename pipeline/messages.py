"""Typed mirrors of the study's three ROS messages (docs/source-study.md §9), with JSON round trip.

The study's programs passed these between the tracker, the pose estimator and the frame
chain. Here every quantity is in SI units (m, rad) and the unit is in the field name; the
study's mm and degrees are converted at the edges.

* :class:`LEDPoints` — tracker → pose: camera number, LED colour, azimuth and elevation
  of markers 1..5 (azimuth positive to the viewer's left, elevation positive downward,
  docs/source-study.md §5.7).
* :class:`BotPositionQuat` — pose → frames: range R1 (camera to marker 1), the QUEST
  quaternion (x, y, z, w; scalar last, as the study wrote it) and the unit vector r1.
* :class:`GlobalPos` — frames → user: X, Y, Z and yaw, pitch, roll in the beacon frame.

Bad input raises ``ValueError`` with one line naming the field.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from scenes.led import SIDE_COLOURS

__all__ = ["BotPositionQuat", "GlobalPos", "LEDPoints"]


def _finite(name: str, value: Any) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return x


def _vector(name: str, value: Any, length: int) -> tuple[float, ...]:
    if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != length:
        raise ValueError(f"{name}: expected {length} numbers, got {value!r}")
    return tuple(_finite(f"{name}[{i}]", v) for i, v in enumerate(value))


class _JsonMessage:
    """JSON round trip shared by the messages (fields are plain numbers, strings, tuples)."""

    _name: ClassVar[str] = "message"

    def to_dict(self) -> dict:
        """Plain-data form; tuples become lists."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    def to_json(self) -> str:
        """Canonical JSON (sorted keys)."""
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: Any):
        """Inverse of :meth:`to_dict`; unknown or missing fields are errors."""
        if not isinstance(data, dict):
            raise ValueError(f"{cls._name}: expected a JSON object, got {type(data).__name__}")
        names = [f.name for f in dataclasses.fields(cls)]
        extra = sorted(set(data) - set(names))
        if extra:
            raise ValueError(f"{extra[0]}: unknown field of {cls._name}")
        missing = [n for n in names if n not in data]
        if missing:
            raise ValueError(f"{missing[0]}: missing field of {cls._name}")
        return cls(**data)

    @classmethod
    def from_json(cls, text: str):
        """Parse :meth:`to_json` output."""
        try:
            data = json.loads(text)
        except (TypeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{cls._name}: not valid JSON ({exc})") from None
        except RecursionError:
            raise ValueError(f"{cls._name}: expected a flat JSON object, got one nested too deep") from None
        return cls.from_dict(data)


@dataclass(frozen=True)
class LEDPoints(_JsonMessage):
    """Tracker output: the five markers of one side as angles.

    Attributes
    ----------
    camera
        Camera number on the ring, 0..N−1.
    colour
        LED colour of the side seen: red, green, blue or yellow.
    azimuth_rad
        Azimuth α of markers 1..5, rad, positive to the viewer's left.
    elevation_rad
        Elevation β of markers 1..5, rad, positive downward.
    """

    _name: ClassVar[str] = "LEDPoints"
    camera: int
    colour: str
    azimuth_rad: tuple[float, ...]
    elevation_rad: tuple[float, ...]

    def __post_init__(self) -> None:
        if isinstance(self.camera, bool) or not isinstance(self.camera, int) or self.camera < 0:
            raise ValueError(f"camera: expected an integer >= 0, got {self.camera!r}")
        if self.colour not in SIDE_COLOURS:
            raise ValueError(f"colour: expected one of {', '.join(SIDE_COLOURS)}, got {self.colour!r}")
        object.__setattr__(self, "azimuth_rad", _vector("azimuth_rad", self.azimuth_rad, 5))
        object.__setattr__(self, "elevation_rad", _vector("elevation_rad", self.elevation_rad, 5))
        for name in ("azimuth_rad", "elevation_rad"):
            if any(abs(a) >= math.pi / 2 for a in getattr(self, name)):
                raise ValueError(f"{name}: expected angles in (-pi/2, pi/2) rad")


@dataclass(frozen=True)
class BotPositionQuat(_JsonMessage):
    """Pose output: range to marker 1, attitude quaternion and line of sight to marker 1.

    Attributes
    ----------
    range_m
        R1, camera centre to marker 1, m (> 0).
    quaternion_xyzw
        QUEST quaternion (x, y, z, w), scalar last, unit norm; its attitude matrix A(q)
        maps study-target-frame vectors into the study camera frame (see
        ``pipeline/CONVENTIONS.md``).
    r1
        Unit vector from the camera to marker 1 in the study camera frame (X backward,
        Y right, Z up).
    """

    _name: ClassVar[str] = "BotPositionQuat"
    range_m: float
    quaternion_xyzw: tuple[float, ...]
    r1: tuple[float, ...]

    def __post_init__(self) -> None:
        r = _finite("range_m", self.range_m)
        if r <= 0:
            raise ValueError(f"range_m: expected a distance > 0 m, got {self.range_m!r}")
        object.__setattr__(self, "range_m", r)
        q = _vector("quaternion_xyzw", self.quaternion_xyzw, 4)
        if abs(math.fsum(c * c for c in q) - 1.0) > 1e-6:
            raise ValueError(f"quaternion_xyzw: expected unit norm, got {q!r}")
        object.__setattr__(self, "quaternion_xyzw", q)
        r1 = _vector("r1", self.r1, 3)
        if abs(math.fsum(c * c for c in r1) - 1.0) > 1e-6:
            raise ValueError(f"r1: expected a unit vector, got {r1!r}")
        object.__setattr__(self, "r1", r1)


@dataclass(frozen=True)
class GlobalPos(_JsonMessage):
    """Frame-chain output: position and attitude in the beacon (global) frame.

    Attributes
    ----------
    x_m, y_m, z_m
        Position of the robot (or camera) centre in the beacon frame (Z down), m.
    yaw_rad, pitch_rad, roll_rad
        Z-Y-X Euler angles of the body frame (x forward, y right, z down) in the
        beacon frame, rad.
    """

    _name: ClassVar[str] = "GlobalPos"
    x_m: float
    y_m: float
    z_m: float
    yaw_rad: float
    pitch_rad: float
    roll_rad: float

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, _finite(f.name, getattr(self, f.name)))
