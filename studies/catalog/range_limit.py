"""Study ``range-limit``: maximum range versus yaw per camera, lens and beacon version.

For each camera × beacon × side × yaw it renders frames over a range grid (seeds ×
jittered poses) and estimates the maximum range with its 95 % interval and limiting
cause (:mod:`studies.engine.max_range`), for the best tracker and the study's. The design's
planned 10 m is drawn against it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine.max_range import estimate_max_range
from studies.engine.report import Report
from studies.engine.sweep import Execution, sweep
from studies.engine.tasks import StudyOptions, grid_conditions

NAME = "range-limit"
PLANNED_RANGE_M = 10.0


def default_options(quick: bool) -> StudyOptions:
    """Full grid, or the quick one the main job runs."""
    if quick:
        return StudyOptions(
            cameras=("canon-t6-18mm", "logitech-c270"),
            yaws_deg=(0.0, 30.0),
            ranges_m=(2.0, 4.0, 6.0, 8.0, 10.0, 12.0),
            currents_mA=(2.0,),
            seeds=3,
            jitter_poses=1,
        )
    return StudyOptions(
        cameras=("logitech-c270", "spedal-920", "canon-t6-18mm", "canon-t6-10mm"),
        beacons=("v1", "v2"),
        yaws_deg=(0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0),
        ranges_m=tuple(float(r) for r in range(2, 17, 2)),  # the logistic fit interpolates between them
        currents_mA=(2.0, 20.0),
        seeds=6,
        jitter_poses=2,
    )


def run(out: Path, options: StudyOptions, execution: Execution = Execution()) -> dict:
    """Run the study into ``out``; returns the summary (``max_range`` records)."""
    frame = sweep(NAME, grid_conditions(options), options, out, execution=execution, estimators=["best"])
    records = []
    keys = ["camera", "beacon", "side", "led_current_mA", "nominal_yaw_deg", "tracker"]
    for key, g in frame.groupby(keys, sort=True):
        cam, beacon, side, current, yaw, tracker = key
        mr = estimate_max_range(g.to_dict("records"))
        records.append(
            {
                "camera": cam,
                "beacon": beacon,
                "side": side,
                "led_current_mA": float(current),
                "yaw_deg": float(yaw),
                "tracker": tracker,
                "max_range_m": mr.max_range_m,
                "low_m": mr.low_m,
                "high_m": mr.high_m,
                "limiting_cause": mr.limiting_cause,
                "fitted_from_m": mr.fitted_from_m,
            }
        )
    summary = {
        "study": NAME,
        "planned_range_m": PLANNED_RANGE_M,
        "max_range": [r for r in records if r["tracker"] == "best"],
        "max_range_thesis_tracker": [r for r in records if r["tracker"] == "thesis"],
    }
    _report(out, options, summary)
    atomic_write_bytes(out / "summary.json", json.dumps(summary, indent=2, allow_nan=True).encode())
    return summary


def _report(out: Path, options: StudyOptions, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("Range limit: maximum range versus yaw")
    rep.text(
        f"Cameras {', '.join(options.cameras)}; beacons {', '.join(options.beacons)}; sides "
        f"{', '.join(options.sides)}; yaw {', '.join(f'{y:g}' for y in options.yaws_deg)}°; ranges "
        f"{', '.join(f'{r:g}' for r in options.ranges_m)} m; {options.seeds} seeds per point. Maximum range: "
        "P(correct side, 5 markers numbered, range within 10 %, yaw within 5°) ≥ 0.95 (logistic fit)."
    )
    for key, label in (("max_range", "best tracker"), ("max_range_thesis_tracker", "study's tracker")):
        frame = pd.DataFrame(summary[key])
        if frame.empty:
            continue
        cams = sorted(set(frame.camera))
        fig, axes = plt.subplots(
            1, len(cams), figsize=(3.6 * len(cams) + 1, 4), sharey=True, squeeze=False, constrained_layout=True
        )
        currents = sorted(set(frame.led_current_mA))
        colours = {c: plt.cm.viridis(i / max(len(currents) - 1, 1) * 0.85) for i, c in enumerate(currents)}
        styles = {"v1": ("s", ":"), "v2": ("o", "-")}
        for ax, cam in zip(axes[0], cams, strict=True):
            for (beacon, side, current), g in frame[frame.camera == cam].groupby(["beacon", "side", "led_current_mA"]):
                r = np.nan_to_num(g.max_range_m.to_numpy(float))
                lo = np.nan_to_num(g.low_m.to_numpy(float))
                hi = np.where(np.isfinite(g.high_m), g.high_m, r)
                marker, line = styles.get(beacon, ("^", "--"))
                # bars clipped at zero: the bootstrap interval need not contain a fit clipped at 0 m
                ax.errorbar(
                    g.yaw_deg,
                    r,
                    yerr=[np.clip(r - lo, 0, None), np.clip(hi - r, 0, None)],
                    marker=marker,
                    ls=line,
                    color=colours[current],
                    capsize=3,
                    label=f"{beacon}, {side}, {current:g} mA",
                )
            ax.axhline(PLANNED_RANGE_M, color="red", ls="--", lw=1, label="planned 10 m")
            ax.set_title(cam, fontsize=10)
            ax.set_xlabel("yaw, degrees")
            ax.set_ylim(bottom=0)
        axes[0][0].set_ylabel("maximum range, m")
        axes[0][-1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
        rep.heading(f"Maximum range, {label}")
        rep.figure(
            fig,
            f"Maximum range (95 % interval) versus yaw, {label}; dashed: the design's planned 10 m. "
            "An upper bar missing means every frame up to the largest range tested was correct.",
        )
        rep.table(frame.drop(columns=["tracker"]), f"Maximum range and limiting cause, {label}")
    rep.write(out / "report.html")
