"""One image in, one answer out: tracker → angles → pose → global frame.

:func:`detect` runs either tracker (``thesis``: :mod:`pipeline.thesis_tracker`; ``best``:
:mod:`pipeline.tracker`) and either estimator (``thesis``: :mod:`pipeline.thesis_pose`;
``best``: :func:`pipeline.pose.pnp_pose`) on a BGR image, optionally undistorted with a
calibration first, and returns a :class:`Detection` whose :meth:`Detection.to_dict` is
the CLI's JSON. It never raises on image content: an image it cannot use gives "no
target" with a reason and a failure code. Bad arguments (tracker name, alpha, resize,
calibration size) raise ``ValueError`` naming the field.

``resize`` is the tracker's processing scale: the study's tracker resizes inside, as the
study did (50 % for the T6); ours runs on a resized copy (area averaging) with the
intrinsics scaled to match. Either way the markers come back in the pixels of the image
as given, and the angles and the pose use the full-resolution intrinsics.

:data:`REAL_PHOTO_FALSE_POSITIVES` records how often each tracker reports a target in
real photographs that show none (tests/pipeline/test_real_photos.py measures it).

Pixel coordinates reported are full-frame, full-resolution pixels of the image as given
(distorted, when a calibration was used: the undistorted centroids are mapped back).
Angles are the tracker's: the study's formula for the study's tracker, the pinhole
(undistorted) angles for the better tracker.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics, full_pixel, pinhole_angles, study_angles, study_unit_vectors
from pipeline.calibration import Calibration, distort_points, new_camera_matrix, undistort
from pipeline.failures import Failure
from pipeline.frames import Pose, global_pose
from pipeline.image_io import as_bgr
from pipeline.markers import TrackResult
from pipeline.messages import LEDPoints
from pipeline.pose import pnp_pose
from pipeline.thesis_pose import STUDY_WEIGHTS, thesis_pose_from_vectors
from pipeline.thesis_tracker import ThesisTrackerSettings, thesis_track
from pipeline.tracker import TrackerSettings, track
from scenes.beacon import BeaconDesign, beacon_design
from scenes.led import SIDE_COLOURS

__all__ = [
    "ESTIMATORS",
    "REAL_PHOTO_FALSE_POSITIVES",
    "TRACKERS",
    "Detection",
    "FalsePositiveCheck",
    "check_resize",
    "detect",
]


@dataclass
class Detection:
    """Everything :func:`detect` found.

    Attributes
    ----------
    side
        Side colour, or None.
    reason
        Why there is no target or no pose; None when all went well.
    markers
        Markers 1..5: id, u, v (px), azimuth_rad, elevation_rad.
    pose
        Camera pose relative to the target, or None.
    global_pose
        Pose in the beacon frame (dict), or None.
    tracker, estimator
        Which were used.
    notes
        Extra findings (ignored blobs, colour doubts, Newton failures).
    led_points
        The study's LEDPoints message when the side and angles are known.
    sigma
        1-σ uncertainties of the best estimator (range_m, attitude_deg, lateral_m), or {}.
    failure
        The code of ``reason`` when there is no complete answer (:class:`pipeline.failures.Failure`), else None.
    blob_counts
        Blobs the tracker found per side colour.
    """

    side: str | None
    reason: str | None
    markers: list[dict] = field(default_factory=list)
    pose: Pose | None = None
    global_pose: dict | None = None
    tracker: str = "best"
    estimator: str = "best"
    notes: list[str] = field(default_factory=list)
    led_points: LEDPoints | None = None
    sigma: dict = field(default_factory=dict)
    failure: Failure | None = None
    blob_counts: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The CLI's JSON fields."""
        out = {
            "side": self.side,
            "reason": self.reason,
            "failure": None if self.failure is None else str(self.failure),
            "tracker": self.tracker,
            "estimator": self.estimator,
        }
        out["markers"] = self.markers
        if self.pose is not None:
            yaw, pitch, roll = (math.degrees(a) for a in self.pose.attitude_rad())
            out |= {
                "range_m": self.pose.range_m,
                "quaternion_wxyz": list(self.pose.quaternion_wxyz()),
                "yaw_deg": yaw,
                "pitch_deg": pitch,
                "roll_deg": roll,
            }
        else:
            out |= dict.fromkeys(("range_m", "quaternion_wxyz", "yaw_deg", "pitch_deg", "roll_deg"))
        out["global"] = self.global_pose
        out["sigma"] = self.sigma
        out["notes"] = self.notes
        out["blob_counts"] = self.blob_counts
        return out


def _track_thesis(bgr, intrinsics: Intrinsics, origin, options: dict) -> TrackResult:
    settings = options.get("thesis_settings")
    if options.get("resize") is not None:  # the study's own resize step, at the scale asked for
        settings = replace(settings or ThesisTrackerSettings(), resize=options["resize"])
    return thesis_track(bgr, intrinsics, settings, origin)


def _track_best(bgr, intrinsics: Intrinsics, origin, options: dict) -> TrackResult:
    settings = options.get("tracker_settings") or TrackerSettings()
    if settings.beacon != options["beacon"]:
        settings = TrackerSettings(**{**settings.__dict__, "beacon": options["beacon"]})
    scale = options.get("resize")
    if scale is None or scale == 1:
        return track(bgr, intrinsics, settings, origin)
    # a resized copy (area averaging keeps each blob's flux) and the frame's intrinsics resized to match;
    # pixel centres aligned, so the crop origin u0 lands at u0·s
    small = cv2.resize(bgr, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    tr = track(small, intrinsics.resized(scale), settings, (origin[0] * scale, origin[1] * scale))
    if tr.uv is not None:
        tr.uv = np.stack(full_pixel(tr.uv[:, 0], tr.uv[:, 1], scale), axis=1)
    for k, b in enumerate(tr.blobs):
        u, v = full_pixel(b.u, b.v, scale)
        tr.blobs[k] = replace(b, u=float(u), v=float(v))
    tr.notes = [*tr.notes, f"tracked on a {100 * scale:g} % copy of the image"]
    return tr


TRACKERS: dict[str, Callable[..., TrackResult]] = {"thesis": _track_thesis, "best": _track_best}
"""Tracker name → function (BGR image, full-frame intrinsics, crop origin, options) → :class:`TrackResult`:
``thesis`` is the study's (:mod:`pipeline.thesis_tracker`), ``best`` ours (:mod:`pipeline.tracker`)."""


_TRACKER_NAMES = {"thesis": "the study's (thesis)", "best": "the best"}


@dataclass(frozen=True)
class FalsePositiveCheck:
    """Which of a set of real photographs without a beacon a tracker reports a target in.

    Attributes
    ----------
    photos
        The photographs tried: names of ``skimage.data`` functions (``motorcycle_left`` and
        ``motorcycle_right`` are the two views of ``stereo_motorcycle``).
    false_positives
        Tracker name → the photographs in which it reported five numbered markers.
    setup
        How they were run (intrinsics, processing scale).
    """

    photos: tuple[str, ...]
    false_positives: dict[str, tuple[str, ...]]
    setup: str

    def rate(self, tracker: str) -> float:
        """Fraction of the photographs with a false target."""
        return len(self.false_positives.get(tracker, ())) / len(self.photos)

    def note(self, tracker: str) -> str:
        """A one-line caveat for a detection by ``tracker``."""
        fps = self.false_positives.get(tracker, ())
        which = f": {', '.join(fps)}" if fps else ""
        return (
            f"{_TRACKER_NAMES.get(tracker, tracker)} tracker has a false-positive rate on real photos: it reported "
            f"a beacon in {len(fps)} of {len(self.photos)} colour photographs that show none "
            f"({100 * self.rate(tracker):.0f} %; scikit-image's bundled photos{which}); its detections may be false"
        )


REAL_PHOTO_FALSE_POSITIVES = FalsePositiveCheck(
    photos=(
        "astronaut", "chelsea", "coffee", "rocket", "hubble_deep_field", "retina", "immunohistochemistry",
        "motorcycle_left", "motorcycle_right",
    ),
    false_positives={"thesis": ("coffee", "rocket"), "best": ()},
    setup="each at full size with fx = fy = its larger side in px and the principal point at its centre",
)  # fmt: skip
"""Measured by tests/pipeline/test_real_photos.py, which fails when the measurement moves away
from these figures. The study's tracker finds five "markers" of one colour in a cup's red
rim (coffee) and in a blue-lit launch scene (rocket); at the study's 50 % resize it finds
a red side in rocket only. Ours reports none with these intrinsics, but with a wide-angle
guess (fx = half the larger side) it fits a yellow target at 0.13 m to five faint galaxies
of ``hubble_deep_field``: its geometric test accepts a reprojection RMS of up to 2 % of the
target's image size, loose for a 460-px target of point-like blobs."""


def _estimate_thesis(tr: TrackResult, intrinsics: Intrinsics, design: BeaconDesign, result: Detection, options) -> None:
    if tr.azimuth_rad is not None:
        s_az, s_el = tr.azimuth_rad, tr.elevation_rad
    else:  # the study's formula on full-resolution, full-frame pixels
        s_az, s_el = study_angles(tr.uv[:, 0], tr.uv[:, 1], (intrinsics.width_px, intrinsics.height_px), intrinsics)
    est = thesis_pose_from_vectors(study_unit_vectors(s_az, s_el), design, weights=options["quest_weights"])
    if not all(est.converged):
        result.notes.append(f"Newton did not converge (triads converged: {list(est.converged)})")
    result.pose = est.pose
    if est.pose is None:
        result.reason, result.failure = est.reason, est.failure


def _estimate_best(tr: TrackResult, intrinsics: Intrinsics, design: BeaconDesign, result: Detection, options) -> None:
    try:
        est = pnp_pose(tr.uv, design, intrinsics, options["sigma_px"])
    except ValueError as exc:
        result.reason, result.failure = str(exc), Failure.POSE
        return
    result.pose = est.pose
    result.sigma = {
        "range_m": est.bound.range_m,
        "attitude_deg": math.degrees(est.bound.attitude_rad),
        "lateral_m": est.bound.lateral_m,
        "reprojection_rms_px": est.reprojection_rms_px,
    }


ESTIMATORS: dict[str, Callable[..., None]] = {"thesis": _estimate_thesis, "best": _estimate_best}
"""Estimator name → function filling a :class:`Detection`'s pose (or its reason) from a
tracker's five numbered markers: ``thesis`` is the study's inverse perspective + QUEST
(:mod:`pipeline.thesis_pose`), ``best`` SQPnP + Levenberg–Marquardt with its covariance
(:func:`pipeline.pose.pnp_pose`)."""


def _check_choice(name: str, value: str, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name}: expected one of {', '.join(allowed)}, got {value!r}")


def check_resize(resize: float | None, size_px: tuple[int, int] | None = None) -> None:
    """Raise ``ValueError`` naming ``resize`` unless it is None or a scale in (0, 1] that,
    given the image's ``size_px`` (width, height), leaves it at least 1 px each way
    (``cv2.resize`` fails on an empty result: ``--resize 1e-300``)."""
    if resize is None:
        return
    ok = isinstance(resize, int | float | np.floating) and not isinstance(resize, bool)
    if not (ok and math.isfinite(resize) and 0 < resize <= 1):
        raise ValueError(f"resize: expected a scale in (0, 1], got {resize!r}")
    if size_px is not None and min(round(size_px[0] * resize), round(size_px[1] * resize)) < 1:
        smallest = 0.5 / min(size_px)
        raise ValueError(
            f"resize: expected a scale that leaves the {size_px[0]}×{size_px[1]} px image at least 1 px "
            f"each way (>= {smallest:.3g}), got {resize!r}"
        )


def detect(
    image,
    intrinsics: Intrinsics,
    *,
    tracker: str = "best",
    estimator: str = "best",
    beacon: str = "v2",
    calibration: Calibration | None = None,
    alpha: float = 0.0,
    crop_origin_px: tuple[int, int] | None = None,
    ring_camera: int | None = None,
    sigma_px: float = 0.3,
    tracker_settings: TrackerSettings | None = None,
    thesis_settings: ThesisTrackerSettings | None = None,
    track_cache: dict | None = None,
    quest_weights: tuple[float, float, float, float] = STUDY_WEIGHTS,
    resize: float | None = None,
) -> Detection:
    """Detect the beacon side in ``image`` and estimate the camera pose.

    Parameters
    ----------
    image
        BGR image (uint8/uint16/float, grey accepted): the camera's full frame, or a crop
        of it whose top-left pixel is ``crop_origin_px``.
    intrinsics
        Nominal pinhole intrinsics of the camera's full frame (frame size, focal lengths
        and principal point, px), e.g. ``Intrinsics.from_geometry(camera_geometry(name))``.
    tracker, estimator
        A name of :data:`TRACKERS` / :data:`ESTIMATORS`: ``thesis`` (the study's) or ``best``.
    beacon
        ``v1`` or ``v2``.
    calibration
        Undistort with this calibration first (its size must be the frame's).
    alpha
        ``getOptimalNewCameraMatrix`` alpha for the undistortion (0 or 1 in the study).
    crop_origin_px
        Full-frame pixel of the image's top-left pixel; None means the image is the full frame.
    ring_camera
        Camera number on the study's 6-camera ring: the global pose is then the robot's;
        None reports the camera's own pose.
    sigma_px
        Centroid noise assumed for the best estimator's covariance, px.
    tracker_settings, thesis_settings
        Tracker parameters (the beacon of ``tracker_settings`` is overridden by ``beacon``).
    track_cache
        A dict shared by calls on the *same image with the same settings* that differ only
        in ``estimator``: the tracker then runs once (it is by far the slower stage).
    quest_weights
        QUEST weights of w2..w5 for the ``thesis`` estimator (default the study's tuned set).
    resize
        The tracker's processing scale in (0, 1] (0.5: the study's T6 images); None: each
        tracker's default (the study's: 0.5 for frames ≥ 3000 px wide, else 1; ours: 1).
        Overrides ``thesis_settings.resize``.
    """
    _check_choice("tracker", tracker, TRACKERS)
    _check_choice("estimator", estimator, ESTIMATORS)
    check_resize(resize)
    design = beacon_design(beacon)
    intr = intrinsics
    result = Detection(None, None, tracker=tracker, estimator=estimator)
    if calibration is not None:
        new_camera_matrix(calibration, alpha)  # validates alpha
        if (calibration.width_px, calibration.height_px) != (intr.width_px, intr.height_px):
            raise ValueError(
                f"calibration: made for {calibration.width_px}×{calibration.height_px} px, "
                f"the frame is {intr.width_px}×{intr.height_px} px"
            )
    bgr, reason = as_bgr(image)
    if bgr is None:
        result.reason, result.failure = reason, Failure.IMAGE
        return result
    h, w = bgr.shape[:2]
    check_resize(resize, (w, h))
    origin, reason = _origin(w, h, intr, crop_origin_px)
    if reason:
        result.reason, result.failure = reason, Failure.IMAGE
        return result
    new_k = None
    if calibration is not None:
        bgr, intr = undistort(bgr, calibration, alpha, origin)
        new_k = intr.matrix()
    options = {
        "beacon": beacon, "tracker_settings": tracker_settings, "thesis_settings": thesis_settings, "resize": resize,
    }  # fmt: skip
    if track_cache is not None and tracker in track_cache:
        tr = track_cache[tracker]
    else:
        tr = TRACKERS[tracker](bgr, intr, origin, options)
    if track_cache is not None:
        track_cache[tracker] = tr
    result.side, result.notes = tr.side, list(tr.notes)
    result.blob_counts = {c: sum(b.colour == c for b in tr.blobs) for c in SIDE_COLOURS}
    result.reason, result.failure = tr.reason, tr.failure
    if not tr.found:
        return result
    az, el = _angles(tr, intr)
    shown = tr.uv if calibration is None else distort_points(tr.uv, calibration, new_k)
    result.markers = [
        {"id": i + 1, "u": float(shown[i, 0]), "v": float(shown[i, 1]), "azimuth_rad": float(az[i]),
         "elevation_rad": float(el[i])}
        for i in range(5)
    ]  # fmt: skip
    if tr.side is not None:
        result.led_points = LEDPoints(ring_camera or 0, tr.side, tuple(az), tuple(el))
    ESTIMATORS[estimator](tr, intr, design, result, {"sigma_px": sigma_px, "quest_weights": quest_weights})
    if result.pose is None:
        return result
    if tr.side is not None:
        g = global_pose(tr.side, result.pose, design.d_t_m, ring_camera)
        result.global_pose = {
            "x_m": g.x_m, "y_m": g.y_m, "z_m": g.z_m,
            "yaw_deg": math.degrees(g.yaw_rad), "pitch_deg": math.degrees(g.pitch_rad),
            "roll_deg": math.degrees(g.roll_rad),
        }  # fmt: skip
    return result


def _origin(w: int, h: int, intrinsics: Intrinsics, crop_origin_px) -> tuple[tuple[int, int], str | None]:
    fw, fh = intrinsics.width_px, intrinsics.height_px
    if crop_origin_px is None:
        if (w, h) != (fw, fh):
            return (0, 0), f"image: {w}×{h} px is not the camera's {fw}×{fh} px frame (give the crop origin for a crop)"
        return (0, 0), None
    u0, v0 = (int(c) for c in crop_origin_px)
    if u0 < 0 or v0 < 0 or u0 + w > fw or v0 + h > fh:
        return (u0, v0), f"image: a {w}×{h} px crop at ({u0}, {v0}) does not fit in the {fw}×{fh} px frame"
    return (u0, v0), None


def _angles(tr: TrackResult, intr: Intrinsics) -> tuple[NDArray, NDArray]:
    if tr.azimuth_rad is not None:
        return tr.azimuth_rad, tr.elevation_rad
    return pinhole_angles(tr.uv[:, 0], tr.uv[:, 1], intr)
