"""The points of the unknowns a prediction is made from: a calibration's NROY set, or an unknowns search's.

``validate`` (and any study that predicts "from what the calibration left") reads one file:

* a history match's ``nroy.csv`` (``beacon-sim calibrate-unknowns``, :mod:`studies.catalog.calibration`):
  the points not ruled out, one column per calibrated unknown; or its ``closest.csv`` (the least
  implausible reference points, with an ``implausibility`` column: taken lowest first, and the set's
  description says none of them is consistent). The primary test's side is the
  point's ``primary_test_side``; V1's sides have their own dimmer settings; of V2's only the primary
  side's was observed (``led_drive_v2_primary``), so V2's other sides are assumed to share it (the
  study set each side with a potentiometer and says nothing of the others);
* an unknowns search's ``samples.csv`` (:func:`studies.catalog.unknowns_search.calibrated_set`).

Points are taken evenly over the file's order (both files are in Sobol' order, so an even pick
stays spread over the set).

Example
-------
>>> from studies.catalog import prediction_set
>>> s = prediction_set.load("results/unknowns-search/samples.csv", limit=2)  # doctest: +SKIP
>>> task = {"scenario": {"beacon": "v2", "side": "red", "camera": "canon-t6-18mm"}, "seed": 0}
>>> s.apply(task, 0)["scenario"]["led_current_mA"]  # doctest: +SKIP
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from studies.catalog import calibration, unknowns_search
from studies.engine.unknowns import Unknown, apply, sample

__all__ = [
    "CALIBRATION",
    "REFERENCE_CLOSEST",
    "REFERENCE_NROY",
    "SEARCH",
    "PredictionSet",
    "load",
    "physics_points",
    "reference_set",
]

CALIBRATION = "calibration"
SEARCH = "unknowns-search"
REFERENCE_NROY = Path(__file__).resolve().parents[2] / "results" / "calibration" / "nroy.csv"
"""The NROY set of the project's own history match (``beacon-sim calibrate-unknowns``, ``results/calibration``)."""
REFERENCE_CLOSEST = REFERENCE_NROY.with_name("closest.csv")
"""Its least implausible reference points (what to predict from, said so, when the NROY set is empty)."""


def reference_set() -> Path:
    """The project's own calibration's set to predict from: its NROY set, or, when that is empty, its
    least implausible points."""
    empty = not REFERENCE_NROY.is_file() or pd.read_csv(REFERENCE_NROY).empty
    return REFERENCE_CLOSEST if empty and REFERENCE_CLOSEST.is_file() else REFERENCE_NROY


STUDY_AXES = ("led_drive",)
"""Unknowns a study sweeps itself (the LED drive is a grid axis), so no point of the physics sets them."""


@dataclass(frozen=True)
class PredictionSet:
    """Points of the unknowns and how to set them on a frame task.

    Attributes
    ----------
    points
        Name → value per point.
    which
        What the set is, in words (for reports).
    source
        :data:`CALIBRATION` or :data:`SEARCH`.
    space
        The unknowns the points set (their registry entries).
    closest
        Whether the points are a calibration's least implausible ones (``closest.csv``: none of them
        consistent with what the study saw), not its NROY set.
    """

    points: tuple[dict[str, Any], ...]
    which: str
    source: str
    space: dict[str, Unknown]
    closest: bool = False

    def primary_side(self, index: int) -> str | None:
        """The primary test's side at point ``index`` (None: the set does not say; the test's own)."""
        return self.points[index].get(calibration.PRIMARY_SIDE.name)

    def apply(self, task: dict, index: int) -> dict:
        """``task`` with point ``index`` set (its beacon side's own dimmer setting)."""
        values = self.points[index]
        if self.source == SEARCH:
            return unknowns_search.apply_point(task, values)
        scenario = task["scenario"]
        beacon, side = scenario["beacon"], scenario["side"]
        own = {k: v for k, v in values.items() if not k.startswith("led_drive_") and k != calibration.PRIMARY_SIDE.name}
        drive = unknowns_search.drive_name(beacon, side)
        own["led_drive"] = values[drive] if drive in values else values[unknowns_search.drive_name(beacon, "primary")]
        registry = {k: u for k, u in unknowns_search.registry_for(self.space).items() if k in own}
        return apply(task, own, registry)


def load(path: str | Path, limit: int | None = None) -> PredictionSet:
    """The set in ``path`` (a calibration's ``nroy.csv`` or a search's ``samples.csv``, told apart by its
    columns), at most ``limit`` points. ``ValueError`` naming the file for anything else, or an empty NROY."""
    path = Path(path)
    try:
        header = list(pd.read_csv(path, nrows=0).columns)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as e:
        reason = str(e).strip().splitlines()[0] if str(e).strip() else "empty"
        raise ValueError(f"{path}: expected a calibration's nroy.csv or a search's samples.csv ({reason})") from None
    if "consistent" in header:
        points, which = unknowns_search.calibrated_set(path, limit)
        return PredictionSet(tuple(points), which, SEARCH, unknowns_search.search_space())
    space = calibration.search_space(calibration.load_observations())
    missing = [n for n in space if n not in header]
    if missing:
        raise ValueError(
            f"{path}: expected a calibration's nroy.csv (a column per calibrated unknown) or a search's samples.csv, "
            f"missing column {missing[0]!r}"
        )
    table = pd.read_csv(path)
    closest = "implausibility" in header
    if table.empty:
        raise ValueError(
            f"{path}: the calibration's NROY set is empty (it ruled out every point; see its report; closest.csv "
            "beside it holds the least implausible points)"
        )
    rows = table[list(space)].to_dict("records")
    n = len(rows)
    if limit is not None and n > limit:
        picks = np.arange(limit) if closest else np.linspace(0, n - 1, limit).round().astype(int)
        rows, table = [rows[i] for i in picks], table.iloc[picks]
    points = tuple({k: _plain(v, space[k]) for k, v in r.items()} for r in rows)
    shared = "V2's sides other than the primary test's share its dimmer setting (not observed)"
    if closest:
        worst = table["implausibility"]
        which = (
            f"the {len(points)} least implausible of the calibration's reference points ({path.name}): NONE is "
            f"consistent with what the study saw (implausibility {worst.min():.2f}-{worst.max():.2f}, above the "
            f"cut-off 3), so these predictions are of the closest the model came; {shared}"
        )
    else:
        which = f"{len(points)} of the {n} points the calibration did not rule out (NROY, {path.name}); {shared}"
    return PredictionSet(points, which, CALIBRATION, space, closest=closest)


def _plain(v: Any, u: Unknown) -> Any:
    """A CSV cell as the unknown's value: numbers as float, choices as the choice they spell."""
    v = v.item() if isinstance(v, np.generic) else v
    if u.kind == "choice":
        for c in u.choices:
            if str(c) == str(v) or (isinstance(c, bool) and str(c).lower() == str(v).lower()):
                return c
        raise ValueError(f"{u.name}: {v!r} is not one of its choices ({u.describe_range()})")
    return float(v) if isinstance(v, int | float) and math.isfinite(float(v)) else v


def physics_points(
    n: int, seed: int = 0, calibration: Path | None = REFERENCE_NROY, *, choices_apart: bool = False
) -> tuple[tuple[dict, ...], str]:
    """``n`` points of the unknowns a study runs at for its noise + physics intervals
    (:attr:`studies.engine.tasks.StudyOptions.physics`), and what they are, in words.

    Every registry entry a study does not sweep itself (:data:`STUDY_AXES`) and that is not one of the
    study's later sessions' tracker settings gets a value: those the calibration covered from its NROY
    set (``calibration``, a history match's ``nroy.csv``: ``n`` of its points, evenly over it), the
    others, and all of them without a calibration, from their registry ranges (scrambled Sobol',
    ``seed``). Cameras and beacons the calibration did not observe are then predicted over their ranges.
    ``choices_apart``: no two choices drawn from their ranges move together over the points
    (:func:`studies.engine.unknowns.sample`; what a sensitivity analysis needs).
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"uncertainty: expected an integer >= 1 (points of the unknowns), got {n!r}")
    registry = {
        k: u for k, u in unknowns_search.load_unknowns().items() if k not in STUDY_AXES and u.namespace != "tracker"
    }
    points = sample(registry, n, seed=seed, choices_apart=choices_apart)
    apart = ", choices kept apart" if choices_apart else ""
    if calibration is None:
        return tuple(
            points
        ), f"{n} points of the {len(registry)} unknowns from their registry ranges (Sobol', seed {seed}{apart})"
    chosen = load(calibration, n)
    if chosen.source != CALIBRATION:
        raise ValueError(f"{calibration}: expected a calibration's nroy.csv, got an unknowns search's samples")
    covered = sorted(set(registry) & set(chosen.space))
    for i, point in enumerate(points):
        point.update({k: chosen.points[i % len(chosen.points)][k] for k in covered})
    reused = ", reused" if len(chosen.points) < n else ""
    kind = "least implausible points (none consistent with what the study saw; " if chosen.closest else "NROY set ("
    which = (
        f"{n} points: {len(covered)} of the {len(registry)} unknowns from the calibration's {kind}"
        f"{Path(calibration).name}, {len(chosen.points)} of its points{reused})"
    )
    if len(covered) < len(registry):
        which += f", the other {len(registry) - len(covered)} from their registry ranges (Sobol', seed {seed}{apart})"
    return tuple(points), which
