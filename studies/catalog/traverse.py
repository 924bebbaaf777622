"""``beacon-sim traverse``: how far apart the beacons may be, and how good the robot's position is.

A robot drives a lava tube (:class:`scenes.tube.Tube`: width ``tube_width_m``, straight or with one
bend) along its centreline, wandering sideways; beacons stand by the left wall every D metres along
it (each with its four sides facing along and across the tube where it stands). A bend's inner wall
hides the beacons around it (a sight line must stay inside the tube). At every step of ``step_m``
its ring of cameras (:class:`pipeline.ring`'s geometry: N cameras on a circle of radius r, facing
outward) looks for them: every camera with a beacon side in its horizontal field (:func:`sightings`)
gives a detection, from one of two sources:

* **drawn** (default): with the probability the camera's **rendered range-limit frames** measured at
  that range and yaw (:class:`DetectionTable`: the fraction of correct poses of a range-limit
  summary's outcomes, interpolated between the ranges and yaws tried, 0 beyond them), its pose drawn
  around the truth with the Cramér–Rao covariance of the marker centroids
  (:func:`pipeline.crlb.planar_covariance`, centroid noise :data:`CENTROID_SD_PX`). Every detection is
  a correct one, every side behaves as the red side the range-limit table ran.
* **rendered** (``rendered=True``, ``--rendered``): a whole frame per ring camera and step holding
  every beacon it sees (:func:`camera_frames`, :func:`frame_task`, :func:`traverse_frame`): each side
  at its range and yaw, the camera turned by the bearing (``Scenario.pan_deg``, so the lens's
  distortion and vignetting act where each beacon really falls), the dark tube, the best tracker and
  estimator after the lens's rectification; the side the detector names and the pose it estimates
  are what the robot gets, wrong ones included, and the robot takes it for the beacon in view whose
  pose fits its prediction best; the measurement covariance is the estimator's error measured on
  those frames per range band (:func:`error_covariances`). Frames are stored in ``out/tasks`` (a
  stopped run resumes) and shared by the spacings and runs that see the same thing.

Each detection's pose in the side's target frame is turned into the robot's global pose through the
beacon's known pose and the camera's mount, with its covariance propagated; detections farther than
χ²₃ = :data:`GATE_CHI2` from the filter's prediction are gated out, the rest of one instant fused
(:func:`pipeline.ring.fuse`) and used to correct **wheel odometry** (:class:`pipeline.odometry.WheelOdometry`,
slip drawn per run from :data:`pipeline.odometry.LOOSE_SAND`, constant along the run or, with the
``odometry`` settings ``slip_sd`` and ``slip_correlation_m``, wandering along it) in a planar EKF
(:mod:`pipeline.ekf`) that carries the odometer's scale as a state (prior from the slip range, a
random walk :data:`SCALE_WALK_PER_M` plus the odometry model's own wander of the slip).

Dust (``dust_extinction_per_m``, rendered frames only) dims every beacon's light by Beer–Lambert over
its range (:attr:`scenes.scenario.Scenario.dust_transmittance`; the light it scatters into the view
is left out, so it costs at least that much).

Rendered frames hold the tube's own basalt walls, ceiling and rough floor around each beacon
(:class:`scenes.tube_walls.TubeWalls`: the straight stretch along the tube's axis where the beacon
stands; the floor may slope). What this is not (yet): the slope in the robot's planar filter (it
takes the horizontal part of each fix). The beacons the robot chooses among are
those truly in a camera's view (a robot would take them from its map around its predicted pose).

Outputs in ``out``: ``steps.parquet`` (one row per spacing × seed × step: truth, odometry, fix and
filter poses, their errors, the detections, gated ones and ones that named another side),
``summary.json`` (per spacing and seed: fraction of steps with a fix, largest and final position
error of the filter and of odometry alone; the largest spacing that keeps the filter's error under
the threshold, per seed and over the seeds; for rendered runs the frames and the error bands),
``report.html`` (the path from above, the error along it, the tables).
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
import pandas as pd

from camera_models.camera import load_camera
from camera_models.optics import RadialMapping
from pipeline.angles import Intrinsics
from pipeline.crlb import planar_covariance, pose_covariance
from pipeline.detect import detect
from pipeline.ekf import mahalanobis2, predict, update
from pipeline.frames import Pose, pose_from_scenario
from pipeline.odometry import LOOSE_SAND, WheelOdometry, scale_prior
from pipeline.ring import PlanarPose, fuse
from scenes.beacon import beacon_design
from scenes.dust import visual_range_m
from scenes.render_cache import atomic_write_bytes
from scenes.scenario import Scenario
from scenes.tube import Tube
from scenes.tube_walls import TubeWalls, tube_defaults
from scenes.view import camera_geometry
from studies.engine import strict_json
from studies.engine.frame import capture_frame, detect_options, render_batch_key
from studies.engine.frame_task import FrameTask
from studies.engine.report import Report
from studies.engine.run_log import resumed_seconds
from studies.engine.runner import Progress, no_progress, run_tasks

__all__ = [
    "CENTROID_SD_PX",
    "ERROR_BANDS_M",
    "GATE_CHI2",
    "NAME",
    "DetectionTable",
    "RenderedDetections",
    "Sighting",
    "Traverse",
    "camera_frames",
    "error_covariances",
    "frame_task",
    "largest_spacing",
    "planar_in_target",
    "run",
    "sightings",
    "simulate",
    "traverse_frame",
]

NAME = "traverse"
FRAME_VERSION = 1
"""Version of :func:`traverse_frame`'s rows (part of every stored frame's key)."""
GATE_CHI2 = 16.27
"""A detection whose robot pose lies farther from the filter's prediction than this squared
Mahalanobis distance (χ² with 3 degrees of freedom, 0.999 quantile) is rejected as an outlier: a
wrong side named, a misjudged range (1 in 1000 correct ones is rejected with it)."""
RENDER_RANGE_FACTOR = 1.5
"""Rendered traverses render no frame beyond this factor times the farthest range at which the
detection table measured any correct pose (assumed: P(correct) falls from its last non-zero value to
0 within a third of the range, as in every range-limit curve so far); those sightings count as missed."""
SCALE_WALK_PER_M = 0.02**2
"""Variance per metre of the filter's odometer-scale random walk, 1/m (assumed: the slip may change
by ~2 % per √m as the sand changes; with a constant slip in the odometry model this only keeps the
filter from trusting its learnt scale for ever). A run whose slip wanders adds the model's own rate,
:attr:`pipeline.odometry.WheelOdometry.scale_walk_per_m`."""
CENTROID_SD_PX = 0.5
"""Noise of one marker centroid, px (assumed: a lit face a few pixels across in a compressed webcam
frame is located to a fraction of a pixel; the CRLB scales with it)."""
DEFAULT_TABLE = Path(__file__).resolve().parents[2] / "results" / "full" / "range-limit.summary.json"
"""The project's own range-limit run (whole rendered frames of the four study cameras, V2, 0-30°)."""
SIDE_ANGLES = {"red": 0.0, "green": math.pi / 2, "blue": math.pi, "yellow": -math.pi / 2}
"""Direction of each side's outward normal in the beacon's planar frame, rad (assumed layout: the
four sides 90° apart in the study's order; only which side faces the camera depends on it)."""


@dataclass(frozen=True)
class DetectionTable:
    """P(correct pose) of one camera from a range-limit summary's outcomes: per yaw tried (°), the
    ranges tried (m) and the fraction of frames with a correct pose at each (best tracker; the
    observed fraction, not a posterior mean: the sequential design tries few frames where P is near
    0 or 1, and a prior's pull toward ½ there would invent detections beyond the far limit)."""

    camera: str
    source: str
    curves: tuple[tuple[float, tuple[float, ...], tuple[float, ...]], ...]

    @classmethod
    def from_summary(cls, path: Path, camera: str, *, beacon: str = "v2", current_mA: float = 2.0) -> DetectionTable:
        """The outcomes of ``camera`` × ``beacon`` at ``current_mA`` (ValueError naming what is missing)."""
        summary = json.loads(Path(path).read_text())
        rows = [
            r
            for r in summary.get("outcomes", [])
            if r["camera"] == camera and r["beacon"] == beacon and float(r["led_current_mA"]) == current_mA
        ]
        if not rows:
            have = sorted({r["camera"] for r in summary.get("outcomes", [])})
            raise ValueError(
                f"camera: expected one the range-limit summary {path} ran ({', '.join(have)}) at {beacon}, "
                f"{current_mA:g} mA, got {camera!r} (run 'beacon-sim study range-limit --cameras {camera}')"
            )
        curves = []
        for yaw in sorted({float(r["yaw_deg"]) for r in rows}):
            at = sorted((float(r["range_m"]), float(r["fraction"])) for r in rows if float(r["yaw_deg"]) == yaw)
            curves.append((yaw, tuple(x for x, _ in at), tuple(p for _, p in at)))
        return cls(camera=camera, source=str(path), curves=tuple(curves))

    def farthest_m(self) -> float:
        """The farthest range at which any yaw's frames gave a correct pose, m (0 when none did)."""
        return max((r for _, ranges, p in self.curves for r, q in zip(ranges, p, strict=True) if q > 0), default=0.0)

    def probability(self, range_m: float, yaw_deg: float) -> float:
        """P(correct) at a range (m) and |yaw| (°): linear in range between the ranges tried at each yaw
        (the nearest's value nearer than it; 0 beyond the farthest, where nothing was tried), then linear
        in yaw between the two yaws tried either side; 0 beyond the largest yaw tried."""
        yaw = abs(yaw_deg)
        yaws = [c[0] for c in self.curves]
        if yaw > yaws[-1]:
            return 0.0

        def at(curve) -> float:
            _, ranges, p = curve
            return 0.0 if range_m > ranges[-1] else float(np.interp(range_m, ranges, p))

        i = int(np.searchsorted(yaws, yaw))
        lo, hi = self.curves[max(i - 1, 0)], self.curves[min(i, len(yaws) - 1)]
        w = 0.0 if hi[0] == lo[0] else (yaw - lo[0]) / (hi[0] - lo[0])
        return (1 - w) * at(lo) + w * at(hi)


@dataclass(frozen=True)
class Traverse:
    """A traverse's settings.

    Attributes
    ----------
    camera, cameras_n, radius_m
        The ring: N cameras (camera file name) on a circle of radius r (m), facing outward, camera 0
        facing forward (the study: six Spedal 920, 0.2 m).
    beacon
        The beacon design placed along the tube.
    path_m, step_m
        Length of the drive (m) and of one odometry step (m).
    tube_width_m, wall_offset_m
        Tube width (m) and how far from the left wall the beacons stand (m).
    bend_deg, bend_at_m, bend_radius_m
        The tube's one bend (:class:`scenes.tube.Tube`): its turn (degrees, positive to the left; 0: a
        straight tube), where along the tube it starts (m) and the centreline's radius there (m;
        assumed 6 m: a tube a few metres wide turning within two or three widths).
    dust_extinction_per_m
        Airborne dust's extinction coefficient, m⁻¹ (0: clear air; rendered frames only; Koschmieder
        visual range 3.912 / σ).
    tube_walls, tube_height_m, slope_deg, floor_rms_m, floor_correlation_m
        Rendered frames only: whether they hold the tube's own walls, ceiling and rough floor around
        each beacon (:class:`scenes.tube_walls.TubeWalls`; False: the dark environment's box around
        the camera-beacon line), the tube's height (m), the floor's rise along the tube (degrees: a
        camera stands higher or lower than the beacon by its distance along the tube times the
        slope's tangent, and the robot pitches with the floor), and the floor's roughness (m); the
        defaults are ``scenes/data/tube.toml``'s.
    wall_reflectance
        Rendered frames with the tube's walls: their grey diffuse reflectance (None: the dark
        environment's basalt, 0.07; a dusty tube 0.15-0.28, :mod:`scenes.tube_walls`).
    wander_m
        Amplitude of the robot's sideways wander about the centreline (m), one period per 20 m.
    first_beacon_m
        Distance along the tube of the first beacon (m; the robot starts at 0 beside a known one
        when 0).
    led_current_mA
        The beacons' LED drive, mA (the detection table's, and the rendered frames').
    odometry
        :class:`pipeline.odometry.WheelOdometry` fields to replace (the slip is drawn per run; e.g.
        ``{"slip_sd": 0.1, "slip_correlation_m": 5.0}`` for a slip that wanders along the run).
    """

    camera: str = "spedal-920"
    cameras_n: int = 6
    radius_m: float = 0.2
    beacon: str = "v2"
    path_m: float = 50.0
    step_m: float = 0.25
    tube_width_m: float = 3.0
    wall_offset_m: float = 0.3
    wander_m: float = 0.3
    bend_deg: float = 0.0
    bend_at_m: float = 20.0
    bend_radius_m: float = 6.0
    dust_extinction_per_m: float = 0.0
    tube_walls: bool = True
    tube_height_m: float = field(default_factory=lambda: tube_defaults()["height_m"])
    slope_deg: float = 0.0
    floor_rms_m: float = field(default_factory=lambda: tube_defaults()["floor_rms_m"])
    floor_correlation_m: float = field(default_factory=lambda: tube_defaults()["floor_correlation_m"])
    wall_reflectance: float | None = None
    first_beacon_m: float = 0.0
    led_current_mA: float = 2.0
    odometry: dict = field(default_factory=dict)

    def validate(self) -> None:
        """One-line errors naming the field, before any work."""
        if self.cameras_n < 2:
            raise ValueError(f"cameras_n: expected an integer >= 2, got {self.cameras_n}")
        for name in ("radius_m", "path_m", "step_m", "tube_width_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected a length > 0 m, got {getattr(self, name)!r}")
        if not 0 < self.wall_offset_m < self.tube_width_m / 2:
            raise ValueError(f"wall_offset_m: expected (0, {self.tube_width_m / 2:g}) m, got {self.wall_offset_m!r}")
        if not 0 <= self.wander_m < self.tube_width_m / 2 - self.wall_offset_m:
            raise ValueError(f"wander_m: expected a wander that keeps the robot off the beacons, got {self.wander_m!r}")
        self.tube.validate()
        for name in ("tube_height_m", "floor_correlation_m"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name}: expected a length > 0 m, got {getattr(self, name)!r}")
        if not (math.isfinite(self.slope_deg) and abs(self.slope_deg) < 45):
            raise ValueError(f"slope_deg: expected an angle in (-45, 45) degrees, got {self.slope_deg!r}")
        if not (math.isfinite(self.floor_rms_m) and 0 <= self.floor_rms_m < self.tube_height_m / 4):
            raise ValueError(f"floor_rms_m: expected >= 0 m, under a quarter of the height, got {self.floor_rms_m!r}")
        if self.wall_reflectance is not None and not (
            self.tube_walls and math.isfinite(self.wall_reflectance) and 0 < self.wall_reflectance < 1
        ):
            raise ValueError(
                f"wall_reflectance: expected a reflectance in (0, 1) of the tube's walls (with tube_walls), "
                f"got {self.wall_reflectance!r}"
            )
        if not (math.isfinite(self.dust_extinction_per_m) and self.dust_extinction_per_m >= 0):
            raise ValueError(f"dust_extinction_per_m: expected >= 0 per m, got {self.dust_extinction_per_m!r}")
        unknown = sorted(set(self.odometry) - {f.name for f in fields(WheelOdometry)})
        if unknown:
            raise ValueError(f"odometry: expected fields of pipeline.odometry.WheelOdometry, got {unknown}")
        WheelOdometry(**self.odometry)
        beacon_design(self.beacon)
        camera_geometry(self.camera)

    @property
    def tube(self) -> Tube:
        """The tube's floor plan."""
        return Tube(self.tube_width_m, self.bend_deg, self.bend_at_m, self.bend_radius_m)

    def walls_at(self, axis_deg: float, beacon_at: tuple[float, float, float], camera_left_m: float = 0.0) -> TubeWalls:
        """The tube around a beacon (by the left wall, ``wall_offset_m`` from it) for a render whose
        target frame has the tube's axis at ``axis_deg``; the beacon at ``beacon_at`` on the floor plan
        (x, y in m, the tube's heading in rad), on the tube's one floor (seed 0). The render's
        stretch is straight (the tangent where the beacon stands): around a bend a camera can stand
        beyond its walls (``camera_left_m``: the camera's distance left of the beacon's axis), and
        the wall on its side is then moved out to the ring's radius beyond the camera (the walls
        near the beacon, which its light reaches first, stay where they are)."""
        left, right = self.wall_offset_m, self.tube_width_m - self.wall_offset_m
        return TubeWalls(
            axis_deg=axis_deg,
            left_m=max(left, camera_left_m + self.radius_m),
            right_m=max(right, -camera_left_m + self.radius_m),
            height_m=self.tube_height_m,
            slope_deg=self.slope_deg,
            floor_rms_m=self.floor_rms_m,
            floor_correlation_m=self.floor_correlation_m,
            floor_x_m=beacon_at[0],
            floor_y_m=beacon_at[1],
            floor_heading_deg=round(math.degrees(beacon_at[2]), 6),
            reflectance=self.wall_reflectance,
        )


def _rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def _along(t: Traverse) -> np.ndarray:
    """Distance along the tube's centreline of every step (m)."""
    return np.arange(0.0, t.path_m + 1e-9, t.step_m)


def _truth(t: Traverse) -> np.ndarray:
    """The true path: (n + 1) × 3 poses (x, y, heading; m, m, rad; x along the tube where it starts,
    y to the left), wandering about the centreline."""
    s = _along(t)
    xy, _ = t.tube.at(s, t.wander_m * np.sin(2 * math.pi * s / 20.0))
    if len(s) < 2:
        return np.column_stack([xy, np.zeros(1)])
    heading = np.arctan2(np.gradient(xy[:, 1], s), np.gradient(xy[:, 0], s))
    return np.column_stack([xy, heading])


def _beacons(t: Traverse, spacing_m: float) -> np.ndarray:
    """Beacons by the left wall, every ``spacing_m`` along the tube from ``first_beacon_m``: k × 3
    (x, y, the tube's heading where each stands; m, m, rad)."""
    s = np.arange(t.first_beacon_m, t.path_m + spacing_m, spacing_m)
    xy, heading = t.tube.at(s, t.tube_width_m / 2 - t.wall_offset_m)
    return np.column_stack([xy, heading])


@dataclass(frozen=True)
class _Ring:
    fov_rad: float
    intrinsics: Intrinsics
    points_t_m: np.ndarray
    d_t_m: float


def _ring(t: Traverse) -> _Ring:
    cam = load_camera(t.camera)
    design = beacon_design(t.beacon)
    return _Ring(
        fov_rad=math.radians(RadialMapping(cam).horizontal_fov_deg()),
        intrinsics=Intrinsics.from_geometry(camera_geometry(t.camera)),
        points_t_m=design.marker_positions_m(),
        d_t_m=design.d_t_m,
    )


def _target_covariance(t: Traverse, ring: _Ring, range_m: float, yaw_deg: float) -> np.ndarray:
    """CRLB of the camera's planar pose in the target frame at a range and yaw, mapped to the planar
    frame used here (u along the side's outward normal, v 90° counter-clockwise from it seen from
    above, angles counter-clockwise): the target frame's z points down, so its y and angle flip."""
    sc = Scenario(camera=t.camera, beacon=t.beacon, range_m=float(range_m), yaw_deg=float(yaw_deg))
    pose = pose_from_scenario(sc)
    cov = planar_covariance(pose_covariance(ring.points_t_m, pose, ring.intrinsics, CENTROID_SD_PX), pose)
    flip = np.diag([1.0, -1.0, -1.0])
    return flip @ cov @ flip


@dataclass(frozen=True)
class Sighting:
    """A beacon side in a ring camera's horizontal field at one step.

    Attributes
    ----------
    camera, beacon, side
        Ring camera index, beacon index along the tube, the side facing the camera.
    u_m, v_m, psi_rad
        The camera in that side's planar target frame: position (u along the side's outward normal,
        v 90° counter-clockwise seen from above; m) and optical axis (counter-clockwise from u; rad).
    bearing_rad
        Direction to marker 1 from the camera's axis, counter-clockwise seen from above, rad.
    beacon_at
        The beacon's place on the floor plan: x, y (m) and the tube's heading there (rad).
    """

    camera: int
    beacon: int
    side: str
    u_m: float
    v_m: float
    psi_rad: float
    bearing_rad: float
    beacon_at: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def range_m(self) -> float:
        """Camera to marker 1 (in the plane), m."""
        return float(math.hypot(self.u_m, self.v_m))

    @property
    def yaw_deg(self) -> float:
        """The camera's angle off the side's normal, counter-clockwise seen from above, degrees."""
        return math.degrees(math.atan2(self.v_m, self.u_m))


def sightings(t: Traverse, fov_rad: float, d_t_m: float, robot: np.ndarray, beacons: np.ndarray) -> list[Sighting]:
    """Every beacon side in a ring camera's horizontal field (``fov_rad``, the lens's) at the robot's
    true pose (x, y, heading): per camera and beacon the side whose outward normal is closest to the
    direction to the camera, when the camera is in front of it and the tube's walls do not hide it."""
    out = []
    tube = t.tube
    for k in range(t.cameras_n):
        axis = robot[2] + 2 * math.pi * k / t.cameras_n
        cam = robot[:2] + t.radius_m * np.array([math.cos(axis), math.sin(axis)])
        for b, (*centre, facing) in enumerate(beacons):
            centre = np.asarray(centre)
            to_cam = math.atan2(*(cam - centre)[::-1])
            side = min(SIDE_ANGLES, key=lambda s: abs(math.remainder(to_cam - SIDE_ANGLES[s] - facing, 2 * math.pi)))
            alpha = SIDE_ANGLES[side] + facing  # red faces along the tube where the beacon stands
            origin = centre + d_t_m * np.array([math.cos(alpha), math.sin(alpha)])
            rel = _rot(-alpha) @ (cam - origin)
            bearing = math.remainder(math.atan2(*(origin - cam)[::-1]) - axis, 2 * math.pi)
            if rel[0] <= 0 or abs(bearing) > fov_rad / 2 or not tube.clear(cam, origin):
                continue
            psi = math.remainder(axis - alpha, 2 * math.pi)
            at = (round(float(centre[0]), 6), round(float(centre[1]), 6), round(float(facing), 9))
            out.append(Sighting(k, b, side, float(rel[0]), float(rel[1]), psi, bearing, at))
    return out


def _robot_pose(t: Traverse, beacons: np.ndarray, d_t_m: float, camera: int, beacon: int, side: str, est, cov):
    """The robot's global planar pose from a camera's pose ``est`` (u, v, ψ) in ``side``'s target frame
    of ``beacon``, through the beacon's known pose and the camera's mount, with ``cov`` propagated."""
    mount = 2 * math.pi * camera / t.cameras_n
    alpha = SIDE_ANGLES[side] + beacons[beacon, 2]
    origin = beacons[beacon, :2] + d_t_m * np.array([math.cos(alpha), math.sin(alpha)])
    heading = est[2] + alpha - mount
    offset = t.radius_m * np.array([math.cos(mount), math.sin(mount)])
    position = origin + _rot(alpha) @ np.asarray(est[:2]) - _rot(heading) @ offset
    d_rot = np.array([[-math.sin(heading), -math.cos(heading)], [math.cos(heading), -math.sin(heading)]])
    jac = np.zeros((3, 3))
    jac[:2, :2], jac[:2, 2], jac[2, 2] = _rot(alpha), -d_rot @ offset, 1.0
    return PlanarPose(*position, math.remainder(heading, 2 * math.pi), jac @ cov @ jac.T)


class _TableDetections:
    """Detections drawn from a :class:`DetectionTable`: each sighting detected with its measured
    P(correct), its pose drawn around the truth with the CRLB."""

    def __init__(self, t: Traverse, ring: _Ring, table: DetectionTable, covariances: dict):
        self.t, self.ring, self.table, self.cov = t, ring, table, covariances

    def __call__(
        self, step: int, seen: list[Sighting], rng
    ) -> list[list[tuple[Sighting, str, np.ndarray, np.ndarray]]]:
        out = []
        for s in seen:
            if rng.random() >= self.table.probability(s.range_m, s.yaw_deg):
                continue
            key = (round(s.range_m, 1), round(s.yaw_deg))
            if key not in self.cov:
                self.cov[key] = _target_covariance(self.t, self.ring, *key)
            est = np.array([s.u_m, s.v_m, s.psi_rad]) + rng.multivariate_normal(np.zeros(3), self.cov[key])
            out.append([(s, s.side, est, self.cov[key])])  # a detection of its own beacon
        return out


def planar_in_target(pose: Pose) -> tuple[float, float, float]:
    """A camera's pose in a side's target frame as the traverse's planar (u, v, ψ): the target frame's
    x is u; its y and z (down) flip into v and the counter-clockwise angle (see :func:`_target_covariance`)."""
    p = pose.camera_position_t_m()
    axis = pose.cv_from_t.T @ np.array([0.0, 0.0, 1.0])
    return float(p[0]), float(-p[1]), float(math.atan2(-axis[1], axis[0]))


def frame_task(t: Traverse, s: Sighting, seed: int, others: Sequence[Sighting] = ()) -> dict:
    """The whole-frame task of a sighting: the side at its range and yaw (the scenario's yaw is the
    target frame's, the sighting's mirrored), the camera turned by the bearing (``pan_deg``), the
    ring at marker 1's height (assumed: the study's ring and beacon heights are not given), the dark
    tube, the traverse's LED drive; detected after rectification with the lens's own distortion
    (an ideal calibration, keeping the whole field: ``alpha`` 1). ``others``: the further beacons the
    same camera sees at that instant, in the same frame (:attr:`FrameTask.others`)."""
    task = FrameTask(scenario=_scenario(t, s), seed=seed, full_frame=True, rectification={"alpha": 1.0}).to_dict()
    if others:
        task["others"] = [_scenario(t, o) for o in others]
    return task


def _scenario(t: Traverse, s: Sighting) -> dict:
    """The Scenario fields of a sighting (:func:`frame_task`). The tube's axis, in the side's planar
    frame at −``SIDE_ANGLES[side]`` (red faces along it), is at +that angle in the target frame (whose
    angles run the other way, as the yaw's); on a slope the camera stands ``along · tan(slope)``
    above marker 1 (``along``: its distance along the tube's axis from the beacon's foot; the ring at
    marker 1's height above its own floor) and its axis pitches with the floor along its heading."""
    scenario = {
        "beacon": t.beacon,
        "side": s.side,
        "range_m": round(s.range_m, 4),
        "yaw_deg": round(-s.yaw_deg, 3),
        "pan_deg": round(math.degrees(s.bearing_rad), 3),
        "camera": t.camera,
        "environment": "dark",
        "led_current_mA": t.led_current_mA,
    }
    if t.dust_extinction_per_m:
        scenario["dust_extinction_per_m"] = t.dust_extinction_per_m
    axis = SIDE_ANGLES[s.side]
    u_axis = s.u_m + beacon_design(t.beacon).d_t_m  # the camera from the beacon's axis, where it stands
    if t.slope_deg:
        grade = math.tan(math.radians(t.slope_deg))
        height = (u_axis * math.cos(axis) - s.v_m * math.sin(axis)) * grade
        pitch = math.atan(grade * math.cos(s.psi_rad + axis))  # the camera's axis, up from level
        elevation = math.atan2(-height, s.range_m)  # marker 1 seen from the camera, up from level
        scenario["range_m"] = round(math.hypot(s.range_m, height), 4)
        scenario["camera_height_m"] = round(height, 4)
        scenario["tilt_deg"] = round(math.degrees(pitch - elevation), 3)
    if t.tube_walls:
        camera_left = u_axis * math.sin(axis) + s.v_m * math.cos(axis)
        scenario["tube_walls"] = t.walls_at(round(math.degrees(axis), 6), s.beacon_at, camera_left).to_dict()
    return scenario


def camera_frames(seen: Sequence[Sighting], max_range_m: float) -> list[list[Sighting]]:
    """The frames of one instant: per ring camera, the beacon sides it sees within ``max_range_m``,
    nearest first (the frame is scored against the nearest; the rest are in it too)."""
    by_camera: dict[int, list[Sighting]] = {}
    for s in seen:
        if s.range_m <= max_range_m:
            by_camera.setdefault(s.camera, []).append(s)
    return [sorted(group, key=lambda s: s.range_m) for _, group in sorted(by_camera.items())]


def traverse_frame(task: dict) -> list[dict]:
    """One camera's frame rendered, captured and detected (best tracker and estimator): the side
    named, the camera's planar pose in that side's target frame (:func:`planar_in_target`; NaN without
    a pose) and the true one."""
    task = FrameTask.coerce(task)
    frame = capture_frame(task)
    det = detect(
        frame.image_bgr,
        Intrinsics.from_geometry(frame.camera.geometry),
        beacon=frame.scenario.beacon,
        **detect_options(task, frame.camera),
    )
    true_u, true_v, true_psi = planar_in_target(pose_from_scenario(frame.scenario))
    u, v, psi = planar_in_target(det.pose) if det.pose is not None and det.side else (math.nan,) * 3
    return [
        {
            "side_detected": det.side or "",
            "failure": "" if det.failure is None else str(det.failure),
            "u_m": u,
            "v_m": v,
            "psi_rad": psi,
            "true_u_m": true_u,
            "true_v_m": true_v,
            "true_psi_rad": true_psi,
        }
    ]


ERROR_BANDS_M = (0.0, 1.0, 2.0, 4.0, 8.0, math.inf)
"""Range bands (m) of the rendered detections' measured error covariance (:func:`error_covariances`)."""


def error_covariances(pairs: Sequence[tuple[dict, dict]], min_frames: int = 10) -> list[dict]:
    """The best estimator's error covariance (u, v, ψ in the target frame) per range band of
    :data:`ERROR_BANDS_M`, measured on rendered frames (task, row) whose detector named the rendered
    side: what a robot's designer gets by characterising the estimator against known poses, used as
    the measurement covariance of the filter. The CRLB is not: the rendered estimates' errors are
    20-80× its thinnest axis (blob-shape and rectification biases, not centroid noise). Gross errors
    (a pose flipped or metres off on the right side) are trimmed as the filter's gate would reject them
    (squared Mahalanobis distance beyond :data:`GATE_CHI2`, repeated until no frame changes side), so
    the covariance is the inliers'; ``outliers`` counts them per band and ``median_error_m`` gives the
    median position error (m) of all its frames (where most frames are gross the trimming cannot tell
    them from the rest: the covariance is then theirs, wide enough for the filter to ignore them, and
    this median says so). A band with fewer than
    ``min_frames`` takes the covariance of all bands together; with fewer in all, the errors' mean
    square with a floor of 1 cm and 0.5° (assumed)."""
    errors, ranges = [], []
    for task, row in pairs:
        if row["side_detected"] == task["scenario"]["side"] and math.isfinite(row["u_m"]):
            e = [row["u_m"] - row["true_u_m"], row["v_m"] - row["true_v_m"]]
            errors.append([*e, math.remainder(row["psi_rad"] - row["true_psi_rad"], 2 * math.pi)])
            ranges.append(math.hypot(row["true_u_m"], row["true_v_m"]))
    errors_a, ranges_a = np.asarray(errors).reshape(-1, 3), np.asarray(ranges)
    floor = np.diag([0.01**2, 0.01**2, math.radians(0.5) ** 2])

    def covariance(e: np.ndarray) -> np.ndarray:
        if len(e) < min_frames:
            return np.maximum(e.T @ e / max(len(e), 1), floor) * np.eye(3)
        # the inliers' second moment about zero (a bias is an error too), gross errors trimmed; started from
        # the median absolute errors (1.4826 MAD: a Gaussian's sd), so that many gross errors cannot mask themselves
        second = np.diag((1.4826 * np.median(np.abs(e), axis=0)) ** 2 + 1e-9)
        keep = np.zeros(len(e), dtype=bool)
        for _ in range(50):
            inside = np.einsum("ij,jk,ik->i", e, np.linalg.inv(second), e) <= GATE_CHI2
            if np.array_equal(inside, keep) or inside.sum() < min_frames:
                break
            keep = inside
            second = e[keep].T @ e[keep] / keep.sum() + 1e-9 * np.eye(3)
        return second

    everything = covariance(errors_a) if len(errors_a) else floor
    out = []
    for low, high in itertools.pairwise(ERROR_BANDS_M):
        inside = errors_a[(ranges_a >= low) & (ranges_a < high)]
        cov = covariance(inside) if len(inside) >= min_frames else everything
        d2 = np.einsum("ij,jk,ik->i", inside, np.linalg.inv(cov), inside) if len(inside) else np.zeros(0)
        out.append(
            {
                "low_m": low,
                "high_m": high,
                "frames": len(inside),
                "outliers": int((d2 > GATE_CHI2).sum()),
                "median_error_m": float(np.median(np.hypot(inside[:, 0], inside[:, 1]))) if len(inside) else None,
                "covariance": cov.tolist(),
            }
        )
    return out


class RenderedDetections:
    """Detections from rendered frames (:func:`traverse_frame` rows by task), one frame per ring camera
    holding every beacon it sees (:func:`camera_frames`): a frame that gave a pose is a detection of
    the side the detector named (a wrong side is an outlier the filter must gate), its covariance the
    estimator's measured one at the estimated range (:func:`error_covariances`). Which beacon it is
    the robot decides: each beacon in the frame is a candidate (:func:`simulate` keeps the one whose
    robot pose lies nearest the filter's prediction). Sightings beyond ``max_range_m`` were not
    rendered: missed, and not in any frame."""

    def __init__(self, t: Traverse, rows: dict[str, dict], seed: int, max_range_m: float, bands: list[dict]):
        self.t, self.rows, self.seed, self.max_range_m, self.bands = t, rows, seed, max_range_m, bands

    def __call__(
        self, step: int, seen: list[Sighting], rng
    ) -> list[list[tuple[Sighting, str, np.ndarray, np.ndarray]]]:
        out = []
        for nearest, *others in camera_frames(seen, self.max_range_m):
            row = self.rows[json.dumps(frame_task(self.t, nearest, self.seed, others), sort_keys=True)]
            if not row["side_detected"] or not math.isfinite(row["u_m"]):
                continue
            est = np.array([row["u_m"], row["v_m"], row["psi_rad"]])
            r = float(math.hypot(est[0], est[1]))
            cov = np.asarray(next(b for b in self.bands if b["low_m"] <= r < b["high_m"])["covariance"])
            out.append([(s, row["side_detected"], est, cov) for s in (nearest, *others)])
        return out


def simulate(
    t: Traverse,
    table: DetectionTable,
    spacing_m: float,
    seed: int,
    *,
    covariances: dict | None = None,
    detections: Callable | None = None,
) -> pd.DataFrame:
    """One traverse at one beacon spacing (m): a row per step (module docstring). ``covariances``:
    the CRLB per (range, yaw) already computed for ``t`` (shared by the runs of one traverse);
    ``detections``: where the detections come from (default drawn from ``table``; a
    :class:`RenderedDetections` for rendered frames): per frame a list of candidates (sighting, side
    named, pose in that side's frame, covariance), one per beacon it may be; the candidate whose
    robot pose fits the filter's prediction best is the frame's detection, then gated."""
    ground = np.random.default_rng(seed)  # the robot's slip and odometry noise: the same at every spacing
    rng = np.random.default_rng([seed, round(spacing_m * 1000)])  # what the cameras see
    slip_low, slip_high = LOOSE_SAND["slip"]
    odo = WheelOdometry(**{"slip": float(ground.uniform(slip_low, slip_high)), **t.odometry})
    truth, along = _truth(t), _along(t)
    beacons = _beacons(t, spacing_m)
    ring = _ring(t)
    cache: dict = {} if covariances is None else covariances
    detect_at = detections or _TableDetections(t, ring, table, cache)
    steps = np.hypot(*np.diff(truth[:, :2], axis=0).T)
    turns = np.array([math.remainder(a, 2 * math.pi) for a in np.diff(truth[:, 2])])
    odo_seed = int(ground.integers(2**32))
    d_hat, turn_hat = odo.report(steps, turns, seed=odo_seed)
    slip = odo.slip_along(steps, seed=odo_seed)  # per step; step i is driven with slip[i - 1]
    scale_walk = SCALE_WALK_PER_M + odo.scale_walk_per_m  # the filter told how the slip may wander
    x_odo = truth[0].copy()  # both start at the known start pose; the filter learns the odometer's scale
    k_mean, k_sd = scale_prior(LOOSE_SAND["slip"])
    x_ekf, p_ekf = np.array([*truth[0], k_mean]), np.diag([1e-4, 1e-4, 1e-6, k_sd**2])
    rows = []
    for i in range(len(truth)):
        if i:
            x_odo, _ = predict(x_odo, np.zeros((3, 3)), d_hat[i - 1], turn_hat[i - 1], np.zeros((2, 2)))
            q = odo.step_covariance(d_hat[i - 1], bias=False)  # the bias is the filter's scale state
            x_ekf, p_ekf = predict(x_ekf, p_ekf, d_hat[i - 1], turn_hat[i - 1], q, scale_walk=scale_walk)
        found = detect_at(i, sightings(t, ring.fov_rad, ring.d_t_m, truth[i], beacons), rng)
        poses = []
        for candidates in found:  # one detection per frame: the beacon whose pose fits the prediction best
            chosen = [
                (s, side, _robot_pose(t, beacons, ring.d_t_m, s.camera, s.beacon, side, est, c))
                for s, side, est, c in candidates
            ]
            poses.append(min(chosen, key=lambda p: mahalanobis2(x_ekf, p_ekf, p[2].vector, p[2].covariance)))
        kept = [
            (s, side, pose)
            for s, side, pose in poses
            if mahalanobis2(x_ekf, p_ekf, pose.vector, pose.covariance) <= GATE_CHI2
        ]
        fix = fuse([pose for _, _, pose in kept]) if kept else None
        if fix is not None:
            x_ekf, p_ekf = update(x_ekf, p_ekf, fix.vector, fix.covariance)
        rows.append(
            {
                "spacing_m": spacing_m,
                "seed": seed,
                "step": i,
                "distance_m": float(along[i]),
                "true_x_m": truth[i, 0],
                "true_y_m": truth[i, 1],
                "odometry_x_m": x_odo[0],
                "odometry_y_m": x_odo[1],
                "filter_x_m": x_ekf[0],
                "filter_y_m": x_ekf[1],
                "filter_sd_m": float(math.sqrt(max(p_ekf[0, 0] + p_ekf[1, 1], 0.0))),
                "filter_scale": float(x_ekf[3]),
                "fix_x_m": fix.x_m if fix else math.nan,
                "fix_y_m": fix.y_m if fix else math.nan,
                "detections": len(kept),
                "gated": len(poses) - len(kept),
                "wrong_side": sum(side != s.side for s, side, _ in poses),
                "seen": ";".join(f"cam{s.camera}:b{s.beacon}:{side}" for s, side, _ in kept),
                "odometry_error_m": float(np.hypot(*(x_odo[:2] - truth[i, :2]))),
                "filter_error_m": float(np.hypot(*(x_ekf[:2] - truth[i, :2]))),
                "fix_error_m": float(np.hypot(fix.x_m - truth[i, 0], fix.y_m - truth[i, 1])) if fix else math.nan,
                "slip": float(slip[max(i - 1, 0)]) if slip.size else odo.slip,
            }
        )
    return pd.DataFrame(rows)


def largest_spacing(per_run: pd.DataFrame, threshold_m: float) -> dict:
    """The largest spacing up to which every spacing tried keeps the filter's error under
    ``threshold_m`` along the whole path, per seed (a spacing that passes beyond one that failed, by
    luck of where the beacons fell, does not count), and over the seeds (low, high: the smallest and
    largest per-seed answer; None where no spacing tried keeps it, "≥" where the largest tried does)."""
    spacings = sorted(set(per_run.spacing_m))
    per_seed = {}
    for seed, g in per_run.groupby("seed"):
        answer = None
        for s in spacings:
            if float(g[g.spacing_m == s].filter_max_error_m.iloc[0]) > threshold_m:
                break
            answer = s
        per_seed[int(seed)] = answer
    values = [v for v in per_seed.values() if v is not None]
    return {
        "threshold_m": threshold_m,
        "per_seed": per_seed,
        "low_m": None if len(values) < len(per_seed) else min(values),
        "high_m": max(values) if values else None,
        "at_least": bool(values) and max(values) == spacings[-1],
        "spacings_m": spacings,
    }


def spacing_text(answer: dict) -> str:
    """The spacing answer in words."""
    if answer["high_m"] is None:
        return f"no spacing tried keeps the error under {answer['threshold_m']:g} m"
    top = f"≥ {answer['high_m']:g}" if answer["at_least"] else f"{answer['high_m']:g}"
    seeds, under = len(answer["per_seed"]), f"error under {answer['threshold_m']:g} m"
    if answer["low_m"] == answer["high_m"]:
        return f"{top} m at {'its one seed' if seeds == 1 else f'each of {seeds} seeds'} ({under})"
    low = "none" if answer["low_m"] is None else f"{answer['low_m']:g}"
    return f"{low} to {top} m over {seeds} seeds ({under})"


def run(
    out: Path,
    t: Traverse,
    *,
    spacings_m: Sequence[float],
    seeds: int,
    threshold_m: float,
    table: DetectionTable,
    progress: Progress = no_progress,
    rendered: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
) -> dict:
    """Every spacing × seed (module docstring); returns the summary. ``rendered``: the detections
    from a rendered whole frame per camera and step (:func:`traverse_frame`, stored in ``out/tasks``
    so a stopped run resumes; ``workers`` local processes, or the Dask ``scheduler`` at that address)
    instead of drawn from ``table``, which then only bounds the ranges rendered
    (:data:`RENDER_RANGE_FACTOR`). ``progress``: the display of the frames, then of the runs."""
    if t.dust_extinction_per_m and not rendered:
        raise ValueError(
            "dust_extinction_per_m: dust acts on rendered frames (the detection table was measured in clear air); "
            "run with rendered frames"
        )
    t0 = time.perf_counter()
    out = Path(out)
    frames, covariances = [], {}  # the CRLB at a range and yaw is the same in every run
    max_range_m = RENDER_RANGE_FACTOR * table.farthest_m()
    rows: dict[str, dict] = {}
    bands: list[dict] = []
    if rendered:
        ring = _ring(t)
        tasks = {}
        for spacing in spacings_m:
            beacons = _beacons(t, float(spacing))
            for pose in _truth(t):
                seen = sightings(t, ring.fov_rad, ring.d_t_m, pose, beacons)
                for nearest, *others in camera_frames(seen, max_range_m):
                    for seed in range(seeds):
                        task = frame_task(t, nearest, seed, others)
                        tasks.setdefault(json.dumps(task, sort_keys=True), task)
        done = run_tasks(
            list(tasks.values()),
            out,
            traverse_frame,
            workers=workers,
            scheduler=scheduler,
            description="traverse frames",
            progress=progress,
            batch_key=render_batch_key,
        )
        rows = dict(zip(tasks, done, strict=True))
        bands = error_covariances(list(zip(tasks.values(), done, strict=True)))
    with progress("traverse runs", len(spacings_m) * seeds, 0) as advance:
        for spacing in spacings_m:
            for seed in range(seeds):
                source = RenderedDetections(t, rows, seed, max_range_m, bands) if rendered else None
                frames.append(simulate(t, table, float(spacing), seed, covariances=covariances, detections=source))
                advance()
    steps = pd.concat(frames, ignore_index=True)
    per_run = (
        steps.groupby(["spacing_m", "seed"])
        .agg(
            fix_fraction=("detections", lambda d: float((d > 0).mean())),
            filter_max_error_m=("filter_error_m", "max"),
            filter_final_error_m=("filter_error_m", "last"),
            odometry_max_error_m=("odometry_error_m", "max"),
            odometry_final_error_m=("odometry_error_m", "last"),
            slip=("slip", "mean"),
            gated=("gated", "sum"),
            wrong_side=("wrong_side", "sum"),
        )
        .reset_index()
    )
    answer = largest_spacing(per_run, threshold_m)
    summary = {
        "study": NAME,
        "traverse": asdict(t),
        "detections": {
            "camera": table.camera,
            "source": table.source,
            "rendered": rendered,
            "frames": len(rows),
            "max_range_m": max_range_m if rendered else None,
            "error_bands": [
                {
                    **{k: b[k] for k in ("low_m", "high_m", "frames", "outliers", "median_error_m")},
                    "sd": np.sqrt(np.diag(b["covariance"])).tolist(),
                }
                for b in bands
            ],
            "centroid_sd_px": CENTROID_SD_PX,
            "gate_chi2": GATE_CHI2,
        },
        "runs": per_run.to_dict("records"),
        "spacing": answer,
        "spacing_answer": spacing_text(answer),
        "wall_s": resumed_seconds(out, NAME) + time.perf_counter() - t0,  # with the parts it resumes
    }
    out.mkdir(parents=True, exist_ok=True)
    steps.to_parquet(out / "steps.parquet.tmp", index=False)
    (out / "steps.parquet.tmp").replace(out / "steps.parquet")
    _report(out, t, steps, per_run, summary)
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def _slip_text(t: Traverse) -> str:
    """How the slip behaves along a run, in words."""
    odo = WheelOdometry(**{"slip": 0.0, **t.odometry})
    if not odo.slip_sd:
        return "constant along it"
    return (
        f"changing along it with a standard deviation of {odo.slip_sd:g} about the run's mean over "
        f"{odo.slip_correlation_m:g} m (1/e correlation)"
    )


def _source_text(detections: dict, t: Traverse) -> str:
    """Where the report's detections came from, in words."""
    if detections["rendered"]:
        basalt = "basalt" if t.wall_reflectance is None else f"grey (reflectance {t.wall_reflectance:g})"
        tube = (
            f"the dark tube's {basalt} walls, ceiling ({t.tube_height_m:g} m) and rough floor ({t.floor_rms_m:g} m "
            f"rms, {t.floor_correlation_m:g} m correlation) around each beacon"
            if t.tube_walls
            else "the dark environment's box around each camera-beacon line"
        )
        slope = f", the floor rising {t.slope_deg:g}° along the tube" if t.slope_deg else ""
        return (
            f"Detections from {detections['frames']} rendered whole frames, one per ring camera and step holding "
            f"every beacon side it had in its field within {detections['max_range_m']:g} m (1.5× the farthest "
            f"correct pose of {detections['source']}; farther ones count as missed), the camera turned by the "
            f"bearing, {tube}{slope}, detected by the best tracker and estimator after the lens's rectification; "
            "each detection taken for the beacon in view whose pose fits the filter's prediction best."
        )
    return (
        f"Detections from {detections['source']} (the camera's rendered range-limit frames: P(correct) as "
        "measured at the ranges and yaws tried, interpolated, 0 beyond them); pose noise the Cramér–Rao bound "
        f"at {detections['centroid_sd_px']:g} px per centroid. Not rendered per step (run with --rendered)."
    )


def _report(out: Path, t: Traverse, steps: pd.DataFrame, per_run: pd.DataFrame, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bend = (
        f" with a {abs(t.bend_deg):g}° {'left' if t.bend_deg > 0 else 'right'} bend at {t.bend_at_m:g} m"
        if t.bend_deg
        else ""
    )
    dust = f", dust of {visual_range_m(t.dust_extinction_per_m):.3g} m visual range" if t.dust_extinction_per_m else ""
    rep = Report(f"Traverse: {t.cameras_n} × {t.camera} ring through a {t.path_m:g} m lava tube{bend}{dust}")
    rep.lead(
        [
            f"Largest beacon spacing that keeps the position error under {summary['spacing']['threshold_m']:g} m: "
            f"{summary['spacing_answer']}.",
            _source_text(summary["detections"], t),
            f"Wheel odometry on loose sand with the slip drawn per run, {_slip_text(t)}; the filter (EKF) "
            "learns the odometer's scale from the fixes (a state, with a random walk) and gates every detection "
            f"whose pose lies beyond χ²₃ = {GATE_CHI2:g} of its prediction.",
        ]
    )
    bands = summary["detections"].get("error_bands") or []
    if bands:
        rep.table(
            pd.DataFrame(
                [
                    {
                        "range band, m": (
                            f"{b['low_m']:g}-{b['high_m']:g}"
                            if math.isfinite(b["high_m"] or math.inf)
                            else f"≥ {b['low_m']:g}"
                        ),
                        "frames": b["frames"],
                        "gross errors": b.get("outliers", 0),
                        "median error, mm": (
                            1e3 * b["median_error_m"] if b.get("median_error_m") is not None else math.nan
                        ),
                        "sd u, mm": 1e3 * b["sd"][0],
                        "sd v, mm": 1e3 * b["sd"][1],
                        "sd heading, °": math.degrees(b["sd"][2]),
                    }
                    for b in bands
                ]
            ),
            "The best estimator's error measured on the rendered frames that named the rendered side (the filter's "
            "measurement covariance: the inliers', gross errors trimmed as the gate would; a band with under 10 "
            "frames takes all the bands' together)",
            float_format="{:.3g}",
        )
    rep.table(
        per_run,
        "Per spacing and seed: fraction of steps with a fix, the filter's and odometry's largest and final "
        "position errors (m), the run's mean slip, detections the gate rejected and detections that named another "
        "side than the one facing the camera (a neighbouring side seen obliquely can be a correct one)",
        float_format="{:.3g}",
    )
    seen = [item.split(":") for text in steps.seen for item in text.split(";") if item]
    if seen:
        counts = pd.DataFrame(seen, columns=["camera", "beacon", "side"]).groupby(["camera", "side"]).size()
        rep.table(
            counts.unstack(fill_value=0).rename_axis(columns=None).reset_index(),
            "Which ring camera saw which side: detections over every spacing, seed and step (cam0 faces forward)",
            float_format="{:.0f}",
        )
    seed0 = steps[steps.seed == steps.seed.min()]
    spacings = sorted(set(seed0.spacing_m))
    walls = [t.tube.at(np.linspace(0.0, t.path_m + 2.0, 400), side * t.tube_width_m)[0] for side in (-0.5, 0.5)]
    if t.bend_deg:  # a floor plan to scale, one panel per spacing
        cols = min(4, len(spacings))
        rows_n = -(-len(spacings) // cols)
        fig, axes = plt.subplots(rows_n, cols, figsize=(4 * cols, 4.6 * rows_n), squeeze=False)
        for ax in axes.flat[len(spacings) :]:
            ax.set_visible(False)
    else:
        fig, axes = plt.subplots(len(spacings), 1, figsize=(10, 2.2 * len(spacings)), squeeze=False)
    for ax, spacing in zip(axes.flat, spacings, strict=False):  # a grid may hold spare panels
        g = seed0[seed0.spacing_m == spacing]
        ax.plot(g.true_x_m, g.true_y_m, "k-", lw=1.5, label="truth")
        ax.plot(g.odometry_x_m, g.odometry_y_m, "C3--", lw=1, label="odometry alone")
        ax.plot(g.filter_x_m, g.filter_y_m, "C0-", lw=1, label="odometry + fixes (EKF)")
        ax.plot(g.fix_x_m, g.fix_y_m, "C2.", ms=3, label="fused fixes")
        b = _beacons(t, spacing)
        ax.plot(b[:, 0], b[:, 1], "k^", ms=6, label="beacons")
        for xy in walls:
            ax.plot(xy[:, 0], xy[:, 1], color="0.6", lw=0.8)
        if t.bend_deg:
            box = np.vstack(walls)
            ax.set_xlim(box[:, 0].min() - 2, box[:, 0].max() + 2)
            ax.set_ylim(box[:, 1].min() - 2, box[:, 1].max() + 2)
            ax.set_aspect("equal")
            ax.set_title(f"beacons {spacing:g} m apart", fontsize=10)
            ax.set_xlabel("x, m")
            ax.set_ylabel("y, m")
        else:
            ax.set_ylabel(f"{spacing:g} m apart\ny, m")
            ax.set_xlim(-1, t.path_m + 1)
    if not t.bend_deg:
        axes[-1, 0].set_xlabel("distance along the tube, m")
    axes[0, 0].legend(fontsize=7, ncol=1 if t.bend_deg else 5, loc="upper left")
    fig.tight_layout()
    rep.figure(fig, "The path from above (first seed): truth, odometry alone, the filter and the fused fixes")
    fig, ax = plt.subplots(figsize=(10, 3.2))
    for i, spacing in enumerate(spacings):
        g = seed0[seed0.spacing_m == spacing]
        ax.plot(g.distance_m, g.filter_error_m, color=f"C{i}", label=f"EKF, beacons {spacing:g} m apart")
    ax.plot(seed0[seed0.spacing_m == spacings[0]].distance_m, seed0[seed0.spacing_m == spacings[0]].odometry_error_m,
            "k--", lw=1, label="odometry alone (first spacing's run)")  # fmt: skip
    ax.axhline(summary["spacing"]["threshold_m"], color="0.5", ls=":", label="threshold")
    ax.set_xlabel("distance along the tube, m")
    ax.set_ylabel("position error, m")
    ax.legend(fontsize=7)
    fig.tight_layout()
    rep.figure(fig, "Position error along the path (first seed)")
    rep.write(out / "report.html")
