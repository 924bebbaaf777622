"""``beacon-sim validate``: the simulation's predictions for each test the source study ran.

Tests (docs/source-study.md §10), all with the study's own tracker, thresholds, QUEST weights
and camera settings (T6 ISO 6400, 1/60 s; webcams automatic):

* preliminary: beacon 150 mm from the C270 webcam, each colour, lights on and off
  (V1: the first build, whose 90 mm cross fits the webcam's 136 mm field at 150 mm —
  V2's 140 mm cross does not);
* range test: C270 and T6 + 18 mm at 2, 5, 7 and 10 m, room lights on and off, V1 and V2;
* primary test: V2, T6 with the 18 mm and 10 mm lenses, 1-5 m × 0-30° yaw, lights off;
* weight experiment: T6 with the 18 mm and 10 mm lenses at 1 m over 0-30° yaw in 5° (0° and 30°
  quick), QUEST with equal weights (0.25 each) and the tuned (0.05, 0.05, 0.45, 0.45), each without
  rectification and rectified with alpha 0 and 1 (at yaw 0 a relative yaw error is undefined);
* V1 vs V2: the side-to-centre marker flux ratio at 2 m (``v1_vs_v2.csv``).

Frames are the camera's whole saved frame (``full_frame``), which the study's tracker scales
to 50 % (the T6) as the study processed them: every false blob a frame holds is there.

Markers as built: foam + one sheet of paper. What the study did not record (the dimmer's
setting, paper colour, webcam, lens focus, glare, ISP, …) comes from a set of points
(``calibration``, :mod:`studies.catalog.prediction_set`): a history match's NROY set (the primary
test's side is then the point's) or an unknowns search's calibrated set; every test runs at each
of its points. Without one, the unknowns stay nominal (matched paper, the datasheet current).
Red side unless the test says each colour (or the point gives the primary test's side). The
study's tracker runs with its printed settings except where the study says a session changed them
(:func:`session_settings`).
``validation.csv`` has one row per tested condition (means over seeds and points;
``detected_low``/``high`` span the Wilson 95 % intervals of every point, i.e. an interval over the
set and the seeds; ``points`` counts them; ``extra_blobs``/``merged``/``lost_fraction`` say why
frames were missed; ``focus_distance_m_low``/``high`` span the lens focus over the points, NaN for
the fixed-focus webcams); the report marks the study's headline conclusions agree/disagree from those rows.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd

from camera_models.camera import load_camera
from camera_models.capture import marker_core_saturation, marker_pixels
from pipeline.thesis_tracker import STUDY_HSV_RANGES, ThesisTrackerSettings, hsv_histogram, hsv_ranges_from_histogram
from scenes.marker_photometry import side_to_centre_flux
from scenes.render_cache import RenderCache, atomic_write_bytes
from scenes.scenario import RenderSettings, Scenario
from studies.catalog import prediction_set
from studies.catalog.unknowns_search import WEBCAMS
from studies.engine import strict_json
from studies.engine.colour_reach import HIGHLIGHTS, LEVELS, reach
from studies.engine.frame import FRAME_VERSION, capture_frame, render_batch_key
from studies.engine.metrics import wilson_interval
from studies.engine.report import Report
from studies.engine.runner import run_tasks
from studies.engine.sweep import Execution, run_frames
from studies.engine.tables import write_tables
from studies.engine.tasks import StudyOptions, frame_tasks
from studies.engine.unknowns import apply, load_unknowns

__all__ = [
    "FOCUS",
    "PRIMARY_TESTS",
    "WEIGHT_VARIANTS",
    "conclusions",
    "core_histogram",
    "default_points",
    "derive_thresholds",
    "overlapping_colours",
    "run",
    "session_settings",
    "test_conditions",
    "v1_vs_v2",
    "validation_table",
]

NAME = "validate"
AS_BUILT = {"foam": True, "paper_sheets": 1, "paper_colour": "matched", "led_current_mA": 20.0}


def test_conditions(quick: bool) -> list[tuple[str, dict]]:
    """(test name, condition) pairs."""
    out: list[tuple[str, dict]] = []
    sides = ("red", "green", "blue", "yellow")
    for side in sides:
        for env in ("dark-room",) if quick else ("dark-room", "lit-room"):
            out.append(
                (
                    "preliminary",
                    {
                        "beacon": "v1",
                        "side": side,
                        "range_m": 0.15,
                        "yaw_deg": 0.0,
                        "camera": "logitech-c270",
                        "environment": env,
                        **AS_BUILT,
                    },
                )
            )
    for cam in ("logitech-c270", "canon-t6-18mm"):
        for beacon in ("v2",) if quick else ("v1", "v2"):
            for env in ("dark-room",) if quick else ("dark-room", "lit-room"):
                for r, side in itertools.product((2.0, 5.0, 7.0, 10.0), ("red",) if quick else sides):
                    out.append(
                        (
                            "range",
                            {
                                "beacon": beacon,
                                "side": side,
                                "range_m": r,
                                "yaw_deg": 0.0,
                                "camera": cam,
                                "environment": env,
                                **AS_BUILT,
                            },
                        )
                    )
    ranges = (1.0, 3.0, 5.0) if quick else (1.0, 2.0, 3.0, 4.0, 5.0)
    yaws = (0.0, 30.0) if quick else (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
    for cam in ("canon-t6-18mm", "canon-t6-10mm"):
        for r in ranges:
            for y in yaws:
                out.append(
                    (
                        "primary",
                        {
                            "beacon": "v2",
                            "side": "red",
                            "range_m": r,
                            "yaw_deg": y,
                            "camera": cam,
                            "environment": "dark-room",
                            **AS_BUILT,
                        },
                    )
                )
    for cam in ("canon-t6-18mm", "canon-t6-10mm"):
        for y in yaws:  # the study's weight figures sweep 0-30° at 1 m with both lenses
            weights = {"beacon": "v2", "side": "red", "range_m": 1.0, "yaw_deg": y, "camera": cam}
            out.append(("weights", {**weights, "environment": "dark-room", **AS_BUILT}))
    return out


PRIMARY_TESTS = ("primary", "weights")
"""Tests on the primary test's set-up, whose side the study does not state (a calibration's point says)."""


def session_settings(task: dict, point: int | None) -> dict:
    """``task`` with the study's own per-session tracker settings where it says it changed them
    (the registry's ``tracker`` unknowns, e.g. the 10 mm lens's erosion turned down from 4 m and
    its close off at 5 m, docs/source-study.md §5.3). No calibration observes them (they act
    beyond its 1 m), so a setting the study did not quantify is spread over its choices by point
    (point ``i`` takes choice ``i`` mod their number; the nominal one without points)."""
    registry = {n: u for n, u in load_unknowns().items() if u.namespace == "tracker"}
    values = {
        n: u.choices[point % len(u.choices)] if u.kind == "choice" and point is not None else u.nominal
        for n, u in registry.items()
    }
    return apply(task, values, registry)


def default_points(calibration: Path) -> int:
    """Points a prediction runs at by default: 20 of a calibration's NROY set (the spread of what
    survives), 2 of an unknowns search's set."""
    header = pd.read_csv(calibration, nrows=0).columns
    return 2 if "consistent" in header else 20


WEIGHT_VARIANTS = tuple(itertools.product(("tuned", "equal"), (None, {"alpha": 0.0}, {"alpha": 1.0})))
"""The weight experiment's detector settings: QUEST weights × rectification (none, alpha 0, alpha 1)."""


def run(
    out: Path,
    quick: bool,
    execution: Execution = Execution(),
    seeds: int | None = None,
    calibration: Path | None = None,
    points: int | None = None,
) -> list[dict]:
    """Run every test into ``out``; returns the validation rows.

    As the study did, the preliminary test's 150 mm captures set the colour thresholds
    (:func:`derive_thresholds`, the cores' colours pooled over the captures); the range and primary tests are
    then scored with the study's printed thresholds and with these derived ones.

    ``calibration``: a history match's ``nroy.csv`` or an unknowns search's ``samples.csv``
    (:func:`studies.catalog.prediction_set.load`); every test then runs at each of ``points`` of
    that set (default :func:`default_points`) and the intervals cover the set and the seeds. Without it, the
    unknowns stay at their nominal values (one point).
    """
    if points is not None and points < 1:
        raise ValueError(f"points: expected an integer >= 1, got {points!r}")
    chosen, which = None, "none: the unknowns at their nominal values"
    if calibration is not None:
        chosen = prediction_set.load(Path(calibration), points or default_points(Path(calibration)))
        which = chosen.which
    calibrated = list(range(len(chosen.points))) if chosen is not None else [None]
    pairs = test_conditions(quick)
    Path(out).mkdir(parents=True, exist_ok=True)
    options = StudyOptions(
        cameras=("canon-t6-18mm",),
        seeds=seeds or 2,
        jitter_poses=1,
        render={"spp": 4, "oversampling": 2, "crop": "target", "near_field_spp": 1024},
    )

    def tasks_for(tests: set[str], variants: dict | None) -> list[dict]:
        tasks = []
        for test, cond in pairs:
            if test not in tests:
                continue
            for t, point in itertools.product(
                frame_tasks([cond], options, trackers=["thesis"], estimators=["thesis"]), range(len(calibrated))
            ):
                t = {**t, "full_frame": True}  # the whole saved frame, as the study processed it
                side_of_test = t["scenario"]["side"]
                if chosen is not None:
                    if test in PRIMARY_TESTS and chosen.primary_side(point) is not None:
                        t = {**t, "scenario": {**t["scenario"], "side": chosen.primary_side(point)}}
                        side_of_test = "primary"  # the point's: the study does not say which side
                    t = chosen.apply(t, point)
                t = session_settings(t, point)
                if variants:
                    t["thesis_hsv_variants"] = variants
                settings = WEIGHT_VARIANTS if test == "weights" else (("tuned", None),)
                for weights, rectification in settings:
                    label = "none" if rectification is None else f"alpha {rectification['alpha']:g}"
                    tags = {"test": test, "weights": weights, "rectification": label, "point": point or 0}
                    task = {**t, "tags": {**tags, "side_of_test": side_of_test}}
                    if weights != "tuned":
                        task["quest_weights"] = weights
                    if rectification is not None:
                        task["rectification"] = rectification
                    tasks.append(task)
        return tasks

    preliminary = tasks_for({"preliminary"}, None)
    rows = run_frames(preliminary, out, execution, description=f"{NAME} preliminary")
    histograms = run_tasks(
        preliminary,
        out,
        core_histogram,
        version=FRAME_VERSION,
        workers=execution.workers,
        scheduler=execution.scheduler,
        description=f"{NAME} thresholds from the preliminary captures",
        progress=execution.progress,
        batch_key=render_batch_key,
    )
    derived = derive_thresholds(histograms)
    atomic_write_bytes(out / "derived_thresholds.json", strict_json.dumps(derived, indent=1).encode())
    later = tasks_for({"range", "primary", "weights"}, {"study": None, "derived": derived})
    rows += run_frames(later, out, execution, description=f"{NAME} range, primary, weights")
    frame = write_tables(out, rows)
    table = validation_table(frame)
    atomic_write_bytes(out / "validation.csv", table.to_csv(index=False, float_format="%.6g").encode())
    flux = v1_vs_v2(options.render)
    atomic_write_bytes(out / "v1_vs_v2.csv", flux.to_csv(index=False, float_format="%.6g").encode())

    study_boxes = {c: [[list(lo), list(hi)] for lo, hi in b] for c, b in ThesisTrackerSettings().ranges().items()}
    verdicts = [
        v
        for label, boxes in (("study", study_boxes), ("derived", derived))
        for v in conclusions(table, frame, label, boxes)
    ]
    which += (
        f"; {options.seeds * len(calibrated)} frames per condition ({len(calibrated)} points × {options.seeds} seeds): "
        "each verdict rests on that many frames per condition, read it with the interval in its evidence; "
        "the study's tracker as printed except where the study says a session changed it (10 mm lens: "
        "erosion turned down from 4 m, 1-3 iterations spread over the points, close off at 5 m)"
    )
    _report(out, table, verdicts, derived, flux, which)
    summary = {"study": NAME, "calibrated_set": which, "conclusions": verdicts, "derived_thresholds": derived}
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return table.to_dict("records")


def core_histogram(task: dict) -> list[dict]:
    """Task function (:func:`studies.engine.runner.run_tasks`): one preliminary capture's
    :func:`pipeline.thesis_tracker.hsv_histogram` of the five marker cores (true positions, core
    radii), the pixels a person tuning the thresholds draws the box around; one row with its
    ``side`` and ``hsv_histogram`` ((3, 256) counts; None when the cores hold no pixel)."""
    frame = capture_frame(task)
    try:
        counts = hsv_histogram(frame.image_bgr, _core_region(frame)).tolist()
    except ValueError:
        counts = None
    return [{"side": task["scenario"]["side"], "hsv_histogram": counts}]


def derive_thresholds(histograms: list[dict]) -> dict:
    """Per colour, HSV boxes from the preliminary captures as a person tuning them would draw them:
    around the five marker cores of that colour in every 150 mm capture of it
    (:func:`pipeline.thesis_tracker.hsv_ranges_from_histogram` of the :func:`core_histogram` rows
    summed; no box for a colour when any of its captures had no core pixels)."""
    out = {}
    for colour in ("red", "green", "blue", "yellow"):
        counts = [r["hsv_histogram"] for r in histograms if r["side"] == colour]
        if not counts or any(c is None for c in counts):
            out[colour] = []  # no lit pixels: that colour cannot be thresholded
            continue
        boxes = hsv_ranges_from_histogram(np.sum(np.asarray(counts, dtype=np.int64), axis=0))
        out[colour] = [[list(lo), list(hi)] for lo, hi in boxes]
    return out


def _core_region(frame) -> np.ndarray:
    """The saved image's pixels inside the five marker cores (true positions, core radii; at least one pixel)."""
    h, w = frame.image_bgr.shape[:2]
    uv = marker_pixels(frame.camera, frame.scenario) - np.array([frame.capture.x0, frame.capture.y0])
    radii = [max(m["core_radius_px"], 1.0) for m in marker_core_saturation(frame.capture, frame.camera, frame.scenario)]
    yy, xx = np.mgrid[0:h, 0:w]
    region = np.zeros((h, w), dtype=bool)
    for (u, v), r in zip(uv, radii, strict=True):
        region |= (xx - u) ** 2 + (yy - v) ** 2 <= r * r
    return region


CONDITION_KEYS = [
    "test", "thresholds", "camera", "beacon", "side", "environment", "nominal_range_m", "nominal_yaw_deg",
    "weights", "rectification",
]  # fmt: skip


def validation_table(frame):
    """One row per tested condition: means over the seeds and the calibrated points, intervals
    over both (:func:`_over_points`)."""
    frame = frame.assign(point=frame["point"] if "point" in frame else 0)
    if "side_of_test" in frame:  # the primary test's side, when a point chose it, is shown as "primary"
        frame = frame.assign(side=frame["side_of_test"].fillna(frame["side"]))
    per_point = []
    for key, g in frame.groupby([*CONDITION_KEYS, "point"], sort=False):
        rec = dict(zip([*CONDITION_KEYS, "point"], key, strict=True))
        recs = g.to_dict("records")
        detected = [bool(r["detected"]) for r in recs]
        # merged or lost: not detected, and the tracker found fewer than five blobs of the side's colour
        merged = [not r["detected"] and not (r["side_blobs"] >= 5) for r in recs]
        failures = _failure_kinds(recs)
        colour_ok = [bool(r["side_correct"]) for r in recs if r["detected"]]
        per_point.append(
            {
                "test": rec["test"],
                "camera": rec["camera"],
                "beacon": rec["beacon"],
                "side": rec["side"],
                "environment": rec["environment"],
                "range_m": rec["nominal_range_m"],
                "yaw_deg": rec["nominal_yaw_deg"],
                "detected_fraction": float(np.mean(detected)),
                "merged_or_lost_fraction": float(np.mean(merged)),
                "colour_correct_fraction": float(np.mean(colour_ok)) if colour_ok else 0.0,
                "range_est_m": float(np.nanmean(g.range_est_m)) if g.range_est_m.notna().any() else np.nan,
                "yaw_est_deg": float(np.nanmean(g.yaw_est_deg)) if g.yaw_est_deg.notna().any() else np.nan,
                "core_saturation": float(np.nanmean(g.core_saturated_fraction_mean)),
                "thresholds": rec["thresholds"],
                "weights": rec["weights"],
                "rectification": rec["rectification"],
                **_intervals(detected, g),
                **failures,
                **dict.fromkeys(("focus_distance_m_low", "focus_distance_m_high"), _focus_m(recs[0])),
            }
        )
    return _over_points(pd.DataFrame(per_point))


FOCUS = "camera.effects.focus_distance_m"
"""The rows' column of a task's focus distance (its camera override)."""


def _focus_m(row: dict) -> float:
    """The lens focus a frame was made with, m: the point's, or the registry's nominal for its lens;
    NaN for a fixed-focus webcam (its blur is its lens's, not an unknown focus)."""
    value = row.get(FOCUS)
    if value is not None and np.isfinite(value):
        return float(value)
    lens = [u for u in load_unknowns().values() if u.target == FOCUS and row["camera"] in u.cameras]
    return float(lens[0].nominal) if lens else np.nan


def _failure_kinds(recs: list[dict]) -> dict:
    """Why frames were missed, as fractions of all frames (:mod:`pipeline.mask_measures`, at the true
    markers): ``extra_blobs`` (more than five blobs of the side's colour: other sides' markers seen
    through the housing, reflections), ``merged`` (the close joined two markers' regions), ``lost``
    (a marker left no blob: out of the box, or too small for the erosion). A missed frame may have
    several; NaN for rows without the measures (frames of an older version)."""
    missed = [r for r in recs if not r["detected"]]
    if any(r.get("side_markers_merged") is None for r in missed):
        return {"extra_blobs_fraction": np.nan, "merged_fraction": np.nan, "lost_fraction": np.nan}
    n = len(recs)
    return {
        "extra_blobs_fraction": sum((r["side_blobs"] or 0) > 5 for r in missed) / n,
        "merged_fraction": sum(r["side_markers_merged"] > 0 for r in missed) / n,
        "lost_fraction": sum(r["side_markers_lost"] > 0 for r in missed) / n,
    }


def _intervals(detected: list[bool], g) -> dict:
    """The evidence behind one point's means: a Wilson 95 % interval of the detected
    fraction, and the lowest and highest range and yaw estimate over its frames."""
    _, low, high = wilson_interval(int(sum(detected)), len(detected))
    out = {"detected_low": low, "detected_high": high}
    for name in ("yaw_est", "range_est"):
        column = g[f"{name}_deg" if name == "yaw_est" else f"{name}_m"].dropna()
        out[f"{name}_low"] = float(column.min()) if len(column) else np.nan
        out[f"{name}_high"] = float(column.max()) if len(column) else np.nan
    return out


def _over_points(per_point: pd.DataFrame) -> pd.DataFrame:
    """Rows of the same condition at different calibrated points as one: means of the
    fractions and estimates (each point weighs the same), the lowest ``*_low`` and highest
    ``*_high`` (an interval over the set and the seeds), and ``points``, how many."""
    keys = ["test", "thresholds", "camera", "beacon", "side", "environment", "range_m", "yaw_deg", "weights"]
    keys.append("rectification")
    lows = [c for c in per_point if c.endswith("_low")]
    highs = [c for c in per_point if c.endswith("_high")]
    means = [c for c in per_point if c not in keys + lows + highs]
    agg = {**{c: "mean" for c in means}, **{c: "min" for c in lows}, **{c: "max" for c in highs}}
    out = per_point.groupby(keys, sort=False, dropna=False).agg(agg).reset_index()
    out["points"] = per_point.groupby(keys, sort=False, dropna=False).size().to_numpy()
    return out[[*per_point.columns, "points"]]


def v1_vs_v2(render: dict) -> pd.DataFrame:
    """Side-to-centre marker flux ratio of each beacon as built (T6 + 18 mm, 2 m, yaw 0, red,
    foam + 1 matched sheet): the mean irradiance at the pupil from markers 2-5 over marker 1's
    (:func:`scenes.marker_photometry.side_to_centre_flux`)."""
    rows = []
    for beacon in ("v1", "v2"):
        scenario = Scenario(
            beacon=beacon, side="red", range_m=2.0, yaw_deg=0.0, camera="canon-t6-18mm", environment="dark-room",
            foam=True, paper_sheets=1, paper_colour="matched", render=RenderSettings(**render),
        )  # fmt: skip
        rows.append({"beacon": beacon, "side_to_centre_flux": side_to_centre_flux(scenario, RenderCache())})
    return pd.DataFrame(rows)


def overlapping_colours(hsv: dict) -> list[str]:
    """Pairs of colours whose HSV boxes intersect (in hue, saturation and value at once):
    a pixel in the intersection matches both, so such thresholds cannot tell them apart."""

    def meet(a, b):
        return all(max(a[0][k], b[0][k]) <= min(a[1][k], b[1][k]) for k in range(3))

    names = sorted(c for c in hsv if hsv[c])
    return [
        f"{a}/{b}"
        for i, a in enumerate(names)
        for b in names[i + 1 :]
        if any(meet(x, y) for x in hsv[a] for y in hsv[b])
    ]


def conclusions(table, frame, thresholds: str = "study", hsv: dict | None = None) -> list[dict]:
    """The study's headline conclusions (docs/source-study.md §10) against the predictions made
    with the given colour thresholds (``study``: its printed numbers; ``derived``: its
    procedure applied to the simulated preliminary captures)."""
    table = table[table.thresholds == thresholds]
    frame = frame[frame.thresholds == thresholds]
    prim = table[(table.test == "primary") & (table.camera == "canon-t6-18mm")]
    rng = table[table.test == "range"]
    web = rng[rng.camera.isin(WEBCAMS)]
    dslr = rng[rng.camera == "canon-t6-18mm"]
    out = []

    def verdict(claim, ok, evidence, reason="", flip=""):
        ok = None if ok is None else bool(ok)  # numpy booleans too
        out.append(
            {
                "thresholds": thresholds,
                "conclusion": claim,
                "simulation": "no evidence" if ok is None else ("agree" if ok else "disagree"),
                "evidence": evidence,
                "reason": reason if ok is False else "",
                "would_flip": flip if ok is False else "",
            }
        )

    # the sides the primary frames showed: the table labels a side a point chose "primary"
    shown = frame.loc[frame.test == "primary", "side"].unique() if len(prim) else ("red",)
    t6_colour = _colour_reach_note("canon-t6-18mm", shown, hsv)
    verdict(
        "The DSLR (18 mm) detected the markers up to 5 m and 30°",
        bool(len(prim)) and prim.detected_fraction.min() >= 0.5,
        f"primary test detected fraction {prim.detected_fraction.min():.2f}-{prim.detected_fraction.max():.2f} "
        f"(over the set and seeds {prim.detected_low.min():.2f}-{prim.detected_high.max():.2f})" + _why_missed(prim)
        if len(prim)
        else "not tested",
        f"{_failures(frame[frame.test == 'primary'])}; {t6_colour}",
        "the side that faced the camera (not stated; the T6 renders the blue and yellow LEDs into their boxes at "
        "every setting, `beacon-sim colour-reach`) or a Canon highlight rendering that turns clipped red cores "
        "pale violet-pink rather than yellow-white",
    )
    det = prim[prim.detected_fraction > 0]
    tested = set(shown) | set(rng.side)
    overlap = [p for p in (overlapping_colours(hsv) if hsv else []) if tested & set(p.split("/"))]
    evidence = (
        f"colour correct among detections {det.colour_correct_fraction.mean():.2f}" if len(det) else "no detections"
    )
    if overlap:  # only the red side was tested: with overlapping boxes 'red' wins by being tried first
        evidence += f"; but the thresholds overlap ({', '.join(overlap)}), so they cannot tell those colours apart"
    verdict(
        "…and could tell their colours",
        bool(len(det)) and det.colour_correct_fraction.min() >= 0.9 and not overlap,
        evidence,
        f"the {thresholds} boxes overlap ({', '.join(overlap)})" if overlap else t6_colour,
        "thresholds whose boxes do not overlap" if overlap else "as above: the side that faced the camera",
    )
    verdict(
        "The webcams over-exposed the LEDs",
        bool(len(web)) and web.core_saturation.min() >= 0.5,
        f"webcam marker cores clipped {web.core_saturation.min():.0%}-{web.core_saturation.max():.0%}",
        "the dimmer settings of the points used leave most webcam marker cores below the clip level",
        "the LED drive (led_drive_*): a dimmer turned up clips the cores",
    )
    far = web[web.range_m >= 5]
    verdict(
        "…and could not tell the colours at range",
        bool(len(far)) and (far.detected_fraction * far.colour_correct_fraction).max() < 0.5,
        f"webcam at ≥ 5 m: correct-colour detections {(far.detected_fraction * far.colour_correct_fraction).max():.2f} "
        f"(detected at most {far.detected_high.max():.2f} over the set and seeds)",
        f"the webcams' markers stay in their boxes at range ({_failures(frame[frame.camera.isin(WEBCAMS)])})",
        "the LED drive and the webcam's highlight handling (highlight_mode): cores that clip leave their box",
    )
    beyond = dslr[dslr.range_m > 5]
    right_beyond = (beyond.detected_fraction * beyond.colour_correct_fraction).max() if len(beyond) else np.nan
    verdict(
        "The planned 10 m was not reached (DSLR detections stop beyond 5 m)",
        bool(len(beyond)) and right_beyond < 0.5,
        f"DSLR correct-colour detections at 7-10 m: {right_beyond:.2f} "
        f"(any detection {beyond.detected_fraction.max():.2f}, at most "
        f"{beyond.detected_high.max():.2f} over the set and seeds)"
        if len(beyond)
        else "not tested",
        "the markers stay apart and in their boxes beyond 5 m",
        "veiling glare (glare_on, veiling_glare_18mm) merges the markers; focus (focus_distance) shrinks them",
    )
    lost = rng[rng.range_m >= 7]
    far_frames = frame.nominal_range_m >= 7
    verdict(
        "Resolution and blob merging limit the range",
        bool(len(lost)) and lost.merged_or_lost_fraction.mean() >= 0.5,
        f"merged-or-lost fraction at 7-10 m: {lost.merged_or_lost_fraction.mean():.2f}" + _why_missed(lost),
        f"frames at 7-10 m that fail do so otherwise: {_failures(frame[(frame.test == 'range') & far_frames])}",
        "veiling glare (glare_on) and the LED drive: brighter halos merge neighbouring markers",
    )
    near, far_p = prim[prim.range_m <= 1], prim[prim.range_m >= 5]
    err = frame[(frame.test == "primary") & frame.detected]
    e1 = float(err[err.nominal_range_m <= 1].yaw_err_deg.abs().mean()) if len(near) else np.nan  # NaN: none
    e5 = float(err[err.nominal_range_m >= 5].yaw_err_deg.abs().mean()) if len(far_p) else np.nan
    verdict(
        "QUEST attitude degrades at longer range",
        bool(e5 > e1) if np.isfinite(e1) and np.isfinite(e5) else None,  # no detections at one end: no evidence
        f"mean |yaw error| {_degrees(e1)} at 1 m vs {_degrees(e5)} at 5 m",
        "the attitude error does not grow with range among the detected frames",
        "blob-centroid bias of the erosion (fixed) grows relative to the shrinking marker spacing; more detections "
        "at 5 m would test it",
    )
    weighted = frame[(frame.test == "weights") & (frame.rectification == "none") & frame.detected]
    errors = {w: np.abs(weighted[weighted.weights == w].yaw_err_deg.dropna()) for w in ("tuned", "equal")}
    counts = {w: len(e) for w, e in errors.items()}
    testable = min(counts.values()) >= 3  # fewer frames cannot tell two means apart
    verdict(
        "Tuning the QUEST weights to (0.05, 0.05, 0.45, 0.45) improved the attitude over equal weights",
        bool(errors["tuned"].mean() < errors["equal"].mean()) if testable else None,
        f"mean |yaw error| at 1 m over 0-30°, both lenses: tuned {errors['tuned'].mean():.2f}° "
        f"({counts['tuned']} frames), "
        f"equal {errors['equal'].mean():.2f}° ({counts['equal']} frames)"
        if testable
        else f"too few detections at 1 m to compare the weights on ({counts['tuned']} tuned, {counts['equal']} equal)",
        "with the study's own pixel-to-angle model the out-of-plane pairs carry no more attitude information",
        "the centroid noise of markers 2-3 against 4-5 (the LED drive of each side)",
    )
    return out


def _why_missed(rows) -> str:
    """ "; of all frames, x % had extra blobs, y % merged markers, z % lost ones" (the mean over the rows'
    conditions; empty when the rows carry no such measures)."""
    cols = ("extra_blobs_fraction", "merged_fraction", "lost_fraction")
    if not len(rows) or any(c not in rows or rows[c].isna().all() for c in cols):
        return ""
    extra, merged, lost = (float(rows[c].mean()) for c in cols)
    return (
        f"; of all frames {extra:.0%} missed with extra blobs, {merged:.0%} with merged markers, "
        f"{lost:.0%} with lost ones"
    )


def _failures(frame) -> str:
    """The commonest failure codes of the frames not detected, with counts."""
    failed = frame[~frame.detected.astype(bool)] if len(frame) else frame
    if not len(failed):
        return "no frame failed"
    counts = failed.failure.fillna("").replace("", "none").value_counts()
    top = ", ".join(f"{code} {n}" for code, n in counts.head(2).items())
    return f"{len(failed)} of {len(frame)} frames undetected ({top})"


def _colour_reach_note(camera: str, sides, hsv: dict | None = None) -> str:
    """Whether the camera can render each tested side's LED into its box (``hsv``, default the
    study's), at any exposure, highlight mode and paper (:mod:`studies.engine.colour_reach`), in words."""
    cam = load_camera(camera)
    boxes = {c: [tuple(map(tuple, b)) for b in v] for c, v in hsv.items()} if hsv else STUDY_HSV_RANGES
    notes = []
    for side in sides:
        hits = {
            (hl, paper_colour): reach(
                cam, side, paper_colour=paper_colour, overrides={"isp.highlight": hl}, ranges=boxes
            ).span(side)
            for hl in HIGHLIGHTS
            for paper_colour in ("matched", "white")
        }
        ok = {k: v for k, v in hits.items() if v}
        if not ok:
            notes.append(f"the {camera} renders the {side} LED into its box at no exposure, highlight mode or paper")
            continue
        words = _spans_in_words(ok, len(hits))
        notes.append(
            f"the {camera} renders the {side} LED into its box {'' if len(ok) == len(hits) else 'only '}at ({words})"
        )
    return "; ".join(notes) + " (`beacon-sim colour-reach`)"


def _degrees(angle: float) -> str:
    """An angle in degrees in words; NaN (no frame to average) as "no detection"."""
    return f"{angle:.2f}°" if np.isfinite(angle) else "no detection"


_SPAN_WORDS = {
    (True, True): "every exposure tried ({lo}-{hi}× the clip level)",
    (True, False): "up to {hi}× the clip level (from the lowest tried, {lo}×)",
    (False, True): "{lo}× the clip level and up (to the highest tried, {hi}×)",
    (False, False): "{lo}-{hi}× the clip level",
}
"""An exposure span in words, by whether it reaches (lowest, highest) exposure tried."""


def _spans_in_words(
    spans: dict[tuple[str, str], tuple[float, float]], tried: int, levels: tuple[float, float] = (LEVELS[0], LEVELS[-1])
) -> str:
    """Exposure spans (multiples of the clip level) per (highlight mode, paper), the settings
    that share a span named together; "every setting" when all ``tried`` settings share it.
    A span that reaches an end of the exposures tried (``levels``: lowest, highest) says so,
    since the box may hold beyond it."""
    by_span: dict[str, list[str]] = {}
    for (highlight, paper), (lo, hi) in spans.items():
        words = _SPAN_WORDS[lo <= levels[0], hi >= levels[1]].format(lo=f"{lo:.3g}", hi=f"{hi:.3g}")
        by_span.setdefault(words, []).append(f"highlight {highlight}, {paper} paper")
    return "; ".join(
        f"{'every setting' if len(names) == tried else ' / '.join(names)}: {span}" for span, names in by_span.items()
    )


def _report(out: Path, table, verdicts: list[dict], derived: dict, flux: pd.DataFrame, calibrated: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("Validation: the simulation's predictions for the source study's tests")
    rep.text(
        "Study tracker (HSV thresholds, morphology, exactly-5-blobs rule), inverse perspective and QUEST "
        "(Gibbs shortcut, weights 0.05/0.05/0.45/0.45); T6 at ISO 6400, 1/60 s; webcams automatic. Markers "
        "as built: foam + 1 sheet of paper. Each frame is the camera's whole saved frame, scaled to 50 % for the "
        f"T6 as the study processed it. Points of the unknowns predicted from: {calibrated}. "
        "Intervals: detected_low/high spans the Wilson 95 % intervals over the seeds of every calibrated point "
        "(the interval over the set and the seeds); *_est_low/high are the lowest and highest estimate seen; "
        "`points` is how many calibrated points a row covers."
    )
    rep.text(
        "Colour thresholds: 'study' = the study's printed HSV ranges; 'derived' = the study's procedure "
        "(percentiles of the five marker cores' pixels in the 150 mm preliminary captures, as a person "
        "drawing the box around them would take) applied to the simulated captures: "
        + "; ".join(f"{c}: {b}" for c, b in derived.items())
    )
    rep.heading("The study's conclusions")
    rep.table(
        pd.DataFrame(verdicts),
        "Headline conclusions (docs/source-study.md §10) against the simulation",
        css_class="answers",  # prose: left-aligned
    )
    prim = table[table.test == "primary"]
    if len(prim):
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        for (thr, cam), g in prim.groupby(["thresholds", "camera"]):
            for y, gy in g.groupby("yaw_deg"):
                label = f"{cam}, {y:g}°, {thr} thresholds"
                axes[0].plot(gy.range_m, gy.detected_fraction, marker="o", label=label)
                axes[1].plot(gy.range_m, gy.range_est_m - gy.range_m, marker="o", label=label)
        axes[0].set_ylabel("detected fraction")
        axes[1].set_ylabel("range estimate − truth, m")
        for ax in axes:
            ax.set_xlabel("range, m")
        axes[0].legend(fontsize=6)
        rep.heading("Primary test")
        rep.figure(fig, "Primary test (V2, T6, lights off): detection and range error versus range, per lens and yaw")
    rep.heading("V1 against V2")
    rep.text(
        "The study: V1's in-plane LEDs point along their arms, so its centre marker was far brighter than the "
        "others (docs/source-study.md §2.5); V2 turns every LED toward the viewer. The simulation, 2 m, yaw 0, "
        "T6, red side as built: mean irradiance from markers 2-5 over marker 1's."
    )
    rep.table(flux, "v1_vs_v2.csv")
    rep.heading("Every tested condition")
    rep.table(table, "validation.csv")
    rep.write(out / "report.html")
