"""Perspective-n-point for a five-marker target: SQPnP, EPnP where SQPnP refuses, then Levenberg–Marquardt.

OpenCV's SQPnP asserts when the points' normalised image coordinates vary less than its
``POINT_VARIANCE_THRESHOLD`` (OpenCV ``modules/3d/src/sqpnp.cpp``, ``computeOmega``): a target that
subtends under ~0.2°, such as V2 (140 mm across) beyond about 19 m whatever the lens. That is a
limit of the solver's conditioning test, not of the geometry: EPnP (Lepetit, Moreno-Noguer & Fua
2009) solves the same problem from the same points and LM refines either start to the same
least-squares pose. Before this module the trackers and the PnP estimator treated the assertion
as a failed detection, which made ~19-20 m the best tracker's far limit for every lens.

>>> import numpy as np
>>> obj = np.array([[0, 0, 0], [-0.046, -0.07, 0], [-0.046, 0.07, 0], [-0.046, 0, -0.07], [-0.046, 0, 0.07]])
>>> k = np.array([[4186.0, 0, 2592], [0, 4186.0, 1728], [0, 0, 1]])
>>> uv = np.array([[2592.0, 1728.0], [2603.7, 1728.0], [2580.3, 1728.0], [2592.0, 1716.3], [2592.0, 1739.7]])
>>> rvec, tvec = solve_pnp(obj, uv, k)  # 25 m away: SQPnP refuses it, EPnP does not
>>> round(float(tvec[2, 0]), 1)
25.0
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["MIN_SPREAD_PX", "solve_pnp"]

MIN_SPREAD_PX = 1.0
"""Smallest extent of the points along u or v that carries a pose, px: points within one pixel are
not a resolved target (the trackers' blobs are further apart than this in any case)."""


def solve_pnp(
    obj: NDArray[np.float64], uv: NDArray[np.float64], k: NDArray[np.float64], criteria: tuple | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The pose (Rodrigues ``rvec``, ``tvec``; OpenCV camera frame) that images ``obj`` at ``uv``.

    Parameters
    ----------
    obj
        (n, 3) target points, m.
    uv
        (n, 2) undistorted pixel positions, px.
    k
        3×3 pinhole camera matrix, px.
    criteria
        OpenCV termination criteria of the LM refinement (None: OpenCV's default).

    Returns
    -------
    ``(rvec, tvec)``, or None when the points span under :data:`MIN_SPREAD_PX` or neither SQPnP
    nor EPnP finds a pose (degenerate points).
    """
    if np.ptp(np.asarray(uv, dtype=np.float64), axis=0).max() < MIN_SPREAD_PX:
        return None  # no resolved target: EPnP would put coincident points at ~1e12 m
    start = None
    for flag in (cv2.SOLVEPNP_SQPNP, cv2.SOLVEPNP_EPNP):
        try:
            ok, rvec, tvec = cv2.solvePnP(obj, uv, k, None, flags=flag)
        except cv2.error:  # SQPnP: too small a spread of points; either: coincident points
            continue
        if ok and np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)):
            start = rvec, tvec
            break
    if start is None:
        return None
    try:
        if criteria is None:
            rvec, tvec = cv2.solvePnPRefineLM(obj, uv, k, None, *start)
        else:
            rvec, tvec = cv2.solvePnPRefineLM(obj, uv, k, None, *start, criteria=criteria)
    except cv2.error:
        return None
    return rvec, tvec
