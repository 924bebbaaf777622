"""Maximum range: where the probability of a correct detection falls to 0.95.

Model: P(success | r) = 1 / (1 + exp((r − r₅₀)/s)), a logistic fall-off with range,
fitted by maximum likelihood to every frame's success (0/1) at its actual range — so
the answer is a continuous range, not a grid point. The maximum range is where P = 0.95:
r₉₅ = r₅₀ − s·ln 19. Its uncertainty comes from a parametric bootstrap (refit to
successes redrawn from the fitted model at the same ranges): ``low_m``/``high_m`` are
the 2.5 and 97.5 percentiles. When every frame succeeds the range is only bounded below
(``high_m`` = inf); when none does, above (``max_range_m`` = 0).

Why it ends there: the failures among frames within ±25 % of r₉₅ (or the nearest
failures) are classified by :func:`failure_cause` and the most common cause is named.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from studies.metrics import detection_success

CAUSES = ("resolution / merging", "signal-to-noise", "colour", "saturation", "pose")
LN19 = math.log(19.0)


def failure_cause(row: dict) -> str:
    """Why a frame failed, from what the detector and the camera report.

    * colour: a side was found but the wrong one (or markers of a wrong colour);
    * saturation: markers not recognised and their cores mostly clipped (> 50 %);
    * resolution / merging: markers not recognised and closer than ~2 blob diameters, or
      the detector reports merged/lost markers;
    * signal-to-noise: markers not recognised, not clipped and well apart (too faint);
    * pose: detected and numbered but range off by > 10 % or yaw by > 5°.
    """
    if row.get("detected"):
        return "pose" if row.get("side_correct") else "colour"
    reason = str(row.get("reason", ""))
    if row.get("core_saturated_fraction_mean", 0.0) > 0.5:
        return "saturation"
    if "merged" in reason or row.get("marker_spacing_px", math.inf) < 2.0 * row.get("core_diameter_px", 0.0):
        return "resolution / merging"
    return "signal-to-noise"


def frame_ok(row: dict) -> bool:
    """Success for the range search: correct side, five markers correctly numbered and a
    usable pose (range within 10 %, yaw within 5°)."""
    if not detection_success(row):
        return False
    r, y = row.get("range_err_m"), row.get("yaw_err_deg")
    rng = row.get("range_m", 1.0)
    return bool(np.isfinite(r) and abs(r) <= 0.1 * rng and np.isfinite(y) and abs(y) <= 5.0)


@dataclass(frozen=True)
class MaxRange:
    """Result of :func:`estimate_max_range` (metres)."""

    max_range_m: float
    low_m: float
    high_m: float
    limiting_cause: str
    frames: int
    successes: int

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


def estimate_max_range(rows: list[dict], bootstrap: int = 300, seed: int = 0) -> MaxRange:
    """Fit the logistic model to ``rows`` (frames with ``range_m``) and find r₉₅."""
    r = np.array([float(x["range_m"]) for x in rows])
    y = np.array([frame_ok(x) for x in rows], dtype=bool)
    n, k = len(rows), int(y.sum())
    if n == 0:
        return MaxRange(math.nan, math.nan, math.nan, "no frames", 0, 0)
    fails = [x for x, ok in zip(rows, y, strict=True) if not ok]
    if k == n:
        return MaxRange(float(r.max()), float(r.max()), math.inf, "not reached (all frames correct)", n, k)
    if k == 0:
        return MaxRange(0.0, 0.0, float(r.min()), _dominant(fails), n, k)
    r50, s = _fit(r, y)
    r95 = r50 - s * LN19
    rng = np.random.default_rng(seed)
    p = 1.0 / (1.0 + np.exp((r - r50) / s))
    boot = []
    for _ in range(bootstrap):
        yb = rng.random(n) < p
        if 0 < yb.sum() < n:
            b50, bs = _fit(r, yb)
            boot.append(b50 - bs * LN19)
    low, high = np.percentile(boot, [2.5, 97.5]) if boot else (math.nan, math.nan)
    near = [x for x in fails if abs(float(x["range_m"]) - r95) <= 0.25 * max(r95, 1.0)] or fails
    return MaxRange(float(max(r95, 0.0)), float(max(low, 0.0)), float(max(high, 0.0)), _dominant(near), n, k)


def _dominant(rows: list[dict]) -> str:
    if not rows:
        return "none"
    counts = Counter(failure_cause(x) for x in rows)
    return counts.most_common(1)[0][0]
