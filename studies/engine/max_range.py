"""Working range: the nearest and farthest ranges where a correct pose has probability ≥ 0.95.

The level is :data:`P_WORKING` (0.95) unless a caller asks for another (``p_working``: a design
that must work 99 % of the time, or one that may miss one frame in ten); every record states it.

Success is "pose success" (:func:`studies.engine.scoring.pose_success`). It need not fall
monotonically from the nearest range: near the camera clipped cores lose their colour
and markers merge. The frames are therefore split at the *peak*, the nominal range with
the highest success rate (the nearest among ties, ``fitted_from_m``), and each side is
fitted on its own:

* **far limit** (``max_range_m``): frames from the peak outward follow a logistic
  fall-off P(r) = 1 / (1 + exp((r − r₅₀)/s)); the far limit is where P = 0.95,
  r₉₅ = r₅₀ − s·ln 19 (at level p: r₅₀ − s·ln(p/(1 − p)));
* **near limit** (``near_limit_m``): frames from the nearest range to the peak follow the
  mirror image, a logistic rise; the near limit is where it reaches 0.95.

Each fit is by maximum likelihood over every frame's success (0/1) at its actual range,
so the limits are continuous, not grid points. Their 95 % intervals come from the
**profile likelihood**: every limit L whose best likelihood (maximised over the slope s
with L held fixed) lies within χ²₁(0.95)/2 = 1.92 log-units of the overall maximum. The
interval is the hull of two such sets: that of the plain likelihood, and that of Firth's
penalised likelihood (Firth 1993; Heinze & Schemper 2002). The plain one alone holds the
true limit in only about 80 % of studies with 3 frames per range (simulation:
``tests/studies/test_max_range.py``); the penalised one alone favours gentle slopes and
excludes the steep fall-offs that perfectly separated frames allow. Unlike a parametric
bootstrap, the hull stays wide where frames are few or perfectly separated (every frame
correct up to one range, every one failing beyond: the fitted slope runs to zero and a
bootstrap redraws the same step, giving a zero-width interval). When the likelihood is
flat over a stretch of limits (perfect separation) the estimate is the middle of that
stretch.

Reading the numbers (metres):

* ``max_range_m`` = 0: no range reaches 0.95 (the fitted P at the peak is below it);
  ``low_m`` = 0: the frames cannot exclude that (e.g. 18 correct of 18 cannot show
  P ≥ 0.95: 59 correct in a row are needed); ``high_m`` = inf: the interval reaches past
  the farthest range tried.
* ``at_least``: the fit shows no fall-off within the ranges tried; the far limit is then
  the farthest range tried and reads "≥" that range.
* ``near_at_most``: no frame nearer than the peak failed; the near limit is then the
  nearest range tried and reads "≤" that range. ``near_low_m`` = 0: the interval reaches
  nearer than the nearest range tried; ``near_high_m`` = inf: it reaches past the peak.
* ``near_failures`` of ``near_frames`` frames nearer than the peak failed, mostly for
  ``near_cause``; ``peak_successes`` of ``peak_frames`` frames at the peak succeeded,
  ``farthest_successes`` of ``farthest_frames`` at the farthest range tried.

:func:`working_range_text`, :func:`far_limit_text`, :func:`far_interval_text` and
:func:`near_failures_text` word a result (or its summary record) the same way in every
report.

Why the far limit is where it is: the failures among frames within ±25 % of it (or the
nearest failures beyond the peak) are classified by :func:`failure_cause` and the most
common cause is named (``limiting_cause``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from studies.engine.scoring import failure_cause, pose_success

__all__ = [
    "COLUMNS",
    "LN19",
    "PLATEAU_TOL",
    "PROFILE_DROP",
    "P_WORKING",
    "MaxRange",
    "check_p_working",
    "estimate_max_range",
    "far_interval_text",
    "far_limit_text",
    "far_side",
    "near_failures_text",
    "profile_loglik",
    "working_range_text",
    "works_best_key",
]

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
"""ln(0.95 / 0.05): the logit of :data:`P_WORKING`."""
P_WORKING = 0.95
"""The probability of a correct pose a working range needs unless a caller says otherwise."""
PROFILE_DROP = float(chi2.ppf(0.95, 1)) / 2
"""Log-likelihood drop bounding the 95 % profile-likelihood interval (χ²₁(0.95)/2 ≈ 1.92)."""
PLATEAU_TOL = 1e-3
"""Log-likelihood within which limits count as equally likely (the estimate is their middle)."""
_SLOPES = 41
"""Slopes s of the profile grid, log-spaced from 0.001 to 10 times the ranges' scale."""
_GOLDEN = 16
"""Golden-section steps refining the best slope per limit (the bracket shrinks 0.618¹⁶ ≈ 5e-4)."""
_EDGE_POINTS = 65
"""Points of the fine grid refining each end of an interval (the grid step / 64)."""


@dataclass(frozen=True)
class MaxRange:
    """Result of :func:`estimate_max_range` (ranges in metres; see the module docstring)."""

    max_range_m: float
    low_m: float
    high_m: float
    limiting_cause: str
    frames: int
    successes: int
    fitted_from_m: float = math.nan
    at_least: bool = False
    near_limit_m: float = math.nan
    near_low_m: float = math.nan
    near_high_m: float = math.nan
    near_at_most: bool = False
    near_frames: int = 0
    near_failures: int = 0
    near_cause: str = "none"
    nearest_tested_m: float = math.nan
    farthest_tested_m: float = math.nan
    peak_frames: int = 0
    peak_successes: int = 0
    farthest_frames: int = 0
    farthest_successes: int = 0
    p_working: float = P_WORKING

    def to_dict(self) -> dict:
        """JSON-able form, with ``high_open`` / ``near_high_open`` saying that ``high_m`` /
        ``near_high_m`` is +inf (the interval is open above), so the record keeps its meaning
        when written as standard JSON, which has no infinity (:mod:`studies.engine.strict_json`)."""
        return {
            **self.__dict__,
            "high_open": self.high_m == math.inf,
            "near_high_open": self.near_high_m == math.inf,
        }


@dataclass(frozen=True)
class _Limit:
    """A fitted limit in the fit's own coordinate x (r on the far side, −r on the near side):
    estimate and 95 % interval, ±inf where they leave the frames' span [start, end]."""

    estimate: float
    low: float
    high: float


def _nominal_m(row: dict) -> float:
    return float(row.get("nominal_range_m", row["range_m"]))


def far_side(rows: list[dict]) -> tuple[list[dict], float]:
    """The frames from the nominal range with the highest success rate (nearest among
    ties) outward, and that range, m."""
    start = _peak(rows)
    return [x for x in rows if _nominal_m(x) >= start], start


def _peak(rows: list[dict]) -> float:
    outcomes: dict[float, list[bool]] = {}
    for x in rows:
        outcomes.setdefault(_nominal_m(x), []).append(pose_success(x))
    rates = {r: float(np.mean(v)) for r, v in outcomes.items()}
    return min(r for r, p in rates.items() if p == max(rates.values()))


def profile_loglik(
    x: np.ndarray,
    y: np.ndarray,
    limits: np.ndarray,
    scale: float,
    penalised: bool = False,
    *,
    p_working: float = P_WORKING,
) -> np.ndarray:
    """Profile log-likelihood of the ``p_working`` point of a logistic fall-off in x.

    Model: P(success | x) = 1 / (1 + exp(−((L − x)/s + logit p))), which is p at x = L and
    falls with x (p = 0.95: logit p = ln 19). For each limit L of ``limits`` the log-likelihood of the outcomes ``y``
    at ``x`` is maximised over the slope s: first on a log grid from 0.001 to 10 times
    ``scale`` (the smallest slope is a step at the frames' resolution, the largest a flat
    P ≈ 0.95), then by golden-section search between the best grid slope's neighbours.
    ``penalised`` adds Firth's penalty ½ log det I(a, b), the Fisher information of the
    model's linear predictor a + b·x (Firth 1993): it keeps the likelihood from running
    to a step under separation, and its profile intervals keep their coverage with few
    frames (Heinze & Schemper 2002).

    Parameters
    ----------
    x : positions of the frames (range, m, or its negative for a rise); binned to 1 cm.
    y : success of each frame.
    limits : candidate p points L, same unit as x.
    scale : the frames' spread, same unit (sets the slope grid).
    penalised : Firth's penalised log-likelihood instead of the plain one.
    p_working : the level p whose point L is (0 < p < 1).

    Returns
    -------
    The profile (penalised) log-likelihood at each limit (natural log, ≤ 0).
    """
    offset = LN19 if p_working == P_WORKING else math.log(p_working / (1.0 - p_working))
    xs, inverse = np.unique(np.round(np.asarray(x, float), 2), return_inverse=True)
    k = np.bincount(inverse, weights=np.asarray(y, float))
    n = np.bincount(inverse).astype(float)
    log_slopes = np.log(scale) + np.log(10.0) * np.linspace(-3.0, 1.0, _SLOPES)

    def loglik(lim: np.ndarray, log_s: np.ndarray) -> np.ndarray:
        """Log-likelihood for limits (..., 1) and log slopes broadcast against them."""
        t = (lim[..., None] - xs) / np.exp(log_s)[..., None] + offset
        ll = -(k * np.logaddexp(0.0, -t) + (n - k) * np.logaddexp(0.0, t)).sum(axis=-1)
        if not penalised:
            return ll
        w = n * np.exp(-np.logaddexp(0.0, -t) - np.logaddexp(0.0, t))  # n p (1 - p)
        xc = xs - xs.mean()
        s0, s1, s2 = w.sum(axis=-1), (w * xc).sum(axis=-1), (w * xc * xc).sum(axis=-1)
        return ll + 0.5 * np.log(np.maximum(s0 * s2 - s1 * s1, 1e-300))

    out = np.empty(len(limits))
    step = max(1, int(2_000_000 // (len(log_slopes) * len(xs))))
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    for i in range(0, len(limits), step):
        lim = np.asarray(limits[i : i + step], float)
        grid = loglik(lim[:, None], log_slopes[None, :])
        j = grid.argmax(axis=1)
        a = log_slopes[np.maximum(j - 1, 0)]
        b = log_slopes[np.minimum(j + 1, len(log_slopes) - 1)]
        c, d = b - golden * (b - a), a + golden * (b - a)
        fc, fd = loglik(lim, c), loglik(lim, d)
        for _ in range(_GOLDEN):
            left = fc > fd  # the maximum lies in [a, d]: shrink from the right, else from the left
            a, b = np.where(left, a, c), np.where(left, d, b)
            c_new = np.where(left, b - golden * (b - a), d)
            d_new = np.where(left, c, a + golden * (b - a))
            f_new = loglik(lim, np.where(left, c_new, d_new))
            fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
            c, d = c_new, d_new
        out[i : i + step] = np.maximum(grid.max(axis=1), np.maximum(fc, fd))
    return out


def _fit_limit(x: np.ndarray, y: np.ndarray, start: float, p_working: float) -> _Limit:
    """The ``p_working`` point of a fall-off in x fitted to frames at x ≥ ``start`` (the peak).

    Estimate: maximum likelihood, the middle of the limits within :data:`PLATEAU_TOL` of
    the best likelihood (a plateau under perfect separation); −inf below ``start`` (P <
    p_working at the peak), capped at the largest x. Interval: the hull of the plain and the
    Firth-penalised profile-likelihood intervals (see the module docstring), widened to
    hold the estimate; −inf when it reaches below ``start``, +inf when it reaches past
    the largest x.
    """
    end = float(x.max())
    scale = max(float(np.ptp(x)), 0.1 * abs(end), 0.1)
    pad = 0.25 * scale
    grid = np.linspace(start - pad, end + pad, max(round((end - start + 2 * pad) / scale * 120), 60) + 1)
    prof = profile_loglik(x, y, grid, scale, p_working=p_working)
    plateau = grid[prof >= float(prof.max()) - PLATEAU_TOL]
    estimate = 0.5 * (float(plateau.min()) + float(plateau.max()))
    penalised = profile_loglik(x, y, grid, scale, penalised=True, p_working=p_working)
    ends = [
        _interval(x, y, grid, scale, prof, False, p_working),
        _interval(x, y, grid, scale, penalised, True, p_working),
    ]
    low = min(min(e[0] for e in ends), estimate)
    high = max(max(e[1] for e in ends), estimate)
    return _Limit(
        estimate=-math.inf if estimate < start else min(estimate, end),
        low=-math.inf if low < start else low,
        high=math.inf if high > end else high,
    )


def _interval(
    x: np.ndarray, y: np.ndarray, grid: np.ndarray, scale: float, prof: np.ndarray, penalised: bool, p_working: float
) -> tuple[float, float]:
    """The limits on ``grid`` whose profile ``prof`` lies within :data:`PROFILE_DROP` of its
    maximum, ends refined on a finer grid; ±inf where they reach the grid's ends."""
    cut = float(prof.max()) - PROFILE_DROP
    inside = np.flatnonzero(prof >= cut)
    lo_i, hi_i = int(inside.min()), int(inside.max())

    def edge(a: float, b: float) -> float:
        """The last limit inside the interval on a fine grid from a (inside) to b (outside)."""
        fine = np.linspace(a, b, _EDGE_POINTS)
        inside_fine = profile_loglik(x, y, fine, scale, penalised, p_working=p_working) >= cut
        return float(fine[np.argmin(inside_fine) - 1]) if not inside_fine.all() else float(b)

    low = edge(grid[lo_i], grid[lo_i - 1]) if lo_i > 0 else -math.inf
    high = edge(grid[hi_i], grid[hi_i + 1]) if hi_i < len(grid) - 1 else math.inf
    return low, high


def check_p_working(p_working: float) -> None:
    """Fail in one line unless ``p_working`` is a probability in (0.5, 1).

    >>> check_p_working(1.0)
    Traceback (most recent call last):
    ...
    ValueError: p_working: expected a probability between 0.5 and 1 (exclusive), got 1.0
    """
    if isinstance(p_working, bool) or not isinstance(p_working, int | float) or not 0.5 < p_working < 1:
        raise ValueError(f"p_working: expected a probability between 0.5 and 1 (exclusive), got {p_working!r}")


def _level(rec: Mapping) -> str:
    """The record's working level as text ("0.95")."""
    return f"{rec.get('p_working', P_WORKING):g}"


def estimate_max_range(
    rows: list[dict], bootstrap: int | None = None, seed: int | None = None, *, p_working: float = P_WORKING
) -> MaxRange:
    """Near and far limits of the working range of ``rows`` (frames with ``range_m``).

    Parameters
    ----------
    rows : frames with ``range_m`` (m), optionally ``nominal_range_m`` (m, the grid point
        they were drawn for) and the fields of :data:`COLUMNS`.
    bootstrap, seed : accepted for compatibility and ignored: the intervals are profile
        likelihood intervals, not bootstrap ones.
    p_working : the probability of a correct pose the working range needs (0.5 < p < 1).

    Returns
    -------
    :class:`MaxRange` (see the module docstring for how to read it).
    """
    del bootstrap, seed
    check_p_working(p_working)
    if not rows:
        return MaxRange(math.nan, math.nan, math.nan, "no frames", 0, 0, p_working=p_working)
    ok = np.array([pose_success(x) for x in rows], dtype=bool)
    nominal = np.array([_nominal_m(x) for x in rows])
    r = np.array([float(x["range_m"]) for x in rows])
    start = _peak(rows)
    nearest, farthest = float(nominal.min()), float(nominal.max())
    n, k = len(rows), int(ok.sum())
    far, near = nominal >= start, nominal <= start
    near_fail = [x for x, nom, good in zip(rows, nominal, ok, strict=True) if nom < start and not good]
    base = dict(
        frames=n,
        successes=k,
        fitted_from_m=start,
        near_frames=int((nominal < start).sum()),
        near_failures=len(near_fail),
        near_cause=_dominant(near_fail),
        nearest_tested_m=nearest,
        farthest_tested_m=farthest,
        peak_frames=int((nominal == start).sum()),
        peak_successes=int(ok[nominal == start].sum()),
        farthest_frames=int((nominal == farthest).sum()),
        farthest_successes=int(ok[nominal == farthest].sum()),
        p_working=p_working,
    )
    # far side: a fall-off in r from the peak
    f = _fit_limit(r[far], ok[far], float(r[far & (nominal == start)].min()), p_working)
    r_far = 0.0 if f.estimate == -math.inf else f.estimate
    at_least = bool(r_far > 0 and r_far >= float(r[far].max()) - 1e-9)
    if at_least:
        r_far = farthest
    far_fail = [x for x, good, side in zip(rows, ok, far, strict=True) if side and not good]
    if at_least:
        cause = f"not reached by {farthest:g} m"
    else:
        around = [x for x in far_fail if abs(float(x["range_m"]) - r_far) <= 0.25 * max(r_far, 1.0)]
        cause = _dominant(around or far_fail)
    # near side: a rise in r up to the peak, i.e. a fall-off in −r
    if not near_fail:
        near_est, near_low, near_high = nearest, nearest, nearest
    else:
        g = _fit_limit(-r[near], ok[near], -float(r[near & (nominal == start)].max()), p_working)
        near_est = math.nan if g.estimate == -math.inf else -g.estimate
        near_low = 0.0 if g.high == math.inf else -g.high
        near_high = math.inf if g.low == -math.inf else -g.low
    if r_far == 0.0 or not math.isfinite(near_est):
        r_far, near_est, at_least = 0.0, math.nan, False
    return MaxRange(
        max_range_m=float(r_far),
        low_m=0.0 if f.low == -math.inf else float(f.low),
        high_m=float(f.high),
        limiting_cause=cause,
        at_least=at_least,
        near_limit_m=float(near_est),
        near_low_m=float(near_low),
        near_high_m=float(near_high),
        near_at_most=not near_fail,
        **base,
    )


def _dominant(rows: list[dict]) -> str:
    if not rows:
        return "none"
    counts = Counter(failure_cause(x) for x in rows)
    return counts.most_common(1)[0][0]


def _m(value: float) -> str:
    """A range in metres to 0.1 m, without a trailing .0."""
    text = f"{value:.1f}"
    return text[:-2] if text.endswith(".0") else text


def far_limit_text(rec: Mapping) -> str:
    """The far limit of a :class:`MaxRange` record: "11.7 m", "≥ 12 m", "none", or "8.2 m
    (failures between it and 12 m end it; the 3 frames at 12 m were all correct, too few to
    show P ≥ 0.95 there)" when the fit ends before a farthest range whose frames all
    succeeded (failures in between)."""
    if not rec.get("frames"):
        return "no frames"
    if rec["max_range_m"] <= 0:
        return "none"
    if rec.get("at_least"):
        return f"≥ {_m(rec['farthest_tested_m'])} m"
    text = f"{_m(rec['max_range_m'])} m"
    n = rec.get("farthest_frames", 0)
    if n and rec.get("farthest_successes") == n:  # success is not monotone: say so rather than hide it
        frames = "frame" if n == 1 else f"{n} frames"
        text += (
            f" (failures between it and {_m(rec['farthest_tested_m'])} m end it; the {frames} at "
            f"{_m(rec['farthest_tested_m'])} m {'was' if n == 1 else 'were all'} correct, too few to show "
            f"P ≥ {_level(rec)} there)"
        )
    return text


def works_best_key(rec: Mapping) -> tuple[float, float]:
    """Sort key of a working-range record: larger is better. The far limit first (to 0.1 m:
    finer differences are the pose jitter of the farthest frames), then the fraction of frames
    correct, so that among settings no range of which reaches P ≥ 0.95 the one that works most
    often comes first."""
    reach = rec.get("max_range_m")
    reach = round(float(reach), 1) if reach is not None and math.isfinite(reach) else 0.0
    frames = rec.get("frames") or 0
    return reach, (rec.get("successes") or 0) / frames if frames else 0.0


def far_interval_text(rec: Mapping) -> str:
    """The far limit's 95 % interval: "7.2 to 10 m", "0 to > 12 m" (0: no range need reach
    0.95; > 12: it may lie beyond the farthest range tried) or "< 2 m" (no range reaches it)."""
    if not rec.get("frames"):
        return "–"
    low, high = rec["low_m"], rec["high_m"]
    if high is None or rec.get("high_open"):  # read back from standard JSON: open above
        high = math.inf
    if rec["max_range_m"] <= 0 and math.isfinite(high) and high < rec["nearest_tested_m"]:
        return f"< {_m(rec['nearest_tested_m'])} m"
    hi = f"> {_m(rec['farthest_tested_m'])}" if not math.isfinite(high) else _m(high)
    return f"{_m(low)} to {hi} m"


def working_range_text(rec: Mapping) -> str:
    """The working range [near limit, far limit]: "3 m to 11.7 m", "≤ 2 m to ≥ 12 m" (every
    frame at the nearest and farthest ranges tried correct), "none (fitted P < 0.95 at
    every range; best: 2 of 3 frames at 4 m)" or "none (0 of 18 frames correct)"."""
    if not rec.get("frames"):
        return "no frames"
    if rec["max_range_m"] <= 0 and not rec["successes"]:
        return f"none (0 of {rec['frames']} frames correct)"
    if rec["max_range_m"] <= 0:
        best = f"{rec['peak_successes']} of {rec['peak_frames']} frames at {_m(rec['fitted_from_m'])} m"
        return f"none (fitted P < {_level(rec)} at every range; best: {best})"
    near = f"≤ {_m(rec['nearest_tested_m'])}" if rec.get("near_at_most") else _m(rec["near_limit_m"])
    return f"{near} m to {far_limit_text(rec)}"


def near_failures_text(rec: Mapping) -> str:
    """The failures nearer than the peak: "3 of 3 frames nearer than 4 m fail (colour)", or
    "none nearer than 4 m" / "" when no range was nearer."""
    if not rec.get("near_frames"):
        return ""
    peak = _m(rec["fitted_from_m"])
    if not rec["near_failures"]:
        return f"none nearer than {peak} m"
    return f"{rec['near_failures']} of {rec['near_frames']} frames nearer than {peak} m fail ({rec['near_cause']})"
