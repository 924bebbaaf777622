"""Sequential design of the range limits: frames spent where the answer is decided.

A fixed grid spends the same frames at every range, most of them far from where
P(correct pose | range) crosses 0.95. A sequential design starts with the study's coarse
grid (its ranges × ``seeds`` frames) and then adds frames in rounds, each round placed
from the fit of the frames so far (:func:`studies.engine.max_range.estimate_max_range`,
the study's one fit with its profile-likelihood 95 % intervals), until each limit is
*decided* or the frame budget is spent.
The level 0.95 below is the design's ``p_working`` (default
:data:`studies.engine.max_range.P_WORKING`).

**Design units.** One working-range estimate is one *unit*: a set of base conditions
(everything but the range) whose frames are pooled into one fit, e.g. one camera × beacon
× side × drive × yaw in ``range-limit``, or one camera × beacon × room × drive over both
sides in ``webcam-vs-dslr``. One *slot* at a range adds one frame of each of the unit's
base conditions there. Units are fitted on the rows ``select`` keeps (the best tracker
and estimator); every tracker's rows are stored and reported.

**When a limit is decided** (:func:`far_status`, :func:`near_status`): its 95 % interval
[low, high] meets a target, either its width ``high − low ≤ target_width_m`` or both ends
within ``±target_relative`` of the limit (L(1 − rel) ≤ low and high ≤ L(1 + rel)), any
target given being enough. A far limit that is the farthest range tried ("≥ farthest") is
decided once the design may not extend the ranges further (``max_range_m``) and its lower
bound meets the target with the farthest range as the limit. A far limit of "none"
(no range reaches 0.95) is decided when its interval ends below the nearest range, or when
the best range's frames put P below 0.95 with 97.5 % posterior probability (the upper end of
its Jeffreys 95 % interval, :func:`studies.engine.metrics.jeffreys_interval`, below 0.95:
the best range is the one where P peaks, nearer and farther ranges do worse); a near
limit is decided when no frame nearer than the peak failed ("≤ nearest"; the design does
not go nearer than the grid's nearest range).

**Where a round's frames go** (:func:`next_ranges`), for each undecided limit, on the
*candidate ranges* (the coarse grid refined ``refine`` times, so frames share renders):

1. when the far limit's interval reaches past the farthest range tried and
   ``max_range_m`` allows, ``seeds`` slots at the next coarse step beyond it;
2. half the limit's slots at the candidates nearest its estimate, where the fitted P is
   0.95 (alternating between the two that bracket it);
3. the other half spread over the candidates within its 95 % interval (one per equal
   stratum of the interval, drawn from a generator seeded by the design's ``seed``, the
   round and the unit), where the interval is to be narrowed.

The round's ``round_frames`` slots are shared between the unit's undecided limits in
proportion to their intervals' width over the width the target allows. A unit stops at
its own budget (``unit_budget_frames``, when given): a limit that sits where P is flat at
about 0.95 cannot be decided by any number of frames, and without a cap it takes the
study's budget from the others (a T6 series of ``webcam-vs-dslr`` took 3 472 of 7 680
frames and stayed undecided). When a round asks for more frames than the budget has left,
each undecided unit gets an equal share of what is left, its picks in the order above; a
unit whose share is below one slot stops. A unit at a point of the unknowns (``--uncertainty``)
may have a smaller budget of its own (``point_budget_grids``): the noise + physics interval is
made of the points' limits, whose spread is the physics'.

**Stored and resumable.** Every frame is an ordinary frame task
(:func:`studies.engine.tasks.frame_task`, noise seed index the next unused one at its
range), run and stored by the runner (``<out>/tasks/``). A round depends only on the
design, the seed and the finished rows, so a re-run after an interruption replays the
stored rounds from the store and resumes the cut one: it reaches the same frames and the
same answer. ``<out>/design.json`` records every round.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.max_range import P_WORKING, check_p_working, estimate_max_range
from studies.engine.metrics import jeffreys_interval
from studies.engine.sweep import Execution, run_frames
from studies.engine.tasks import StudyOptions, frame_task, grid_conditions

__all__ = [
    "DEFAULT_BUDGET_PER_UNIT",
    "DEFAULT_ROUND_FRAMES",
    "MAX_ROUNDS",
    "DesignResult",
    "LimitStatus",
    "SequentialDesign",
    "UnitOutcome",
    "best_rows",
    "candidate_ranges",
    "decision_text",
    "design_evidence",
    "far_status",
    "near_status",
    "next_ranges",
    "run_design",
    "summary_p_working",
]

DEFAULT_ROUND_FRAMES = 12
"""Slots a unit adds per round (assumed: about four times the 3 frames a quick grid has per
range, so one round can move an interval, yet 10-20 rounds fit a budget of a few hundred)."""
DEFAULT_BUDGET_PER_UNIT = 240
"""Frames per unit when no budget is given (assumed: a bound, so that a target a unit
cannot reach, e.g. a flat P ≈ 0.95, still ends)."""
MAX_ROUNDS = 200
"""Rounds after which a design stops whatever its budget (a guard; never reached in tests)."""
_EPS = 1e-9

FrameRunner = Callable[..., list[dict]]
"""Runs frame tasks: ``(tasks, out, execution, description=...) -> rows`` in task order
(:func:`studies.engine.sweep.run_frames`; tests pass stand-ins)."""


@dataclass(frozen=True)
class SequentialDesign:
    """What a sequential design aims for and may spend (ranges in metres).

    Attributes
    ----------
    target_width_m : a limit is decided when its 95 % interval is at most this wide, m.
    target_relative : ... or when both ends lie within ± this fraction of the limit (0.2: ±20 %).
    budget_frames : frames the design may spend in all (coarse grid included); default
        :data:`DEFAULT_BUDGET_PER_UNIT` per unit.
    unit_budget_frames : frames one unit may spend (its coarse grid included); None: only
        the design's budget bounds it.
    point_budget_grids : a unit at a point of the unknowns (its key's ``point`` set:
        :func:`studies.engine.uncertainty.over_points`) may spend this many of its coarse grids of
        frames (and no more than ``unit_budget_frames``); None: as every unit. A noise + physics
        interval is made of the points' limits, whose spread is the physics': each point's own
        limit needs less precision than the nominal's (the interval's rate holds with the
        estimates' noise, :mod:`studies.engine.uncertainty`).
    round_frames : slots each undecided unit adds per round.
    refine : the candidate ranges are the coarse grid's smallest step divided by this.
    max_range_m : farthest range the design may extend to when the farthest range tried
        still works (default: the coarse grid's farthest, no extension).
    seed : seeds where the spread frames of each round go (the same seed and the same
        finished frames give the same next round).
    near : also decide the near limit (else only the far limit).
    p_working : the probability of a correct pose a working range needs (0.5 < p < 1;
        :func:`studies.engine.max_range.estimate_max_range`).
    """

    target_width_m: float | None = None
    target_relative: float | None = None
    budget_frames: int | None = None
    unit_budget_frames: int | None = None
    point_budget_grids: float | None = None
    round_frames: int = DEFAULT_ROUND_FRAMES
    refine: int = 2
    max_range_m: float | None = None
    seed: int = 0
    near: bool = True
    p_working: float = P_WORKING

    def validate(self) -> None:
        """Fail fast with one line naming the bad field."""
        width = self.target_width_m
        if width is not None and not (isinstance(width, int | float) and math.isfinite(width) and width > 0):
            raise ValueError(f"target_width_m: expected a width > 0 m, got {self.target_width_m!r}")
        if self.target_relative is not None and not (
            isinstance(self.target_relative, int | float) and 0 < self.target_relative < 1
        ):
            raise ValueError(f"target_relative: expected a fraction in (0, 1), got {self.target_relative!r}")
        if self.budget_frames is not None and not (isinstance(self.budget_frames, int) and self.budget_frames >= 1):
            raise ValueError(f"budget_frames: expected an integer >= 1, got {self.budget_frames!r}")
        unit = self.unit_budget_frames
        if unit is not None and not (isinstance(unit, int) and not isinstance(unit, bool) and unit >= 1):
            raise ValueError(f"unit_budget_frames: expected an integer >= 1, got {unit!r}")
        grids = self.point_budget_grids
        if grids is not None and not (
            isinstance(grids, int | float) and not isinstance(grids, bool) and math.isfinite(grids) and grids >= 1
        ):
            raise ValueError(f"point_budget_grids: expected a number >= 1 (coarse grids per point), got {grids!r}")
        if not isinstance(self.round_frames, int) or self.round_frames < 2:
            raise ValueError(f"round_frames: expected an integer >= 2, got {self.round_frames!r}")
        if not isinstance(self.refine, int) or not 1 <= self.refine <= 16:
            raise ValueError(f"refine: expected an integer from 1 to 16, got {self.refine!r}")
        if self.max_range_m is not None and not (
            isinstance(self.max_range_m, int | float) and math.isfinite(self.max_range_m) and self.max_range_m > 0
        ):
            raise ValueError(f"max_range_m: expected a range > 0 m, got {self.max_range_m!r}")
        if not isinstance(self.seed, int):
            raise ValueError(f"seed: expected an integer, got {self.seed!r}")
        check_p_working(self.p_working)

    def with_overrides(self, **overrides) -> SequentialDesign:
        """This design with the user's non-None overrides."""
        return replace(self, **{k: v for k, v in overrides.items() if v is not None})

    def target_text(self) -> str:
        """The target in words: "±20 % of the limit or 1 m wide"."""
        parts = []
        if self.target_relative is not None:
            parts.append(f"±{100 * self.target_relative:g} % of the limit")
        if self.target_width_m is not None:
            parts.append(f"{self.target_width_m:g} m wide")
        return " or ".join(parts) if parts else "none (until the budget is spent)"


@dataclass(frozen=True)
class LimitStatus:
    """Where one limit stands (metres): its estimate and 95 % interval as the design uses them
    (``high`` = inf: past the farthest range tried), whether it is decided, and how far its
    interval is from the target (``excess``: width over the allowed width; ≤ 1 when met)."""

    decided: bool
    estimate: float
    low: float
    high: float
    excess: float
    how: str
    """Why it is decided ("interval within ±20 % of the limit", "no range reaches 0.95", ...),
    or why not ("interval 4.1 m wide")."""


def _allowed(design: SequentialDesign, limit: float) -> float:
    """The widest interval the targets allow around ``limit``, m (0: no target)."""
    return max(design.target_width_m or 0.0, 2 * (design.target_relative or 0.0) * max(limit, 0.0))


def _meets(design: SequentialDesign, limit: float, low: float, high: float) -> str:
    """The target the interval [low, high] around ``limit`` meets, in words, or ""."""
    rel, width = design.target_relative, design.target_width_m
    if rel is not None and limit > 0 and low >= limit * (1 - rel) - _EPS and high <= limit * (1 + rel) + _EPS:
        return f"interval within ±{100 * rel:g} % of the limit"
    if width is not None and high - low <= width + _EPS:
        return f"interval at most {width:g} m wide"
    return ""


def _excess(design: SequentialDesign, limit: float, low: float, high: float, span: float) -> float:
    allowed = _allowed(design, limit)
    return min(high - low, span) / allowed if allowed > 0 else math.inf


def far_status(rec: Mapping, design: SequentialDesign, max_range_m: float | None = None) -> LimitStatus:
    """Status of the far limit of a :class:`studies.engine.max_range.MaxRange` record.

    ``max_range_m``: the farthest range the design may try (default the design's, else the
    farthest range tried: no extension).
    """
    if not rec.get("frames"):
        return LimitStatus(False, math.nan, 0.0, math.inf, math.inf, "no frames")
    nearest, farthest = float(rec["nearest_tested_m"]), float(rec["farthest_tested_m"])
    top = max(farthest, float(max_range_m if max_range_m is not None else design.max_range_m or farthest))
    can_extend = top > farthest + _EPS
    span = max(farthest - nearest, _EPS)
    low, high = float(rec["low_m"]), float(rec["high_m"])
    if rec["max_range_m"] <= 0:
        k, n = int(rec.get("peak_successes", 0)), int(rec.get("peak_frames", 0))
        peak_high = float(jeffreys_interval(k, n)[2]) if n else 1.0
        below = math.isfinite(high) and high < nearest
        level = float(rec.get("p_working", design.p_working))
        decided = below or peak_high < level
        how = (
            f"no range reaches {level:g}"
            + ("" if below else f" (P ≤ {peak_high:.2f} at the best range, {k} of {n} frames)")
            if decided
            else f"P at the best range may still reach {level:g}"
        )
        return LimitStatus(decided, float(rec["fitted_from_m"]), nearest, min(high, farthest), math.inf, how)
    if rec.get("at_least") or not math.isfinite(high):
        if can_extend:
            return LimitStatus(False, float(rec["max_range_m"]), low, math.inf, math.inf, "reaches past the farthest")
        if rec.get("at_least"):
            met = _meets(design, farthest, low, farthest)
            how = f"≥ the farthest range allowed, lower bound {met.removeprefix('interval ')}" if met else ""
            excess = _excess(design, farthest, low, farthest, span)
            return LimitStatus(bool(met), farthest, low, farthest, excess, how or f"lower bound {low:.1f} m")
        return LimitStatus(False, float(rec["max_range_m"]), low, math.inf, math.inf, "interval open above")
    limit = float(rec["max_range_m"])
    met = _meets(design, limit, low, high)
    return LimitStatus(
        bool(met), limit, low, high, _excess(design, limit, low, high, span), met or f"interval {high - low:.1f} m wide"
    )


def near_status(rec: Mapping, design: SequentialDesign) -> LimitStatus:
    """Status of the near limit of a :class:`studies.engine.max_range.MaxRange` record (decided
    when not asked for, when there is no working range, or when nothing nearer than the
    peak failed)."""
    nearest = float(rec.get("nearest_tested_m", math.nan))
    if not design.near or not rec.get("frames"):
        return LimitStatus(True, math.nan, math.nan, math.nan, 0.0, "not asked for")
    if rec["max_range_m"] <= 0 or not math.isfinite(rec["near_limit_m"]):
        return LimitStatus(True, math.nan, math.nan, math.nan, 0.0, "no working range")
    if rec.get("near_at_most"):
        return LimitStatus(True, nearest, nearest, nearest, 0.0, "no failure nearer than the best range")
    limit, low, high = float(rec["near_limit_m"]), float(rec["near_low_m"]), float(rec["near_high_m"])
    peak = float(rec["fitted_from_m"])
    span = max(peak - nearest, _EPS)
    low_c, high_c = max(low, nearest), min(high, peak)
    met = _meets(design, limit, low, high) if math.isfinite(high) and low > 0 else ""
    excess = _excess(design, limit, low_c, high_c, span) if not met else 0.0
    return LimitStatus(bool(met), limit, low_c, high_c, excess, met or f"interval {low:.1f} to {high:.1f} m")


def candidate_ranges(coarse: Sequence[float], design: SequentialDesign) -> tuple[float, ...]:
    """The ranges a design may put frames at, m: the coarse grid and its smallest step
    divided by ``refine`` from the nearest coarse range to the farthest (or to the design's
    ``max_range_m``), rounded to 1 mm."""
    ranges = sorted({float(r) for r in coarse})
    if len(ranges) < 2:
        raise ValueError(f"ranges_m: expected at least 2 ranges for a sequential design, got {ranges}")
    step = float(np.min(np.diff(ranges))) / design.refine
    top = max(ranges[-1], float(design.max_range_m or ranges[-1]))
    fine = ranges[0] + step * np.arange(math.floor((top - ranges[0]) / step + 1e-6) + 1)
    return tuple(sorted({round(float(r), 3) for r in (*ranges, *fine, top)}))


def _rng(design: SequentialDesign, round_index: int, key: tuple, limit: str) -> np.random.Generator:
    """The stream of a unit's choices; a unit field it lacks (None: a nominal unit beside points of
    the unknowns) does not enter it, so such a unit draws as it would in a run without them."""
    key = tuple(k for k in key if k is not None)
    digest = hashlib.sha256(repr((design.seed, round_index, key, limit)).encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


def _place(
    status: LimitStatus, slots: int, candidates: np.ndarray, farthest: float, rng: np.random.Generator
) -> list[float]:
    """``slots`` picks for one limit: half at the candidates nearest its estimate, half one per
    equal stratum of its interval (clipped to the candidates tried so far)."""
    usable = candidates[candidates <= farthest + _EPS]
    lo = max(float(status.low), float(usable[0])) if math.isfinite(status.low) else float(usable[0])
    hi = min(float(status.high), float(usable[-1]))
    est = min(max(float(status.estimate), float(usable[0])), float(usable[-1]))
    if hi < lo:
        lo, hi = est, est
    order = np.argsort(np.abs(usable - est), kind="stable")
    nearest = [float(usable[i]) for i in order[:2]]
    picks = [nearest[i % len(nearest)] for i in range(math.ceil(slots / 2))]
    n = slots - len(picks)
    for u in (np.arange(n) + rng.random(n)) / max(n, 1):
        target = lo + u * (hi - lo)
        picks.append(float(usable[int(np.argmin(np.abs(usable - target)))]))
    return picks


def next_ranges(
    rec: Mapping,
    design: SequentialDesign,
    candidates: Sequence[float],
    coarse: Sequence[float],
    coarse_seeds: int,
    round_index: int,
    key: tuple,
) -> list[float]:
    """The ranges of one unit's next round, in priority order (a range once per slot; empty
    when its limits are decided). See the module docstring for the rules."""
    far, near = far_status(rec, design), near_status(rec, design)
    if far.decided and near.decided:
        return []
    cand = np.asarray(candidates, float)
    farthest = float(rec["farthest_tested_m"])
    picks: list[float] = []
    if not far.decided and not math.isfinite(far.high):  # reaches past the farthest range tried
        steps = np.diff(sorted(coarse))
        beyond = cand[cand > farthest + _EPS]
        if len(beyond):
            nxt = min(farthest + float(steps[-1]), float(beyond[-1]))
            picks += [float(beyond[int(np.argmin(np.abs(beyond - nxt)))])] * coarse_seeds
    budget = max(design.round_frames - len(picks), 2)
    open_limits = [(name, s) for name, s in (("far", far), ("near", near)) if not s.decided]
    weights = np.array([min(s.excess, 1e3) for _, s in open_limits])
    weights = weights / weights.sum() if weights.sum() > 0 else np.full(len(open_limits), 1 / len(open_limits))
    shares = np.maximum(np.floor(weights * budget).astype(int), 1)
    shares[0] += max(budget - int(shares.sum()), 0)
    for (name, status), share in zip(open_limits, shares, strict=True):
        picks += _place(status, int(share), cand, farthest, _rng(design, round_index, key, name))
    return picks


@dataclass(frozen=True)
class UnitOutcome:
    """How a unit's design ended: its frames (slots × base conditions), rounds, frames per
    range, the final status of each limit and why it stopped (``decided``, ``budget``,
    ``unit budget``, ``rounds``)."""

    key: tuple
    frames: int
    rounds: int
    frames_per_range: dict
    far_decided: bool
    near_decided: bool
    far_how: str
    near_how: str
    stop: str

    def to_dict(self) -> dict:
        """JSON-able form (``frames_per_range`` keys as text, m)."""
        d = asdict(self)
        d["key"] = list(self.key)
        d["frames_per_range"] = {f"{r:g}": n for r, n in sorted(self.frames_per_range.items())}
        return d


@dataclass(frozen=True)
class DesignResult:
    """A finished design: every row (task order, round by round), the units' outcomes, the
    frames spent and the rounds' log."""

    rows: list[dict]
    units: tuple[UnitOutcome, ...]
    frames: int
    budget_frames: int
    design: SequentialDesign
    rounds: list[dict] = field(default_factory=list)

    def summary(self) -> dict:
        """JSON-able summary (no rows)."""
        return {
            "design": asdict(self.design),
            "target": self.design.target_text(),
            "budget_frames": self.budget_frames,
            "frames": self.frames,
            "rounds": self.rounds,
            "units": [u.to_dict() for u in self.units],
        }


def summary_p_working(summary: Mapping | None) -> float:
    """The working level of a design's :meth:`DesignResult.summary` (None, or one written before
    the level could be chosen: :data:`~studies.engine.max_range.P_WORKING`)."""
    return float(((summary or {}).get("design") or {}).get("p_working", P_WORKING))


def best_rows(row: Mapping) -> bool:
    """The rows a design fits: the best tracker's, with the best estimator where rows name one."""
    return row.get("tracker", "best") == "best" and row.get("estimator", "best") == "best"


def decision_text(rec: Mapping, outcome: Mapping | None) -> str:
    """How many frames decided a limit record, in words: "84 frames: decided (interval within
    ±20 % of the limit)" or "240 frames: not decided (budget spent; interval 3.1 m wide)";
    "" without a design. ``outcome``: the unit's :meth:`UnitOutcome.to_dict`."""
    if outcome is None:
        return ""
    n = rec.get("frames", 0)
    if rec.get("tracker", "best") != "best":
        return f"{n} frames (placed for the best tracker)"
    if outcome["far_decided"]:
        return f"{n} frames: decided ({outcome['far_how']})"
    why = {"budget": "budget spent", "unit budget": "its unit's budget spent", "rounds": "rounds spent"}.get(
        outcome["stop"], outcome["stop"]
    )
    return f"{n} frames: not decided ({why}; {outcome['far_how']})"


def design_evidence(summary: Mapping) -> str:
    """How a sequential design decided a study summary's far limits, in one sentence ("" without
    one): the target, how many of the best tracker's far limits (``max_range`` records) met it,
    the frames per limit and in all, and the budget."""
    design = summary.get("design")
    if not design:
        return ""
    recs = summary.get("max_range", [])
    frames = sorted(r["frames"] for r in recs)
    span = f"{frames[0]}" if frames[0] == frames[-1] else f"{frames[0]}-{frames[-1]}"
    decided = sum(bool(r.get("far_decided")) for r in recs)
    return (
        f"Sequential design: from the coarse grid, frames added in rounds near each undecided limit until its 95 % "
        f"interval is within {design['target']}: {decided} of {len(recs)} far limits decided, {span} frames per "
        f"limit, {design['frames']} frames in all (budget {design['budget_frames']})."
    )


def _units(conditions: Sequence[dict], unit_fields: Sequence[tuple[str, str]]) -> dict[tuple, list[dict]]:
    """Base conditions (range removed) of each unit, in order of first appearance."""
    units: dict[tuple, list[dict]] = {}
    for c in conditions:
        key = tuple(c.get(f) for f, _ in unit_fields)  # a field some conditions lack (a point): None
        base = {k: v for k, v in c.items() if k != "range_m"}
        if base not in units.setdefault(key, []):
            units[key].append(base)
    return units


def _unit_budgets(
    units: Mapping[tuple, list[dict]], unit_fields: Sequence[tuple[str, str]], design: SequentialDesign, slots: int
) -> dict[tuple, int | None]:
    """Each unit's own budget of frames (None: none): ``unit_budget_frames``, and for a unit at a point
    of the unknowns at most ``point_budget_grids`` of its coarse grids (``slots`` slots of its base
    conditions each; never below one grid)."""
    at = next((i for i, (f, _) in enumerate(unit_fields) if f == "point"), None)
    out: dict[tuple, int | None] = {}
    for key, bases in units.items():
        budget = design.unit_budget_frames
        if design.point_budget_grids is not None and at is not None and key[at] is not None:
            cap = math.floor(design.point_budget_grids * slots) * len(bases)
            budget = cap if budget is None else min(budget, cap)
        out[key] = budget
    return out


def run_design(
    name: str,
    options: StudyOptions,
    design: SequentialDesign,
    out: Path,
    unit_fields: Sequence[tuple[str, str]],
    estimators: Sequence[str] | None = None,
    execution: Execution = Execution(),
    frames: FrameRunner | None = None,
    select: Callable[[Mapping], bool] = best_rows,
) -> DesignResult:
    """Run a sequential design over the units of ``options``' grid (see the module docstring).

    Parameters
    ----------
    name : the study's name (progress display).
    options : the study's options: its coarse grid is ``ranges_m`` × ``seeds``.
    design : targets, budget and rules of the design.
    out : the study's output directory (``tasks/`` and ``design.json``).
    unit_fields : (condition field, row column) pairs naming a unit, e.g.
        ``(("camera", "camera"), ("yaw_deg", "nominal_yaw_deg"))``; every other grid axis but
        the range is pooled into the unit.
    estimators : the frames' estimators (as :func:`studies.engine.sweep.sweep`).
    execution : where the frames run.
    frames : runs a round's tasks (default :func:`studies.engine.sweep.run_frames`).
    select : the rows a unit's fit uses (default :func:`best_rows`).

    Returns
    -------
    :class:`DesignResult` (its rows are every frame's rows, all trackers).
    """
    design.validate()
    options.validate()
    coarse = sorted({float(r) for r in options.ranges_m})
    candidates = candidate_ranges(coarse, design)
    units = _units(grid_conditions(options), unit_fields)
    coarse_frames = sum(len(b) for b in units.values()) * len(coarse) * options.seeds
    budget = design.budget_frames or DEFAULT_BUDGET_PER_UNIT * len(units)
    if budget < coarse_frames:
        raise ValueError(f"budget_frames: expected at least the coarse grid's {coarse_frames} frames, got {budget}")
    unit_coarse = max(len(b) for b in units.values()) * len(coarse) * options.seeds
    if design.unit_budget_frames is not None and design.unit_budget_frames < unit_coarse:
        raise ValueError(
            f"unit_budget_frames: expected at least a unit's coarse grid of {unit_coarse} frames, "
            f"got {design.unit_budget_frames}"
        )
    unit_budget = _unit_budgets(units, unit_fields, design, len(coarse) * options.seeds)
    run = frames or run_frames
    counts: dict[tuple, dict[float, int]] = {k: {} for k in units}
    fitted: dict[tuple, list[dict]] = {k: [] for k in units}
    todo: dict[tuple, list[float]] = {k: [r for r in coarse for _ in range(options.seeds)] for k in units}
    rounds: dict[tuple, int] = dict.fromkeys(units, 0)
    stop: dict[tuple, str] = {}
    records: dict[tuple, dict] = {}
    all_rows: list[dict] = []
    spent, log = 0, []
    for round_index in range(MAX_ROUNDS):
        tasks = []
        for key, picks in todo.items():
            for r in picks:
                seed = counts[key].get(r, 0)
                counts[key][r] = seed + 1
                tasks += [frame_task({**b, "range_m": r}, seed, options, estimators=estimators) for b in units[key]]
            rounds[key] += bool(picks)
        rows = run(tasks, out, execution, description=f"{name} round {round_index + 1}")
        spent += len(tasks)
        all_rows += rows
        for row in rows:
            if select(row):
                key = tuple(row.get(c) for _, c in unit_fields)
                if key not in fitted:
                    raise ValueError(f"unit_fields: row of unit {key} matches no unit of the grid")
                fitted[key].append(row)
        for key in todo:
            records[key] = estimate_max_range(fitted[key], p_working=design.p_working).to_dict()
        todo = {}
        for key in units:
            if key in stop:
                continue
            picks = next_ranges(records[key], design, candidates, coarse, options.seeds, round_index + 1, key)
            if picks and unit_budget[key] is not None:  # what the unit's own budget leaves
                spent_by_unit = sum(counts[key].values()) * len(units[key])
                left_slots = (unit_budget[key] - spent_by_unit) // len(units[key])
                if left_slots < 1:
                    stop[key] = "unit budget"
                    continue
                picks = picks[:left_slots]
            if picks:
                todo[key] = picks
            else:
                stop[key] = "decided"
        log.append({"round": round_index, "frames": len(tasks), "spent": spent, "open_units": len(todo)})
        if not todo:
            break
        left = budget - spent
        if sum(len(p) * len(units[k]) for k, p in todo.items()) > left:  # equal shares of what is left
            share = left // len(todo)
            for key in list(todo):
                todo[key] = todo[key][: share // len(units[key])]
                if not todo[key]:
                    del todo[key]
                    stop[key] = "budget"
            if not todo:
                break
    for key in units:
        stop.setdefault(key, "rounds")
    outcomes = tuple(
        UnitOutcome(
            key=key,
            frames=sum(counts[key].values()) * len(units[key]),
            rounds=rounds[key],
            frames_per_range={r: n * len(units[key]) for r, n in counts[key].items()},
            far_decided=far_status(records[key], design).decided,
            near_decided=near_status(records[key], design).decided,
            far_how=far_status(records[key], design).how,
            near_how=near_status(records[key], design).how,
            stop=stop[key],
        )
        for key in units
    )
    result = DesignResult(all_rows, outcomes, spent, budget, design, log)
    Path(out).mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(out) / "design.json", strict_json.dumps(result.summary(), indent=2).encode())
    return result
