"""Crop versus whole frame: what the detectors see when only the rendered crop is captured.

Until frame version 4 the studies captured and searched only the rendered crop around the
beacon. A camera saves its whole frame, and in the dark at high gain sensor noise makes blobs
all over it: the detectors then have tens to hundreds of false blobs to choose from that the
crop never showed them. Study tasks are now whole frames by default
(:attr:`studies.engine.tasks.StudyOptions.frame`); this experiment measures the difference.

For every camera × range × LED current × noise seed it builds the frame task the studies
build (:func:`studies.engine.tasks.frame_tasks`: V2 beacon, red side, yaw 0, dark, the
studies' default diffuser, exact nominal pose) once with ``frame="crop"`` and once with
``frame="full"``, and runs both through the engine's one frame path
(:func:`studies.engine.frame.simulate_frame`) with the same noise seed: both trackers, the
best estimator (detection success does not depend on the estimator). The render is shared
(held in memory), so the time measured per frame is the camera (lens, sensor, ISP, JPEG)
and the detectors, in one process, s.

:func:`run` returns and (given ``out``) writes:

``crop_vs_full.csv``          one row per camera × range × current × seed × tracker: per path
                              (``_crop``, ``_full``) the blobs the tracker found (all colours),
                              those of the true side's colour, detection and pose success,
                              range error (m), the detector's reason and the frame's time (s)
``crop_vs_full_summary.csv``  per camera × range × current × tracker: frames, successes and mean
                              blob counts per path
``crop_vs_full.json``         rows, summary, per camera cost (median s per frame, crop and full,
                              and their ratio) and the settings
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine import frame as engine_frame
from studies.engine import strict_json
from studies.engine.scoring import detection_success, pose_success
from studies.engine.tasks import RENDER, STUDY_CAMERAS, StudyOptions, frame_tasks, grid_conditions

__all__ = [
    "RANGES_M",
    "ROW_COLUMNS",
    "SEEDS",
    "SUMMARY_COLUMNS",
    "CropVsFull",
    "compare_pair",
    "comparison_tasks",
    "cost",
    "run",
    "summarise",
    "timed_rows",
]

RANGES_M = (2.0, 5.0)
"""Ranges of the comparison, m (camera → marker 1)."""
SEEDS = 3
"""Noise seeds per condition."""
PATHS = ("crop", "full")
ROW_COLUMNS = (
    "camera", "range_m", "led_current_mA", "seed", "tracker",
    *(f"{k}_{p}" for p in PATHS for k in ("blobs", "side_blobs", "correct", "pose_ok", "range_err_m", "reason",
                                          "seconds", "pixels")),
)  # fmt: skip
SUMMARY_COLUMNS = (
    "camera", "range_m", "led_current_mA", "tracker", "frames",
    "correct_crop", "correct_full", "pose_ok_crop", "pose_ok_full", "blobs_mean_crop", "blobs_mean_full",
)  # fmt: skip


@dataclass
class CropVsFull:
    """What :func:`run` measured: rows (:data:`ROW_COLUMNS`), summary (:data:`SUMMARY_COLUMNS`),
    cost per camera and the files written (empty without ``out``)."""

    rows: list[dict]
    summary: list[dict]
    cost: list[dict]
    paths: dict[str, Path] = field(default_factory=dict)


def comparison_tasks(
    cameras: Sequence[str],
    ranges_m: Sequence[float] = RANGES_M,
    seeds: int = SEEDS,
    currents_mA: Sequence[float] = (20.0,),
    render: dict | None = None,
) -> list[tuple[dict, dict]]:
    """(crop task, whole-frame task) pairs of every camera × range × current × seed, as the studies
    build them (V2, red side, yaw 0, dark, default diffuser, no pose jitter)."""
    options = StudyOptions(
        cameras=tuple(cameras),
        ranges_m=tuple(float(r) for r in ranges_m),
        currents_mA=tuple(float(c) for c in currents_mA),
        seeds=seeds,
        jitter_poses=1,
        render=dict(render or RENDER),
    )
    options.validate()
    conditions = grid_conditions(options)
    crop = frame_tasks(conditions, replace(options, frame="crop"), estimators=["best"])
    full = frame_tasks(conditions, replace(options, frame="full"), estimators=["best"])
    return list(zip(crop, full, strict=True))


def timed_rows(task: dict) -> tuple[list[dict], float, int]:
    """The engine's rows of a task, the seconds its camera and detectors took (render held in
    memory beforehand) and the saved image's pixel count."""
    scenario, _, radiance, _ = engine_frame.frame_inputs(task)  # rendered (or read) first: not part of the time
    t0 = time.perf_counter()
    rows = engine_frame.simulate_frame(task)
    seconds = time.perf_counter() - t0
    g = scenario.geometry
    pixels = g.width_px * g.height_px if task.get("full_frame") else radiance.grid.width * radiance.grid.height
    return rows, seconds, pixels


def compare_pair(crop: dict, full: dict) -> list[dict]:
    """One row per tracker comparing the crop and whole-frame answers of one frame (same seed)."""
    out: dict[str, dict] = {}
    for path, task in zip(PATHS, (crop, full), strict=True):
        rows, seconds, pixels = timed_rows(task)
        for r in rows:
            row = out.setdefault(
                r["tracker"],
                {
                    "camera": r["camera"],
                    "range_m": r["nominal_range_m"],
                    "led_current_mA": r["led_current_mA"],
                    "seed": r["seed"],
                    "tracker": r["tracker"],
                },
            )
            row |= {
                f"blobs_{path}": r["blobs"],
                f"side_blobs_{path}": r["side_blobs"],
                f"correct_{path}": detection_success(r),
                f"pose_ok_{path}": pose_success(r),
                f"range_err_m_{path}": r["range_err_m"],
                f"reason_{path}": r["reason"],
                f"seconds_{path}": seconds,
                f"pixels_{path}": pixels,
            }
    return list(out.values())


def summarise(rows: Sequence[dict]) -> list[dict]:
    """Per camera × range × current × tracker: frames, successes and mean blob counts per path."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["camera"], r["range_m"], r["led_current_mA"], r["tracker"]), []).append(r)
    out = []
    for (camera, range_m, current, tracker), g in groups.items():
        s = {"camera": camera, "range_m": range_m, "led_current_mA": current, "tracker": tracker, "frames": len(g)}
        for p in PATHS:
            s[f"correct_{p}"] = sum(bool(r[f"correct_{p}"]) for r in g)
            s[f"pose_ok_{p}"] = sum(bool(r[f"pose_ok_{p}"]) for r in g)
            s[f"blobs_mean_{p}"] = statistics.fmean(r[f"blobs_{p}"] or 0 for r in g)
        out.append({k: s[k] for k in SUMMARY_COLUMNS})
    return out


def cost(rows: Sequence[dict]) -> list[dict]:
    """Per camera: median seconds per frame (camera + both trackers) on the crop and the whole
    frame, their ratio, and the pixels of each."""
    out = []
    for camera in dict.fromkeys(r["camera"] for r in rows):
        frames = {(r["range_m"], r["led_current_mA"], r["seed"]): r for r in rows if r["camera"] == camera}
        c = statistics.median(r["seconds_crop"] for r in frames.values())
        f = statistics.median(r["seconds_full"] for r in frames.values())
        out.append(
            {
                "camera": camera,
                "frames": len(frames),
                "seconds_crop": c,
                "seconds_full": f,
                "ratio": f / c if c > 0 else math.inf,
                "pixels_crop_median": statistics.median(r["pixels_crop"] for r in frames.values()),
                "pixels_full": next(iter(frames.values()))["pixels_full"],
            }
        )
    return out


def run(
    out: Path | None = None,
    cameras: Sequence[str] | None = None,
    ranges_m: Sequence[float] = RANGES_M,
    seeds: int = SEEDS,
    currents_mA: Sequence[float] = (20.0,),
    render: dict | None = None,
) -> CropVsFull:
    """Compare crop and whole frame for every camera (default the source study's four,
    :data:`studies.engine.tasks.STUDY_CAMERAS`) ×
    range (m) × current (mA) × seed, in this process (times are per frame, s); write the
    tables into ``out`` when given (module docstring)."""
    cameras = tuple(cameras or STUDY_CAMERAS)
    pairs = comparison_tasks(cameras, ranges_m, seeds, currents_mA, render)
    rows = [row for crop, full in pairs for row in compare_pair(crop, full)]
    result = CropVsFull(rows, summarise(rows), cost(rows))
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        result.paths = {
            "rows": out / "crop_vs_full.csv",
            "summary": out / "crop_vs_full_summary.csv",
            "json": out / "crop_vs_full.json",
        }
        _write_csv(result.paths["rows"], rows, ROW_COLUMNS)
        _write_csv(result.paths["summary"], result.summary, SUMMARY_COLUMNS)
        settings = {
            "cameras": list(cameras),
            "ranges_m": [float(r) for r in ranges_m],
            "seeds": seeds,
            "currents_mA": [float(c) for c in currents_mA],
            "render": dict(render or RENDER),
            "frame_version": engine_frame.FRAME_VERSION,
            "scene": "V2, red side, yaw 0, dark, foam + 1 sheet of matched paper, nominal pose",
            "seconds": "per frame, camera (lens, sensor, ISP, JPEG) + both trackers + best estimator, render held",
        }
        document = {"settings": settings, "cost": result.cost, "summary": result.summary, "rows": rows}
        atomic_write_bytes(result.paths["json"], strict_json.dumps(document, indent=2).encode())
    return result


def _write_csv(path: Path, rows: Sequence[dict], columns: Sequence[str]) -> None:
    frame = pd.DataFrame(list(rows), columns=list(columns))
    atomic_write_bytes(path, frame.to_csv(index=False, float_format="%.6g").encode())
