"""Study ``range-limit``: the working range versus yaw per camera, lens and beacon version.

For each camera × beacon × side × LED drive × yaw it renders frames over a range grid
(seeds × jittered poses) and estimates the working range, [near limit, far limit] where a
correct pose has P ≥ 0.95, with profile-likelihood 95 % intervals and the causes of the
failures on either side (:mod:`studies.engine.max_range`), for the best tracker and the
study's. The design's planned 10 m is drawn against it.

With a :class:`studies.engine.sequential.SequentialDesign` (``run(..., design=...)``; the
main job's is :func:`default_design`) the range grid is only the coarse start: frames are
added in rounds where each far (and near) limit is undecided, until its interval meets the
target or the budget is spent, and every record says how many frames decided it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.max_range import (
    estimate_max_range,
    far_interval_text,
    far_limit_text,
    near_failures_text,
    working_range_text,
    works_best_key,
)
from studies.engine.report import Report
from studies.engine.sequential import (
    SequentialDesign,
    decision_text,
    design_evidence,
    run_design,
    summary_p_working,
)
from studies.engine.sweep import Execution, sweep
from studies.engine.tables import pose_outcomes, write_tables
from studies.engine.tasks import StudyOptions, grid_conditions
from studies.engine.uncertainty import (
    interval_text,
    limits_at_points,
    nominal_rows,
    over_points,
    physics_interval,
    physics_note,
    point_rows,
)

__all__ = [
    "ANSWER_LABELS",
    "DECISION_LABEL",
    "GROUP",
    "NAME",
    "PHYSICS_LABEL",
    "UNIT_FIELDS",
    "analyse",
    "default_design",
    "default_options",
    "lead_lines",
    "run",
    "write_outputs",
]

NAME = "range-limit"
PLANNED_RANGE_M = 10.0
GROUP = ["camera", "beacon", "side", "led_current_mA", "nominal_yaw_deg", "tracker"]
"""One working-range estimate per these columns."""
UNIT_FIELDS = (
    ("camera", "camera"),
    ("beacon", "beacon"),
    ("side", "side"),
    ("led_current_mA", "led_current_mA"),
    ("yaw_deg", "nominal_yaw_deg"),
)
"""A sequential design's unit (condition field, row column): :data:`GROUP` without the tracker."""
ANSWER_LABELS = {
    "camera": "camera",
    "beacon": "beacon",
    "side": "side",
    "led_current_mA": "LED drive, mA",
    "yaw_deg": "yaw, °",
    "working_range": "working range (P ≥ 0.95)",
    "far_interval": "far limit, 95 % interval",
    "limiting_cause": "what ends it",
    "failures_nearer": "failures nearer than the best range",
    "correct": "correct frames",
}
"""Columns of the answer table and their headers."""
PHYSICS_LABEL = {
    "far_interval_physics": "far limit, noise + physics",
    "near_interval_physics": "near limit, noise + physics",
}
"""The answer table's column with ``--uncertainty`` (the rate and points are in each cell)."""
DECISION_LABEL = {"decision": "frames that decided it"}
"""The answer table's extra column when a sequential design placed the frames."""


def default_options(quick: bool) -> StudyOptions:
    """Full grid, or the quick one the main job runs (every built-in camera, so the main job states
    each one's far limit at 0° and 30°)."""
    if quick:
        return StudyOptions(
            cameras=("canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920"),
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


def default_design(quick: bool) -> SequentialDesign:
    """The sequential design the main job runs (quick) or a full run starts from: far and near
    limits to ±20 % (the issue's goal), extended to 20 m when the farthest range still works;
    the quick one within 120 frames per unit (assumed: the fake of known truth needs 60-150
    at ±20 %, ``tests/studies/test_sequential.py``), the full one within 240 (the default)."""
    grid = default_options(quick)
    units = len(grid.cameras) * len(grid.beacons) * len(grid.sides) * len(grid.currents_mA) * len(grid.yaws_deg)
    return SequentialDesign(target_relative=0.2, budget_frames=120 * units if quick else None, max_range_m=20.0)


def run(
    out: Path, options: StudyOptions, execution: Execution = Execution(), design: SequentialDesign | None = None
) -> dict:
    """Run the study into ``out``; returns the summary (``max_range`` records).

    ``design``: place the frames sequentially (:mod:`studies.engine.sequential`), starting from
    ``options``' grid; None: the fixed grid. With points of the unknowns (``options.physics``) every
    point repeats the grid, and its budget (a budget of frames is the nominal grid's)."""
    if design is None:
        frame = sweep(NAME, grid_conditions(options), options, out, execution=execution, estimators=["best"])
        return write_outputs(out, options, frame)
    fields, design = over_points(UNIT_FIELDS, design, len(options.physics))
    result = run_design(NAME, options, design, out, fields, estimators=["best"], execution=execution)
    return write_outputs(out, options, write_tables(out, result.rows), result.summary())


def write_outputs(out: Path, options: StudyOptions, frame: pd.DataFrame, design: dict | None = None) -> dict:
    """summary.json and report.html of a finished sweep's results table; returns the summary.

    Parameters
    ----------
    out : the study's output directory.
    options : what was swept (named in the report).
    frame : results table (one row per frame and tracker, ``results.parquet``).
    design : :meth:`studies.engine.sequential.DesignResult.summary` when a sequential design
        placed the frames.
    """
    summary = analyse(frame, design)
    if options.physics:
        summary["physics"] = {"points": len(options.physics), "source": options.physics_source}
    _report(Path(out), options, nominal_rows(frame), summary)
    atomic_write_bytes(Path(out) / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def analyse(frame: pd.DataFrame, design: dict | None = None) -> dict:
    """The summary: one working-range record per camera × beacon × side × drive × yaw for
    each tracker (``max_range``: best tracker; ``max_range_thesis_tracker``: the study's),
    each with the fields of :class:`studies.engine.max_range.MaxRange` and its wording
    (``working_range``, ``far_limit``, ``far_interval``, ``failures_nearer``), and the
    best tracker's outcomes per range point (``outcomes``, Jeffreys posterior of P).

    With a sequential ``design`` (its summary) the summary holds it as ``design`` and each
    record says how many frames decided its limits (``decision``; ``far_decided``,
    ``near_decided``, ``design_stop``: the best tracker's, which placed the frames)."""
    units = {tuple(u["key"]): u for u in (design or {}).get("units", [])}
    level = summary_p_working(design)
    physics, near_physics = limits_at_points(point_rows(frame), GROUP, p_working=level)
    frame = nominal_rows(frame)
    records = []
    for key, g in frame.groupby(GROUP, sort=True):
        cam, beacon, side, current, yaw, tracker = key
        mr = estimate_max_range(g.to_dict("records"), p_working=level).to_dict()
        rec = {
            "camera": cam,
            "beacon": beacon,
            "side": side,
            "led_current_mA": float(current),
            "yaw_deg": float(yaw),
            "tracker": tracker,
            **mr,
        }
        rec.update(
            working_range=working_range_text(rec),
            far_limit=far_limit_text(rec),
            far_interval=far_interval_text(rec),
            failures_nearer=near_failures_text(rec),
        )
        if key in physics:
            iv = physics_interval(physics[key])
            # each point's far limit in point order (0: no range works; inf, null in JSON: ≥ the farthest tried)
            far = iv.to_dict() | {"at_points_m": physics[key]}
            rec.update(far_physics=far, far_interval_physics=interval_text(iv, zero="none"))
        if key in near_physics:
            iv = physics_interval(near_physics[key])
            rec.update(near_physics=iv.to_dict(), near_interval_physics=interval_text(iv))
        elif key in physics:
            rec.update(near_interval_physics="none: no range works at any point")
        if design is not None:
            unit = units.get((cam, beacon, side, float(current), float(yaw)) + ((None,) if physics else ()))
            rec.update(
                decision=decision_text(rec, unit),
                far_decided=bool(unit and unit["far_decided"]),
                near_decided=bool(unit and unit["near_decided"]),
                design_stop=unit["stop"] if unit else "",
            )
        records.append(rec)
    best = frame[frame.tracker == "best"]
    outcomes = pose_outcomes(best, ["camera", "beacon", "side", "led_current_mA", "nominal_yaw_deg"])
    summary = {
        "study": NAME,
        "planned_range_m": PLANNED_RANGE_M,
        "frames_per_point": int(outcomes.frames.min()) if len(outcomes) else 0,
        "max_range": [r for r in records if r["tracker"] == "best"],
        "max_range_thesis_tracker": [r for r in records if r["tracker"] == "thesis"],
        "outcomes": outcomes.rename(columns={"nominal_yaw_deg": "yaw_deg", "nominal_range_m": "range_m"}).to_dict(
            "records"
        ),
    }
    if design is not None:
        summary["design"] = design
    return summary


def lead_lines(summary: dict) -> list[str]:
    """One sentence per camera: its working range at the smallest and largest yaw for the
    beacon, side and drive that work best (best tracker; farthest limits on average, then most
    frames correct: :func:`studies.engine.max_range.works_best_key`), and what ends it."""
    table = pd.DataFrame(summary["max_range"])
    lines = []
    if table.empty:
        return ["No frames."]
    for cam, g in table.groupby("camera", sort=True):
        config = ["beacon", "side", "led_current_mA"]
        # the setting that works best: farthest limits on average, then most frames correct
        score = {k: np.mean([works_best_key(r) for r in c.to_dict("records")], axis=0) for k, c in g.groupby(config)}
        beacon, side, current = max(score, key=lambda k: tuple(score[k]))
        sel = g[(g.beacon == beacon) & (g.side == side) & (g.led_current_mA == current)].sort_values("yaw_deg")
        parts = []
        for rec in (sel.iloc[0], sel.iloc[-1]) if len(sel) > 1 else (sel.iloc[0],):
            if rec.max_range_m > 0:
                text = (
                    f"at {rec.yaw_deg:g}° it works {rec.working_range} (far limit 95 % interval {rec.far_interval}; "
                    f"{_cause(rec)})"
                )
            elif rec.successes:
                best = rec.working_range.split("best: ")[-1].removesuffix(")")
                text = f"at {rec.yaw_deg:g}° no range reaches P ≥ 0.95 (best: {best}; failures: {rec.limiting_cause})"
            else:
                text = f"at {rec.yaw_deg:g}° no frame is correct (failures: {rec.limiting_cause})"
            if rec.near_failures:
                text += f"; {rec.failures_nearer}"
            parts.append(text)
        lines.append(f"{cam} ({beacon.upper()} {side}, {current:g} mA): " + "; ".join(parts) + ".")
    return lines


def _cause(rec) -> str:
    cause = str(rec.limiting_cause)
    return cause if cause.startswith("not reached") else f"ended by {cause}"


def _report(out: Path, options: StudyOptions, frame: pd.DataFrame, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("Range limit: how far each camera localises the beacon, versus yaw")
    rep.lead([*lead_lines(summary), _evidence_note(summary), *physics_note(summary)])
    rep.text(
        f"Cameras {', '.join(options.cameras)}; beacons {', '.join(options.beacons)}; sides "
        f"{', '.join(options.sides)}; LED drive {', '.join(f'{c:g}' for c in options.currents_mA)} mA; yaw "
        f"{', '.join(f'{y:g}' for y in options.yaws_deg)}°; ranges {', '.join(f'{r:g}' for r in options.ranges_m)} m; "
        f"{options.seeds} frames per point{_design_words(summary)}. Working range: where P(correct side, 5 markers "
        "numbered, range within "
        "10 %, yaw within 5°) ≥ 0.95, from a logistic rise up to the range with the best success rate and a "
        "logistic fall-off beyond it (maximum likelihood; 95 % intervals from the plain and the Firth-penalised "
        "profile likelihood)."
    )
    for key, label in (("max_range", "best tracker"), ("max_range_thesis_tracker", "study's tracker")):
        table = pd.DataFrame(summary[key])
        if table.empty:
            continue
        rep.heading(f"Working range, {label}")
        outcomes = pose_outcomes(
            frame[frame.tracker == table.tracker.iloc[0]],
            ["camera", "beacon", "side", "led_current_mA", "nominal_yaw_deg"],
        )
        if outcomes.correct.any():
            ends = {float(outcomes.nominal_yaw_deg.min()), float(outcomes.nominal_yaw_deg.max())}
            shown_yaws = " and ".join(f"{y:g}°" for y in sorted(ends))
            rep.figure(
                _outcome_figure(plt, outcomes[outcomes.nominal_yaw_deg.isin(ends)], table),
                f"Fraction of correct poses versus range at {shown_yaws} (every yaw is in the tables), {label}, with "
                "its 95 % credible interval (Beta posterior, Jeffreys prior; frames at each point in the table "
                "below); bars under the axis, the working range (thick) and the far limit's 95 % interval (thin; an "
                "arrow: it reaches past the farthest range tried); with --uncertainty a wide pale band, the noise + "
                "physics interval. Points of different series are offset sideways so none hides another.",
            )
            if len(set(table.yaw_deg)) > 2:
                rep.figure(
                    _far_limit_figure(plt, table),
                    f"Far limit (95 % interval) versus yaw, {label}; dashed: the design's planned "
                    f"{PLANNED_RANGE_M:g} m; an arrow: the interval reaches past the farthest range tried; a wide "
                    "pale band (with --uncertainty): the noise + physics interval.",
                )
        else:
            rep.text(f"No frame gave a correct pose with the {label}.")
        answers = table.assign(
            correct=[f"{s} of {n}" for s, n in zip(table.successes, table.frames, strict=True)],
            failures_nearer=[t or "– (none tried nearer)" for t in table.failures_nearer],
        )
        labels = {
            **ANSWER_LABELS,
            **{k: v for k, v in PHYSICS_LABEL.items() if k in answers},
            **(DECISION_LABEL if "decision" in answers else {}),
        }
        rep.table(
            answers[list(labels)],
            f"Working range per camera and yaw, {label}",
            labels=labels,
            formats={"led_current_mA": "{:g}", "yaw_deg": "{:g}"},
            css_class="keys",
        )
        if key == "max_range":
            shown = outcomes.assign(
                correct=[f"{k} of {n}" for k, n in zip(outcomes.correct, outcomes.frames, strict=True)],
                failures=[
                    f"{f} ({c}: {cf})" if f else "–"
                    for f, c, cf in zip(outcomes.failed, outcomes.cause, outcomes.cause_frames, strict=True)
                ],
            )
            rep.table(
                shown[
                    [
                        "camera",
                        "beacon",
                        "side",
                        "led_current_mA",
                        "nominal_yaw_deg",
                        "nominal_range_m",
                        "correct",
                        "p_low",
                        "p_high",
                        "failures",
                    ]
                ],
                f"Every range point, {label}",
                float_format="{:.2f}",
                formats={"led_current_mA": "{:g}", "nominal_yaw_deg": "{:g}", "nominal_range_m": "{:g}"},
                labels={
                    "led_current_mA": "LED drive, mA",
                    "nominal_yaw_deg": "yaw, °",
                    "nominal_range_m": "range, m",
                    "correct": "correct poses",
                    "p_low": "P(correct): 2.5 %",
                    "p_high": "97.5 % (Jeffreys)",
                    "failures": "failed (main cause: frames)",
                },
                css_class="keys",
            )
    rep.write(out / "report.html")


def _design_words(summary: dict) -> str:
    design = summary.get("design")
    return f" to start, then more where the limits are undecided (target {design['target']})" if design else ""


def _evidence_note(summary: dict) -> str:
    if summary.get("design"):
        return (
            design_evidence(summary) + " An interval from 0 m means the frames cannot exclude that no range reaches "
            "P ≥ 0.95; '≥' means the fit shows no fall-off up to the farthest range tried."
        )
    n = summary.get("frames_per_point", 0)
    return (
        f"Evidence: {n} frames per range point. An interval from 0 m means the frames cannot exclude that no range "
        "reaches P ≥ 0.95 (showing P ≥ 0.95 at one range needs at least 59 correct frames in a row there); "
        "'≥' means the fit shows no fall-off up to the farthest range tried."
    )


_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
_LINES = ("-", "--", ":", "-.")


def _series_styles(keys: list) -> dict:
    """A distinct colour, marker and line style per series key."""
    return {
        k: {"color": f"C{i % 10}", "marker": _MARKERS[i % len(_MARKERS)], "ls": _LINES[i % len(_LINES)]}
        for i, k in enumerate(keys)
    }


def _outcome_figure(plt, outcomes: pd.DataFrame, table: pd.DataFrame):
    """Per camera: P(correct pose) versus range with credible intervals, one series per
    beacon × side × drive × yaw, and the working ranges as bars under the axis."""
    cams = sorted(set(outcomes.camera))
    config = ["beacon", "side", "led_current_mA", "nominal_yaw_deg"]
    keys = sorted({tuple(k) for k in outcomes[config].itertuples(index=False)})
    styles = _series_styles(keys)
    ranges = sorted(set(outcomes.nominal_range_m))
    step = min(np.diff(ranges)) if len(ranges) > 1 else 1.0
    ncols = min(2, len(cams))
    nrows = math.ceil(len(cams) / ncols)
    height = 3.2 + 0.22 * len(keys)
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(4.3 * ncols + 2.4, height * nrows),
        sharey=True,
        squeeze=False,
        constrained_layout=True,
    )
    for ax in axes.flat[len(cams) :]:
        ax.set_visible(False)
    for ax, cam in zip(axes.flat, cams, strict=False):
        present = [k for k in keys if ((outcomes.camera == cam) & _match(outcomes, config, k)).any()]
        for i, k in enumerate(present):
            g = outcomes[(outcomes.camera == cam) & _match(outcomes, config, k)]
            dx = (i - (len(present) - 1) / 2) * 0.06 * step
            ax.errorbar(
                g.nominal_range_m + dx,
                g.fraction,
                yerr=[g.fraction - g.p_low, g.p_high - g.fraction],
                capsize=3,
                lw=1.6,
                ms=7,
                mfc="white" if i % 2 else None,
                label=_series_label(k),
                **styles[k],
            )
            rec = table[
                (table.camera == cam)
                & (table.beacon == k[0])
                & (table.side == k[1])
                & (table.led_current_mA == k[2])
                & (table.yaw_deg == k[3])
            ]
            if len(rec):
                _working_bar(ax, rec.iloc[0], -0.09 * (i + 1), styles[k]["color"], max(ranges))
        ax.axhline(0.95, color="grey", ls=":", lw=1)
        ax.text(min(ranges) - 0.55 * step, 0.93, "0.95", color="grey", fontsize=8, va="top")
        ax.set_ylim(-0.09 * (len(present) + 1) - 0.02, 1.05)
        ax.set_yticks([0, 0.25, 0.5, 0.75, 1.0])
        ax.set_title(cam, fontsize=11)
        ax.set_xlabel("range, m", fontsize=10)
        ax.set_xlim(min(ranges) - 0.6 * step, max(ranges) + 0.6 * step)
    for row in axes:
        row[0].set_ylabel("P(correct pose)", fontsize=10)
    handles = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    fig.legend(
        list(handles.values()), list(handles), fontsize=9, loc="outside right center", title="beacon, side, drive, yaw"
    )
    return fig


def _match(frame: pd.DataFrame, columns: list[str], key: tuple) -> pd.Series:
    mask = pd.Series(True, index=frame.index)
    for c, v in zip(columns, key, strict=True):
        mask &= frame[c] == v
    return mask


def _series_label(key: tuple) -> str:
    beacon, side, current, yaw = key
    return f"{beacon.upper()} {side}, {current:g} mA, {yaw:g}°"


def _working_bar(ax, rec, y: float, colour: str, farthest: float) -> None:
    """The working range (thick), the far limit's interval (thin) and, with ``--uncertainty``, its noise +
    physics interval (a wide pale band) at height y."""
    physics = _physics_span(getattr(rec, "far_physics", None), farthest)
    if physics:
        ax.plot(physics, [y, y], color=colour, lw=11, alpha=0.22, solid_capstyle="butt")
    if rec.max_range_m > 0:
        near = rec.nearest_tested_m if rec.near_at_most else rec.near_limit_m
        ax.plot([near, rec.max_range_m], [y, y], color=colour, lw=5, solid_capstyle="butt")
    low = rec.low_m
    high = rec.high_m if math.isfinite(rec.high_m) else farthest
    ax.plot([low, high], [y, y], color=colour, lw=1.2)
    if not math.isfinite(rec.high_m):
        ax.annotate("", xy=(farthest + 0.5, y), xytext=(farthest, y), arrowprops={"arrowstyle": "->", "color": colour})


def _physics_span(physics, farthest: float) -> tuple[float, float] | None:
    """(low, high) of a record's noise + physics interval, m, the farthest range tried for an open end;
    None without one."""
    if not isinstance(physics, dict):
        return None
    low, high = physics["low"], physics["high"]  # None: "≥ the farthest tried" (a far limit)
    return farthest if low is None else float(low), farthest if high is None else float(high)


def _far_limit_figure(plt, table: pd.DataFrame):
    """Per camera: the far limit versus yaw with its interval, one series per beacon × side × drive."""
    cams = sorted(set(table.camera))
    config = ["beacon", "side", "led_current_mA"]
    keys = sorted({tuple(k) for k in table[config].itertuples(index=False)})
    styles = _series_styles(keys)
    width = min(5.2, (10.6 - 2.0) / len(cams))
    fig, axes = plt.subplots(
        1, len(cams), figsize=(width * len(cams) + 2.4, 4.2), sharey=True, squeeze=False, constrained_layout=True
    )
    top = float(table.farthest_tested_m.max())
    for ax, cam in zip(axes[0], cams, strict=True):
        for i, k in enumerate(keys):
            g = table[(table.camera == cam) & _match(table, config, k)].sort_values("yaw_deg")
            if g.empty:
                continue
            x = g.yaw_deg + (i - (len(keys) - 1) / 2) * 0.4
            r = g.max_range_m.to_numpy(float)
            for xi, physics in zip(x, g.get("far_physics", [None] * len(g)), strict=True):
                span = _physics_span(physics, top)
                if span:
                    ax.plot([xi, xi], span, color=styles[k]["color"], lw=9, alpha=0.22, solid_capstyle="butt")
            hi = np.where(np.isfinite(g.high_m), g.high_m, top)
            ax.errorbar(
                x,
                r,
                yerr=[np.clip(r - g.low_m, 0, None), np.clip(hi - r, 0, None)],
                capsize=3,
                ms=7,
                label=f"{k[0].upper()} {k[1]}, {k[2]:g} mA",
                **styles[k],
            )
            for xi, ok in zip(x, ~np.isfinite(g.high_m), strict=True):
                if ok:
                    ax.annotate(
                        "",
                        xy=(xi, top * 1.06),
                        xytext=(xi, top),
                        arrowprops={"arrowstyle": "->", "color": styles[k]["color"]},
                    )
        ax.axhline(PLANNED_RANGE_M, color="red", ls="--", lw=1, label=f"planned {PLANNED_RANGE_M:g} m")
        ax.set_title(cam, fontsize=11)
        ax.set_xlabel("yaw, °", fontsize=10)
        ax.set_ylim(0, top * 1.1)
    axes[0][0].set_ylabel("far limit, m", fontsize=10)
    axes[0][-1].legend(fontsize=9, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return fig
