"""Study ``webcam-vs-dslr``: which camera sees the beacon farthest and keeps its colours.

Sweep: cameras × beacons × sides × ranges × environments × seeds (with pose jitter),
markers as the study built them (foam + 1 sheet of matched paper, datasheet current),
each camera at its study settings (T6 manual ISO 6400, 1/60 s; webcams automatic).
Outputs: detection probability versus range per camera and tracker (Wilson 95 %),
maximum range (:mod:`studies.engine.max_range`), colour separability of the sides in
linear-RGB chromaticity (pairwise Mahalanobis distance, ΔE2000 of mean colours) and the
detectors' colour confusion matrices, a ranking, and the study's image mosaic (the same
target at 2, 5 and 7 m through every camera).
"""

from __future__ import annotations

import io
import itertools
import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine.frame import target_crop_png
from studies.engine.max_range import estimate_max_range
from studies.engine.metrics import confusion_matrix, delta_e_2000, mahalanobis_separability
from studies.engine.report import Report
from studies.engine.sweep import Execution, sweep
from studies.engine.tables import detection_curve
from studies.engine.tasks import StudyOptions, frame_tasks, grid_conditions

NAME = "webcam-vs-dslr"
ALL_CAMERAS = ("logitech-c270", "spedal-920", "canon-t6-18mm", "canon-t6-10mm")
MOSAIC_RANGES_M = (2.0, 5.0, 7.0)
DRIVES_MA = (2.0, 20.0)
"""LED drive: the study dimmed its LEDs with potentiometers to an unknown setting, so the
sweep brackets it: 20 mA (datasheet test current) and 2 mA (a tenth, well dimmed)."""


def default_options(quick: bool) -> StudyOptions:
    """Full grid, or the quick one the main job runs."""
    if quick:
        return StudyOptions(
            cameras=ALL_CAMERAS,
            sides=("red", "green"),
            ranges_m=(2.0, 5.0, 7.0, 10.0),
            currents_mA=DRIVES_MA,
            seeds=2,
            jitter_poses=1,
        )
    return StudyOptions(
        cameras=ALL_CAMERAS,
        beacons=("v1", "v2"),
        sides=("red", "green", "blue", "yellow"),
        ranges_m=tuple(float(r) for r in range(1, 11)),
        environments=("dark", "lit-room"),
        currents_mA=DRIVES_MA,
        seeds=6,
        jitter_poses=2,
    )


def run(out: Path, options: StudyOptions, execution: Execution = Execution()) -> dict:
    """Run the study into ``out``; returns the summary."""
    frame = sweep(NAME, grid_conditions(options), options, out, execution=execution)
    summary = analyse(frame)
    mosaic = mosaic_png(options, out)
    _report(out, options, frame, summary, mosaic)
    atomic_write_bytes(out / "summary.json", json.dumps(summary, indent=2, allow_nan=True).encode())
    return summary


def analyse(frame) -> dict:
    """Headline numbers: max range per camera, drive and tracker; colour separability per
    camera and drive; cameras ranked by their best drive's maximum range (best tracker, to
    0.1 m), then by that drive's colour separability."""
    summary: dict = {"study": NAME, "max_range": [], "colour_separability": [], "ranking": []}
    keys = ["camera", "beacon", "environment", "led_current_mA", "tracker"]
    for key, g in frame[frame.estimator == "best"].groupby(keys):
        mr = estimate_max_range(g.to_dict("records"))
        summary["max_range"].append({**dict(zip(keys, key, strict=True)), **mr.to_dict()})
    frames = frame[(frame.tracker == "best") & (frame.estimator == "best")]  # one row per frame
    for (camera, current), g in frames.groupby(["camera", "led_current_mA"]):
        summary["colour_separability"].append({"camera": camera, "led_current_mA": current, **colour_separability(g)})
    best: dict[str, tuple[float, float, float]] = {}  # camera -> (max range, separability, current)
    for rec in summary["max_range"]:
        if rec["tracker"] != "best":
            continue
        sep = next(
            (
                s["min_mahalanobis"]
                for s in summary["colour_separability"]
                if s["camera"] == rec["camera"] and s["led_current_mA"] == rec["led_current_mA"]
            ),
            None,
        )
        # ranges compared to 0.1 m: finer differences are the pose jitter of the farthest frames
        cand = (round(rec["max_range_m"], 1), np.nan_to_num(sep if sep is not None else 0.0), rec["led_current_mA"])
        if rec["camera"] not in best or cand[:2] > best[rec["camera"]][:2]:
            best[rec["camera"]] = cand
    ranking = sorted(best, key=lambda c: (-best[c][0], -best[c][1]))
    summary["ranking"] = [
        {
            "rank": i + 1,
            "camera": c,
            "max_range_m": best[c][0],
            "at_led_current_mA": best[c][2],
            "min_colour_mahalanobis": best[c][1],
        }
        for i, c in enumerate(ranking)
    ]
    return summary


def colour_separability(frames) -> dict:
    """Pairwise separability of the sides' marker colours seen by one camera.

    Each frame contributes its five markers' chromaticities (r, g); the distance
    between two sides is the Mahalanobis distance of their chromaticity samples under
    the pooled covariance, and ΔE2000 compares their mean sRGB colours.
    """
    samples, means = {}, {}
    for side, g in frames.groupby("side"):
        chroma = np.array(
            [
                [row[f"marker{i}_r_chroma"], row[f"marker{i}_g_chroma"]]
                for row in g.to_dict("records")
                for i in range(1, 6)
            ]
        )
        srgb = np.array([[row[f"marker{i}_{c}"] for c in "RGB"] for row in g.to_dict("records") for i in range(1, 6)])
        samples[side] = chroma[np.all(np.isfinite(chroma), axis=1)]
        means[side] = np.nanmean(srgb, axis=0)
    pairs = []
    for a, b in itertools.combinations(sorted(samples), 2):
        pairs.append(
            {
                "pair": f"{a}-{b}",
                "mahalanobis": mahalanobis_separability(samples[a], samples[b]),
                "delta_e_2000": delta_e_2000(means[a], means[b]),
            }
        )
    m = [p["mahalanobis"] for p in pairs if np.isfinite(p["mahalanobis"])]
    return {
        "pairs": pairs,
        "min_mahalanobis": float(min(m)) if m else None,
        "mean_srgb": {k: v.tolist() for k, v in means.items()},
    }


def mosaic_png(options: StudyOptions, out: Path) -> bytes:
    """The same target at 2, 5 and 7 m through every camera (first side and beacon)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cams = options.cameras
    beacon = "v2" if "v2" in options.beacons else options.beacons[0]  # V1's markers face sideways
    fig, axes = plt.subplots(
        len(cams),
        len(MOSAIC_RANGES_M),
        figsize=(2.6 * len(MOSAIC_RANGES_M), 2.6 * len(cams)),
        squeeze=False,
        constrained_layout=True,
    )
    for i, cam in enumerate(cams):
        for j, r in enumerate(MOSAIC_RANGES_M):
            cond = grid_conditions(
                StudyOptions(
                    cameras=(cam,),
                    beacons=(beacon,),
                    sides=options.sides[:1],
                    ranges_m=(r,),
                    environments=options.environments[:1],
                    currents_mA=options.currents_mA,
                    diffusers=options.diffusers[:1],
                )
            )
            task = frame_tasks(cond, StudyOptions(cameras=(cam,), seeds=1, jitter_poses=1, render=options.render))[0]
            png = target_crop_png(task)
            img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
            ax = axes[i, j]
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"{r:g} m")
            if j == 0:
                ax.set_ylabel(cam, fontsize=9)
    fig.suptitle(
        f"{beacon.upper()} {options.sides[0]} side at {options.currents_mA[0]:g} mA, 240 mm square around marker 1\n"
        "saved JPEG, camera pixels shown as blocks"
    )

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write_bytes(out / "mosaic.png", buf.getvalue())
    return buf.getvalue()


def _report(out: Path, options: StudyOptions, frame, summary: dict, mosaic: bytes) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("Webcam vs DSLR: how far each camera sees the beacon, and whether it keeps the colours")
    rep.text(
        f"{len(frame) // 4} frames: cameras {', '.join(options.cameras)}; beacons {', '.join(options.beacons)}; "
        f"sides {', '.join(options.sides)}; ranges {', '.join(f'{r:g}' for r in options.ranges_m)} m; "
        f"environments {', '.join(options.environments)}; {options.seeds} seeds per condition. Markers: foam + 1 "
        "sheet of matched paper at the datasheet current; T6 at ISO 6400, 1/60 s; webcams expose automatically."
    )
    rep.heading("Ranking")
    rep.table(pd.DataFrame(summary["ranking"]), "Cameras by maximum range (best tracker), then colour separability")
    rep.heading("Detection probability versus range")
    curve = detection_curve(frame[frame.estimator == "best"], ["camera", "tracker", "led_current_mA", "beacon"])
    currents = sorted(set(curve.led_current_mA))
    fig, axes = plt.subplots(
        2, len(currents), figsize=(5.5 * len(currents), 7), sharex=True, sharey=True, squeeze=False
    )
    colours = {cam: f"C{i}" for i, cam in enumerate(options.cameras)}
    for (i, tracker), (j, current) in itertools.product(enumerate(("thesis", "best")), enumerate(currents)):
        ax = axes[i][j]
        sel = curve[(curve.tracker == tracker) & (curve.led_current_mA == current)]
        for (cam, beacon), g in sel.groupby(["camera", "beacon"]):
            ax.errorbar(
                g.nominal_range_m,
                g.p_detect,
                yerr=[np.clip(g.p_detect - g.p_low, 0, None), np.clip(g.p_high - g.p_detect, 0, None)],
                marker="o" if beacon == "v2" else "s",
                ls="-" if beacon == "v2" else ":",
                color=colours.get(cam),
                capsize=3,
                label=f"{cam}, {beacon}",
            )
        ax.axhline(0.95, color="grey", ls=":", lw=1)
        ax.set_title(f"{tracker} tracker, {current:g} mA", fontsize=10)
        ax.set_xlabel("range, m")
        ax.set_ylabel("P(correct side, 5 markers numbered)")
    axes[0][-1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    rep.figure(
        fig,
        "Probability of a correct detection with Wilson 95 % intervals, over sides, environments and seeds; "
        "dotted line: 0.95.",
    )
    rep.heading("Maximum range")
    rep.table(
        pd.DataFrame(summary["max_range"]).drop(columns=["frames", "successes"]),
        "Largest range with P(correct) ≥ 0.95 (logistic fit, bootstrap 95 % interval) and the limiting cause",
    )
    rep.heading("Colour separability")
    rows = [{"camera": s["camera"], **p} for s in summary["colour_separability"] for p in s["pairs"]]
    if rows:
        rep.table(pd.DataFrame(rows), "Pairwise separability of side colours (chromaticity Mahalanobis; ΔE2000)")
    frames = frame[frame.estimator == "best"]
    for tracker in ("thesis", "best"):
        g = frames[frames.tracker == tracker]
        sides = sorted(set(g.side))
        labels = list(sides) + [c for c in ("red", "green", "blue", "yellow") if c not in sides]
        for cam, gc in g.groupby("camera"):
            m = confusion_matrix(list(gc.side), [x if isinstance(x, str) else None for x in gc.side_detected], labels)
            table = pd.DataFrame(m[: len(sides)], columns=[*labels, "none"])
            table.insert(0, "true side", sides)
            rep.table(table, f"Colour confusion, {tracker} tracker, {cam} (frames)", float_format="{:.0f}")
    rep.heading("Mosaic")
    rep.image_png(mosaic, "The same target at 2, 5 and 7 m as each camera saves it")
    rep.write(out / "report.html")
