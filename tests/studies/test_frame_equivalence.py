"""Whole frames by the fast camera path and by the reference path it replaced: what the detectors see.

Issue 24's contract in place of byte identity: false blobs per dark whole frame (both
trackers, ≥ 50 frames per path, a two-sample Mann-Whitney U test) and, behind the ``slow``
marker, detection and pose success on a paired grid of ≥ 200 study frames (each path's
rate inside the other's Wilson 95 % interval).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import stats

from camera_models.camera import load_camera
from camera_models.exposure import auto_exposure, manual_exposure
from camera_models.isp import process
from camera_models.isp_reference import reference_process
from camera_models.sensor import SensorSettings
from camera_models.sensor_kernel import available
from camera_models.sensor_paths import expose
from pipeline.angles import Intrinsics
from pipeline.detect import TRACKERS

pytestmark = pytest.mark.skipif(not available(), reason="no fast Dr.Jit backend (libLLVM >= 16 or CUDA)")

FRAMES = 50


def dark_frame_blobs(name: str, seed: int, reference: bool) -> dict[str, int]:
    """Blobs each tracker finds on a dark whole frame (no light; the camera's exposure for the dark)."""
    cam = load_camera(name)
    ex = auto_exposure(cam, lambda t, g: 0.0) if cam.exposure.mode == "auto" else manual_exposure(cam)
    g = cam.geometry
    mean = np.zeros((g.height_px, g.width_px), np.float32)
    settings = SensorSettings(ex.exposure_s, ex.analog_gain)
    raw = expose(mean, cam.sensor, settings, seed, path="numpy" if reference else "drjit")
    img = reference_process(raw, cam) if reference else process(raw, cam, analog_gain=ex.analog_gain)
    bgr = cv2.imdecode(np.frombuffer(img.jpeg, np.uint8), cv2.IMREAD_COLOR)
    intr = Intrinsics.from_geometry(g)
    return {t: len(TRACKERS[t](bgr, intr, (0, 0), {"beacon": "v2"}).blobs) for t in TRACKERS}


def _blob_counts(name: str, frames: int) -> dict[bool, dict[str, np.ndarray]]:
    out = {}
    for reference in (True, False):
        rows = [dark_frame_blobs(name, 1000 + k, reference) for k in range(frames)]
        out[reference] = {t: np.array([r[t] for r in rows]) for t in TRACKERS}
    return out


def _same_distribution(a: np.ndarray, b: np.ndarray) -> float:
    """p-value that two samples of counts share one distribution (two-sided Mann-Whitney U;
    1 when both are constant and equal)."""
    if np.all(a == a[0]) and np.all(b == a[0]):
        return 1.0
    return float(stats.mannwhitneyu(a, b, alternative="two-sided").pvalue)


@pytest.mark.parametrize("name", ["logitech-c270", pytest.param("spedal-920", marks=pytest.mark.slow)])
def test_false_blobs_per_dark_webcam_frame_agree(name):
    counts = _blob_counts(name, FRAMES)
    for tracker in TRACKERS:
        old, new = counts[True][tracker], counts[False][tracker]
        p = _same_distribution(old, new)
        print(name, tracker, f"blobs per dark frame: reference {old.mean():.1f}, fast {new.mean():.1f}, p = {p:.3f}")
        assert p > 1e-3


@pytest.mark.slow
def test_false_blobs_per_dark_t6_frame_agree():
    counts = _blob_counts("canon-t6-18mm", FRAMES)
    for tracker in TRACKERS:
        old, new = counts[True][tracker], counts[False][tracker]
        p = _same_distribution(old, new)
        print("canon-t6-18mm", tracker, f"reference {old.mean():.1f}, fast {new.mean():.1f}, p = {p:.3f}")
        assert p > 1e-3


def wilson(k: int, n: int) -> tuple[float, float]:
    """Wilson score 95 % interval of a binomial proportion k / n (scipy)."""
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return ci.low, ci.high


@pytest.mark.slow
def test_detection_and_pose_success_agree_on_a_paired_grid():
    """≥ 200 study frames (the three quick studies' mix, whole frames), captured by both paths from
    the same renders: per tracker, detection and pose success of each path inside the other's
    Wilson 95 % interval."""
    from studies.engine.frame import simulate_frame
    from studies.engine.scoring import pose_success
    from studies.experiments.bench import study_mix

    tasks = study_mix(per_study=70, seed=3)
    assert len(tasks) >= 200
    rows = {ref: [r for t in tasks for r in simulate_frame({**t, "reference_camera": ref})] for ref in (True, False)}
    for tracker in TRACKERS:
        for measure in ("detected", "pose"):
            k = {}
            for ref, rs in rows.items():
                mine = [r for r in rs if r["tracker"] == tracker and r["estimator"] == "best"]
                k[ref] = sum(bool(r["detected"]) if measure == "detected" else pose_success(r) for r in mine)
                n = len(mine)
            lo_old, hi_old = wilson(k[True], n)
            lo_new, hi_new = wilson(k[False], n)
            print(tracker, measure, f"reference {k[True]}/{n}, fast {k[False]}/{n}")
            assert lo_old <= k[False] / n <= hi_old and lo_new <= k[True] / n <= hi_new
