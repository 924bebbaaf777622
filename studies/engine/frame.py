"""One simulated frame, end to end: render → camera → saved JPEG → detectors → result rows.

A *frame task* is a :class:`studies.engine.frame_task.FrameTask` (its fields are documented there):
the scenario (with the scene data files' values it replaces), render settings, a noise-seed index
and options (manual exposure, whole frame, detectors, camera overrides). The functions here take
one or its plain form (a JSON-able dict, as stored and sent to workers), which they check with
:meth:`FrameTask.coerce`.

:func:`capture_frame` is the one render → capture path: it returns what the camera saved
(:class:`CapturedFrame`), which experiments measure directly (e.g. core saturation).
:func:`simulate_frame` scores it: one row per tracker × estimator with the task's
parameters, the camera's exposure, ground truth, detection and pose results, and the
marker measurements that do not depend on the detector (core saturation, colour).
"""

from __future__ import annotations

import hashlib
import json
import math
import resource
import time
from dataclasses import dataclass, replace

import colour
import cv2
import numpy as np
from numpy.typing import NDArray

from camera_models.camera import Camera, load_camera, with_overrides
from camera_models.capture import Capture, capture, marker_core_saturation, marker_pixels
from camera_models.exposure import manual_exposure
from camera_models.rectification import opencv_distortion
from pipeline.angles import Intrinsics
from pipeline.calibration import Calibration
from pipeline.detect import ESTIMATORS, TRACKERS
from pipeline.evaluate import evaluate_detection
from pipeline.mask_measures import marker_mask_measures
from pipeline.thesis_pose import QUEST_WEIGHTS
from pipeline.thesis_tracker import ThesisTrackerSettings, processed_hsv
from scenes.background import render_background
from scenes.radiance import SpectralRadiance
from scenes.render import render, with_emission
from scenes.render_cache import RenderCache
from scenes.scenario import RenderSettings, Scenario
from studies.engine.frame_task import FrameTask

__all__ = [
    "FRAME_VERSION",
    "NOISE_SEED_FIELDS",
    "ROW_FIELDS",
    "SCORING_FIELDS",
    "CapturedFrame",
    "aligned_radiance",
    "camera_with_overrides",
    "capture_frame",
    "detect_options",
    "frame_inputs",
    "frame_scenario",
    "marker_colours",
    "noise_seed",
    "other_beacons",
    "render_batch_key",
    "simulate_frame",
    "target_crop_png",
]

FRAME_VERSION = 10
"""Bump when a change alters the rows a task produces (invalidates stored results).
3: rows carry the detector's failure code and the true side's blob count.
4: study tasks are whole frames by default (``full_frame``); rows carry ``frame`` (full or crop)
and ``blobs`` (every blob the tracker found); ``align_px`` is ignored on whole frames, and an aligned
crop's unit render is padded with it (it was not: the lens saw the render shifted by the padding).
5: the sensor's noise from the Dr.Jit kernels and the ISP on 16-bit values (issue 24: new random
streams, the same distributions).
6: the lit faces' direct view by primary rays and the room background once per band
(:mod:`scenes.direct_view`, ``RenderSettings.direct``/``background``); the best tracker's
noise-aware threshold (issue 24).
7: the 16-bit ISP re-encodes values next to a code step from their exact linear value (its
rounding had moved dark codes up more often than down: +1.6 % false blobs on a C270 dark frame),
and the sensor's noise from a seed per frame (:func:`noise_seed`), not per seed index (issue 24).
8: PnP falls back to EPnP where OpenCV's SQPnP refuses a distant target (:mod:`pipeline.pnp`; V2
beyond ~19 m, V1 beyond ~12 m had failed as "no fit"); scenarios may carry data-file overrides
(``Scenario.data``) and cameras the ISP's white point and borrowed sensitivities; the study's
tracker counts every colour's blobs (``side_blobs`` of a side after the first with exactly 5 had been
0), its answer unchanged (issue 25).
9: the study's tracker's rows carry its near-miss measures of the side's colour at the true markers
(``side_box_distance``, ``side_in_box_fraction``, ``side_closed_height_px``, ``survivor_height_px``,
``side_markers_merged``, ``side_markers_lost``: :mod:`pipeline.mask_measures`; issue 25).
10: the best tracker's noise σ is the median of small tiles' spreads, not the whole image's (a lit
room's brightness variation had put its threshold above full scale: no blob in any lit-room Spedal
920 frame; issue 24)."""


ROW_FIELDS = frozenset(
    {"seed", "frame", "nominal_range_m", "nominal_yaw_deg", "exposure_s", "analog_gain", "iso", "tracker",
     "thresholds", "estimator", "detected", "side_detected", "side_correct", "numbering_correct", "side_blobs",
     "blobs", "reason", "failure", "frame_s"}
)  # fmt: skip
"""Fields every frame's rows carry that a task's ``tags`` must not shadow (a tag ``frame`` had replaced
the row's ``frame``, full or crop, and the other way round)."""


def frame_scenario(task: FrameTask | dict) -> Scenario:
    """The :class:`Scenario` of a task (validates it)."""
    task = FrameTask.coerce(task)
    return Scenario(**task.scenario, render=RenderSettings(**(task.render or {})))


@dataclass(frozen=True)
class CapturedFrame:
    """What the camera saved for a frame task, with what produced it.

    Attributes
    ----------
    scenario, camera
        The task's scenario and camera model.
    capture
        The capture (raw mosaic, exposure, saved JPEG; crop origin ``x0``, ``y0``).
    image_bgr
        The saved JPEG decoded (uint8 BGR): the crop, or the full frame for ``full_frame`` tasks.
    """

    scenario: Scenario
    camera: Camera
    capture: Capture
    image_bgr: NDArray[np.uint8]

    @property
    def origin(self) -> tuple[int, int]:
        """Full-frame pixel of the image's top-left pixel."""
        return self.capture.x0, self.capture.y0


NOISE_SEED_FIELDS = ("scenario", "render", "exposure", "full_frame", "align_px", "camera_overrides")
"""The task fields that make a frame's mean image, mixed into its noise seed (:func:`noise_seed`)."""


def noise_seed(task: FrameTask | dict) -> int:
    """The sensor-noise seed of a frame task (a 63-bit integer): its ``seed`` hashed (SHA-256)
    with the fields that make the frame (:data:`NOISE_SEED_FIELDS`, and ``others`` where a task has
    further beacons: mixed in only then, so every task without them keeps the seed it had).

    Frames that differ in anything (range, yaw, drive, camera, ...) draw independent noise, so
    outcomes across a study's conditions are independent trials. With the bare ``seed`` (frame
    version 6 and before) every frame of one seed and camera shared its read-noise field, and
    with it most of its false blobs: a webcam's detections at different ranges were correlated.
    The same task gives the same seed; the reference and fast camera paths share it.

    >>> t = {"scenario": {"range_m": 4.0}, "seed": 0}
    >>> noise_seed(t) == noise_seed(dict(t)), noise_seed(t) == noise_seed({**t, "seed": 1})
    (True, False)
    """
    plain = task.to_dict() if isinstance(task, FrameTask) else task
    what = [int(plain["seed"]), {k: plain.get(k) for k in NOISE_SEED_FIELDS}]
    if plain.get("others"):
        what.append(plain["others"])
    digest = hashlib.sha256(json.dumps(what, sort_keys=True, default=repr).encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def capture_frame(task: FrameTask | dict) -> CapturedFrame:
    """Render (or reuse the render of) a frame task and capture it with its camera."""
    task = FrameTask.coerce(task)
    scenario, camera, radiance, background = frame_inputs(task)
    others = other_beacons(task, scenario)
    settings = task.exposure or {}
    exposure = None
    if settings.get("iso") is not None or settings.get("exposure_s") is not None:
        exposure = manual_exposure(camera, settings.get("exposure_s"), settings.get("iso"))
    cap = capture(
        radiance,
        camera,
        noise_seed(task),
        background,
        exposure,
        f_number=settings.get("f_number"),
        full=task.is_full_frame,
        noise=task.with_noise,
        reference=bool(task.reference_camera),
        view=scenario.view_rotation(),
        others=others,
    )
    image_bgr = cv2.imdecode(np.frombuffer(cap.image.encoded, np.uint8), cv2.IMREAD_COLOR)  # what was saved
    return CapturedFrame(scenario, camera, cap, image_bgr)


SCORING_FIELDS = ("trackers", "estimators", "thesis_hsv_variants", "thesis_morphology", "tags", "quest_weights",
                  "rectification")  # fmt: skip
"""Task fields that change how a frame is scored, not the frame: tasks that differ only in these
share one capture in a worker (:func:`simulate_frame`)."""


@dataclass
class _ScoredFrame:
    """One captured frame with what its tasks share: the measures that do not depend on a detector,
    and the study's tracker's results per setting (filled as tasks ask for them)."""

    frame: CapturedFrame
    truth_uv: NDArray[np.float64]
    saturation: list[dict]
    colours: list[dict]
    processed: dict  # the study's tracker's processed image per resize
    near: dict  # (tracker, settings) → near-miss measures
    tracked: dict  # (tracker, settings, rectification) → track cache of detect()


_last_frame: dict[str, _ScoredFrame] = {}  # this process's last frame, by its task's frame fields


def _scored_frame(task: FrameTask) -> _ScoredFrame:
    """The frame of ``task`` (:func:`capture_frame`) with its detector-free measures: the last one
    this process made when only :data:`SCORING_FIELDS` differ (a weight experiment's six detector
    variants of one frame follow one another in a render batch), else a new one."""
    key = json.dumps({k: v for k, v in task.to_dict().items() if k not in SCORING_FIELDS}, sort_keys=True)
    if key not in _last_frame:
        _last_frame.clear()  # one frame held at a time
        frame = capture_frame(task)
        truth_uv = marker_pixels(frame.camera, frame.scenario)
        saturation = marker_core_saturation(frame.capture, frame.camera, frame.scenario)
        colours = marker_colours(frame.image_bgr, truth_uv, saturation, frame.origin)
        _last_frame[key] = _ScoredFrame(frame, truth_uv, saturation, colours, {}, {}, {})
    return _last_frame[key]


def simulate_frame(task: FrameTask | dict) -> list[dict]:
    """Simulate one frame task (see module docstring) and score every detector on it.

    Tasks that differ only in how the frame is scored (:data:`SCORING_FIELDS`) and follow one
    another in a worker share the capture and the study's tracker's results (the same rows)."""
    t0 = time.perf_counter()
    task = FrameTask.coerce(task)
    clash = sorted(set(task.tags or {}) & ROW_FIELDS)
    if clash:
        raise ValueError(f"tags.{clash[0]}: a row field of every frame; expected another tag name")
    shared = _scored_frame(task)
    frame = shared.frame
    scenario, camera, cap, image_bgr = frame.scenario, frame.camera, frame.capture, frame.image_bgr
    truth_uv, saturation, colours = shared.truth_uv, shared.saturation, shared.colours
    truth = {
        "markers_px": truth_uv.tolist(),
        "range_m": scenario.range_m,
        "yaw_deg": scenario.yaw_deg,
        "side": scenario.side,
    }
    base = {
        **{k: v for k, v in task.scenario.items()},
        **(task.tags or {}),
        **{f"camera.{path}": value for path, value in (task.camera_overrides or {}).items()},
        "seed": task.seed,
        "frame": "full" if task.is_full_frame else "crop",
        "nominal_range_m": (task.nominal or {}).get("range_m", scenario.range_m),
        "nominal_yaw_deg": (task.nominal or {}).get("yaw_deg", scenario.yaw_deg),
        "exposure_s": cap.exposure.exposure_s,
        "analog_gain": cap.exposure.analog_gain,
        "iso": cap.exposure.iso,
        "frame_saturated_fraction": cap.saturated_fraction,
        "core_saturated_fraction_mean": float(np.nanmean([m["saturated_fraction"] for m in saturation])),
        "core_saturated_fraction_max": float(np.nanmax([m["saturated_fraction"] for m in saturation])),
        "marker_spacing_px": _min_spacing(truth_uv),
        "core_diameter_px": float(2 * np.mean([m["core_radius_px"] for m in saturation])),
        "worker_peak_rss_MiB": _peak_rss_mib(),
        **{f"marker{i + 1}_{k}": v for i, c in enumerate(colours) for k, v in c.items()},
    }
    intrinsics = Intrinsics.from_geometry(camera.geometry)
    options = detect_options(task, camera)
    rows = []
    radii = [m["core_radius_px"] for m in saturation]
    rectification = json.dumps(task.rectification, sort_keys=True)
    for tracker, label, settings in _detectors(task):
        if (tracker, repr(settings)) not in shared.near:
            shared.near[tracker, repr(settings)] = _mask_measures(
                tracker, image_bgr, intrinsics, truth_uv, radii, scenario.side, settings, cap, shared.processed
            )
        near = shared.near[tracker, repr(settings)]
        # the tracker runs once per setting and rectification; each estimator reuses its result
        tracked = shared.tracked.setdefault((tracker, repr(settings), rectification), {})
        for estimator in tuple(ESTIMATORS) if task.estimators is None else task.estimators:
            ev = evaluate_detection(
                image_bgr,
                intrinsics,
                truth,
                tracker=tracker,
                estimator=estimator,
                beacon=scenario.beacon,
                crop_origin_px=(cap.x0, cap.y0),
                thesis_settings=settings,
                track_cache=tracked,
                **options,
            )
            rows.append(
                {
                    **base,
                    "tracker": tracker,
                    "thresholds": label,
                    "estimator": estimator,
                    "detected": bool(ev["detected"]),
                    "side_detected": ev.get("side"),
                    "side_correct": bool(ev.get("side_correct")),
                    "numbering_correct": bool(ev.get("numbering_correct")),
                    "centroid_rms_px": _num(ev.get("centroid_rms_px")),
                    "range_est_m": _num(ev.get("range_m")),
                    "range_err_m": _num(ev.get("range_error_m")),
                    "yaw_est_deg": _num(ev.get("yaw_deg")),
                    "yaw_err_deg": _num(ev.get("yaw_error_deg")),
                    "reason": ev.get("reason") or "",
                    "failure": ev.get("failure") or "",
                    "side_blobs": ev.get("side_blobs"),
                    "blobs": len(tracked[tracker].blobs) if tracker in tracked else None,
                    **near,
                }
            )
    seconds = time.perf_counter() - t0
    return [{**row, "frame_s": seconds} for row in rows]


def _mask_measures(tracker: str, image_bgr, intrinsics, uv, radii, side: str, settings, cap, processed: dict) -> dict:
    """The study's tracker's near-miss measures of the side's colour at the true markers
    (:mod:`pipeline.mask_measures`); empty for another tracker. ``processed`` memoises the processed
    image per resize setting."""
    if tracker != "thesis":
        return {}
    s = settings or ThesisTrackerSettings()
    if s.resize not in processed:
        processed[s.resize] = processed_hsv(image_bgr, intrinsics, s)
    m = marker_mask_measures(
        image_bgr,
        intrinsics,
        uv,
        radii,
        side,
        settings=s,
        crop_origin_px=(cap.x0, cap.y0),
        processed=processed[s.resize],
    )
    return {
        "side_box_distance": m.box_distance,
        "side_in_box_fraction": m.in_box_fraction,
        "side_closed_height_px": m.closed_height_px,
        "survivor_height_px": m.survivor_height_px,
        "side_markers_merged": m.merged_markers,
        "side_markers_lost": m.lost_markers,
    }


def detect_options(task: FrameTask, camera: Camera) -> dict:
    """Detector options a task asks for: the study's weight experiment (``quest_weights``:
    ``tuned`` or ``equal``) and rectification (``rectification``: ``{"alpha": 0 or 1}``, with
    the lens's own distortion in OpenCV's model as the calibration: an ideal calibration)."""
    options = {}
    if task.quest_weights:
        if task.quest_weights not in QUEST_WEIGHTS:
            raise ValueError(f"quest_weights: expected one of {', '.join(QUEST_WEIGHTS)}, got {task.quest_weights!r}")
        options["quest_weights"] = QUEST_WEIGHTS[task.quest_weights]
    if task.rectification is not None:
        fit = opencv_distortion(camera)
        options["calibration"] = Calibration(
            fit.camera_matrix, fit.dist_coeffs, fit.width_px, fit.height_px, fit.max_error_px, 0
        )
        options["alpha"] = float(task.rectification["alpha"])
    return options


def _detectors(task: FrameTask):
    """(tracker, threshold label, thesis settings) to run: the study's tracker once per
    HSV threshold variant in ``task["thesis_hsv_variants"]`` (label → per-colour boxes,
    None for the study's own numbers), the best tracker once."""
    variants = task.thesis_hsv_variants or {"study": None}
    for tracker in tuple(TRACKERS) if task.trackers is None else task.trackers:
        if tracker != "thesis":
            yield tracker, "", None
            continue
        for label, boxes in variants.items():
            settings = None
            if boxes:
                ranges = {
                    c: [tuple(tuple(int(x) for x in corner) for corner in box) for box in b] for c, b in boxes.items()
                }
                settings = ThesisTrackerSettings(hsv_ranges=ranges)
            if task.thesis_morphology:
                settings = replace(settings or ThesisTrackerSettings(), **task.thesis_morphology)
            yield tracker, label, settings


def marker_colours(image_bgr, uv, saturation: list[dict], origin: tuple[int, int]) -> list[dict]:
    """Mean colour of each marker's core in the saved image (true positions, so it does
    not depend on any detector): linear-RGB chromaticity (r, g) and mean sRGB (0-1)."""
    h, w = image_bgr.shape[:2]
    out = []
    for (u, v), sat in zip(uv, saturation, strict=True):
        r = max(sat["core_radius_px"], 1.0)
        x, y = u - origin[0], v - origin[1]
        c0, c1 = max(math.floor(x - r), 0), min(math.ceil(x + r) + 1, w)
        r0, r1 = max(math.floor(y - r), 0), min(math.ceil(y + r) + 1, h)
        if c1 <= c0 or r1 <= r0:
            out.append({"r_chroma": math.nan, "g_chroma": math.nan, "R": math.nan, "G": math.nan, "B": math.nan})
            continue
        yy, xx = np.mgrid[r0:r1, c0:c1]
        core = (xx - x) ** 2 + (yy - y) ** 2 <= r * r
        srgb = image_bgr[r0:r1, c0:c1][core][:, ::-1].astype(np.float64) / 255.0
        lin = colour.cctf_decoding(srgb, function="sRGB").mean(axis=0)
        total = lin.sum()
        mean_srgb = colour.cctf_encoding(lin, function="sRGB")
        out.append(
            {
                "r_chroma": float(lin[0] / total) if total > 0 else math.nan,
                "g_chroma": float(lin[1] / total) if total > 0 else math.nan,
                "R": float(mean_srgb[0]),
                "G": float(mean_srgb[1]),
                "B": float(mean_srgb[2]),
            }
        )
    return out


def _peak_rss_mib() -> float:
    """Peak resident memory of this process so far, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _min_spacing(uv) -> float:
    uv = np.asarray(uv, float)
    d = np.hypot(*(uv[:, None, :] - uv[None, :, :]).transpose(2, 0, 1))
    d[np.eye(len(uv), dtype=bool)] = np.inf
    return float(d.min())


def _num(x) -> float:
    return float(x) if x is not None and np.isfinite(x) else math.nan


def frame_inputs(task: FrameTask | dict):
    """What a frame task's capture needs: (scenario, camera, render of the crop,
    low-resolution full-frame background or None).

    The background is rendered only where it is used: for automatic exposure's metering
    and for full-frame captures. Renders of the last few geometries are kept in memory
    at unit LED scale, so the frames of one render (drives, seeds) rescale them instead
    of reading the cache again — light transport is linear, the bytes are the same.
    """
    task = FrameTask.coerce(task)
    scenario = frame_scenario(task)
    camera = camera_with_overrides(load_camera(scenario.camera), task.camera_overrides)
    needs_background = camera.exposure.mode == "auto" or task.is_full_frame
    key = json.dumps({**scenario.without_gains().to_dict(), "background": needs_background}, sort_keys=True)
    held = _RENDERS.pop(key, None)
    if held is None:
        cache = RenderCache()
        held = (render(scenario, cache), render_background(scenario, cache) if needs_background else None)
    _RENDERS[key] = held  # most recently used last
    while len(_RENDERS) > 4:
        _RENDERS.pop(next(iter(_RENDERS)))
    radiance, background = (None if r is None else with_emission(r, scenario) for r in held)
    if task.align_px and not task.is_full_frame:  # a whole frame is aligned by itself
        radiance = aligned_radiance(radiance, int(task.align_px))
    return scenario, camera, radiance, background


def other_beacons(task: FrameTask | dict, scenario: Scenario) -> tuple[tuple[SpectralRadiance, np.ndarray | None], ...]:
    """The renders of a task's further beacons (``others``) with each one's view rotation: each a
    Scenario of the task's camera, environment and render settings, rendered (or read from the
    cache) with its own drive. Light transport is linear, so a frame with several
    beacons is the sum of their renders; each render's own room adds the light its beacon scatters
    off the walls near it. Only in whole frames, and only where nothing but the LEDs lights the room
    (a second render's room light would count the room twice): one-line errors otherwise."""
    task = FrameTask.coerce(task)
    if not task.others:
        return ()
    if not task.is_full_frame:
        raise ValueError("task.others: further beacons need a whole frame (full_frame: true)")
    if scenario.env.has_ambient:
        raise ValueError(
            f"task.others: further beacons only where the LEDs alone light the room, not {scenario.environment!r}"
        )
    out = []
    for i, fields in enumerate(task.others):
        for name in ("camera", "environment"):
            if fields.get(name, getattr(scenario, name)) != getattr(scenario, name):
                raise ValueError(f"task.others[{i}].{name}: expected the frame's own ({getattr(scenario, name)!r})")
        other = Scenario(**{**fields, "camera": scenario.camera, "environment": scenario.environment},
                         render=scenario.render)  # fmt: skip
        out.append((render(other, RenderCache()), other.view_rotation()))
    return tuple(out)


def camera_with_overrides(camera: Camera, overrides: dict | None) -> Camera:
    """``camera`` with a task's ``camera_overrides`` applied (the same object when there are none).

    The geometry cannot be overridden: the render is made on the camera's own pixel grid."""
    if not overrides:
        return camera
    for path in overrides:
        if str(path).split(".")[0] == "geometry":
            raise ValueError(f"camera override {path!r}: the geometry is fixed by the camera name (the render uses it)")
    return with_overrides(camera, overrides)


def aligned_radiance(radiance: SpectralRadiance, align: int) -> SpectralRadiance:
    """``radiance`` padded with zero radiance so the crop's origin and size are multiples of ``align``
    (within the frame). The dark surroundings return ~1e-6 of the LED radiance, so the
    padded crop's pixels equal the full frame's apart from the noise realisation. A component's
    unit render (``unit_image``, which the lens stage uses instead of the scaled image) is padded
    alike; before frame version 4 it was not, and aligned crops showed the unpadded render
    shifted by the padding."""
    g = radiance.grid
    x0, y0 = (g.x0 // align) * align, (g.y0 // align) * align
    x1 = min(g.frame_width_px, -(-(g.x0 + g.width) // align) * align)
    y1 = min(g.frame_height_px, -(-(g.y0 + g.height) // align) * align)
    if (x0, y0, x1 - x0, y1 - y0) == (g.x0, g.y0, g.width, g.height):
        return radiance
    s = g.oversampling
    pad = ((s * (g.y0 - y0), s * (y1 - g.y0 - g.height)), (s * (g.x0 - x0), s * (x1 - g.x0 - g.width)))
    comps = tuple(
        replace(
            c,
            image_W_m2_sr=np.pad(c.image_W_m2_sr, pad),
            unit_image=None if c.unit_image is None else np.pad(c.unit_image, pad),  # the lens works on this one
        )
        for c in radiance.components
    )
    grid = replace(g, x0=x0, y0=y0, width=x1 - x0, height=y1 - y0)
    return SpectralRadiance(grid, comps, radiance.scenario, radiance.variant, radiance.from_cache)


_RENDERS: dict[str, tuple] = {}
"""Renders (crop, background) of the most recently used geometries in this process."""


def render_batch_key(task: FrameTask | dict) -> str:
    """Label of the frames that share a task's render (everything but drive and seed);
    the runner sends them to one worker together (:func:`studies.engine.runner.run_tasks`)."""
    task = FrameTask.coerce(task)
    scenario = {k: v for k, v in task.scenario.items() if k != "led_current_mA"}
    return json.dumps([scenario, task.render or {}, task.is_full_frame], sort_keys=True)


def target_crop_png(task: FrameTask | dict, half_width_m: float = 0.12, size_px: int = 200) -> bytes:
    """The saved image around the target (±``half_width_m`` at the marker plane), scaled
    to ``size_px`` with nearest-neighbour so camera pixels stay visible; PNG bytes."""
    frame = capture_frame(task)
    image, camera, scenario = frame.image_bgr, frame.camera, frame.scenario
    u, v = marker_pixels(camera, scenario)[0] - np.array(frame.origin)
    half = max(2, round(half_width_m * camera.geometry.focal_length_px / scenario.range_m))
    padded = cv2.copyMakeBorder(image, half, half, half, half, cv2.BORDER_CONSTANT, value=(0, 0, 0))
    cu, cv_ = round(u) + half, round(v) + half
    crop = padded[cv_ - half : cv_ + half, cu - half : cu + half]
    crop = cv2.resize(crop, (size_px, size_px), interpolation=cv2.INTER_NEAREST)
    ok, png = cv2.imencode(".png", crop)
    if not ok:
        raise RuntimeError("mosaic: PNG encoding failed")
    return png.tobytes()
