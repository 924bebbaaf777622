"""The study's own calibration, repeated over the unknowns: which settings of what the study
did not record let its printed detector work where the study tuned it.

The study set its colour thresholds by hand on close-range images and dimmed its LEDs until
the markers were usable (docs/source-study.md §2.9, §5.2, §10.1). So the unknowns of
:mod:`studies.engine.unknowns` are constrained by exactly that: a set of values is
*consistent* with a close-range condition when the study's tracker, with its printed
thresholds, morphology and exactly-5 rule (nothing changed), detects every colour's target
there with the right colour and all five markers numbered
(:func:`studies.engine.scoring.detection_success`).

Two close-range conditions (:data:`CONDITIONS`), dark room, yaw 0, each of the four sides:

``webcam-150mm``  where the thresholds were tuned (§10.1): V1 150 mm from a webcam, the whole
                  saved frame. Which webcam is not said: an unknown of the search (:data:`TUNING_WEBCAM`).
``t6-1m``         the primary test's nearest frame: V2 with the Canon T6 + 18 mm at ISO 6400,
                  1/60 s, 1 m; a crop aligned to 16 px (JPEG blocks and the 50 % resize group
                  the pixels as in the full frame).

Each beacon side has its own dimmer setting (§2.9: brightness set with potentiometers; V1 and
V2 were separate builds), so the drive is searched per beacon and side (``led_drive_v1_red``
… from the registry's ``led_drive``). Both beacons are built as the studies build them:
foam + one sheet of paper (its colour an unknown).

The search draws ``samples`` points of the unknowns (scrambled Sobol', one seed);
each point is scored on every condition and side with ``seeds`` noise seeds. Outputs:

``samples.csv``   one row per point: the values, ``<condition>_<side>`` successes,
                  ``consistent_<condition>`` and ``consistent`` (every condition)
``summary.json``  per condition (and for all together) how many points are consistent and, per
                  unknown, its prior range against the range of the consistent points: which the
                  calibration pins down and which it leaves wide (not judged from fewer than
                  :data:`MIN_POINTS_TO_JUDGE` points)

:func:`calibrated_points` reads the consistent points back for the predictions
(``beacon-sim validate``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.led import SIDE_COLOURS
from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.scoring import detection_success
from studies.engine.sweep import Execution, run_frames
from studies.engine.tasks import StudyOptions, frame_tasks
from studies.engine.unknowns import Unknown, apply, fixed, load_unknowns, sample

__all__ = [
    "BUILT",
    "CONDITIONS",
    "HELD",
    "MIN_POINTS_TO_JUDGE",
    "REFERENCE_SEARCH",
    "TUNING",
    "TUNING_WEBCAM",
    "WEBCAMS",
    "apply_point",
    "calibrated_set",
    "drive_name",
    "registry_for",
    "relevant",
    "run",
    "search_space",
    "summarise",
    "task_values",
    "tasks",
]

WEBCAMS = ("logitech-c270", "spedal-920")
CONDITIONS: dict[str, dict] = {
    "webcam-150mm": {
        "scenario": {"beacon": "v1", "range_m": 0.15, "camera": WEBCAMS[0]},
        "task": {"full_frame": True},
    },
    "t6-1m": {
        "scenario": {"beacon": "v2", "range_m": 1.0, "camera": "canon-t6-18mm"},
        "task": {"align_px": 16},
    },
}
"""The close-range conditions: scenario fields and frame-task options (see the module docstring)."""
BUILT = {"yaw_deg": 0.0, "environment": "dark-room", "foam": True, "paper_sheets": 1}
"""What both conditions share: the beacons as built (foam + one sheet), dark room, facing the camera."""
TUNING_WEBCAM = Unknown(
    name="tuning_webcam",
    target="scenario.camera",
    kind="choice",
    nominal=WEBCAMS[0],
    choices=WEBCAMS,
    cameras=WEBCAMS,
    provenance="source: docs/source-study.md §10.1: the thresholds were tuned on images from 'a webcam' at "
    "150 mm; the study had the C270 and the Spedal 920 and does not say which",
)
HELD: tuple[str, ...] = ()
"""Unknowns held at their nominal in the search (none: every unknown varies, the data-file ones included)."""
RENDER = {"spp": 4, "oversampling": 2, "crop": "target", "near_field_spp": 1024}


def drive_name(beacon: str, side: str) -> str:
    """Name of the drive unknown of one beacon's side (``led_drive_v2_red``)."""
    return f"led_drive_{beacon}_{side}"


def search_space(unknowns: dict[str, Unknown] | None = None) -> dict[str, Unknown]:
    """The unknowns of the conditions' cameras and ranges, with one drive per beacon and side,
    :data:`TUNING_WEBCAM`, and :data:`HELD` fixed."""
    unknowns = load_unknowns() if unknowns is None else unknowns
    cameras = {c["scenario"]["camera"] for c in CONDITIONS.values()} | set(WEBCAMS)
    reach = max(c["scenario"]["range_m"] for c in CONDITIONS.values())
    space = {n: u for n, u in unknowns.items() if (not u.cameras or cameras & set(u.cameras)) and u.applies_at(reach)}
    drive = space.pop("led_drive")
    for c in CONDITIONS.values():
        for side in SIDE_COLOURS:
            name = drive_name(c["scenario"]["beacon"], side)
            space[name] = dataclasses.replace(drive, name=name)
    space[TUNING_WEBCAM.name] = TUNING_WEBCAM
    return fixed(space, **{n: space[n].nominal for n in HELD if n in space})


def task_values(values: dict, beacon: str, side: str) -> dict:
    """A point's values as registry names for one beacon side: its own drive as ``led_drive``."""
    out = {k: v for k, v in values.items() if not k.startswith("led_drive_")}
    out["led_drive"] = values[drive_name(beacon, side)]
    return out


def registry_for(space: dict[str, Unknown]) -> dict[str, Unknown]:
    """The search space as :func:`studies.engine.unknowns.apply` takes it (one ``led_drive``)."""
    out = {k: u for k, u in space.items() if not k.startswith("led_drive_")}
    first = next(u for k, u in space.items() if k.startswith("led_drive_"))
    out["led_drive"] = dataclasses.replace(first, name="led_drive")
    return out


def tasks(points: Sequence[dict], space: dict[str, Unknown], seeds: int) -> list[dict]:
    """Frame tasks of every point × condition × side × seed (the study's tracker and estimator only)."""
    registry = registry_for(space)
    out = []
    for index, values in enumerate(points):
        for name, condition in CONDITIONS.items():
            camera = condition["scenario"]["camera"]
            # each condition's task options say its frame (webcam-150mm: the whole frame)
            options = StudyOptions(cameras=(camera,), seeds=seeds, jitter_poses=1, render=dict(RENDER), frame="crop")
            for side in SIDE_COLOURS:
                scenario = {**BUILT, **condition["scenario"], "side": side, "paper_colour": "matched"}
                scenario["led_current_mA"] = 20.0
                own = task_values(values, scenario["beacon"], side)
                for task in frame_tasks([scenario], options, trackers=["thesis"], estimators=["thesis"]):
                    task = {**task, **condition["task"], "tags": {"point": index, "condition": name}}
                    out.append(apply(task, own, registry))
    return out


def run(out: Path, samples: int = 64, seeds: int = 1, seed: int = 0, execution: Execution = Execution()) -> dict:
    """Search, write ``samples.csv`` and ``summary.json`` into ``out``; returns the summary."""
    if samples < 1 or seeds < 1:
        raise ValueError(f"samples, seeds: expected integers >= 1, got {samples}, {seeds}")
    space = search_space()
    points = sample(space, samples, seed=seed)
    rows = run_frames(tasks(points, space, seeds), out, execution, description="unknowns search")
    frame = pd.DataFrame(rows)
    frame["success"] = [detection_success(r) for r in rows]
    per_side = frame.groupby(["point", "condition", "side"]).success.all()
    table = pd.DataFrame(points)
    for name in CONDITIONS:
        for side in SIDE_COLOURS:
            table[f"{name}_{side}"] = per_side.xs((name, side), level=("condition", "side")).to_numpy()
        table[f"consistent_{name}"] = table[[f"{name}_{s}" for s in SIDE_COLOURS]].all(axis=1)
    table["consistent"] = table[[f"consistent_{name}" for name in CONDITIONS]].all(axis=1)
    Path(out).mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(out) / "samples.csv", table.to_csv(index=False, float_format="%.6g").encode())
    summary = summarise(table, space, samples, seeds, seed)
    atomic_write_bytes(Path(out) / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def relevant(u: Unknown, condition: str) -> bool:
    """Whether ``u`` can change the frames of ``condition`` (its camera, its beacon's drives)."""
    scenario = CONDITIONS[condition]["scenario"]
    cameras = set(WEBCAMS) if scenario["camera"] in WEBCAMS else {scenario["camera"]}
    if u.name.startswith("led_drive_"):
        return u.name.startswith(f"led_drive_{scenario['beacon']}_")
    return not u.cameras or bool(cameras & set(u.cameras))


def summarise(table: pd.DataFrame, space: dict[str, Unknown], samples: int, seeds: int, seed: int) -> dict:
    """Per condition and for all together: consistent points and, per unknown, prior vs consistent range."""
    per_condition = {}
    for name in CONDITIONS:
        ok = table[table[f"consistent_{name}"]]
        per_condition[name] = {
            "scenario": {**BUILT, **CONDITIONS[name]["scenario"]},
            "consistent_points": len(ok),
            "per_side_detected": {s: int(table[f"{name}_{s}"].sum()) for s in SIDE_COLOURS},
            "unknowns": {n: _judge(u, ok) for n, u in space.items() if relevant(u, name)},
        }
    ok = table[table.consistent]
    agree = table[[f"{c}_{s}" for c in CONDITIONS for s in SIDE_COLOURS]].astype(bool).sum(axis=1)
    best = table[agree == agree.max()]
    return {
        "samples": samples,
        "seeds_per_side": seeds,
        "seed": seed,
        "conditions": per_condition,
        "consistent_points": len(ok),
        "unknowns": {n: _judge(u, ok) for n, u in space.items()},
        "best_agreeing": {
            "observations": f"{int(agree.max())} of {len(CONDITIONS) * len(SIDE_COLOURS)} (condition × side)",
            "points": len(best),
            "which": [f"{c}_{s}" for c in CONDITIONS for s in SIDE_COLOURS if best[f"{c}_{s}"].any()],
            "unknowns": {n: _judge(u, best) for n, u in space.items()},
        },
    }


def _judge(u: Unknown, ok: pd.DataFrame) -> dict:
    """An unknown's prior and its range (or choices) among the consistent points ``ok``."""
    if u.kind == "fixed":
        return {"held_at": u.nominal}
    prior = list(u.choices) if u.kind == "choice" else [u.low, u.high]
    if ok.empty:
        found = None
    elif u.kind == "choice":
        found = sorted(set(ok[u.name]), key=str)
    else:
        found = [float(ok[u.name].min()), float(ok[u.name].max())]
    return {"prior": prior, "consistent": found, "pinned": _pinned(u, found, len(ok))}


MIN_POINTS_TO_JUDGE = 8
"""Fewer consistent points than this cannot say whether an unknown is pinned down: the
spread of a handful of points is narrow by chance."""


def _pinned(u: Unknown, found, points: int) -> bool | None:
    """Whether the consistent points occupy clearly less than the prior (None: too few
    consistent points to tell, see :data:`MIN_POINTS_TO_JUDGE`)."""
    if found is None or points < MIN_POINTS_TO_JUDGE:
        return None
    if u.kind == "choice":
        return len(found) < len(u.choices)
    log = u.kind == "loguniform"
    span = (np.log(u.high) - np.log(u.low)) if log else (u.high - u.low)
    got = (np.log(found[1]) - np.log(found[0])) if log else (found[1] - found[0])
    return bool(got < 0.5 * span)


REFERENCE_SEARCH = Path(__file__).resolve().parents[2] / "results" / "unknowns-search" / "samples.csv"
"""The search kept in the repository (results/README.md): ``validate``'s default calibrated set."""
TUNING = "webcam-150mm"
"""The condition the study tuned its thresholds on (docs/source-study.md §10.1)."""


def calibrated_set(samples_csv: Path, limit: int | None = None) -> tuple[list[dict], str]:
    """The points a prediction is made from, read from a search's ``samples.csv``, and which set they are.

    In order of preference: the points consistent with every close-range condition; the points
    consistent with :data:`TUNING`, where the study tuned; when neither exists, the points that
    agree with the most close-range observations (condition × side), however few; the
    description says which. ``limit`` keeps that many, spread evenly over the file's (Sobol')
    order. Unknowns registered after the search ran (no column in the file) are held at their nominal
    values, and the description names them. Raises ``ValueError`` (naming the file) for a file that
    is not a search's output or whose points agree with no observation at all.
    """
    try:
        table = pd.read_csv(samples_csv)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as e:
        reason = str(e).strip().splitlines()[0]
        raise ValueError(
            f"{samples_csv}: expected an unknowns-search samples.csv, cannot read it as CSV ({reason})"
        ) from None
    observations = [f"{c}_{s}" for c in CONDITIONS for s in SIDE_COLOURS]
    need = ["consistent", f"consistent_{TUNING}", *observations]
    missing = [c for c in need if c not in table]
    if missing:
        raise ValueError(f"{samples_csv}: expected an unknowns-search samples.csv, missing column {missing[0]!r}")
    space = search_space()
    absent = [n for n in space if n not in table]  # registered after the search was run
    for name in absent:
        table[name] = [space[name].nominal] * len(table)
    agree = table[observations].astype(bool).sum(axis=1)
    if table.consistent.astype(bool).any():
        ok, which = table[table.consistent.astype(bool)], "consistent at every close-range condition"
    elif table[f"consistent_{TUNING}"].astype(bool).any():
        ok = table[table[f"consistent_{TUNING}"].astype(bool)]
        which = f"consistent at {TUNING}, where the study tuned (no point is consistent at every condition)"
    elif agree.max() > 0:
        ok = table[agree == agree.max()]
        which = (
            f"agreeing with the most close-range observations, {agree.max()} of {len(observations)} "
            "(condition × side): no point is consistent with a whole condition, so this set is not a calibration"
        )
    else:
        raise ValueError(f"{samples_csv}: no point agrees with any close-range observation; nothing to predict from")
    points = [{k: _plain(v) for k, v in row.items()} for row in ok[list(space)].to_dict("records")]
    if limit is not None and len(points) > limit:
        points = [points[i] for i in np.linspace(0, len(points) - 1, limit).round().astype(int)]
    held = f"; held at nominal, not varied by that search: {', '.join(absent)}" if absent else ""
    return points, f"{len(points)} of {len(ok)} points {which}{held}"


def apply_point(task: dict, values: dict) -> dict:
    """A frame task with one calibrated point's values set (its beacon side's own drive)."""
    scenario = task["scenario"]
    return apply(task, task_values(values, scenario["beacon"], scenario["side"]), registry_for(search_space()))


def _plain(v):
    """numpy and pandas scalars as plain Python values (bools read back from CSV stay bools)."""
    return v.item() if isinstance(v, np.generic) else v
