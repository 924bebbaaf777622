"""Fake frames of a known truth for studies run at points of the unknowns: the best tracker's
success falls off logistically with range around a midpoint that a test plants as a function of the
task (e.g. of one unknown's value), drawn from the task's content so that reruns agree."""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable

import numpy as np

__all__ = ["CHROMA_SD", "FALL_OFF_M", "planted_rows", "red_bin"]

CHROMA_SD = 0.01
"""Spread of a planted marker chromaticity (r and g each), dimensionless."""

FALL_OFF_M = 0.4
"""Width s of the logistic fall-off, m: the far limit is r₅₀ − s ln 19."""


def red_bin(task: dict) -> float:
    """The red LEDs' luminous intensity bin the task sets (cd; the data file's 5.1 when it sets none)."""
    return (task["scenario"].get("data") or {}).get("leds.red.luminous_intensity_cd", 5.1)


def planted_rows(
    r50: Callable[[dict], float],
    chroma: Callable[[dict], tuple[float, float]] | None = None,
    near50: Callable[[dict], float] | None = None,
):
    """A stand-in for :func:`studies.engine.sweep.run_frames`: one best-tracker row per task. With
    ``chroma`` every marker's (r, g) chromaticity is drawn around ``chroma(task)`` with sd
    :data:`CHROMA_SD` in each (independent), its sRGB codes (r, g, 1 − r − g) × 255, cores unclipped.
    With ``near50`` success also rises logistically with range around it (the same width), so the
    near limit is near50 + s ln 19 where the two fall-offs are far apart."""

    def rows(tasks, out, execution, description=""):
        made = []
        for task in tasks:
            sc = task["scenario"]
            u = int.from_bytes(hashlib.sha256(json.dumps(task, sort_keys=True).encode()).digest()[:8], "little")
            colours = {}
            if chroma is not None:
                draws = np.random.default_rng(u).normal(chroma(task), CHROMA_SD, (5, 2))
                for i, (r, g) in enumerate(draws, 1):
                    colours |= {f"marker{i}_r_chroma": r, f"marker{i}_g_chroma": g, f"marker{i}_R": 255 * r,
                                f"marker{i}_G": 255 * g, f"marker{i}_B": 255 * (1 - r - g)}  # fmt: skip
                colours["core_saturated_fraction_mean"] = 0.0
            p = 1 / (1 + math.exp((sc["range_m"] - r50(task)) / FALL_OFF_M))
            if near50 is not None:
                p /= 1 + math.exp((near50(task) - sc["range_m"]) / FALL_OFF_M)
            ok = u / 2**64 < p
            made.append({**sc, **(task.get("tags") or {}), "nominal_range_m": task["nominal"]["range_m"],
                         "nominal_yaw_deg": task["nominal"]["yaw_deg"], "seed": task["seed"], "tracker": "best",
                         "estimator": "best", "detected": ok, "side_correct": ok, "numbering_correct": ok,
                         "range_err_m": 0.01 if ok else math.nan, "yaw_err_deg": 0.1 if ok else math.nan,
                         "failure": "" if ok else "no-blobs", "reason": "",
                         "side_detected": sc.get("side") if ok else None, **colours})  # fmt: skip
        return made

    return rows
