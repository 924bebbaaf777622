"""Intervals that include the physics: a limit's spread over points of the unknowns, with its noise.

A study run at N points of the unknowns (a calibration's NROY set, or the registry's ranges)
estimates a limit at each point i, L̂_i (the fit of :mod:`studies.engine.max_range`, with the
noise of its frames and poses). The true hardware is one more point of the same set, unknown. If
the N points are draws from the set (exchangeable with the truth), the truth's limit L* lies
between the k-th smallest and the k-th largest of the N limits with probability 1 − 2k/(N + 1)
(order statistics: every rank of L* among the N + 1 is equally likely). The estimates carry their
frames' noise on top, which spreads them a little wider than the limits themselves, so the
interval between the k-th smallest and k-th largest *estimate* holds L* at least that often (the
*noise + physics* interval; tests/studies/test_uncertainty.py measures both on a planted truth).
Nothing is assumed of how the limit depends on the unknowns, and a censored estimate ("≥ the
largest range tried": ∞; for a near limit "≤ the nearest tried": −∞) keeps its rank: an interval
whose k-th largest is censored says "≥", one whose k-th smallest is censored below says "≤".

With N = 16 and k = 1 the rate is 1 − 2/17 = 88 %; 95 % needs N ≥ 39. The rate is reported
beside the interval, never rounded up.

Example
-------
>>> iv = physics_interval([3.0, 6.0, 4.5])
>>> (iv.low, iv.high, round(iv.rate, 2), iv.order)
(3.0, 6.0, 0.5, 1)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from studies.engine.max_range import P_WORKING, estimate_max_range

__all__ = [
    "POINT_BUDGET_GRIDS",
    "PhysicsInterval",
    "far_limits_at_points",
    "interval_text",
    "limits_at_points",
    "nominal_rows",
    "order_for",
    "over_points",
    "physics_interval",
    "physics_note",
    "point_rows",
    "values_at_points",
]


POINT_BUDGET_GRIDS = 2.0
"""Coarse grids of frames one unit at a point may spend in a sequential design run with
``--uncertainty`` (``main-job``, ``study``; :attr:`studies.engine.sequential.SequentialDesign.point_budget_grids`):
its coarse grid and as many frames again, enough to extend past the farthest range or to narrow the
crossing once. Assumed: the interval is made of the points' limits, whose spread is the physics'
(16 registry points of V2 + T6 18 mm at 0° gave far limits from none to ≥ 20 m), so a point's own
limit needs less precision than the nominal's ±20 %, and the interval keeps its rate with the
estimates' noise (module docstring; tests/studies/test_uncertainty.py). The sensitivity study keeps
the design's full budget: its emulator is fitted to each point's value."""


@dataclass(frozen=True)
class PhysicsInterval:
    """A noise + physics interval over points of the unknowns.

    Attributes
    ----------
    low, high
        The interval, in the limit's unit (m); ``high`` is ∞ when the k-th largest estimate is
        censored ("≥ the largest range tried"), ``low`` −∞ when the k-th smallest is censored
        below ("≤ the nearest range tried", a near limit).
    rate
        Its coverage: 1 − 2k/(N + 1) (at least, with the estimates' noise).
    points
        N, the points it is made from.
    order
        k, the rank of its ends among the points' estimates.
    median
        The points' median estimate, a central prediction (∞ when a middle estimate is censored).
    """

    low: float
    high: float
    rate: float
    points: int
    order: int
    median: float = math.nan

    def to_dict(self) -> dict:
        """Plain form for strict JSON: a censored end or median is None, on the limit's open side (a far
        limit's "≥ the farthest tried", a near limit's "≤ the nearest tried")."""
        return {
            "low": None if math.isinf(self.low) else self.low,
            "high": None if math.isinf(self.high) else self.high,
            "rate": self.rate,
            "points": self.points,
            "order": self.order,
            "median": None if math.isinf(self.median) else self.median,
        }


def order_for(points: int, rate: float = 0.95) -> int:
    """The largest k ≥ 1 with 1 − 2k/(N + 1) ≥ ``rate`` (1 when even k = 1 falls short: the interval
    then states its lower rate)."""
    if not isinstance(points, int) or points < 1:
        raise ValueError(f"points: expected an integer >= 1, got {points!r}")
    if not 0 < rate < 1:
        raise ValueError(f"rate: expected a number in (0, 1), got {rate!r}")
    return max(1, math.floor((1 - rate) * (points + 1) / 2))


def physics_interval(limits: Sequence[float], *, rate: float = 0.95) -> PhysicsInterval:
    """The noise + physics interval of a limit from its estimate at each point (module docstring).

    Parameters
    ----------
    limits
        Per point, the estimated limit (m); ``inf`` for "≥ the largest range tried", ``-inf`` for
        "≤ the nearest range tried"; NaN is refused (a point without an estimate must be dropped,
        and said so, by the caller).
    rate
        The coverage wanted; the interval uses the largest order k that reaches it, and states
        the rate it has.

    Returns
    -------
    PhysicsInterval
    """
    x = np.asarray(limits, dtype=float)
    if x.ndim != 1 or len(x) == 0:
        raise ValueError(f"limits: expected a non-empty sequence of numbers, got shape {x.shape}")
    if np.isnan(x).any():
        raise ValueError("limits: expected numbers or ±inf, no NaN (drop points without an estimate)")
    n = len(x)
    k = order_for(n, rate)
    ranked = np.sort(x)
    return PhysicsInterval(low=float(ranked[k - 1]), high=float(ranked[n - k]), rate=1 - 2 * k / (n + 1),
                           points=n, order=k, median=float(np.median(ranked)))  # fmt: skip


def nominal_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows of the nominal point (a run with ``--uncertainty`` also holds rows tagged ``point``)."""
    return frame[frame["point"].isna()] if "point" in frame else frame


def point_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows run at points of the unknowns (none without ``--uncertainty``)."""
    return frame[frame["point"].notna()] if "point" in frame else frame.iloc[:0]


def values_at_points(
    rows: pd.DataFrame, group: list[str], value: Callable[[pd.DataFrame], float]
) -> dict[tuple, list[float]]:
    """Per ``group`` key, ``value`` of that key's rows at each point of the unknowns, in point order;
    a point where ``value`` is NaN (nothing to measure there) is left out.

    Parameters
    ----------
    rows
        Results rows run at points (:func:`point_rows`), with a ``point`` column.
    group
        The columns of one estimate (a study's unit and tracker).
    value
        The estimate from one key's rows at one point (a far limit, m; a separability; a probability).
    """
    out = {
        k: [v for v in (float(x) for x in xs) if not math.isnan(v)] for k, xs in _at_points(rows, group, value).items()
    }
    return {k: v for k, v in out.items() if v}


def _at_points(rows: pd.DataFrame, group: list[str], value: Callable[[pd.DataFrame], object]) -> dict[tuple, list]:
    """Per ``group`` key, ``value`` of that key's rows at each point, in point order."""
    out: dict[tuple, list] = {}
    if rows.empty:
        return out
    for key, g in rows.groupby([*group, "point"], sort=True):
        out.setdefault(tuple(key[:-1]), []).append(value(g))
    return out


def far_limits_at_points(
    rows: pd.DataFrame, group: list[str], *, p_working: float = P_WORKING
) -> dict[tuple, list[float]]:
    """Per ``group`` key, the far limit at each point of the unknowns (m; ∞ for "≥ the farthest range
    tried", 0 where no range works): :func:`studies.engine.max_range.estimate_max_range` of its rows
    at level ``p_working``."""
    return limits_at_points(rows, group, p_working=p_working)[0]


def limits_at_points(
    rows: pd.DataFrame, group: list[str], *, p_working: float = P_WORKING
) -> tuple[dict[tuple, list[float]], dict[tuple, list[float]]]:
    """(far, near) limits at each point of the unknowns, from one fit per key and point: the far ones
    as :func:`far_limits_at_points`, the near ones in m (−∞ for "≤ the nearest range tried"; a point
    where no range works has no near limit and is left out: its far limit, 0, says so)."""
    fits = _at_points(rows, group, lambda g: estimate_max_range(g.to_dict("records"), p_working=p_working))
    far = {k: [math.inf if m.at_least else max(float(m.max_range_m), 0.0) for m in ms] for k, ms in fits.items()}
    near = {
        k: [-math.inf if m.near_at_most else float(m.near_limit_m) for m in ms if m.max_range_m > 0]
        for k, ms in fits.items()
    }
    return far, {k: v for k, v in near.items() if v}


def interval_text(
    iv: PhysicsInterval,
    *,
    unit: str = " m",
    at_least: str = "≥ the farthest tried",
    at_most: str = "≤ the nearest tried",
    zero: str | None = None,
) -> str:
    """A noise + physics interval in words, "3.1 to 6 m (88 %, 16 points)"; ``unit`` follows the
    numbers, ``at_least`` stands for a censored upper end ("3.1 m to ≥ the farthest tried"), ``at_most``
    for a censored lower one, ``zero`` (if given) for an end at 0 (a far limit of 0 is "none": no range
    worked); two ends that read alike read once ("≥ the farthest tried", "none").

    Examples
    --------
    >>> interval_text(physics_interval([3.1, 6.0, 4.0]))
    '3.1 to 6 m (50 %, 3 points)'
    >>> interval_text(physics_interval([-math.inf, 2.5, 4.0]))
    '≤ the nearest tried to 4 m (50 %, 3 points)'
    >>> interval_text(physics_interval([3.1, math.inf, math.inf]))
    '3.1 m to ≥ the farthest tried (50 %, 3 points)'
    >>> interval_text(physics_interval([0.0, 0.0, math.inf]), zero="none")
    'none to ≥ the farthest tried (50 %, 3 points)'
    """

    def part(x: float) -> tuple[str, bool]:
        """The end in words, and whether it is a number (which the unit follows)."""
        if zero is not None and x == 0:
            return zero, False
        if math.isinf(x):
            return (at_least if x > 0 else at_most), False
        return f"{x:.3g}", True

    (low, low_number), (high, high_number) = part(iv.low), part(iv.high)
    if low == high and not low_number:
        span = low
    elif low_number and high_number:
        span = f"{low} to {high}{unit}"
    else:
        span = f"{low}{unit if low_number else ''} to {high}{unit if high_number else ''}"
    return f"{span} ({100 * iv.rate:.0f} %, {iv.points} points)"


def over_points(fields: tuple, design, points: int) -> tuple[tuple, object]:
    """A sequential design (:class:`studies.engine.sequential.SequentialDesign`) and its unit fields
    for a run at ``points`` points of the unknowns besides the nominal one: each point is a unit of
    its own (its limits are decided on its own frames) and the budget, which is the nominal grid's,
    is repeated for each point. Unchanged when ``points`` is 0."""
    if not points:
        return fields, design
    if design.budget_frames is not None:
        design = design.with_overrides(budget_frames=design.budget_frames * (points + 1))
    return (*fields, ("point", "point")), design


def physics_note(summary: dict) -> list[str]:
    """What a study's noise + physics intervals rest on, for its report's lead (none when the run
    was not at points of the unknowns: its summary has no ``physics``)."""
    physics = summary.get("physics")
    if not physics:
        return []
    return [
        f"Noise + physics: each condition also ran at {physics['source']}. A noise + physics interval lies "
        "between the k-th smallest and k-th largest of the points' estimates, a predictive interval for hardware "
        "drawn from the same set at the rate it states (studies/engine/uncertainty.py); every other number, and "
        "the 95 % intervals beside them, is the nominal point's noise and pose alone."
    ]
