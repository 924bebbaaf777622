"""Issue 24 item 3: both trackers before and after, side by side in one run, on the same frames.

The "old" trackers are the code of commit ``a4fb580`` (the branch point), loaded from git into
private modules; the new ones are the working tree's. Frames come from
:func:`studies.engine.frame.capture_frame` on the study mix (:func:`studies.experiments.bench.study_mix`:
the quick range-limit, brightness-diffuser and webcam-vs-DSLR tasks, whole frames), each captured
once and given to all four trackers. Prints JSON: per tracker, detection and pose successes old
vs new (counts, Wilson 95 % intervals, the exact McNemar p of the paired difference), blob
counts, and tracker times (median over frames, and on one dark T6 and one webcam whole frame,
best of 3).

Usage: ``python scripts/detectors_old_vs_new.py [per_study] [out.json]`` from the repository root.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

import pipeline.detect as detect_module
from pipeline.angles import Intrinsics
from pipeline.evaluate import evaluate_detection
from studies.engine.frame import capture_frame
from studies.engine.scoring import detection_success, pose_success
from studies.experiments.bench import study_mix

BASE = "a4fb580"


def _old_module(path: str, name: str):
    source = subprocess.run(["git", "show", f"{BASE}:{path}"], capture_output=True, text=True, check=True).stdout
    file = Path(tempfile.mkdtemp()) / f"{name}.py"
    file.write_text(source)
    spec = importlib.util.spec_from_file_location(name, file)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


OLD_BEST = _old_module("pipeline/tracker.py", "_old_tracker")
OLD_THESIS = _old_module("pipeline/thesis_tracker.py", "_old_thesis_tracker")
NEW = {"best": detect_module.track, "thesis": detect_module.thesis_track}
OLD = {"best": OLD_BEST.track, "thesis": OLD_THESIS.thesis_track}


def _use(version: dict) -> None:
    detect_module.track, detect_module.thesis_track = version["best"], version["thesis"]


def _wilson(k: int, n: int) -> list[float]:
    if n == 0:
        return [float("nan")] * 2
    z, p = 1.959964, k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [float(centre - half), float(centre + half)]


def _score(frame, task, tracker: str) -> dict:
    cap, camera, scenario = frame.capture, frame.camera, frame.scenario
    from camera_models.capture import marker_pixels

    truth = {
        "markers_px": marker_pixels(camera, scenario).tolist(),
        "range_m": scenario.range_m,
        "yaw_deg": scenario.yaw_deg,
        "side": scenario.side,
    }
    intr = Intrinsics.from_geometry(camera.geometry)
    cache: dict = {}
    t0 = time.perf_counter()
    ev = evaluate_detection(
        frame.image_bgr,
        intr,
        truth,
        tracker=tracker,
        estimator="best",
        beacon=scenario.beacon,
        crop_origin_px=(cap.x0, cap.y0),
        track_cache=cache,
    )
    seconds = time.perf_counter() - t0
    row = {
        "detected": ev["detected"],
        "side_correct": ev.get("side_correct"),
        "numbering_correct": ev.get("numbering_correct"),
        "range_err_m": ev.get("range_error_m") if ev.get("range_error_m") is not None else float("nan"),
        "yaw_err_deg": ev.get("yaw_error_deg") if ev.get("yaw_error_deg") is not None else float("nan"),
        "range_m": scenario.range_m,
    }
    return {
        "detection": detection_success(row),
        "pose": pose_success(row),
        "blobs": len(cache[tracker].blobs) if tracker in cache else None,
        "seconds": seconds,
    }


def _time_tracker(image, intr, origin, tracker: str, version: dict, repeats: int = 3) -> float:
    _use(version)
    fn = detect_module.TRACKERS[tracker]
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(image, intr, origin, {"resize": None, "thesis_settings": None, "beacon": "v2", "tracker_settings": None})
        best = min(best, time.perf_counter() - t0)
    return best


def main(per_study: int = 16, out: str | None = None) -> dict:
    tasks = study_mix(per_study)
    rows = {(v, t): [] for v in ("old", "new") for t in ("thesis", "best")}
    frames_info = []
    whole = {}
    for i, task in enumerate(tasks):
        frame = capture_frame(task)
        cam = task["scenario"]["camera"]
        frames_info.append({"camera": cam, "range_m": task["scenario"]["range_m"], "side": task["scenario"]["side"]})
        for version, impl in (("old", OLD), ("new", NEW)):
            _use(impl)
            for tracker in ("thesis", "best"):
                rows[(version, tracker)].append(_score(frame, task, tracker))
        if cam not in whole and cam in ("canon-t6-18mm", "logitech-c270"):
            whole[cam] = (frame, task)
        print(f"{i + 1}/{len(tasks)} {cam} {task['scenario']['range_m']} m", file=sys.stderr, flush=True)
    _use(NEW)
    report = {"frames": len(tasks), "per_study": per_study, "base_commit": BASE, "trackers": {}}
    for tracker in ("thesis", "best"):
        old, new = rows[("old", tracker)], rows[("new", tracker)]
        entry = {}
        for what in ("detection", "pose"):
            a = np.array([r[what] for r in old])
            b = np.array([r[what] for r in new])
            only_old, only_new = int((a & ~b).sum()), int((~a & b).sum())
            discordant = only_old + only_new
            entry[what] = {
                "old": int(a.sum()),
                "new": int(b.sum()),
                "old_95": _wilson(int(a.sum()), len(a)),
                "new_95": _wilson(int(b.sum()), len(b)),
                "only_old": only_old,
                "only_new": only_new,
                "mcnemar_p": float(binomtest(only_old, discordant).pvalue) if discordant else 1.0,
            }
        blobs_old = [r["blobs"] for r in old if r["blobs"] is not None]
        blobs_new = [r["blobs"] for r in new if r["blobs"] is not None]
        entry["blobs_median"] = {"old": float(np.median(blobs_old)), "new": float(np.median(blobs_new))}
        entry["blobs_max"] = {"old": int(np.max(blobs_old)), "new": int(np.max(blobs_new))}
        entry["detect_s_median"] = {
            "old": float(np.median([r["seconds"] for r in old])),
            "new": float(np.median([r["seconds"] for r in new])),
        }
        report["trackers"][tracker] = entry
    report["whole_frame_tracker_s"] = {}
    for cam, (frame, _task) in whole.items():
        intr = Intrinsics.from_geometry(frame.camera.geometry)
        origin = (frame.capture.x0, frame.capture.y0)
        report["whole_frame_tracker_s"][cam] = {
            f"{tracker}_{version}": _time_tracker(frame.image_bgr, intr, origin, tracker, impl)
            for tracker in ("thesis", "best")
            for version, impl in (("old", OLD), ("new", NEW))
        }
    _use(NEW)
    report["frames_info"] = frames_info
    report["per_frame"] = {f"{v}_{t}": rows[(v, t)] for (v, t) in rows}
    text = json.dumps(report, indent=1)
    if out:
        Path(out).write_text(text)
    return report


if __name__ == "__main__":
    rep = main(int(sys.argv[1]) if len(sys.argv) > 1 else 16, sys.argv[2] if len(sys.argv) > 2 else None)
    print(json.dumps({k: v for k, v in rep.items() if k not in ("per_frame", "frames_info")}, indent=1))
