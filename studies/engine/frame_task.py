"""The frame task: everything that makes one simulated frame, as one typed record.

A study's grid, a sequential design, the calibration's waves and the experiments all make frame
tasks; the runner stores them by content and sends them to workers as plain JSON
(:meth:`FrameTask.to_dict`), and the frame path (:mod:`studies.engine.frame`) reads them back with
:meth:`FrameTask.coerce`, which refuses a field it does not know in one line naming the nearest
one. Every unknown of the registry (``studies/data/unknowns.toml``) reaches a frame through one of
three fields: ``scenario`` (its Scenario fields, ``data`` among them: the scene data files'
values), ``camera_overrides`` (the camera model) and ``render``.

Fields left out (None) are left out of the plain form too, so the plain form of a task is the
dict it was made from and a stored task keeps its key.

>>> t = FrameTask.coerce({"scenario": {"range_m": 4.0}, "seed": 1, "full_frame": True})
>>> t.is_full_frame, t.with_noise, t.to_dict()
(True, True, {'scenario': {'range_m': 4.0}, 'seed': 1, 'full_frame': True})
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["MORPHOLOGY_FIELDS", "FrameTask"]

MORPHOLOGY_FIELDS = ("close_iterations", "erode_iterations")
"""Settings of the study's tracker a task may replace (:class:`pipeline.thesis_tracker.ThesisTrackerSettings`)."""


@dataclass(frozen=True)
class FrameTask:
    """One frame to simulate (plain JSON-able values; None: not given, the default applies).

    Attributes
    ----------
    scenario
        Keyword arguments of :class:`scenes.scenario.Scenario` without ``render`` (``data``: the
        scene data files' values it replaces, :mod:`scenes.data_overrides`).
    seed
        Sensor-noise seed index (>= 0); the sensor draws from
        :func:`studies.engine.frame.noise_seed`, the index hashed with what makes the frame.
    render
        Keyword arguments of :class:`scenes.scenario.RenderSettings`.
    nominal
        The grid condition's nominal ``range_m`` and ``yaw_deg`` before pose jitter.
    exposure
        Manual settings ``{"iso", "exposure_s", "f_number"}`` (else the camera's own control).
    trackers, estimators
        Which detectors to run (default: every registered one).
    thesis_hsv_variants
        Label → per-colour HSV boxes for the study's tracker (None: its printed boxes).
    tags
        Fields copied into every result row (e.g. the test's name).
    full_frame
        Capture and detect on the camera's whole saved frame (True) or on the rendered crop.
    noise
        False: the noiseless frame (for checks); default True.
    reference_camera
        True: the reference sensor and ISP the fast path replaced (equivalence tests).
    quest_weights
        ``tuned`` (the study's) or ``equal`` QUEST weights.
    rectification
        ``{"alpha": 0 or 1}``: undistort before detecting, as the study's rectification did.
    align_px
        Pad a crop's render so its origin and size are multiples of this (ignored on whole frames).
    camera_overrides
        Camera-model fields to replace, ``{"lens.f_number": 5.6}``
        (:func:`camera_models.camera.with_overrides`).
    thesis_morphology
        Morphology iterations of the study's tracker to replace, ``{"erode_iterations": 2}``
        (:data:`MORPHOLOGY_FIELDS`): the sessions in which the study says it changed them.
    others
        Further beacons in the same whole frame, each a table of Scenario fields like ``scenario``
        (the same camera and environment; its own beacon, side, range, yaw, turn and drive): their
        LEDs' light is added to the frame (:func:`studies.engine.frame.other_beacons`). The frame is
        scored against ``scenario``'s beacon.
    """

    scenario: dict
    seed: int
    render: dict | None = None
    nominal: dict | None = None
    exposure: dict | None = None
    trackers: list[str] | None = None
    estimators: list[str] | None = None
    thesis_hsv_variants: dict | None = None
    tags: dict | None = None
    full_frame: bool | None = None
    noise: bool | None = None
    reference_camera: bool | None = None
    quest_weights: str | None = None
    rectification: dict | None = None
    align_px: int | None = None
    camera_overrides: dict | None = None
    thesis_morphology: dict | None = None
    others: list[dict] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.scenario, Mapping):
            raise ValueError(f"task.scenario: expected a table of Scenario fields, got {self.scenario!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"task.seed: expected an integer >= 0, got {self.seed!r}")
        tables = ("render", "nominal", "exposure", "thesis_hsv_variants", "tags", "rectification", "thesis_morphology")
        for name in tables:
            value = getattr(self, name)
            if value is not None and not isinstance(value, Mapping):
                raise ValueError(f"task.{name}: expected a table, got {value!r}")
        for key, value in (self.thesis_morphology or {}).items():
            if key not in MORPHOLOGY_FIELDS:
                raise ValueError(f"task.thesis_morphology.{key}: expected one of {', '.join(MORPHOLOGY_FIELDS)}")
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"task.thesis_morphology.{key}: expected a whole number >= 0, got {value!r}")
        for name in ("full_frame", "noise", "reference_camera"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, bool):
                raise ValueError(f"task.{name}: expected true or false, got {value!r}")
        if self.others is not None and (
            isinstance(self.others, Mapping | str) or not all(isinstance(o, Mapping) for o in self.others)
        ):
            raise ValueError(f"task.others: expected a list of tables of Scenario fields, got {self.others!r}")
        for name in ("trackers", "estimators"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, str) or not all(isinstance(v, str) for v in value)):
                raise ValueError(f"task.{name}: expected a list of names, got {value!r}")

    @classmethod
    def coerce(cls, task: FrameTask | Mapping) -> FrameTask:
        """``task`` itself, or the task a plain mapping describes (``ValueError``, one line, on a field
        it does not know, naming the nearest field)."""
        if isinstance(task, FrameTask):
            return task
        if not isinstance(task, Mapping):
            raise ValueError(f"task: expected a table of frame-task fields, got {type(task).__name__}")
        known = [f.name for f in dataclasses.fields(cls)]
        for key in task:
            if key not in known:
                near = difflib.get_close_matches(str(key), known, n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else f" (expected some of {', '.join(known)})"
                raise ValueError(f"task.{key}: not a frame-task field{hint}")
        for key in ("scenario", "seed"):
            if key not in task:
                raise ValueError(f"task.{key}: missing")
        return cls(**copy.deepcopy(dict(task)))

    def to_dict(self) -> dict[str, Any]:
        """The plain form (what the runner hashes, stores and sends): the fields given, in order."""
        return {
            f.name: copy.deepcopy(getattr(self, f.name))
            for f in dataclasses.fields(self)
            if getattr(self, f.name) is not None
        }

    @property
    def is_full_frame(self) -> bool:
        """Whether the frame is the camera's whole saved frame."""
        return bool(self.full_frame)

    @property
    def with_noise(self) -> bool:
        """Whether the sensor's noise is drawn (the default)."""
        return self.noise is None or bool(self.noise)
