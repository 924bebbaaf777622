"""Calibrate the unknowns by history matching against what the study saw at close range (issue 25).

The study set itself up on close-range frames: it tuned its colour boxes by hand on a webcam's
images of V1 at 150 mm, each colour, lights on and off, and its primary test found V2 at 1 m over
0-30° with both lenses (docs/source-study.md §10). Those observations (``studies/data/observations.toml``,
each with its observation error and model discrepancy) are the only calibration data; every range
of 2 m and beyond stays a prediction.

A point of the unknowns (every registry entry of the conditions' cameras, one dimmer setting per
beacon side, and which webcam the thresholds were tuned on: the space of
:func:`studies.catalog.unknowns_search.search_space`) becomes frame tasks of every observed
condition × noise seed; the simulator's output for an observation is the mean over the seeds of
:data:`OUTPUTS`. The history match (:func:`studies.engine.calibration.history_match`) emulates those
outputs with Gaussian processes, rules out the points whose implausibility exceeds the cut-off and
refocuses, wave after wave; what is not ruled out (NROY) is the calibrated set.

Writes into ``out``: ``history.json`` (every wave, rewritten after each so an interrupted run
resumes from it), ``nroy.csv`` (the not-ruled-out points, values), ``summary.json`` and the
figures of :func:`studies.engine.calibration.write_figures`; finished frames in ``tasks/`` as
every study's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from scenes.led import SIDE_COLOURS
from scenes.render_cache import atomic_write_bytes
from scenes.sourced import DataFileError, load_tables
from studies.catalog import unknowns_search
from studies.engine import strict_json
from studies.engine.calibration import (
    KINDS,
    HistoryMatch,
    InputSpace,
    Observation,
    Settings,
    closest_points,
    from_json,
    history_match,
    nroy_sample,
    observation_shares,
    to_json,
    write_figures,
)
from studies.engine.calibration.plots import ranked_inputs
from studies.engine.frame_task import FrameTask
from studies.engine.report import Report
from studies.engine.sweep import Execution, run_frames
from studies.engine.unknowns import Unknown, apply

__all__ = [
    "CONDITIONS",
    "OBSERVATIONS_FILE",
    "OUTPUTS",
    "PRIMARY_SIDE",
    "Observed",
    "load_observations",
    "run",
    "search_space",
    "simulator",
    "tasks",
    "write_outputs",
    "write_report",
]

NAME = "calibrate-unknowns"
OBSERVATIONS_FILE = Path(__file__).resolve().parents[1] / "data" / "observations.toml"
RENDER = {"spp": 4, "oversampling": 2, "crop": "target", "near_field_spp": 1024}
"""Render settings of the calibration's frames (close range: the target alone is in view)."""
QUICK_RENDER = {**RENDER, "near_field_spp": 256}
CLOSEST = 64
"""Reference points ``closest.csv`` holds: the least implausible, whether or not any survives (a
prediction made from them when nothing does says so)."""
NROY_SAMPLE = 256
"""Points of the NROY set ``nroy.csv`` holds (drawn from it: the reference sample's few survivors of a
small set are too few to predict from)."""
"""The quick form's: near fields at a quarter of the samples. Measured on V1's red marker (foam + one
sheet): the radial profile's centre bin (1/144 of the face's area) scatters ±16 % over seeds at 256
samples and ±11 % at 1 024; the outer bins ±5 %. A near field is 16 s of one core at 1 024 samples
(4 s at 256), about a quarter of a calibration point's cost beside its 12 beacon renders and 24
captures."""

CONDITIONS: dict[str, dict] = {
    "webcam-150mm": {
        "scenario": {"beacon": "v1", "range_m": 0.15, "camera": unknowns_search.WEBCAMS[0]},
        "task": {"full_frame": True},
    },
    "t6-18mm-1m": {
        "scenario": {"beacon": "v2", "range_m": 1.0, "camera": "canon-t6-18mm"},
        "task": {"align_px": 16},
    },
    "t6-10mm-1m": {
        "scenario": {"beacon": "v2", "range_m": 1.0, "camera": "canon-t6-10mm"},
        "task": {"align_px": 16},
    },
}
"""The close-range set-ups: Scenario fields and frame-task options. The webcam frame is the whole
saved frame (the tuning webcam is an unknown); the T6 frames a crop aligned to 16 px, so JPEG blocks
and the study's 50 % resize group the pixels as in the whole frame, at the primary test's ISO 6400
and 1/60 s."""
BUILT = {"foam": True, "paper_sheets": 1, "paper_colour": "matched", "led_current_mA": 20.0}
"""The beacons as built (foam + one sheet, docs/source-study.md §3); the drive is the point's."""
T6_EXPOSURE = {"iso": 6400, "exposure_s": 1 / 60}
"""The primary test's DSLR settings (docs/source-study.md §10, item 2)."""


def _thesis_mean(field: str) -> Callable[[Sequence[dict]], float]:
    """The mean over frames of one field of the study's tracker's rows (NaN where none has it)."""

    def output(rows: Sequence[dict]) -> float:
        values = [float(r[field]) for r in rows if r["tracker"] == "thesis" and r.get(field) is not None]
        values = [v for v in values if math.isfinite(v)]
        return float(np.mean(values)) if values else math.nan

    output.__doc__ = f"Mean ``{field}`` of the study's tracker's rows."
    return output


OUTPUTS: dict[str, Callable[[Sequence[dict]], float]] = {
    "side_blobs": _thesis_mean("side_blobs"),
    "side_closed_height_px": _thesis_mean("side_closed_height_px"),
    "side_box_distance": _thesis_mean("side_box_distance"),
    "core_clipped": _thesis_mean("core_saturated_fraction_mean"),
}
"""Simulator outputs an observation may name: frames' rows → one number (the mean over the seeds):
the study's tracker's blobs of the side's colour (printed boxes and morphology), its near-miss measures
at the true markers (:mod:`pipeline.mask_measures`) and the marker cores' clipped fraction (raw)."""
PRIMARY_SIDE = Unknown(
    name="primary_test_side",
    target="scenario.side",
    kind="choice",
    nominal="red",
    choices=SIDE_COLOURS,
    cameras=("canon-t6-18mm", "canon-t6-10mm"),
    provenance="source: docs/source-study.md §10, item 3 names the primary test's beacon (V2), lenses, ranges, "
    "yaws and room, not the side that faced the camera: any of the four",
)
"""The side the primary test showed the camera (its frames' ``side = "primary"``)."""


@dataclass(frozen=True)
class Observed:
    """One observation and the frames that simulate it.

    Attributes
    ----------
    observation
        The observed value with its error and discrepancy (:class:`studies.engine.calibration.Observation`),
        named ``<frame>.<output>``.
    frame
        The observed frame's table name: the frames of one table serve all its outputs.
    condition
        Key of :data:`CONDITIONS`.
    side, environment, yaw_deg
        The frame's side (``primary``: :data:`PRIMARY_SIDE`, the point's), room and yaw, degrees.
    drive_mA
        The LED drive, mA; None: the side's dimmer setting, an unknown of the point.
    output
        Key of :data:`OUTPUTS`.
    """

    observation: Observation
    frame: str
    condition: str
    side: str
    environment: str
    yaw_deg: float
    drive_mA: float | None
    output: str


_FRAME_KEYS = {"condition", "side", "environment", "yaw_deg", "drive"}
_OUTPUT_KEYS = {"kind", "z", "obs_sd", "obs_reason", "disc_sd", "disc_reason"}


def load_observations(path: str | Path = OBSERVATIONS_FILE) -> tuple[Observed, ...]:
    """The observations file, checked (:class:`scenes.sourced.DataFileError`, one line naming the field)."""
    raw = load_tables(path, "observations")
    out = []
    for name, table in raw.items():
        out += _frame(name, table, f"{path}: {name}")
    if not out:
        raise DataFileError(f"{path}: no observation (expected a [frame.output] table)")
    return tuple(out)


def _frame(name: str, t: Any, at: str) -> list[Observed]:
    if not isinstance(t, dict):
        raise DataFileError(f"{at}: expected a table")
    outputs = {k: v for k, v in t.items() if isinstance(v, dict)}
    fields = {k: v for k, v in t.items() if k not in outputs}
    extra = sorted(set(fields) - _FRAME_KEYS) + sorted(set(outputs) - set(OUTPUTS))
    if extra:
        expected = f"some of {', '.join(sorted(_FRAME_KEYS))}, or an output table: {', '.join(OUTPUTS)}"
        raise DataFileError(f"{at}.{extra[0]}: unknown key (expected {expected})")
    for key in ("condition", "side", "environment", "drive"):
        if key not in fields:
            raise DataFileError(f"{at}.{key}: missing")
    yaw = fields.get("yaw_deg", 0.0)
    primary = fields["condition"] in CONDITIONS and fields["condition"].startswith("t6-")
    sides = (*SIDE_COLOURS, "primary") if primary else SIDE_COLOURS
    checks = (
        ("condition", fields["condition"] in CONDITIONS, ", ".join(CONDITIONS)),
        ("side", fields["side"] in sides, ", ".join(sides)),
        ("environment", fields["environment"] in ("dark-room", "lit-room"), "dark-room or lit-room"),
        (
            "drive",
            fields["drive"] == "dimmed" or _number(fields["drive"], positive=True),
            '"dimmed" or a current > 0 mA',
        ),
        ("yaw_deg", _number(yaw) and abs(yaw) <= 90, "an angle in [-90, 90]"),
    )
    for key, ok, expected in checks:
        if not ok:
            raise DataFileError(f"{at}.{key}: expected {expected}, got {fields.get(key)!r}")
    if not outputs:
        raise DataFileError(f"{at}: no output observed (expected a [{name}.<output>] table: {', '.join(OUTPUTS)})")
    drive = None if fields["drive"] == "dimmed" else float(fields["drive"])
    return [
        Observed(_observation(f"{name}.{output}", o, f"{at}.{output}"), name, fields["condition"], fields["side"],
                 fields["environment"], float(yaw), drive, output)
        for output, o in outputs.items()
    ]  # fmt: skip


def _observation(name: str, t: dict, at: str) -> Observation:
    extra = sorted(set(t) - _OUTPUT_KEYS)
    if extra:
        raise DataFileError(f"{at}.{extra[0]}: unknown key (expected some of {', '.join(sorted(_OUTPUT_KEYS))})")
    for key in ("z", "obs_sd", "disc_sd"):
        if key not in t:
            raise DataFileError(f"{at}.{key}: missing")
    for key in ("obs_reason", "disc_reason"):
        if not isinstance(t.get(key), str) or len(t[key].strip()) < 10:
            raise DataFileError(f"{at}.{key}: expected the reasoning (a sentence)")
    checks = (
        ("kind", t.get("kind", "equal") in KINDS, ", ".join(KINDS)),
        ("z", _number(t["z"]), "a finite number"),
        ("obs_sd", _number(t["obs_sd"]) and t["obs_sd"] >= 0, "a standard deviation >= 0"),
        ("disc_sd", _number(t["disc_sd"]) and t["disc_sd"] >= 0, "a standard deviation >= 0"),
    )
    for key, ok, expected in checks:
        if not ok:
            raise DataFileError(f"{at}.{key}: expected {expected}, got {t.get(key)!r}")
    return Observation(
        name=name,
        z=float(t["z"]),
        obs_var=float(t["obs_sd"]) ** 2,
        disc_var=float(t["disc_sd"]) ** 2,
        obs_reason=t["obs_reason"],
        disc_reason=t["disc_reason"],
        kind=t.get("kind", "equal"),
    )


def _number(x: Any, positive: bool = False) -> bool:
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return False
    return x > 0 if positive else True


def search_space(observed: Sequence[Observed]) -> dict[str, Unknown]:
    """The unknowns of the observed conditions' cameras that act at their ranges (not the study's
    later sessions' tracker settings), one dimmer setting per beacon side that an
    observation leaves dimmed (``led_drive_v2_primary`` for the primary test's side), which webcam
    tuned the thresholds (when a webcam frame is observed) and the primary test's side (when one of
    its frames is)."""
    space = unknowns_search.search_space()
    cameras = {CONDITIONS[o.condition]["scenario"]["camera"] for o in observed}
    webcam = bool(cameras & set(unknowns_search.WEBCAMS))
    cameras |= set(unknowns_search.WEBCAMS) if webcam else set()
    if "canon-t6-10mm" in cameras:  # the search of unknowns-search had no 10 mm condition
        reach = max(c["scenario"]["range_m"] for c in CONDITIONS.values())
        space.update(
            {
                n: u
                for n, u in unknowns_search.load_unknowns().items()
                if "canon-t6-10mm" in u.cameras and u.applies_at(reach)
            }
        )
    drive = next(u for n, u in space.items() if n.startswith("led_drive_"))
    drives = {
        unknowns_search.drive_name(CONDITIONS[o.condition]["scenario"]["beacon"], o.side)
        for o in observed
        if o.drive_mA is None
    }
    out = {}
    for name, u in space.items():
        if name.startswith("led_drive_"):
            continue
        if name == unknowns_search.TUNING_WEBCAM.name:
            if webcam:
                out[name] = u
        elif not u.cameras or cameras & set(u.cameras):
            out[name] = u
    out.update({name: replace(drive, name=name) for name in sorted(drives)})
    if any(o.side == "primary" for o in observed):
        out[PRIMARY_SIDE.name] = PRIMARY_SIDE
    return out


def tasks(
    points: Sequence[dict],
    observed: Sequence[Observed],
    space: dict[str, Unknown],
    seeds: int,
    render: dict | None = None,
) -> list[dict]:
    """Frame tasks of every point × observed frame × seed (the study's tracker and estimator only), tagged
    with the point and the frame's table name (the outputs observed on one frame share its frames)."""
    registry = unknowns_search.registry_for(space) if any(k.startswith("led_drive_") for k in space) else space
    registry = {k: u for k, u in registry.items() if k != PRIMARY_SIDE.name}
    frames = {o.frame: o for o in observed}  # one set of frames per table, whatever it observes
    out = []
    for index, values in enumerate(points):
        for o in frames.values():
            condition = CONDITIONS[o.condition]
            side = values[PRIMARY_SIDE.name] if o.side == "primary" else o.side
            scenario = {
                **BUILT,
                **condition["scenario"],
                "side": side,
                "environment": o.environment,
                "yaw_deg": o.yaw_deg,
            }
            point = {k: v for k, v in values.items() if k != PRIMARY_SIDE.name}
            if o.drive_mA is None:
                own = unknowns_search.task_values(point, scenario["beacon"], o.side)
            else:
                own = {k: v for k, v in point.items() if not k.startswith("led_drive_")}
                scenario["led_current_mA"] = o.drive_mA
            for seed in range(seeds):
                task = {
                    "scenario": dict(scenario),
                    "render": dict(RENDER if render is None else render),
                    "seed": seed,
                    "trackers": ["thesis"],
                    "estimators": ["thesis"],
                    **condition["task"],
                    "tags": {"point": index, "observed": o.frame},
                }
                if scenario["camera"].startswith("canon-t6"):
                    task["exposure"] = dict(T6_EXPOSURE)
                task = apply(task, own, registry)  # tuning_webcam sets a webcam frame's camera
                out.append(FrameTask.coerce(task).to_dict())
    return out


def simulator(
    out: Path,
    observed: Sequence[Observed],
    space: dict[str, Unknown],
    seeds: int,
    execution: Execution,
    render: dict | None = None,
):
    """``simulate(values) -> (n, m) outputs`` for :func:`studies.engine.calibration.history_match`: the
    points' frames run (and stored in ``out``, so a repeated point is not simulated twice), each
    observation's output the mean over its seeds (NaN where no frame of it ran)."""

    def simulate(points: list[dict[str, Any]]) -> np.ndarray:
        rows = run_frames(
            tasks(points, observed, space, seeds, render), out, execution, description="calibration frames"
        )
        frame = pd.DataFrame(rows)
        result = np.full((len(points), len(observed)), np.nan)
        for (index, name), g in frame.groupby(["point", "observed"]):
            records = g.to_dict("records")
            for j, o in enumerate(observed):
                if o.frame == name:
                    result[int(index), j] = OUTPUTS[o.output](records)
        return result

    return simulate


def run(
    out: Path,
    *,
    settings: Settings | None = None,
    seeds: int = 2,
    observations: str | Path = OBSERVATIONS_FILE,
    execution: Execution = Execution(),
    render: dict | None = None,
) -> HistoryMatch:
    """History-match the unknowns to the observations; write the record, NROY set, summary and figures.

    An interrupted run resumes from ``out/history.json`` (its finished waves) and ``out/tasks`` (its
    finished frames).
    """
    settings = Settings() if settings is None else settings
    if seeds < 1:
        raise ValueError(f"seeds: expected an integer >= 1, got {seeds!r}")
    observed = load_observations(observations)
    unknowns = search_space(observed)
    space = InputSpace.from_unknowns(unknowns)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    record = out / "history.json"
    resume = from_json(record.read_text(encoding="utf-8")) if record.is_file() else None

    def save(result: HistoryMatch) -> None:
        atomic_write_bytes(record, to_json(result).encode())

    result = history_match(
        simulator(out, observed, unknowns, seeds, execution, render),
        space,
        [o.observation for o in observed],
        settings=settings,
        resume=resume,
        on_wave=save,
    )
    save(result)
    write_outputs(result, observed, out)
    return result


def write_outputs(result: HistoryMatch, observed: Sequence[Observed], out: Path) -> None:
    """``nroy.csv`` (:data:`NROY_SAMPLE` points not ruled out, :func:`nroy_sample`), ``closest.csv``
    (the :data:`CLOSEST` least implausible reference points, with their implausibility), the figures,
    ``summary.json`` and ``report.html`` of a match (also of one read back from its ``history.json``
    while it is still running: they then say "running")."""
    out = Path(out)
    sample = nroy_sample(result, NROY_SAMPLE)
    values = result.space.values(sample[0]) if len(sample[0]) else []
    nroy = pd.DataFrame(values) if values else pd.DataFrame(columns=list(result.space.names))
    atomic_write_bytes(out / "nroy.csv", nroy.to_csv(index=False, float_format="%.6g").encode())
    near, implausibility = closest_points(result, CLOSEST) if result.waves else (np.empty((0, 0)), np.empty(0))
    closest = pd.DataFrame(result.space.values(near) if len(near) else [], columns=list(result.space.names))
    closest["implausibility"] = implausibility
    atomic_write_bytes(out / "closest.csv", closest.to_csv(index=False, float_format="%.6g").encode())
    write_figures(result, out)
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary(result, observed, sample), indent=2).encode())
    write_report(result, observed, out, sample)


def summary(result: HistoryMatch, observed: Sequence[Observed], sample: tuple[np.ndarray, int] | None = None) -> dict:
    """What the match found, in plain data: waves with their NROY fraction, why it stopped, and per
    observation its condition and the discrepancy it needed."""
    alone, without = observation_shares(result)
    return {
        "study": NAME,
        "stopped": result.stopped,
        "waves": [
            {
                "wave": w.index,
                "runs": len(w.design),
                "failed_runs": int(np.isnan(w.outputs).any(axis=1).sum()),
                "nroy_fraction": w.nroy_fraction,
                "loo_coverage_95": [d.coverage_95 for d in w.loo],
            }
            for w in result.waves
        ],
        "nroy_points": len(result.nroy_points),
        "nroy_sample": dict(zip(("points", "drawn"), _sample_counts(result, sample), strict=True)),
        "discrepancy": [
            {
                "observation": d.observation,
                "stated_sd": d.stated_sd,
                "alone_sd": d.alone_sd,
                "joint_sd": d.joint_sd,
                "rules_out_alone": d.rules_out_alone,
                "share_ruled_out_alone_wave1": float(a),
                "share_left_without_it_wave1": float(w),
            }
            for d, a, w in zip(result.discrepancy, alone, without, strict=False)  # no waves: no discrepancy
        ],
        "observations": [
            {
                "name": o.observation.name,
                "frame": o.frame,
                "condition": o.condition,
                "side": o.side,
                "environment": o.environment,
                "yaw_deg": o.yaw_deg,
                "output": o.output,
                "kind": o.observation.kind,
                "z": o.observation.z,
            }
            for o in observed
        ],
        "inputs": list(result.space.names),
    }


RUNS_PER_INPUT = 10
"""Runs per input below which the report warns that the emulators are thin (Loeppky, Sacks & Welch 2009)."""
DESCRIBED = 20
"""Fewest NROY reference points the report describes by their ranges (fewer: it says how many, no ranges)."""
PINNED = 0.8
"""An unknown counts as narrowed when the NROY set keeps less than this share of its range (5-95 % span;
for a categorical one, of its choices)."""


def _sample_counts(result: HistoryMatch, sample: tuple[np.ndarray, int] | None) -> tuple[int, int]:
    points, drawn = nroy_sample(result, NROY_SAMPLE) if sample is None else sample
    return len(points), drawn


def input_table(result: HistoryMatch, points: np.ndarray | None = None) -> pd.DataFrame:
    """Per input, most constraining first (:func:`studies.engine.calibration.plots.ranked_inputs`): its
    range, and the NROY set's 5-95 % span (continuous) or the choices it keeps (categorical), with
    the share of the range that span covers; over ``points`` (unit points of the NROY set, e.g.
    :func:`nroy_sample`'s; default the reference sample's survivors)."""
    q = result.nroy_points if points is None else points
    rows = []
    for i in ranked_inputs(result):
        inp = result.space.inputs[i]
        unit = f" {inp.unit}" if inp.unit else ""
        if inp.categorical:
            kept = sorted({str(v) for v in inp.from_unit(q[:, i])}) if len(q) else []
            every = len(kept) == len(inp.choices) and len(kept) > 3
            choices = f"{len(inp.choices)} choices" if len(inp.choices) > 3 else " | ".join(map(str, inp.choices))
            rows.append(
                {
                    "input": inp.name,
                    "range": choices,
                    "NROY": f"all {len(kept)}" if every else " | ".join(kept) if kept else "–",
                    "share kept": len(kept) / len(inp.choices),
                }
            )
            continue
        if len(q):
            lo_q, hi_q = np.percentile(q[:, i], [5, 95])
            lo, hi = inp.from_unit(np.array([lo_q, hi_q]))
            kept, share = f"{lo:.3g}-{hi:.3g}{unit}", float(hi_q - lo_q) / 0.9
        else:
            kept, share = "–", math.nan
        scale = ", log" if inp.log else ""
        rows.append({"input": inp.name, "range": f"{inp.low:g}-{inp.high:g}{unit}{scale}", "NROY": kept,
                     "share kept": share})  # fmt: skip
    return pd.DataFrame(rows)


def write_report(
    result: HistoryMatch, observed: Sequence[Observed], out: Path, sample: tuple[np.ndarray, int] | None = None
) -> Path:
    """``report.html``: what the match found, in words first, then the figures and tables (waves,
    inputs over the NROY sample ``sample`` (:func:`nroy_sample`: points, drawn), observations with the
    discrepancy each needs, emulator diagnostics)."""
    out = Path(out)
    points, drawn = nroy_sample(result, NROY_SAMPLE) if sample is None else sample
    frames = len({o.frame for o in observed})
    runs = sum(len(w.design) for w in result.waves)
    plural = "" if len(result.waves) == 1 else "s"
    rep = Report("Calibration by history matching: the unknowns against what the study saw at close range")
    lead = [
        f"{len(result.observations)} observed outputs on {frames} close-range frames (docs/source-study.md §10: the "
        f"150 mm threshold tuning and the primary test's 1 m frames), {result.space.dim} unknowns; "
        f"{len(result.waves)} wave{plural} of {result.settings.n_per_wave} points ({runs} points simulated); a point "
        f"is ruled out when the {_ordinal(result.settings.order)} implausibility over the outputs exceeds "
        f"{result.settings.cutoff:g}. "
        + (
            f"Still running: {len(result.waves)} of at most {result.settings.max_waves} waves written; what follows "
            "is the state after the last of them."
            if result.stopped == "running"
            else f"Stopped: {result.stopped}."
        ),
    ]
    if runs < RUNS_PER_INPUT * result.space.dim:
        lead.append(
            f"Caution: {runs} runs for {result.space.dim} inputs, fewer than the {RUNS_PER_INPUT} per input a "
            'Gaussian-process emulator is usually given (Loeppky, Sacks & Welch 2009, "Choosing the sample size '
            'of a computer experiment"): what the emulators rule out between the runs is their guess; the '
            "simulated outputs below are the evidence."
        )
    found = (
        f"Not ruled out (NROY): {result.nroy_fraction:.3g} of the space ({len(result.nroy_points)} of "
        f"{result.settings.n_reference} reference points); nroy.csv holds {len(points)} points drawn from it "
        f"({len(points)} of {drawn} Sobol' points passed every wave)"
    )
    if 0 < len(points) < DESCRIBED:
        lead.append(
            f"{found}: too few to describe by ranges. The discrepancy table says which observations leave so little."
        )
    elif len(points):
        table = input_table(result, points)
        pinned = table[table["share kept"] < PINNED]
        lead.append(
            f"{found}. "
            + (
                "Narrowed: " + "; ".join(f"{r.input} to {r.NROY} (range {r.range})" for r in pinned.itertuples())
                if len(pinned)
                else "No unknown is narrowed"
            )
            + f"; the other {len(table) - len(pinned)} keep at least {PINNED:.0%} of their range."
        )
    else:
        shares, _ = observation_shares(result)
        alone = [o.name for o, a in zip(result.observations, shares, strict=True) if a >= 1.0]
        _, worst = closest_points(result, DESCRIBED) if result.waves else (None, np.array([]))
        lead.append(
            "Nothing survives at the stated discrepancies"
            + (
                f": {' and '.join(alone)} each rule out the whole space alone (under the first wave's emulators)."
                if alone
                else "."
            )
            + " The discrepancy table says how much each observation would need where the earlier waves left "
            "room, and what each rules out alone."
            + (
                f" The {len(worst)} least implausible reference points (closest.csv; their implausibility "
                f"{worst.min():.2f}-{worst.max():.2f} against the cut-off {result.settings.cutoff:g}) are what a "
                "prediction can be made from, saying that none of them is consistent."
                if len(worst)
                else ""
            )
        )
    rep.lead(lead)
    for name, caption in (
        ("outputs", "What the simulator gave at each wave's points (dots, a colour per wave) beside what the study "
         "saw (black line) and the band the cut-off accepts with no emulator error (grey: z ± 3σ, σ² the "
         "observation and discrepancy variances; for a bound, its accepted side)."),
        ("nroy_fraction", "Share of the space not ruled out after each wave."),
        ("nroy_marginals", "Per unknown, most constraining first: the lowest implausibility reachable with it at "
         "each value (blue line; red dashes: the cut-off) and the share of points there not ruled out (green "
         "bars, right axis)."),
        ("nroy_pairs", "Pairs of the most constraining unknowns."),
        ("loo_errors", "Emulator diagnostics: leave-one-out standardised errors (about 95 % should lie in ±2)."),
    ):  # fmt: skip
        path = out / f"{name}.png"
        if path.is_file():
            rep.image_png(path.read_bytes(), caption)
    rep.heading("Waves")
    rep.table(
        pd.DataFrame(
            [
                {
                    "wave": w.index,
                    "points": len(w.design),
                    "failed": int(np.isnan(w.outputs).any(axis=1).sum()),
                    "region share": w.region_fraction,
                    "NROY share": w.nroy_fraction,
                }
                for w in result.waves
            ]
        )
    )
    rep.heading("Unknowns, most constraining first")
    rep.table(input_table(result, points), formats={"share kept": "{:.2f}"})
    rep.heading("Observations and the discrepancy each needs")
    need = {d.observation: d for d in result.discrepancy}
    alone, without = observation_shares(result)
    shares = {o.name: (a, w) for o, a, w in zip(result.observations, alone, without, strict=True)}
    rep.table(
        pd.DataFrame(
            [
                {
                    "observation": o.observation.name,
                    "kind": o.observation.kind,
                    "z": o.observation.z,
                    "obs sd": math.sqrt(o.observation.obs_var),
                    "stated disc. sd": math.sqrt(o.observation.disc_var),
                    "needed alone": need[o.observation.name].alone_sd if o.observation.name in need else math.nan,
                    "needed jointly": need[o.observation.name].joint_sd if o.observation.name in need else math.nan,
                    "rules out all alone": bool(need[o.observation.name].rules_out_alone)
                    if o.observation.name in need
                    else False,
                    "share it rules out (wave 1)": shares[o.observation.name][0],
                    "share left without it (wave 1)": shares[o.observation.name][1],
                }
                for o in observed
            ]
        ),
        caption="needed: the smallest discrepancy sd under which some point (alone) or the best point overall "
        "(jointly) is not ruled out by that observation, from the last wave's emulators; shares of the whole "
        "space under the first wave's emulators: what the observation rules out by itself, and what the "
        "others leave",
    )
    if result.waves:
        last = result.waves[-1]
        rep.heading(f"Emulators of wave {last.index}")
        rep.table(
            pd.DataFrame(
                [
                    {
                        "output": d.output,
                        "LOO 95 % coverage": d.coverage_95,
                        "LOO 68 % coverage": d.coverage_68,
                        "LOO rmse": d.rmse,
                    }
                    for d in last.loo
                ]
            )
        )
    rep.text(
        "Records: history.json (every wave, its emulators and runs), nroy.csv (the points not ruled out), "
        "closest.csv (the least implausible reference points, with their implausibility), summary.json; the "
        "frames in tasks/.",
        note=True,
    )
    return rep.write(out / "report.html")


def _ordinal(k: int) -> str:
    return {1: "largest", 2: "second-largest", 3: "third-largest"}[k]


def quick_settings(settings: Settings) -> Settings:
    """The small form: 8 runs per wave, 3 waves, a 1024-point reference sample (tests and a first look)."""
    return replace(settings, n_per_wave=8, min_waves=3, max_waves=3, n_reference=1024, n_restarts=1)
