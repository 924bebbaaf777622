"""Scoring one detection against ground truth (for the end-to-end tables on rendered frames).

:func:`evaluate_detection` runs :func:`pipeline.detect.detect` and compares with a truth
given as marker pixels (full frame), range and yaw, as ``beacon-sim render`` writes them
(``render.json``: ``markers_ground_truth_px`` and ``scenario``) or as a plain dict.
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.angles import Intrinsics
from pipeline.detect import detect

__all__ = ["evaluate_detection"]


def _truth_markers(truth: dict) -> np.ndarray:
    raw = truth.get("markers_px", truth.get("markers_ground_truth_px"))
    if raw is None:
        raise ValueError("truth: expected 'markers_px' (5 × (u, v)) or 'markers_ground_truth_px'")
    if raw and isinstance(raw[0], dict):
        raw = [[m["u"], m["v"]] for m in sorted(raw, key=lambda m: m["id"])]
    uv = np.asarray(raw, dtype=np.float64)
    if uv.shape != (5, 2) or not np.all(np.isfinite(uv)):
        raise ValueError(f"truth.markers_px: expected 5 finite (u, v) pairs, got shape {uv.shape}")
    return uv


def _truth_value(truth: dict, key: str):
    if key in truth:
        return truth[key]
    return truth.get("scenario", {}).get(key)


def evaluate_detection(image_bgr, intrinsics: Intrinsics, truth: dict, **detect_kwargs) -> dict:
    """Detect in ``image_bgr`` and score the answer.

    Parameters
    ----------
    image_bgr
        BGR image: the full frame, or a crop with ``crop_origin_px`` in ``detect_kwargs``.
    intrinsics
        Nominal intrinsics of the camera's full frame (see :func:`pipeline.detect.detect`).
    truth
        ``markers_px`` (5 × (u, v), markers 1..5, full-frame pixels), ``range_m``,
        ``yaw_deg`` and optionally ``side``; a ``render.json`` dict also works.
    **detect_kwargs
        Passed to :func:`pipeline.detect.detect` (tracker, estimator, beacon, ...).

    Returns
    -------
    dict
        ``detected`` (five markers numbered), ``side``, ``side_correct`` (None without a
        true side), ``numbering_correct`` (every marker's nearest true marker has its
        id, within half the smallest true marker spacing), ``marker_errors_px`` (per
        marker, to the true marker of the same id), ``centroid_rms_px``,
        ``range_m``, ``range_error_m``, ``yaw_deg``, ``yaw_error_deg``, ``reason``, ``failure``
        (:class:`pipeline.failures.Failure` code or None), ``side_blobs`` (blobs the tracker
        found of the true side's colour; None without a true side), ``notes`` (the detector's).
    """
    uv_true = _truth_markers(truth)
    range_true = _truth_value(truth, "range_m")
    yaw_true = _truth_value(truth, "yaw_deg")
    side_true = _truth_value(truth, "side")
    det = detect(image_bgr, intrinsics, **detect_kwargs).to_dict()
    out = {
        "detected": bool(det["markers"]),
        "side": det["side"],
        "side_correct": None if side_true is None else det["side"] == side_true,
        "numbering_correct": None,
        "marker_errors_px": None,
        "centroid_rms_px": None,
        "range_m": det["range_m"],
        "range_error_m": None,
        "yaw_deg": det["yaw_deg"],
        "yaw_error_deg": None,
        "reason": det["reason"],
        "failure": det["failure"],
        "side_blobs": None if side_true is None else det["blob_counts"].get(side_true, 0),
        "notes": list(det["notes"]),
    }
    if not det["markers"]:
        out["numbering_correct"] = False
        return out
    uv = np.array([[m["u"], m["v"]] for m in det["markers"]])
    errors = np.hypot(*(uv - uv_true).T)
    spacing = min(np.hypot(*(uv_true[i] - uv_true[j])) for i in range(5) for j in range(i + 1, 5))
    nearest = np.argmin(np.hypot(*(uv[:, None, :] - uv_true[None, :, :]).transpose(2, 0, 1)), axis=1)
    out["numbering_correct"] = bool(np.all(nearest == np.arange(5)) and np.all(errors < 0.5 * spacing))
    out["marker_errors_px"] = errors.tolist()
    out["centroid_rms_px"] = float(np.sqrt(np.mean(errors**2)))
    if det["range_m"] is not None and range_true is not None:
        out["range_error_m"] = float(det["range_m"] - range_true)
    if det["yaw_deg"] is not None and yaw_true is not None:
        out["yaw_error_deg"] = float((det["yaw_deg"] - yaw_true + 180.0) % 360.0 - 180.0)
    if out["range_error_m"] is not None and not math.isfinite(out["range_error_m"]):
        out["range_error_m"] = None
    return out
