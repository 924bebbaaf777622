"""What counts as success: the one definition every study, experiment and report uses.

Two levels, each a pure function of a result row (:mod:`studies.engine.frame`) and a
column-wise twin for whole tables:

* **detection success** (:func:`detection_success`): the tracker returned the right side
  with all five markers, each correctly numbered;
* **pose success** (:func:`pose_success`): a detection success whose pose is usable:
  range within :data:`RANGE_TOLERANCE` of the true range and yaw within
  :data:`YAW_TOLERANCE_DEG`. The maximum range is where this falls below 0.95.

:func:`failure_cause` names why a frame is not a pose success.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pipeline.failures import Failure

__all__ = [
    "CAUSES",
    "CLIPPED_CORES",
    "RANGE_TOLERANCE",
    "YAW_TOLERANCE_DEG",
    "detection_success",
    "detection_successes",
    "failure_cause",
    "pose_success",
]

RANGE_TOLERANCE = 0.10
"""Largest relative range error of a usable pose (10 %)."""
YAW_TOLERANCE_DEG = 5.0
"""Largest yaw error of a usable pose, degrees."""

CAUSES = (
    "resolution / merging",
    "signal-to-noise",
    "colour",
    "colour box",
    "colour box (cores clipped)",
    "saturation",
    "false blobs",
    "numbering",
    "pose",
    "image",
)
"""Failure causes named by :func:`failure_cause`."""

CLIPPED_CORES = 0.5
"""Mean fraction of a marker core's pixels at the clip level above which a frame's cores count
as clipped."""

_DETECTION_COLUMNS = ("detected", "side_correct", "numbering_correct")


def detection_success(row: dict) -> bool:
    """A frame counts as a correct detection when the tracker returns the right side
    with all five markers and every marker correctly numbered."""
    return all(bool(row.get(c)) for c in _DETECTION_COLUMNS)


def detection_successes(frame) -> NDArray[np.bool_]:
    """:func:`detection_success` of every row of a results table (column-wise)."""
    return np.logical_and.reduce([frame[c].astype(bool) for c in _DETECTION_COLUMNS])


def pose_success(row: dict) -> bool:
    """A detection success whose range is within 10 % and yaw within 5° of the truth."""
    if not detection_success(row):
        return False
    r, y = row.get("range_err_m"), row.get("yaw_err_deg")
    rng = row.get("range_m", 1.0)
    return bool(np.isfinite(r) and abs(r) <= RANGE_TOLERANCE * rng and np.isfinite(y) and abs(y) <= YAW_TOLERANCE_DEG)


def failure_cause(row: dict) -> str:
    """Why a frame failed: from the detector's failure code (``failure``, a
    :class:`pipeline.failures.Failure` value) first, then from what the camera reports.

    * colour: a side was found but the wrong one, or five markers of an unclear colour
      (``colour-unclear``);
    * colour box: the markers' pixels fell outside the tracker's colour box of the true side,
      so fewer than five blobs of its colour were found (``no-side-colour``;
      ``no-colour-with-five`` or ``no-fit`` with fewer than five blobs of the side's colour and
      markers well apart); "colour box (cores clipped)" when the marker cores are mostly clipped
      (> :data:`CLIPPED_CORES`), the usual reason a core leaves its box;
    * false blobs: more than five blobs of the true side's colour (``side_blobs``) and no five
      of them taken correctly (``no-colour-with-five``, ``no-fit``, or misnumbered markers):
      the tracker took blobs of sensor noise or clutter for markers;
    * resolution / merging: too few blobs of the side's colour (``too-few-blobs``), or no
      five of them fit with markers closer than ~2 core diameters;
    * signal-to-noise: nothing above the background (``no-blobs``), or no code and markers not
      clipped and well apart (too faint);
    * saturation: no code, markers not recognised and their cores mostly clipped;
    * numbering: five blobs the study's numbering rule cannot order (``numbering``);
    * pose: detected and numbered but range off by > 10 % or yaw by > 5° (or misnumbered
      with no extra blob to blame; ``range``, ``attitude``, ``pose``);
    * image: the image could not be used (``image``).
    """
    side_blobs = row.get("side_blobs")
    side_blobs = side_blobs if isinstance(side_blobs, int | float) and math.isfinite(side_blobs) else 0
    extra = side_blobs > 5
    if row.get("detected"):
        if not row.get("side_correct"):
            return "colour"
        return "false blobs" if extra and not row.get("numbering_correct") else "pose"
    clipped = (row.get("core_saturated_fraction_mean") or 0.0) > CLIPPED_CORES
    spacing = row.get("marker_spacing_px")
    spacing = spacing if isinstance(spacing, int | float) and math.isfinite(spacing) else math.inf
    merged = spacing < 2.0 * (row.get("core_diameter_px") or 0.0)
    box = "colour box (cores clipped)" if clipped else "colour box"
    code = row.get("failure") or ""
    if code == Failure.TOO_FEW_BLOBS:
        return "resolution / merging"
    if code == Failure.NO_BLOBS:
        return "signal-to-noise"
    if code == Failure.NO_SIDE_COLOUR:
        return box
    if code == Failure.COLOUR_UNCLEAR:
        return "colour"
    if code in (Failure.NO_COLOUR_WITH_FIVE, Failure.NO_FIT):
        if extra:
            return "false blobs"
        if merged:
            return "resolution / merging"
        return box if side_blobs < 5 else "pose"  # five of the side's colour that do not fit its shape
    if code == Failure.NUMBERING:
        return "numbering"
    if code in (Failure.RANGE, Failure.ATTITUDE, Failure.POSE):
        return "pose"
    if code == Failure.IMAGE:
        return "image"
    if clipped:
        return "saturation"
    if merged:
        return "resolution / merging"
    return "signal-to-noise"
