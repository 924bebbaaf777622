"""What a study sweeps: its options, the grid of nominal conditions, and frame tasks with pose jitter.

Study frames are the camera's whole saved frame by default (:attr:`StudyOptions.frame`
``"full"``): the detectors then see every blob the camera would give them, including the
false blobs that sensor noise makes outside the rendered crop around the beacon (tens to
hundreds at a webcam's maximum auto-exposure gain). ``"crop"`` keeps the older, cheaper
path that captures and detects on the rendered crop only (optimistic about detection;
:mod:`studies.experiments.crop_vs_full` measures the difference).

Frames of one nominal condition differ by sensor-noise seed and by a small pose jitter
(range ±0.5 %, yaw ±0.5°, camera height ±5 mm, drawn deterministically from the
condition's geometry and the jitter index), so detection probabilities are not those of
a single lucky pose. ``jitter_poses`` jittered poses are rendered per condition; seeds
cycle over them. The jitter does not depend on the LED drive, so every drive of a
condition sees the same poses: drive sweeps are paired and reuse one render per pose.

With points of the unknowns (:attr:`StudyOptions.physics`, ``--uncertainty``) every nominal
condition is run once more at each point: the condition gains ``"point": i`` and its frames the
point's values (:func:`studies.engine.unknowns.apply`) and the tag ``point``; the nominal run
stays as it was (same tasks, same stored frames), so its noise-and-pose interval sits beside the
noise + physics one (:mod:`studies.engine.uncertainty`).
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from scenes.beacon import beacon_design, beacon_names
from scenes.diffusers import DiffuserConfig
from scenes.environment import ENVIRONMENT_NAMES
from scenes.led import SIDE_COLOURS
from scenes.scenario import MAX_RANGE_M
from scenes.view import camera_names
from studies.engine.unknowns import apply, load_unknowns

__all__ = [
    "FRAMES",
    "GRID_AXES",
    "RENDER",
    "STUDY_CAMERAS",
    "StudyOptions",
    "frame_task",
    "frame_tasks",
    "grid_conditions",
    "jitter",
]

FRAMES = ("full", "crop")
"""What a study's frames are: ``full``, the camera's whole saved frame (the rendered crop inside
a frame-sized background, sensor noise, ISP and JPEG on all of it), or ``crop``, the rendered
crop alone (the path before frame version 4)."""

RENDER = {"spp": 4, "oversampling": 2, "crop": "beacon", "near_field_spp": 1024}
"""Render settings of study frames (near-field marker renders cached per configuration)."""

STUDY_CAMERAS = ("canon-t6-10mm", "canon-t6-18mm", "logitech-c270", "spedal-920")
"""The source study's four cameras, in the order ``beacon-sim cameras`` lists them: the default of the
experiments that would otherwise run every camera (``crop-vs-full``, ``colour-reach``). Cameras added
since (the Raspberry Pi HQ lenses, the mvBlueFOX3-2016C) run where named (``--cameras``), so adding a
camera file changes no default grid and no main-job result; each study names its own cameras."""


@dataclass(frozen=True)
class StudyOptions:
    """What a study sweeps (each study has full and quick defaults)."""

    cameras: tuple[str, ...]
    beacons: tuple[str, ...] = ("v2",)
    sides: tuple[str, ...] = ("red",)
    ranges_m: tuple[float, ...] = (2.0, 5.0)
    yaws_deg: tuple[float, ...] = (0.0,)
    environments: tuple[str, ...] = ("dark",)
    currents_mA: tuple[float, ...] = (20.0,)
    seeds: int = 2
    jitter_poses: int = 2
    diffusers: tuple[tuple[bool, int, str], ...] = ((True, 1, "matched"),)
    render: dict = field(default_factory=lambda: dict(RENDER))
    frame: str = "full"
    """One of :data:`FRAMES`: the whole frame (default) or the rendered crop only."""
    physics: tuple[dict, ...] = ()
    """Points of the unknowns (registry name → value) each condition is also run at (empty: the
    nominal run only)."""
    physics_source: str = ""
    """What the points are, in words (for reports)."""

    def swept_fields(self) -> frozenset[str]:
        """Scenario fields the grid itself varies (two or more values). A point of the unknowns leaves
        them as the grid sets them: brightness-diffuser compares white paper with matched, so the
        unknown paper colour (V2's as built, which the other studies run) must not overwrite its axis."""
        values = {
            "camera": self.cameras,
            "beacon": self.beacons,
            "side": self.sides,
            "range_m": self.ranges_m,
            "yaw_deg": self.yaws_deg,
            "environment": self.environments,
            "led_current_mA": self.currents_mA,
            "foam": [d[0] for d in self.diffusers],
            "paper_sheets": [d[1] for d in self.diffusers],
            "paper_colour": [d[2] for d in self.diffusers],
        }
        return frozenset(name for name, v in values.items() if len(set(v)) > 1)

    def validate(self) -> None:
        """Fail fast, before any work, with one line naming the bad option."""

        _check_choices("cameras", self.cameras, camera_names())
        for name in ("cameras", "beacons", "sides", "environments", "ranges_m", "yaws_deg", "currents_mA", "diffusers"):
            _check_distinct(name, getattr(self, name))
        if self.frame not in FRAMES:
            raise ValueError(f"frame: expected one of {', '.join(FRAMES)}, got {self.frame!r}")
        _check_choices("beacons", self.beacons, beacon_names())
        _check_choices("sides", self.sides, SIDE_COLOURS)
        _check_choices("environments", self.environments, ENVIRONMENT_NAMES)
        for name, values in (
            ("ranges_m", self.ranges_m),
            ("yaws_deg", self.yaws_deg),
            ("currents_mA", self.currents_mA),
        ):
            if not values:
                raise ValueError(f"{name}: expected at least one value, got an empty list")
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise ValueError(f"{name}: expected finite numbers, got {list(values)}")
        if min(self.ranges_m) <= 0 or max(self.ranges_m) > MAX_RANGE_M:
            raise ValueError(f"ranges_m: expected distances > 0 m and <= {MAX_RANGE_M:g} m, got {list(self.ranges_m)}")
        if max(abs(y) for y in self.yaws_deg) > 90:
            raise ValueError(f"yaws_deg: expected angles in [-90, 90], got {list(self.yaws_deg)}")
        for current in self.currents_mA:
            if current <= 0:
                raise ValueError(f"currents_mA: expected currents > 0 mA, got {current!r}")
            for side in self.sides:
                for beacon in self.beacons:
                    beacon_design(beacon).led(side).check_current(current)
        if not isinstance(self.seeds, int) or self.seeds < 1:
            raise ValueError(f"seeds: expected an integer >= 1, got {self.seeds!r}")
        for foam, sheets, colour in self.diffusers:
            DiffuserConfig(foam, sheets, colour).validate()
        registry = load_unknowns() if self.physics else {}
        for i, point in enumerate(self.physics):
            for name, value in point.items():
                if name not in registry:
                    raise ValueError(f"physics[{i}].{name}: not an unknown (beacon-sim unknowns lists them)")
                if not registry[name].contains(value):
                    raise ValueError(f"physics[{i}].{name}: {value!r} is outside {registry[name].describe_range()}")

    def with_overrides(self, **overrides) -> StudyOptions:
        """These options with the user's non-None overrides."""
        return replace(self, **{k: v for k, v in overrides.items() if v is not None})


def _check_distinct(name: str, values: Sequence) -> None:
    """Refuse a repeated grid value: each would count the same stored frames again."""
    seen = set()
    for value in values:
        try:
            repeated = value in seen
            seen.add(value)
        except TypeError:  # unhashable: validated (and refused) by the checks that follow
            return
        if repeated:
            raise ValueError(f"{name}: expected each value once, got {value!r} more than once")


def _check_choices(name: str, values: Sequence[str], allowed: Sequence[str]) -> None:
    if not values:
        raise ValueError(f"{name}: expected at least one of {', '.join(allowed)}, got an empty list")
    bad = [v for v in values if v not in allowed]
    if bad:
        raise ValueError(f"{name}: expected some of {', '.join(allowed)}, got unknown {', '.join(map(str, bad))}")


GRID_AXES = {
    "camera": "cameras",
    "beacon": "beacons",
    "side": "sides",
    "environment": "environments",
    "yaw_deg": "yaws_deg",
    "range_m": "ranges_m",
    "led_current_mA": "currents_mA",
    "diffuser": "diffusers",
}
"""Axes of a study grid, in the default loop order (first outermost), and the
:class:`StudyOptions` field holding each one's values."""


def grid_conditions(o: StudyOptions, order: Sequence[str] = tuple(GRID_AXES)) -> list[dict]:
    """Nominal conditions for every combination of the options' values, looping over
    the axes of :data:`GRID_AXES` in ``order`` (first outermost; all eight named)."""
    if sorted(order) != sorted(GRID_AXES):
        raise ValueError(f"order: expected each of {', '.join(GRID_AXES)} once, got {', '.join(order)}")
    out = []
    for values in itertools.product(*(getattr(o, GRID_AXES[axis]) for axis in order)):
        v = dict(zip(order, values, strict=True))
        foam, sheets, colour = v["diffuser"]
        out.append(
            {
                "beacon": v["beacon"],
                "side": v["side"],
                "range_m": float(v["range_m"]),
                "yaw_deg": float(v["yaw_deg"]),
                "camera": v["camera"],
                "environment": v["environment"],
                "led_current_mA": float(v["led_current_mA"]),
                "foam": foam,
                "paper_sheets": sheets,
                "paper_colour": colour,
            }
        )
        out += [{**out[-1], "point": i} for i in range(len(o.physics))]
    return out


def jitter(condition: dict, index: int) -> dict:
    """Deterministic small pose offsets for jittered pose ``index`` of a condition (0: none);
    the same for every LED drive of the condition."""
    if index == 0:
        return {"range_scale": 1.0, "yaw_offset_deg": 0.0, "height_m": 0.0}
    geometry = sorted((k, v) for k, v in condition.items() if k != "led_current_mA")
    digest = hashlib.sha256(repr((geometry, index)).encode()).digest()
    u = np.frombuffer(digest[:24], dtype=np.uint64).astype(np.float64) / 2.0**64 * 2 - 1  # three in (-1, 1)
    return {"range_scale": 1.0 + 0.005 * u[0], "yaw_offset_deg": 0.5 * u[1], "height_m": 0.005 * u[2]}


def frame_tasks(
    conditions: Iterable[dict],
    options: StudyOptions,
    exposure: dict | None = None,
    trackers: Sequence[str] | None = None,
    estimators: Sequence[str] | None = None,
) -> list[dict]:
    """Frame tasks for every condition × seed (see module docstring).

    A condition holds Scenario fields; ``range_m``/``yaw_deg`` are nominal and get jittered.
    With ``options.frame == "full"`` every task is a whole-frame task (``"full_frame": True``).
    """
    if options.frame not in FRAMES:
        raise ValueError(f"frame: expected one of {', '.join(FRAMES)}, got {options.frame!r}")
    return [
        frame_task(condition, seed, options, exposure, trackers, estimators)
        for condition in conditions
        for seed in range(options.seeds)
    ]


def frame_task(
    condition: dict,
    seed: int,
    options: StudyOptions,
    exposure: dict | None = None,
    trackers: Sequence[str] | None = None,
    estimators: Sequence[str] | None = None,
) -> dict:
    """The frame task of one condition and noise seed index ``seed`` (≥ 0; jittered pose
    ``seed % options.jitter_poses``): what :func:`frame_tasks` makes for each seed, and what a
    sequential design (:mod:`studies.engine.sequential`) makes for the seeds it adds. A condition's
    ``point`` (index into ``options.physics``) sets that point's unknowns, except on the grid's own
    axes (:meth:`StudyOptions.swept_fields`), and tags the frame; the pose jitter does not depend on it
    (the points are paired)."""
    if options.frame not in FRAMES:
        raise ValueError(f"frame: expected one of {', '.join(FRAMES)}, got {options.frame!r}")
    if not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")
    point = condition.get("point")
    condition = {k: v for k, v in condition.items() if k != "point"}
    j = jitter(condition, seed % options.jitter_poses)
    scenario = dict(condition)
    scenario["range_m"] = round(condition["range_m"] * j["range_scale"], 9)
    scenario["yaw_deg"] = round(max(-90.0, min(90.0, condition["yaw_deg"] + j["yaw_offset_deg"])), 9)
    scenario["camera_height_m"] = round(j["height_m"], 9)
    task = {
        "scenario": scenario,
        "render": dict(options.render),
        "seed": seed,
        "nominal": {"range_m": condition["range_m"], "yaw_deg": condition["yaw_deg"]},
    }
    if options.frame == "full":
        task["full_frame"] = True
    if exposure:
        task["exposure"] = exposure
    if trackers:
        task["trackers"] = list(trackers)
    if estimators:
        task["estimators"] = list(estimators)
    if point is not None:
        task = apply(task, options.physics[point])
        task["scenario"].update({name: scenario[name] for name in options.swept_fields() if name in scenario})
        task["tags"] = {**(task.get("tags") or {}), "point": point}
    return task
