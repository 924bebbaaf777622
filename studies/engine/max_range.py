"""Maximum range: where the probability of a correct detection falls to 0.95.

Model: P(success | r) = 1 / (1 + exp((r − r₅₀)/s)), a logistic fall-off with range,
fitted by maximum likelihood to every frame's success (0/1) at its actual range — so
the answer is a continuous range, not a grid point. The maximum range is where P = 0.95:
r₉₅ = r₅₀ − s·ln 19. Its uncertainty comes from a parametric bootstrap (refit to
successes redrawn from the fitted model at the same ranges): ``low_m``/``high_m`` are
the 2.5 and 97.5 percentiles. When every frame succeeds the range is only bounded below
(``high_m`` = inf); when none does, above (``max_range_m`` = 0).

Near the camera a marker can fail too (clipped cores lose their colour), so success
need not fall monotonically from the nearest range: the fall-off is fitted to the frames
from the range with the highest success rate outward (``fitted_from_m``; the nearest one
among ties). Where that rate is below 0.95 no range qualifies and the maximum range is 0.
Nor is r₉₅ extrapolated beyond the farthest range tested: a fit that puts it there (no
fall-off in the data, only isolated failures) gives that range, with ``high_m`` = inf.

Why it ends there: the failures among frames within ±25 % of r₉₅ (or the nearest
failures) are classified by :func:`failure_cause` and the most common cause is named.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit

from studies.engine.scoring import failure_cause, pose_success

COLUMNS = (
    "range_m",
    "nominal_range_m",
    "detected",
    "side_correct",
    "numbering_correct",
    "range_err_m",
    "yaw_err_deg",
    "failure",
    "core_saturated_fraction_mean",
    "marker_spacing_px",
    "core_diameter_px",
)
"""The row fields the estimate reads (a table can be cut to these before making row dicts)."""
LN19 = math.log(19.0)


@dataclass(frozen=True)
class MaxRange:
    """Result of :func:`estimate_max_range` (metres)."""

    max_range_m: float
    low_m: float
    high_m: float
    limiting_cause: str
    frames: int
    successes: int
    fitted_from_m: float = math.nan

    def to_dict(self) -> dict:
        """JSON-able form."""
        return dict(self.__dict__)


def _fit(r: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """ML logistic fit; returns (r50, s)."""

    def nll(p):
        r50, log_s = p
        z = (r - r50) / math.exp(log_s)
        # success prob 1/(1+e^z): log-likelihood terms, numerically stable
        return float(np.sum(np.logaddexp(0.0, z) - np.where(y, 0.0, z)))

    start = np.array([np.median(r), math.log(max(np.ptp(r), 1.0) / 4)])
    res = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 4000})
    return float(res.x[0]), float(math.exp(res.x[1]))


def _nominal_m(row: dict) -> float:
    return float(row.get("nominal_range_m", row["range_m"]))


def far_side(rows: list[dict]) -> tuple[list[dict], float]:
    """The frames from the nominal range with the highest success rate (nearest among
    ties) outward, and that range, m."""
    outcomes: dict[float, list[bool]] = {}
    for x in rows:
        outcomes.setdefault(_nominal_m(x), []).append(pose_success(x))
    rates = {r: float(np.mean(v)) for r, v in outcomes.items()}
    start = min(r for r, p in rates.items() if p == max(rates.values()))
    return [x for x in rows if _nominal_m(x) >= start], start


def estimate_max_range(rows: list[dict], bootstrap: int = 300, seed: int = 0) -> MaxRange:
    """Fit the logistic model to ``rows`` (frames with ``range_m``) and find r₉₅."""
    if not rows:
        return MaxRange(math.nan, math.nan, math.nan, "no frames", 0, 0)
    fitted, start = far_side(rows)
    nearer_failed = start > min(_nominal_m(x) for x in rows)  # a near failure zone was left out
    r = np.array([float(x["range_m"]) for x in fitted])
    y = np.array([pose_success(x) for x in fitted], dtype=bool)
    n, k = len(rows), sum(pose_success(x) for x in rows)
    fails = [x for x, ok in zip(fitted, y, strict=True) if not ok]
    if y.all():
        return MaxRange(float(r.max()), float(r.max()), math.inf, "not reached (all frames correct)", n, k, start)
    if not y.any():
        return MaxRange(0.0, 0.0, float(r.min()), _dominant(fails), n, k, start)
    floor = float(r.min()) if nearer_failed else -math.inf  # no extrapolation into the near zone
    ceiling = float(r.max())  # nor beyond the farthest frame (isolated failures fit no fall-off)

    def r95_of(b50: float, bs: float) -> float:
        value = b50 - bs * LN19
        return min(value, ceiling) if value >= floor else 0.0

    r50, s = _fit(r, y)
    r95 = r95_of(r50, s)
    rng = np.random.default_rng(seed)
    p = expit((r50 - r) / s)  # 1 / (1 + e^((r - r50)/s)) without overflow
    boot = []
    for _ in range(bootstrap):
        yb = rng.random(len(r)) < p
        if 0 < yb.sum() < len(r):
            boot.append(r95_of(*_fit(r, yb)))
    low, high = np.percentile(boot, [2.5, 97.5]) if boot else (math.nan, math.nan)
    if high >= ceiling - 1e-9:
        high = math.inf  # the upper end lies beyond the ranges tested
    near = [x for x in fails if abs(float(x["range_m"]) - r95) <= 0.25 * max(r95, 1.0)] or fails
    return MaxRange(float(max(r95, 0.0)), float(max(low, 0.0)), float(max(high, 0.0)), _dominant(near), n, k, start)


def _dominant(rows: list[dict]) -> str:
    if not rows:
        return "none"
    counts = Counter(failure_cause(x) for x in rows)
    return counts.most_common(1)[0][0]
