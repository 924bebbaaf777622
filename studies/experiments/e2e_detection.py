"""Issue 5's end-to-end acceptance: the study's primary test through the engine's frame path, scored.

Conditions: the V2 beacon's red side in the dark, markers as built for the study (foam + one
sheet of matched paper), LEDs at the datasheet test current (20 mA), seen by the Canon T6 +
18 mm at the study's exposure (ISO 6400, 1/60 s, the lens file's default f-number) at every
range (camera → marker 1: 1–5 m in 1 m steps) × yaw (0–30° in 5° steps) × sensor-noise seed.
Poses are exactly nominal (``jitter_poses=1``). Nothing is tuned.

Every frame is a frame task of :mod:`studies.engine.tasks`, run by
:func:`studies.engine.sweep.run_frames` (resumable; results stored under ``out/tasks``) and
scored by :func:`studies.engine.frame.simulate_frame` with both trackers (``thesis``,
``best``) × both estimators (``thesis``, ``best``). The render covers the region around the
beacon (``crop='beacon'``: all four targets plus a margin); the task's ``align_px`` = 16 pads
it with zero radiance so its origin and size are multiples of 16 px, and the JPEG's MCUs and
the study's 50 % resize group the pixels as in the full frame. The detector gets the crop with
its full-frame origin and no lens calibration (distorted pixels, pinhole intrinsics).

Success is the engine's (:mod:`studies.engine.scoring`): a *detection success* is the right
side with five markers, each correctly numbered; a *pose success* is a detection success with
the range within 10 % and the yaw within 5° of the truth (range truth = camera → marker 1, m;
yaw truth = the scenario's yaw, degrees).

The optional full-frame check runs one condition's task again with ``full_frame`` (the whole
18 MP frame captured and searched; a separate noise realisation) and compares each detector's
side and reason with the crop's.

Outputs (:func:`run`), in ``out``:

``results.csv``, ``results.parquet``
    The engine's rows: one per range × yaw × seed × tracker × estimator.
``summary.csv``, ``summary_by_range.csv``
    Per range × yaw (and per range) × tracker × estimator (:data:`SUMMARY_COLUMNS`):
    frames, detection and pose-success counts and rates, median |error| and RMS error of
    range (m) and yaw (degrees) over the detection successes, mean marker-core saturated
    fraction (0–1), most common detector failure code and failure cause.
``summary.md``, ``config.json``
    The summary as text; the options, exposure, success definitions and run time (s).
``full_frame_check.csv``
    When run: per tracker × estimator, the crop's and the full frame's answers.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from camera_models.camera import load_camera
from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.scoring import RANGE_TOLERANCE, YAW_TOLERANCE_DEG, detection_success, failure_cause, pose_success
from studies.engine.sweep import Execution, run_frames
from studies.engine.tables import write_tables
from studies.engine.tasks import GRID_AXES, StudyOptions, frame_tasks, grid_conditions

__all__ = [
    "ALIGN_PX",
    "EXPOSURE",
    "FULL_FRAME_CONDITION",
    "ORDER",
    "RENDER",
    "SUMMARY_COLUMNS",
    "E2EResult",
    "aggregate",
    "default_options",
    "describe",
    "full_frame_check",
    "run",
    "summarise",
    "summary_markdown",
    "tasks",
    "write_outputs",
]

RANGES_M = (1.0, 2.0, 3.0, 4.0, 5.0)
YAWS_DEG = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
QUICK_RANGES_M = (1.0, 3.0, 5.0)
QUICK_YAWS_DEG = (0.0, 15.0, 30.0)
ALIGN_PX = 16
"""Crop origin and size are padded to multiples of this, px: JPEG MCUs (16×8 for 4:2:2, 16×16 for 4:2:0)
and the study's 50 % resize then see the same pixel groups as in the full frame."""
EXPOSURE = {"iso": 6400.0, "exposure_s": 1.0 / 60.0, "f_number": None}
"""The study's manual exposure (exposure time in s); f-number None: the lens file's default."""
RENDER = {"spp": 8, "oversampling": 2, "crop": "beacon", "near_field_spp": 1024, "seed": 0}
"""Render settings (:class:`scenes.scenario.RenderSettings` fields)."""
FULL_FRAME_CONDITION = (2.0, 15.0)
"""(range m, yaw °) of the full-frame check."""
ORDER = (*(a for a in GRID_AXES if a not in ("range_m", "yaw_deg")), "range_m", "yaw_deg")
"""Grid loop order: range outer, yaw inner."""

SUMMARY_COLUMNS = (
    "tracker", "estimator", "frames", "detection_successes", "detection_rate", "pose_successes", "pose_success_rate",
    "range_err_median_abs_m", "range_err_rms_m", "yaw_err_median_abs_deg", "yaw_err_rms_deg",
    "core_saturated_fraction_mean", "top_failure", "top_failure_count", "top_cause", "top_cause_count",
)  # fmt: skip


def default_options(quick: bool = False, seeds: int | None = None) -> StudyOptions:
    """The study's primary test (``quick``: ranges 1, 3, 5 m × yaws 0, 15, 30° and one seed)."""
    return StudyOptions(
        cameras=("canon-t6-18mm",),
        beacons=("v2",),
        sides=("red",),
        ranges_m=QUICK_RANGES_M if quick else RANGES_M,
        yaws_deg=QUICK_YAWS_DEG if quick else YAWS_DEG,
        environments=("dark",),
        currents_mA=(20.0,),
        seeds=seeds if seeds is not None else (1 if quick else 3),
        frame="crop",  # the table is on crops; its full-frame check (FULL_FRAME_CONDITION) compares the two
        jitter_poses=1,
        diffusers=((True, 1, "matched"),),
        render=dict(RENDER),
    )


def tasks(options: StudyOptions, exposure: dict = EXPOSURE) -> list[dict]:
    """Frame tasks of every range × yaw × seed, crops aligned to :data:`ALIGN_PX`."""
    conditions = grid_conditions(options, ORDER)
    return [{**t, "align_px": ALIGN_PX} for t in frame_tasks(conditions, options, exposure)]


@dataclass
class E2EResult:
    """What :func:`run` produced: the engine's rows, the two summaries, the full-frame check
    (None when not run), run time per step (s) and the files written."""

    rows: list[dict]
    summary: list[dict]
    summary_by_range: list[dict]
    full_frame_check: list[dict] | None
    seconds: dict
    paths: dict[str, Path]


def run(
    out: Path,
    options: StudyOptions | None = None,
    execution: Execution | None = None,
    exposure: dict = EXPOSURE,
    full_frame: bool = False,
) -> E2EResult:
    """Run the table into ``out`` (re-run to resume) and write the outputs (module docstring).
    ``execution``: where the frames run and the progress display (default: local processes, none)."""
    options = options or default_options()
    options.validate()
    execution = execution or Execution()
    out = Path(out)
    t0 = time.perf_counter()
    rows = run_frames(tasks(options, exposure), out, execution, description="e2e-detection")
    write_tables(out, rows)
    seconds = {"frames": time.perf_counter() - t0}
    check = None
    if full_frame:
        t1 = time.perf_counter()
        check = full_frame_check(options, out, execution, exposure)
        seconds["full_frame_check"] = time.perf_counter() - t1
    seconds["total"] = time.perf_counter() - t0
    result = E2EResult(rows, summarise(rows, ["range_m", "yaw_deg"]), summarise(rows, ["range_m"]), check, seconds, {})
    result.paths = write_outputs(result, out, options, exposure)
    return result


# -- summaries -----------------------------------------------------------------------


def summarise(rows: list[dict], keys: Sequence[str]) -> list[dict]:
    """One :func:`aggregate` row per distinct value of ``keys`` × tracker × estimator, in first-seen order.
    ``range_m`` and ``yaw_deg`` group by the rows' nominal range and yaw."""
    columns = {"range_m": "nominal_range_m", "yaw_deg": "nominal_yaw_deg"}
    names = (*keys, "tracker", "estimator")
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(r[columns.get(k, k)] for k in names), []).append(r)
    return [dict(zip(names, key, strict=True)) | aggregate(members) for key, members in groups.items()]


def aggregate(rows: list[dict]) -> dict:
    """Counts, rates and errors of a group of rows (:data:`SUMMARY_COLUMNS` less tracker, estimator)."""
    good = [r for r in rows if detection_success(r)]
    n_pose = sum(pose_success(r) for r in rows)
    rng = np.array([r["range_err_m"] for r in good], float)
    yaw = np.array([r["yaw_err_deg"] for r in good], float)
    rng, yaw = rng[np.isfinite(rng)], yaw[np.isfinite(yaw)]
    failures = Counter(r["failure"] for r in rows if not detection_success(r) and r["failure"])
    causes = Counter(failure_cause(r) for r in rows if not pose_success(r))
    top_failure = failures.most_common(1)[0] if failures else ("", 0)
    top_cause = causes.most_common(1)[0] if causes else ("", 0)
    return {
        "frames": len(rows),
        "detection_successes": len(good),
        "detection_rate": len(good) / len(rows),
        "pose_successes": n_pose,
        "pose_success_rate": n_pose / len(rows),
        "range_err_median_abs_m": float(np.median(np.abs(rng))) if rng.size else math.nan,
        "range_err_rms_m": float(np.sqrt(np.mean(rng**2))) if rng.size else math.nan,
        "yaw_err_median_abs_deg": float(np.median(np.abs(yaw))) if yaw.size else math.nan,
        "yaw_err_rms_deg": float(np.sqrt(np.mean(yaw**2))) if yaw.size else math.nan,
        "core_saturated_fraction_mean": float(np.mean([r["core_saturated_fraction_mean"] for r in rows])),
        "top_failure": top_failure[0],
        "top_failure_count": top_failure[1],
        "top_cause": top_cause[0],
        "top_cause_count": top_cause[1],
    }


# -- full frame vs crop --------------------------------------------------------------


def full_frame_check(
    options: StudyOptions,
    out: Path,
    execution: Execution | None = None,
    exposure: dict = EXPOSURE,
    condition: tuple[float, float] = FULL_FRAME_CONDITION,
) -> list[dict]:
    """One condition's seed-0 task on the crop and with ``full_frame``: per tracker × estimator,
    both answers and whether the side and the reason agree. The full frame's noise is its own
    realisation, so positions and errors differ slightly; the answer should not."""
    execution = execution or Execution()
    one = replace(options, ranges_m=(condition[0],), yaws_deg=(condition[1],), seeds=1)
    crop = tasks(one, exposure)[0]
    rows = run_frames([crop, {**crop, "full_frame": True}], out, execution, description="full-frame check")
    half = len(rows) // 2
    check = []
    for c, f in zip(rows[:half], rows[half:], strict=True):
        row = {k: c[k] for k in ("nominal_range_m", "nominal_yaw_deg", "seed", "tracker", "estimator")}
        for name, r in (("crop", c), ("full", f)):
            row |= {
                f"side_{name}": r["side_detected"],
                f"detection_success_{name}": detection_success(r),
                f"pose_success_{name}": pose_success(r),
                f"range_est_m_{name}": r["range_est_m"],
                f"yaw_est_deg_{name}": r["yaw_est_deg"],
                f"reason_{name}": r["reason"],
            }
        row["same_side_and_reason"] = c["side_detected"] == f["side_detected"] and c["reason"] == f["reason"]
        check.append(row)
    return check


# -- output --------------------------------------------------------------------------


def describe(options: StudyOptions, exposure: dict = EXPOSURE) -> str:
    """One line: what was simulated."""
    camera = options.cameras[0]
    foam, sheets, colour = options.diffusers[0]
    f_number = exposure.get("f_number") or load_camera(camera).lens.f_number
    r = options.render
    return (
        f"{options.beacons[0].upper()} beacon, {options.sides[0]} side, {options.environments[0]} environment; "
        f"markers: {'foam + ' if foam else ''}{sheets} sheet(s) of {colour} paper, LEDs at "
        f"{options.currents_mA[0]:g} mA; {camera} at ISO {exposure['iso']:g}, 1/{1 / exposure['exposure_s']:.0f} s, "
        f"f/{f_number:g}; render spp {r.get('spp')}, oversampling {r.get('oversampling')}, crop '{r.get('crop')}' "
        f"aligned to {ALIGN_PX} px, near-field spp {r.get('near_field_spp')}, render seed {r.get('seed', 0)}"
    )


def write_outputs(result: E2EResult, out: Path, options: StudyOptions, exposure: dict) -> dict[str, Path]:
    """summary.csv, summary_by_range.csv, summary.md, config.json (and full_frame_check.csv);
    results.csv/.parquet are written by :func:`run`."""
    out = Path(out)
    paths = {
        "results": out / "results.csv",
        "summary": out / "summary.csv",
        "summary_by_range": out / "summary_by_range.csv",
        "markdown": out / "summary.md",
        "config": out / "config.json",
    }
    _write_csv(paths["summary"], result.summary, ("range_m", "yaw_deg", *SUMMARY_COLUMNS))
    _write_csv(paths["summary_by_range"], result.summary_by_range, ("range_m", *SUMMARY_COLUMNS))
    if result.full_frame_check:
        paths["full_frame_check"] = out / "full_frame_check.csv"
        _write_csv(paths["full_frame_check"], result.full_frame_check, tuple(result.full_frame_check[0]))
    atomic_write_bytes(paths["markdown"], summary_markdown(result, options, exposure).encode())
    config = {
        "options": asdict(options),
        "exposure": exposure,
        "align_px": ALIGN_PX,
        "description": describe(options, exposure),
        "detection_success": detection_success.__doc__,
        "pose_success": pose_success.__doc__,
        "errors_over": "detection successes",
        "seconds": result.seconds,
    }
    atomic_write_bytes(paths["config"], (strict_json.dumps(config, indent=2) + "\n").encode())
    return paths


def _write_csv(path: Path, rows: list[dict], columns: Sequence[str]) -> None:
    atomic_write_bytes(
        path, pd.DataFrame(rows, columns=list(columns)).to_csv(index=False, float_format="%.6g").encode()
    )


def summary_markdown(result: E2EResult, options: StudyOptions, exposure: dict = EXPOSURE) -> str:
    """The short markdown summary."""
    lines = [
        "# End-to-end detection on captured frames (issue 5 acceptance)",
        "",
        f"Configuration: {describe(options, exposure)}.",
        f"Conditions: ranges {', '.join(f'{r:g}' for r in options.ranges_m)} m × yaws "
        f"{', '.join(f'{y:g}' for y in options.yaws_deg)}° × {options.seeds} noise seed(s) = "
        f"{len(result.rows) // 4} frames, each through both trackers × both estimators. Nothing tuned.",
        "",
        "Detection success: the right side, five markers, each correctly numbered. Pose success: a detection"
        f" success with range within {RANGE_TOLERANCE:.0%} and yaw within {YAW_TOLERANCE_DEG:g}°. Errors: median"
        " |e| / RMS over the detection successes (range truth = camera → marker 1).",
        "",
        "## Overall",
        "",
        *_md_table(summarise(result.rows, []), ()),
        "",
        "## By range",
        "",
        *_md_table(result.summary_by_range, ("range_m",)),
    ]
    if result.full_frame_check:
        c0 = result.full_frame_check[0]
        lines += [
            "",
            f"## Full frame vs crop ({c0['nominal_range_m']:g} m, {c0['nominal_yaw_deg']:g}°, seed {c0['seed']})",
            "",
            "| tracker | estimator | side crop / full | pose success crop / full | same side and reason |",
            "|---|---|---|---|---|",
        ]
        for c in result.full_frame_check:
            lines.append(
                f"| {c['tracker']} | {c['estimator']} | {c['side_crop'] or '–'} / {c['side_full'] or '–'} | "
                f"{c['pose_success_crop']} / {c['pose_success_full']} | {c['same_side_and_reason']} |"
            )
    seconds = ", ".join(f"{k} {v:.0f} s" for k, v in result.seconds.items())
    lines += ["", f"Run time: {seconds} (stored frames and cached renders are reused).", ""]
    return "\n".join(lines)


def _md_table(summary: list[dict], keys: Sequence[str]) -> list[str]:
    head = [*(k.replace("_m", " m").replace("_deg", " °") for k in keys), "tracker", "estimator"]
    head += ["detected", "pose ok", "range err mm", "yaw err °", "core clipped", "top failure / cause"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in summary:
        cells = [f"{s[k]:g}" for k in keys] + [s["tracker"], s["estimator"]]
        cells += [
            f"{s['detection_successes']}/{s['frames']}",
            f"{s['pose_successes']}/{s['frames']}",
            f"{_num(s['range_err_median_abs_m'], 1e3)} / {_num(s['range_err_rms_m'], 1e3)}",
            f"{_num(s['yaw_err_median_abs_deg'])} / {_num(s['yaw_err_rms_deg'])}",
            f"{s['core_saturated_fraction_mean']:.0%}",
            f"{s['top_failure'] or '–'} / {s['top_cause'] or '–'}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _num(x: float, scale: float = 1.0) -> str:
    return "–" if not math.isfinite(x) else f"{x * scale:.3g}"
