"""The best tracker's pruned 5-subset search against the full search, on the studies' frames.

:func:`pipeline.tracker.best_five` skips the PnP fit of every candidate five whose
image-space lower bound on the reprojection RMS (:func:`pipeline.tracker.rms_lower_bounds`)
shows it cannot change the answer; ``TrackerSettings(prune=False)`` is the full search,
which fits every candidate that passes the cross and image-plane screens. This experiment
runs both on the same saved JPEGs and checks that the answers are identical, then measures
what the pruning saves.

Frames: the quick grids of the catalogued studies (:data:`studies.catalog.STUDIES`), as
frame tasks (:func:`studies.engine.tasks.frame_tasks`) with ``frame="crop"`` by default,
through the engine's one render → capture path (:func:`studies.engine.frame.capture_frame`;
renders come from the cache when they are there). For each frame, both searches run
through :func:`pipeline.evaluate.evaluate_detection` with each estimator (detection, side,
numbering, marker errors, range and yaw and their errors, reason, failure code), and the
tracker alone (:func:`pipeline.tracker.track`) is timed, best of ``repeats`` runs each,
with its PnP fits counted.
"""

from __future__ import annotations

import contextlib
import math
import statistics
import time
from collections.abc import Iterator, Sequence
from dataclasses import replace

from camera_models.capture import marker_pixels
from pipeline import tracker
from pipeline.angles import Intrinsics
from pipeline.detect import ESTIMATORS
from pipeline.evaluate import evaluate_detection
from studies.catalog import STUDIES
from studies.engine.frame import capture_frame
from studies.engine.tasks import frame_tasks, grid_conditions

__all__ = ["QUICK_STUDIES", "compare_frame", "run", "study_tasks"]

QUICK_STUDIES = ("webcam-vs-dslr", "brightness-diffuser", "range-limit", "replication")
"""Studies whose quick grids are used by default."""


def study_tasks(studies: Sequence[str] = QUICK_STUDIES, frame: str = "crop") -> list[dict]:
    """Frame tasks of the quick grids of ``studies``, with ``frame`` (``crop`` or ``full``), tagged by study."""
    tasks = []
    for name in studies:
        if name not in STUDIES:
            raise ValueError(f"studies: expected some of {', '.join(STUDIES)}, got unknown {name!r}")
        module = STUDIES[name]
        options = replace(module.default_options(True), frame=frame)
        conditions = module.conditions(options) if hasattr(module, "conditions") else grid_conditions(options)
        tasks += [{**t, "tags": {**t.get("tags", {}), "study": name}} for t in frame_tasks(conditions, options)]
    return tasks


@contextlib.contextmanager
def _counting_fits() -> Iterator[list[int]]:
    """Count the tracker's PnP fits (calls of its ``_fit``) while the block runs."""
    count = [0]
    original = tracker._fit

    def counted(*args):
        count[0] += 1
        return original(*args)

    tracker._fit = counted
    try:
        yield count
    finally:
        tracker._fit = original


def _timed_track(image, intrinsics: Intrinsics, settings: tracker.TrackerSettings, origin, repeats: int):
    """(result, best time over ``repeats`` runs in s, PnP fits of one run)."""
    best = math.inf
    result, fits = None, 0
    for _ in range(repeats):
        with _counting_fits() as count:
            t0 = time.perf_counter()
            result = tracker.track(image, intrinsics, settings, origin)
            best = min(best, time.perf_counter() - t0)
        fits = count[0]
    return result, best, fits


def _same(a, b) -> bool:
    """Equal values, NaN equal to NaN (for the evaluation dicts)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def compare_frame(task: dict, repeats: int = 3) -> dict:
    """Both searches on one task's saved frame: identity of the answers, times and fits.

    Returns
    -------
    dict
        ``study``, ``camera``, ``range_m``, ``yaw_deg``, ``seed``; ``identical`` (every
        estimator's evaluation and the tracker's result equal), ``differences`` (the
        evaluation fields that differ, per estimator), ``detected`` and
        ``numbering_correct`` (full search, best estimator); ``time_full_s``,
        ``time_pruned_s`` (the tracker alone, best of ``repeats``); ``fits_full``,
        ``fits_pruned`` (PnP fits of one tracker run).
    """
    frame = capture_frame(task)
    scenario, camera = frame.scenario, frame.camera
    intrinsics = Intrinsics.from_geometry(camera.geometry)
    truth = {
        "markers_px": marker_pixels(camera, scenario).tolist(),
        "range_m": scenario.range_m,
        "yaw_deg": scenario.yaw_deg,
        "side": scenario.side,
    }
    settings = tracker.TrackerSettings(beacon=scenario.beacon)
    full, pruned = replace(settings, prune=False), settings
    differences, evaluations = {}, {}
    for estimator in ESTIMATORS:
        kwargs = {"tracker": "best", "estimator": estimator, "beacon": scenario.beacon, "crop_origin_px": frame.origin}
        a = evaluate_detection(frame.image_bgr, intrinsics, truth, tracker_settings=full, **kwargs)
        b = evaluate_detection(frame.image_bgr, intrinsics, truth, tracker_settings=pruned, **kwargs)
        evaluations[estimator] = a
        diff = sorted(k for k in a.keys() | b.keys() if not _same(a.get(k), b.get(k)))
        if diff:
            differences[estimator] = diff
    ra, ta, fa = _timed_track(frame.image_bgr, intrinsics, full, frame.origin, repeats)
    rb, tb, fb = _timed_track(frame.image_bgr, intrinsics, pruned, frame.origin, repeats)
    same_track = (ra.side, ra.reason, ra.notes, ra.failure, _uv(ra)) == (
        rb.side,
        rb.reason,
        rb.notes,
        rb.failure,
        _uv(rb),
    )
    if not same_track:
        differences["track"] = ["side, uv, reason, notes or failure"]
    best = evaluations["best"]
    return {
        "study": task.get("tags", {}).get("study"),
        "camera": scenario.camera,
        "range_m": scenario.range_m,
        "yaw_deg": scenario.yaw_deg,
        "seed": int(task["seed"]),
        "identical": not differences,
        "differences": differences,
        "detected": bool(best["detected"]),
        "numbering_correct": bool(best["numbering_correct"]),
        "time_full_s": ta,
        "time_pruned_s": tb,
        "fits_full": fa,
        "fits_pruned": fb,
    }


def _uv(result) -> list | None:
    return None if result.uv is None else result.uv.tolist()


def run(tasks: Sequence[dict] | None = None, max_frames: int | None = None, repeats: int = 3) -> dict:
    """Compare the pruned and the full search on study frames and measure the saving.

    Parameters
    ----------
    tasks
        Frame tasks; default :func:`study_tasks` (the quick grids, rendered crops).
    max_frames
        Use at most this many tasks (evenly spaced over the list); None: all.
    repeats
        Tracker runs per frame and search; the fastest counts (the machine may be shared).

    Returns
    -------
    dict
        ``frames``; ``identical`` (frames whose detection, pose and tracker result are equal);
        ``different`` (the rows of the others, with the fields that differ); ``detected``
        (frames with a detection, full search); ``time_full_ms``, ``time_pruned_ms``
        (median and 90th percentile of the tracker's time per frame, ms); ``speedup_median``
        (ratio of the medians); ``fits_full``, ``fits_pruned`` (PnP fits, all frames);
        ``pruned_fraction`` (1 − fits_pruned / fits_full: candidates the full search fits
        that the pruned one does not); ``fits_pruned_per_frame`` (median, 90th percentile
        and maximum); ``rows`` (one per frame, :func:`compare_frame`).
    """
    tasks = list(study_tasks() if tasks is None else tasks)
    if max_frames is not None and len(tasks) > max_frames:
        step = len(tasks) / max_frames
        tasks = [tasks[int(i * step)] for i in range(max_frames)]
    rows = [compare_frame(task, repeats) for task in tasks]
    if not rows:
        raise ValueError("tasks: expected at least one frame task, got none")
    t_full = [1e3 * r["time_full_s"] for r in rows]
    t_pruned = [1e3 * r["time_pruned_s"] for r in rows]
    fits_full = sum(r["fits_full"] for r in rows)
    fits_pruned = sum(r["fits_pruned"] for r in rows)
    per_frame = sorted(r["fits_pruned"] for r in rows)
    return {
        "frames": len(rows),
        "identical": sum(r["identical"] for r in rows),
        "different": [r for r in rows if not r["identical"]],
        "detected": sum(r["detected"] for r in rows),
        "time_full_ms": {"median": statistics.median(t_full), "p90": _quantile(t_full, 0.9)},
        "time_pruned_ms": {"median": statistics.median(t_pruned), "p90": _quantile(t_pruned, 0.9)},
        "speedup_median": statistics.median(t_full) / statistics.median(t_pruned),
        "fits_full": fits_full,
        "fits_pruned": fits_pruned,
        "pruned_fraction": 1.0 - fits_pruned / fits_full if fits_full else 0.0,
        "fits_pruned_per_frame": {
            "median": statistics.median(per_frame),
            "p90": _quantile(per_frame, 0.9),
            "max": per_frame[-1],
        },
        "rows": rows,
    }


def _quantile(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (linear interpolation)."""
    v = sorted(values)
    pos = q * (len(v) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (pos - lo) * (v[hi] - v[lo])
