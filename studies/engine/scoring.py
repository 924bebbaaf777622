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

RANGE_TOLERANCE = 0.10
"""Largest relative range error of a usable pose (10 %)."""
YAW_TOLERANCE_DEG = 5.0
"""Largest yaw error of a usable pose, degrees."""

CAUSES = ("resolution / merging", "signal-to-noise", "colour", "saturation", "false blobs", "pose")
"""Failure causes named by :func:`failure_cause`."""

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
    """Why a frame failed, from what the detector and the camera report.

    * colour: a side was found but the wrong one (or markers of a wrong colour);
    * false blobs: the right side's colour, but not its five markers correctly numbered, with
      more than five blobs of that colour to choose from (``side_blobs``): the tracker took
      blobs of sensor noise or clutter for markers (a whole frame at high gain has hundreds);
    * saturation: markers not recognised and their cores mostly clipped (> 50 %);
    * resolution / merging: markers not recognised and closer than ~2 blob diameters, or
      the detector reports too few blobs (markers lost or merged,
      :attr:`pipeline.failures.Failure.TOO_FEW_BLOBS`);
    * signal-to-noise: markers not recognised, not clipped and well apart (too faint);
    * pose: detected and numbered but range off by > 10 % or yaw by > 5° (or misnumbered
      with no extra blob to blame).
    """
    if row.get("detected"):
        if not row.get("side_correct"):
            return "colour"
        extra = (row.get("side_blobs") or 0) > 5
        return "false blobs" if extra and not row.get("numbering_correct") else "pose"
    if row.get("core_saturated_fraction_mean", 0.0) > 0.5:
        return "saturation"
    merged = row.get("failure") == Failure.TOO_FEW_BLOBS
    if merged or row.get("marker_spacing_px", math.inf) < 2.0 * row.get("core_diameter_px", 0.0):
        return "resolution / merging"
    return "signal-to-noise"
