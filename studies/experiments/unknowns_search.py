"""The study's own calibration, repeated over the unknowns: which settings of what the study
did not record let its printed detector work where the study tuned it.

The study set its colour thresholds by hand on close-range images and dimmed its LEDs until
the markers were usable (docs/source-study.md §5.2, §10). So the unknowns of
:mod:`studies.engine.unknowns` are constrained by exactly that: a set of values is
*consistent* when the study's tracker, with its printed thresholds, morphology and
exactly-5 rule (nothing changed), detects every colour's target at close range with the
right colour and all five markers numbered (:func:`studies.engine.scoring.detection_success`).
The consistent set is then what every prediction at 2 m and beyond is made from.

Close range here is the primary test's nearest condition: the V2 beacon as built (foam +
one sheet of matched paper, black housing) in the dark room, the Canon T6 + 18 mm at
ISO 6400, 1/60 s, 1 m, yaw 0, each of the four sides. (The study's other close-range
images, the webcam at 150 mm, show V1, whose side markers the model cannot light yet:
V1 as built is still to come, so that condition is left out and said so.) The frames are
crops aligned to 16 px (JPEG blocks and the 50 % resize group pixels as in the full frame).

The search draws ``samples`` points of the settable unknowns (scrambled Sobol', one seed)
with the others at their nominal; each point is scored on every side with ``seeds`` noise
seeds. Outputs: ``samples.csv`` (one row per point: the values, per-side successes,
``consistent``) and ``summary.json`` (how many points are consistent and, per unknown, its
prior range against the range of the consistent points: which the calibration pins down
and which it leaves wide; not judged from fewer than 8 consistent points).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.led import SIDE_COLOURS
from scenes.render_cache import atomic_write_bytes
from studies.engine.scoring import detection_success
from studies.engine.sweep import Execution, run_frames
from studies.engine.tasks import StudyOptions, frame_tasks
from studies.engine.unknowns import Unknown, apply, fixed, load_unknowns, sample, settable

CLOSE_RANGE = {
    "beacon": "v2",
    "range_m": 1.0,
    "yaw_deg": 0.0,
    "camera": "canon-t6-18mm",
    "environment": "dark-room",
    "foam": True,
    "paper_sheets": 1,
}
"""The close-range condition (each side): the primary test's nearest frame, V2 as built."""
HELD = ("housing", "paper_colour", "noise_reduction")
"""Unknowns held at their nominal in the search: the housing and paper as built for V2 (the
renders are shared by every point), and noise reduction, whose strength table only the
bodies' ``in-camera`` processing loads."""
RENDER = {"spp": 4, "oversampling": 2, "crop": "target", "near_field_spp": 1024}


def search_space(unknowns: dict[str, Unknown] | None = None) -> dict[str, Unknown]:
    """The settable unknowns that apply to the close-range camera, with :data:`HELD` fixed."""
    unknowns = settable(load_unknowns() if unknowns is None else unknowns)
    relevant = {n: u for n, u in unknowns.items() if not u.cameras or CLOSE_RANGE["camera"] in u.cameras}
    return fixed(relevant, **{n: relevant[n].nominal for n in HELD if n in relevant})


def tasks(points: Sequence[dict], space: dict[str, Unknown], seeds: int) -> list[dict]:
    """Frame tasks of every point × side × seed (the study's tracker and estimator only)."""
    options = StudyOptions(cameras=(CLOSE_RANGE["camera"],), seeds=seeds, jitter_poses=1, render=dict(RENDER))
    out = []
    for index, values in enumerate(points):
        for side in SIDE_COLOURS:
            condition = {**CLOSE_RANGE, "side": side, "led_current_mA": 20.0, "paper_colour": "matched"}
            for task in frame_tasks([condition], options, trackers=["thesis"], estimators=["thesis"]):
                task = apply({**task, "align_px": 16, "tags": {"point": index}}, values, space)
                out.append(task)
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
    per_side = frame.groupby(["point", "side"]).success.all().unstack("side")
    table = pd.DataFrame(points)
    for side in SIDE_COLOURS:
        table[f"{side}_detected"] = per_side[side].to_numpy()
    table["consistent"] = per_side[list(SIDE_COLOURS)].all(axis=1).to_numpy()
    Path(out).mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(out) / "samples.csv", table.to_csv(index=False, float_format="%.6g").encode())
    summary = summarise(table, space, samples, seeds, seed)
    atomic_write_bytes(Path(out) / "summary.json", json.dumps(summary, indent=2).encode())
    return summary


def summarise(table: pd.DataFrame, space: dict[str, Unknown], samples: int, seeds: int, seed: int) -> dict:
    """Per unknown: its prior range and the range (or choices) among the consistent points."""
    ok = table[table.consistent]
    unknowns = {}
    for name, u in space.items():
        if u.kind == "fixed":
            unknowns[name] = {"held_at": u.nominal}
            continue
        prior = list(u.choices) if u.kind == "choice" else [u.low, u.high]
        if ok.empty:
            found = None
        elif u.kind == "choice":
            found = sorted(set(ok[name]), key=str)
        else:
            found = [float(ok[name].min()), float(ok[name].max())]
        unknowns[name] = {"prior": prior, "consistent": found, "pinned": _pinned(u, found, len(ok))}
    return {
        "condition": CLOSE_RANGE,
        "samples": samples,
        "seeds_per_side": seeds,
        "seed": seed,
        "consistent_points": int(table.consistent.sum()),
        "per_side_detected": {s: int(table[f"{s}_detected"].sum()) for s in SIDE_COLOURS},
        "unknowns": unknowns,
    }


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
