"""Study ``webcam-vs-dslr``: which camera sees the beacon farthest and keeps its colours.

Sweep: cameras × beacons × sides × ranges × environments × seeds (with pose jitter),
markers as the study built them (foam + 1 sheet of matched paper, datasheet current),
each camera at its study settings (T6 manual ISO 6400, 1/60 s; webcams automatic).
Outputs: detection probability versus range per camera and tracker (Wilson 95 %),
maximum range (:mod:`studies.engine.max_range`), colour separability of the sides in
linear-RGB chromaticity (pairwise Mahalanobis distance, ΔE2000 of mean colours) and the
detectors' colour confusion matrices, a ranking, and the study's image mosaic (the same
target at 2, 5 and 7 m through every camera).

With a :class:`studies.engine.sequential.SequentialDesign` (``run(..., design=...)``) the
range grid is the coarse start of a sequential design per camera × beacon × room × drive
(both sides pooled, as the working range pools them) and every working-range record says
how many frames decided it.
"""

from __future__ import annotations

import io
import itertools
import math
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.frame import target_crop_png
from studies.engine.max_range import (
    estimate_max_range,
    far_interval_text,
    far_limit_text,
    near_failures_text,
    working_range_text,
    works_best_key,
)
from studies.engine.metrics import bayes_error, confusion_matrix, delta_e_2000, mahalanobis_separability
from studies.engine.report import Report
from studies.engine.sequential import (
    SequentialDesign,
    decision_text,
    design_evidence,
    run_design,
    summary_p_working,
)
from studies.engine.sweep import Execution, sweep
from studies.engine.tables import detection_curve, write_tables
from studies.engine.tasks import StudyOptions, frame_tasks, grid_conditions
from studies.engine.uncertainty import (
    far_limits_at_points,
    interval_text,
    nominal_rows,
    over_points,
    physics_interval,
    physics_note,
    point_rows,
    values_at_points,
)

__all__ = [
    "CAMERA_STYLES",
    "DRIVES_MA",
    "FULL_UNIT_BUDGET_FRAMES",
    "NAME",
    "RANGE_LABELS",
    "UNIT_FIELDS",
    "analyse",
    "colour_separability",
    "confusions",
    "default_design",
    "default_options",
    "lead_lines",
    "mosaic_png",
    "run",
    "separability_interval_text",
    "separability_text",
    "small_probability",
    "write_outputs",
]

NAME = "webcam-vs-dslr"
ALL_CAMERAS = ("logitech-c270", "spedal-920", "canon-t6-18mm", "canon-t6-10mm")
MOSAIC_RANGES_M = (2.0, 5.0, 7.0)
DRIVES_MA = (2.0, 20.0)
"""LED drive: the study dimmed its LEDs with potentiometers to an unknown setting, so the
sweep brackets it: 20 mA (datasheet test current) and 2 mA (a tenth, well dimmed)."""
FULL_UNIT_BUDGET_FRAMES = 600
"""Frames one working-range record of the full design may spend (assumed: 2.5 times the
average share of 240, above the 560 that the most demanding decided record needed in the frame
version 9 run, where one record whose P stayed near 0.95, the T6 10 mm at 20 mA in the dark, took
3 472 of the 7 680 frames and stayed undecided)."""
UNIT_FIELDS = (
    ("camera", "camera"),
    ("beacon", "beacon"),
    ("environment", "environment"),
    ("led_current_mA", "led_current_mA"),
)
"""A sequential design's unit (condition field, row column): one working-range record's
frames (sides and yaws pooled), without the tracker."""


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


def default_design(quick: bool) -> SequentialDesign:
    """The sequential design the main job runs (quick) or a full run starts from: far and near
    limits to ±20 %, extended to 16 m when the farthest range still works; the quick one
    within 60 slots (120 frames over its 2 sides) per unit (assumed: the fake of known truth
    needs 60-150 frames at ±20 %, ``tests/studies/test_sequential.py``), the full one within
    240 frames per unit on average (the default) and :data:`FULL_UNIT_BUDGET_FRAMES` for any one."""
    grid = default_options(quick)
    units = len(grid.cameras) * len(grid.beacons) * len(grid.environments) * len(grid.currents_mA)
    per_slot = len(grid.sides) * len(grid.yaws_deg) * len(grid.diffusers)
    if quick:
        return SequentialDesign(target_relative=0.2, budget_frames=60 * per_slot * units, max_range_m=16.0)
    return SequentialDesign(target_relative=0.2, unit_budget_frames=FULL_UNIT_BUDGET_FRAMES, max_range_m=16.0)


def run(
    out: Path, options: StudyOptions, execution: Execution = Execution(), design: SequentialDesign | None = None
) -> dict:
    """Run the study into ``out``; returns the summary.

    ``design``: place the frames sequentially (:mod:`studies.engine.sequential`), starting from
    ``options``' grid; None: the fixed grid."""
    if design is None:
        frame = sweep(NAME, grid_conditions(options), options, out, execution=execution)
        mosaic_png(options, out)
        return write_outputs(out, options, frame)
    fields, design = over_points(UNIT_FIELDS, design, len(options.physics))
    result = run_design(NAME, options, design, out, fields, execution=execution)
    frame = write_tables(out, result.rows)
    mosaic_png(options, out)
    return write_outputs(out, options, frame, result.summary())


def write_outputs(out: Path, options: StudyOptions, frame: pd.DataFrame, design: dict | None = None) -> dict:
    """summary.json and report.html of a finished sweep's results table (the mosaic is
    taken from ``out/mosaic.png`` where :func:`mosaic_png` wrote it); returns the summary.
    ``design``: :meth:`studies.engine.sequential.DesignResult.summary` when a sequential
    design placed the frames."""
    out = Path(out)
    summary = analyse(frame, design)
    if options.physics:
        summary["physics"] = {"points": len(options.physics), "source": options.physics_source}
    mosaic = (out / "mosaic.png").read_bytes() if (out / "mosaic.png").is_file() else None
    _report(out, options, nominal_rows(frame), summary, mosaic)
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def analyse(frame, design: dict | None = None) -> dict:
    """Headline numbers.

    * ``max_range``: the working range per camera, beacon, environment, drive and tracker
      (best estimator; :class:`studies.engine.max_range.MaxRange` fields and their wording);
    * ``colour_separability``: per camera and drive, the sides' pairwise separability and how
      many of the best tracker's detections named the right side (``right_colour`` of
      ``detections``) and which sides the others were named (``confused``, :func:`confusions`);
    * ``ranking``: cameras by the far limit of the drive that works best for them (best tracker;
      :func:`studies.engine.max_range.works_best_key`: far limit to 0.1 m, then the fraction of
      frames correct; ``at_least``: no fall-off up to the farthest range tried, printed "≥"),
      then by that fraction and that drive's colour separability; ``tied_on_range`` names the
      cameras whose far limits are equal;
    * ``yaws_deg``: the yaws swept (every record pools them);
    * with rows at points of the unknowns (``--uncertainty``; every other number is the nominal
      point's): ``far_physics``/``far_interval_physics`` on each ``max_range`` record and
      ``separability_physics``/``separability_interval_physics`` (the closest pair's d at each
      point, :func:`studies.engine.uncertainty.physics_interval`) on each ``colour_separability``
      record, both carried into ``ranking``;
    * ``design`` (with a sequential ``design``, its summary): then each ``max_range`` record
      says how many frames decided it (``decision``, ``far_decided``, ``near_decided``,
      ``design_stop``: the best tracker's, which placed the frames).
    """
    summary: dict = {"study": NAME, "max_range": [], "colour_separability": [], "ranking": []}
    units = {tuple(u["key"]): u for u in (design or {}).get("units", [])}
    at_points = point_rows(frame)
    frame = nominal_rows(frame)
    keys = ["camera", "beacon", "environment", "led_current_mA", "tracker"]
    level = summary_p_working(design)
    best = at_points[at_points.estimator == "best"] if len(at_points) else at_points
    far_physics = far_limits_at_points(best, keys, p_working=level) if len(at_points) else {}
    seen = at_points[(at_points.tracker == "best") & (at_points.estimator == "best")] if len(at_points) else at_points
    sep_physics = values_at_points(seen, ["camera", "led_current_mA"], _closest_pair)
    if "nominal_yaw_deg" in frame:
        summary["yaws_deg"] = sorted(float(y) for y in set(frame.nominal_yaw_deg))
    for key, g in frame[frame.estimator == "best"].groupby(keys):
        rec = {
            **dict(zip(keys, key, strict=True)),
            **estimate_max_range(g.to_dict("records"), p_working=level).to_dict(),
        }
        rec.update(
            working_range=working_range_text(rec),
            far_limit=far_limit_text(rec),
            far_interval=far_interval_text(rec),
            failures_nearer=near_failures_text(rec),
        )
        if key in far_physics:
            iv = physics_interval(far_physics[key])
            # each point's far limit in point order (0: no range works; inf, null in JSON: ≥ the farthest tried)
            far = iv.to_dict() | {"at_points_m": far_physics[key]}
            rec.update(far_physics=far, far_interval_physics=interval_text(iv, zero="none"))
        if design is not None:
            unit = units.get((rec["camera"], rec["beacon"], rec["environment"], float(rec["led_current_mA"])))
            rec.update(
                decision=decision_text(rec, unit),
                far_decided=bool(unit and unit["far_decided"]),
                near_decided=bool(unit and unit["near_decided"]),
                design_stop=unit["stop"] if unit else "",
            )
        summary["max_range"].append(rec)
    frames = frame[(frame.tracker == "best") & (frame.estimator == "best")]  # one row per frame
    for (camera, current), g in frames.groupby(["camera", "led_current_mA"]):
        detected = g[g.detected.astype(bool)]
        summary["colour_separability"].append(
            {
                "camera": camera,
                "led_current_mA": float(current),
                **colour_separability(g),
                "frames": len(g),
                "detections": len(detected),
                "right_colour": int(detected.side_correct.astype(bool).sum()),
                "confused": confusions(detected),
            }
        )
        if (camera, current) in sep_physics:
            iv = physics_interval(sep_physics[(camera, current)])
            summary["colour_separability"][-1].update(
                separability_physics=iv.to_dict(), separability_interval_physics=separability_interval_text(iv)
            )
    best: dict[str, dict] = {}
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
        # the drive that works best: the farthest limit, then the most frames correct, then separability
        reach, correct = works_best_key(rec)
        cand = {"reach": reach, "correct": correct, "sep": sep if sep is not None and not math.isnan(sep) else 0.0}
        cand["sep_physics"] = next(
            (
                s.get("separability_interval_physics")
                for s in summary["colour_separability"]
                if s["camera"] == rec["camera"] and s["led_current_mA"] == rec["led_current_mA"]
            ),
            None,
        )
        cand["rec"] = rec
        old = best.get(rec["camera"])
        if old is None or (reach, correct, cand["sep"]) > (old["reach"], old["correct"], old["sep"]):
            best[rec["camera"]] = cand
    ranking = sorted(best, key=lambda c: (-best[c]["reach"], -best[c]["correct"], -best[c]["sep"]))
    for i, c in enumerate(ranking):
        rec = best[c]["rec"]
        tied = [o for o in ranking if o != c and best[o]["reach"] == best[c]["reach"]]
        summary["ranking"].append(
            {
                "rank": i + 1,
                "camera": c,
                "max_range_m": best[c]["reach"],
                "at_least": bool(rec["at_least"]),
                "far_limit": rec["far_limit"],
                "far_interval": rec["far_interval"],
                "working_range": rec["working_range"],
                "at_led_current_mA": rec["led_current_mA"],
                "correct": f"{rec['successes']} of {rec['frames']}",
                "environment": rec["environment"],
                "beacon": rec["beacon"],
                "min_colour_mahalanobis": best[c]["sep"],
                "tied_on_range": tied,
                **({"far_interval_physics": rec["far_interval_physics"]} if "far_interval_physics" in rec else {}),
                **({"separability_interval_physics": best[c]["sep_physics"]} if best[c]["sep_physics"] else {}),
            }
        )
    if design is not None:
        summary["design"] = design
    return summary


def colour_separability(frames) -> dict:
    """Pairwise separability of the sides' marker colours seen by one camera.

    Each frame contributes its five markers' chromaticities (r, g); the distance
    between two sides is the Mahalanobis distance of their chromaticity samples under
    the pooled covariance (inf: they do not overlap in any direction, a perfect
    separation; ``no_overlap`` says so where standard JSON writes the inf as null), with the
    Bayes error Φ(−d/2) of two Gaussian classes that far apart; ΔE2000 compares their mean
    sRGB colours. ``min_mahalanobis`` is the closest pair's distance (None without two sides
    with samples; ``no_overlap`` at the record: every pair is perfectly separated).
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
        d = mahalanobis_separability(samples[a], samples[b])
        pairs.append(
            {
                "pair": f"{a}-{b}",
                "mahalanobis": d,
                "no_overlap": d == math.inf,
                "bayes_error": bayes_error(d) if not math.isnan(d) else math.nan,
                "delta_e_2000": delta_e_2000(means[a], means[b]),
            }
        )
    m = [p["mahalanobis"] for p in pairs if not math.isnan(p["mahalanobis"])]
    return {
        "pairs": pairs,
        "min_mahalanobis": float(min(m)) if m else None,
        "no_overlap": bool(m) and min(m) == math.inf,
        "mean_srgb": {k: v.tolist() for k, v in means.items()},
    }


def _closest_pair(frames) -> float:
    """The closest pair's Mahalanobis distance of one point's frames (inf: no overlap; NaN: fewer
    than two sides seen, a point left out of the interval)."""
    d = colour_separability(frames)["min_mahalanobis"]
    return math.nan if d is None else float(d)


def separability_interval_text(iv) -> str:
    """The closest pair's distance over the points in words: "d 4.1 to 9.3 (88 %, 16 points)", an
    end at ∞ read "no overlap"."""
    low = "no overlap" if math.isinf(iv.low) else f"{iv.low:.3g}"
    high = "no overlap" if math.isinf(iv.high) else f"{iv.high:.3g}"
    span = low if iv.low == iv.high else f"{low} to {high}"
    return f"d {span} ({100 * iv.rate:.0f} %, {iv.points} points)"


def confusions(detected) -> list[dict]:
    """The detections that named a wrong side, counted per true and named side:
    ``[{"true": "red", "named": "yellow", "frames": 3}, ...]``, most frames first."""
    wrong = detected[~detected.side_correct.astype(bool)]
    counts = wrong.groupby([wrong.side, wrong.side_detected.astype(str)]).size()
    rows = [{"true": t, "named": n, "frames": int(k)} for (t, n), k in counts.items()]
    return sorted(rows, key=lambda r: (-r["frames"], r["true"], r["named"]))


def separability_text(sep: dict) -> str:
    """A camera's colour separability in words, over every pair of the sides that were run, with
    the confusion observed beside it: "closest pair green-red, d = 9.03 (Gaussian-model error
    3.2e-06), of 1 pair among the sides run (green, red); observed: 13 of 16 detections the right
    colour, 3 red named yellow (a side not run)", from a ``colour_separability`` record."""
    pairs = [
        {**p, "mahalanobis": math.inf if p.get("no_overlap") else p["mahalanobis"]} for p in sep.get("pairs", [])
    ]  # a summary read back from standard JSON has null for inf (``no_overlap``) and for NaN
    pairs = [p for p in pairs if p["mahalanobis"] is not None and not math.isnan(p["mahalanobis"])]
    if not pairs:
        return "not measured (fewer than two sides seen)"
    run = sorted({side for p in pairs for side in p["pair"].split("-")})
    among = f"of {len(pairs)} pair{'s' if len(pairs) > 1 else ''} among the sides run ({', '.join(run)})"
    worst = min(pairs, key=lambda p: p["mahalanobis"])
    if math.isinf(worst["mahalanobis"]):
        text = f"no overlap in any {among.removeprefix('of ')}"
    else:
        text = (
            f"closest pair {worst['pair']}, d = {worst['mahalanobis']:.3g} "
            f"(Gaussian-model error {small_probability(worst['bayes_error'])}), {among}"
        )
    if "detections" not in sep:
        return text
    observed = f"{sep['right_colour']} of {sep['detections']} detections the right colour"
    named = [
        f"{c['frames']} {c['true']} named {c['named']}" + ("" if c["named"] in run else " (a side not run)")
        for c in sep.get("confused", [])
    ]
    return f"{text}; observed: {observed}" + (f", {', '.join(named)}" if named else "")


def small_probability(p: float) -> str:
    """A probability to 2 significant figures, "< 1e-6" below 10⁻⁶."""
    return "< 1e-6" if p < 1e-6 else f"{p:.2g}"


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
            one = StudyOptions(cameras=(cam,), seeds=1, jitter_poses=1, render=options.render, frame="crop")
            task = frame_tasks(cond, one)[0]
            png = target_crop_png(task)
            img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
            ax = axes[i, j]
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(f"{r:g} m", fontsize=13)
            if j == 0:
                ax.set_ylabel(cam, fontsize=12)
    fig.suptitle(
        f"{beacon.upper()} {options.sides[0]} side at {options.currents_mA[0]:g} mA, 240 mm square around marker 1\n"
        "saved JPEG, camera pixels shown as blocks"
    )

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(out / "mosaic.png", buf.getvalue())
    return buf.getvalue()


RANGE_LABELS = {
    "camera": "camera",
    "beacon": "beacon",
    "environment": "room",
    "led_current_mA": "LED drive, mA",
    "tracker": "tracker",
    "working_range": "working range (P ≥ 0.95)",
    "far_interval": "far limit, 95 % interval",
    "limiting_cause": "what ends it",
    "failures_nearer": "failures nearer than the best range",
    "correct": "correct frames",
}
"""Columns of the working-range table and their headers."""
CAMERA_STYLES = {
    "logitech-c270": {"color": "C0", "marker": "o", "ls": "-"},
    "spedal-920": {"color": "C1", "marker": "s", "ls": "--"},
    "canon-t6-18mm": {"color": "C2", "marker": "^", "ls": "-."},
    "canon-t6-10mm": {"color": "C3", "marker": "D", "ls": ":"},
}
"""A colour, marker and line style per camera, the same in every panel."""


def lead_lines(summary: dict) -> list[str]:
    """The answer in sentences: the ranking (with ties said as ties) and, per camera, its best
    drive's working range and colour separability."""
    ranking = summary["ranking"]
    if not ranking:
        return ["No frames."]
    lines = []
    top = ranking[0]
    if top["tied_on_range"]:
        names = ", ".join([top["camera"], *top["tied_on_range"]])
        lines.append(
            f"Tied on range: {names} all reach {top['far_limit']}"
            + (" (the farthest range tried), so this sweep cannot rank them by range" if top["at_least"] else "")
            + f"; ranked by colour separability, {top['camera']} comes first."
        )
    else:
        lines.append(f"Farthest: {top['camera']}, {top['far_limit']} at {top['at_led_current_mA']:g} mA.")
    seps = {(s["camera"], s["led_current_mA"]): s for s in summary["colour_separability"]}
    for r in ranking:
        sep = seps.get((r["camera"], r["at_led_current_mA"]), {})
        colour = separability_text(sep) if sep else "not measured"
        lines.append(
            f"{r['rank']}. {r['camera']} at {r['at_led_current_mA']:g} mA ({r['beacon'].upper()}, {r['environment']}): "
            f"works {r['working_range']} (far limit 95 % interval {r['far_interval']}; {r['correct']} frames "
            f"correct); colour separability {colour}." + _physics_words(r)
        )
    return lines


def _physics_words(r: dict) -> str:
    """A ranking record's noise + physics intervals in a sentence ("" without ``--uncertainty``)."""
    parts = [
        f"{label} {r[key]}"
        for key, label in (("far_interval_physics", "far limit"), ("separability_interval_physics", "closest pair"))
        if r.get(key)
    ]
    return f" With the unknowns (noise + physics): {'; '.join(parts)}." if parts else ""


def _report(out: Path, options: StudyOptions, frame, summary: dict, mosaic: bytes | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("Webcam vs DSLR: how far each camera sees the beacon, and whether it keeps the colours")
    per_point = frame[(frame.tracker == "best") & (frame.estimator == "best")].groupby(
        ["camera", "beacon", "side", "environment", "led_current_mA", "nominal_range_m"]
    )
    evidence = (
        design_evidence(summary)
        if summary.get("design")
        else f"Evidence: {int(per_point.size().min()) if len(frame) else 0} frames per camera, side, range and drive."
    )
    rep.lead(
        [
            *lead_lines(summary),
            f"{evidence} An interval from 0 m means the frames cannot exclude that no range reaches P ≥ 0.95; "
            "'≥' means no fall-off up to the farthest range tried.",
            *physics_note(summary),
        ]
    )
    currents = sorted(set(frame.led_current_mA))
    rep.text(
        f"{len(frame) // 4} frames: cameras {', '.join(options.cameras)}; beacons {', '.join(options.beacons)}; "
        f"sides {', '.join(options.sides)}; ranges {', '.join(f'{r:g}' for r in options.ranges_m)} m; "
        f"environments {', '.join(options.environments)}; LED drive {' and '.join(f'{c:g}' for c in currents)} mA "
        "(20 mA is the datasheet's test current; the study dimmed its LEDs to an unrecorded setting); "
        f"{options.seeds} seeds per condition. Markers: foam + 1 sheet of matched paper; T6 at ISO 6400, 1/60 s; "
        "webcams expose automatically."
    )
    rep.heading("Ranking")
    ranking = pd.DataFrame(summary["ranking"])
    if not ranking.empty:
        ranking = ranking.assign(tied_on_range=[", ".join(t) or "–" for t in ranking.tied_on_range])
        columns = ["rank", "camera", "far_limit", "far_interval", "far_interval_physics", "at_led_current_mA"]
        columns += ["correct", "min_colour_mahalanobis", "separability_interval_physics", "tied_on_range"]
        rep.table(
            ranking[[c for c in columns if c in ranking]],
            "Cameras by far limit (best tracker, at the drive that works best for each: farthest limit, then most "
            "frames correct), then colour separability",
            labels={
                "far_limit": "far limit",
                "far_interval": "far limit, 95 % interval",
                "far_interval_physics": "far limit, noise + physics",
                "separability_interval_physics": "closest pair, noise + physics",
                "at_led_current_mA": "at LED drive, mA",
                "correct": "frames correct at that drive",
                "min_colour_mahalanobis": "colour separability (closest pair, Mahalanobis d)",
                "tied_on_range": "tied on range with",
            },
            formats={"at_led_current_mA": "{:g}", "min_colour_mahalanobis": "{:.3g}"},
            css_class="keys",
        )
    rep.heading("Detection probability versus range")
    rep.figure(
        _curves_figure(plt, frame, options),
        "Fraction of frames with a correct detection (right side, five markers numbered), with Wilson 95 % "
        "intervals, over sides, environments and seeds; dotted line: 0.95. One colour, marker and line style per "
        "camera; the cameras' points are offset sideways so that equal curves stay visible.",
    )
    rep.heading("Working range")
    table = pd.DataFrame(summary["max_range"])
    table = table.assign(
        correct=[f"{k} of {n}" for k, n in zip(table.successes, table.frames, strict=True)],
        failures_nearer=[t or "– (none tried nearer)" for t in table.failures_nearer],
    )
    labels = {**RANGE_LABELS, **({"decision": "frames that decided it"} if "decision" in table else {})}
    rep.table(
        table[list(labels)],
        "Where P(correct pose) ≥ 0.95 (logistic rise and fall-off; profile-likelihood 95 % interval) and what ends it",
        labels=labels,
        formats={"led_current_mA": "{:g}"},
        css_class="keys",
    )
    rep.heading("Colour separability")
    rows = [
        {
            "camera": s["camera"],
            "led_current_mA": s["led_current_mA"],
            **{k: v for k, v in p.items() if k != "no_overlap"},
            "right_colour": f"{s['right_colour']} of {s['detections']}",
            "confused": ", ".join(f"{c['frames']} {c['true']} as {c['named']}" for c in s.get("confused", [])) or "–",
        }
        for s in summary["colour_separability"]
        for p in s["pairs"]
    ]
    if rows:
        rep.table(
            pd.DataFrame(rows),
            "Pairwise separability of the sides' colours per camera and LED drive, over every pair of the sides run "
            "(marker chromaticities, best tracker's frames; inf: the samples do not overlap), with the confusion the "
            "best tracker's detections showed beside it (a side not run can still be named)",
            labels={
                "led_current_mA": "LED drive, mA",
                "pair": "sides",
                "mahalanobis": "Mahalanobis d",
                "bayes_error": "Gaussian-model error Φ(−d/2)",
                "delta_e_2000": "ΔE2000 of mean colours",
                "right_colour": "observed: detections of the right colour",
                "confused": "observed: named wrongly",
            },
            formats={
                "led_current_mA": "{:g}",
                "mahalanobis": "{:.3g}",
                "bayes_error": small_probability,
                "delta_e_2000": "{:.3g}",
            },
            css_class="keys",
        )
    frames = frame[frame.estimator == "best"]
    for tracker in ("best", "thesis"):
        g = frames[frames.tracker == tracker]
        sides = sorted(set(g.side))
        labels = list(sides) + [c for c in ("red", "green", "blue", "yellow") if c not in sides]
        blocks = []
        for (cam, current), gc in g.groupby(["camera", "led_current_mA"]):
            m = confusion_matrix(list(gc.side), [x if isinstance(x, str) else None for x in gc.side_detected], labels)
            block = pd.DataFrame(m[: len(sides)], columns=[*(f"as {c}" for c in labels), "not found"])
            block.insert(0, "true side", sides)
            block.insert(0, "LED drive, mA", f"{current:g}")
            block.insert(0, "camera", cam)
            blocks.append(block)
        if blocks:
            rep.table(
                pd.concat(blocks, ignore_index=True),
                f"Colour confusion, {tracker} tracker: frames of each true side by the side the tracker named",
                float_format="{:.0f}",
                css_class="keys",
            )
    if mosaic is not None:
        rep.heading("Mosaic")
        rep.image_png(mosaic, "The same target at 2, 5 and 7 m as each camera saves it")
    rep.write(out / "report.html")


def _curves_figure(plt, frame, options: StudyOptions):
    """P(correct detection) versus range: rows the trackers, columns the drives."""
    curve = detection_curve(frame[frame.estimator == "best"], ["camera", "tracker", "led_current_mA", "beacon"])
    currents = sorted(set(curve.led_current_mA))
    cams = [c for c in options.cameras if c in set(curve.camera)] + sorted(set(curve.camera) - set(options.cameras))
    ranges = sorted(set(curve.nominal_range_m))
    step = min(np.diff(ranges)) if len(ranges) > 1 else 1.0
    fig, axes = plt.subplots(
        2,
        len(currents),
        figsize=(min(4.4 * len(currents), 8.6) + 2.4, 7.6),
        sharex=True,
        sharey=True,
        squeeze=False,
        constrained_layout=True,
    )
    series = [(cam, beacon) for cam in cams for beacon in sorted(set(curve.beacon))]
    for (i, tracker), (j, current) in itertools.product(enumerate(("best", "thesis")), enumerate(currents)):
        ax = axes[i][j]
        sel = curve[(curve.tracker == tracker) & (curve.led_current_mA == current)]
        for n, (cam, beacon) in enumerate(series):
            g = sel[(sel.camera == cam) & (sel.beacon == beacon)]
            if g.empty:
                continue
            style = dict(CAMERA_STYLES.get(cam, {"color": f"C{4 + n % 6}", "marker": "v", "ls": "-"}))
            if beacon != "v2":
                style.update(ls=(0, (1, 3)), mfc="white")
            dx = (n - (len(series) - 1) / 2) * 0.05 * step
            ax.errorbar(
                g.nominal_range_m + dx,
                g.p_detect,
                yerr=[np.clip(g.p_detect - g.p_low, 0, None), np.clip(g.p_high - g.p_detect, 0, None)],
                capsize=3,
                lw=1.6,
                ms=7,
                label=f"{cam}, {beacon.upper()}",
                **style,
            )
        ax.axhline(0.95, color="grey", ls=":", lw=1)
        ax.set_title(f"{tracker} tracker, {current:g} mA", fontsize=11)
        if len(ranges) <= 12:
            ax.set_xticks(ranges)
        else:  # a sequential design's added ranges: let matplotlib space the ticks
            ax.xaxis.set_major_locator(plt.MaxNLocator(nbins=10, steps=[1, 2, 5, 10]))
        if i == 1:
            ax.set_xlabel("range, m", fontsize=10)
        if j == 0:
            ax.set_ylabel("P(correct detection)", fontsize=10)
    handles, labels = axes[0][0].get_legend_handles_labels()
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, fontsize=9, loc="outside right center")
    return fig
