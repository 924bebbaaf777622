"""Maximum-range estimation on synthetic frames with a known fall-off."""

from __future__ import annotations

import math

import numpy as np
import pytest

from studies.engine.max_range import estimate_max_range
from studies.engine.scoring import failure_cause


def _frames(r50, s, ranges, per_range, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for r in ranges:
        p = 1 / (1 + math.exp((r - r50) / s))
        for _ in range(per_range):
            ok = bool(rng.random() < p)
            rows.append(
                {
                    "range_m": r,
                    "detected": ok,
                    "side_correct": ok,
                    "numbering_correct": ok,
                    "range_err_m": 0.0,
                    "yaw_err_deg": 0.0,
                    "core_saturated_fraction_mean": 0.0,
                    "reason": "" if ok else "no blob",
                    "marker_spacing_px": 50.0,
                    "core_diameter_px": 5.0,
                }
            )
    return rows


def test_recovers_the_true_95_percent_range_within_its_interval():
    r50, s = 8.0, 0.6
    truth = r50 - s * math.log(19)
    result = estimate_max_range(_frames(r50, s, np.arange(2, 14.01, 0.5), 40))
    assert result.low_m <= truth <= result.high_m
    assert result.max_range_m == pytest.approx(truth, abs=0.5)
    assert result.limiting_cause == "signal-to-noise"


def test_continuous_not_a_grid_point():
    result = estimate_max_range(_frames(6.3, 0.4, [2, 4, 6, 8, 10], 60, seed=3))
    assert result.max_range_m not in (2, 4, 6, 8, 10)


def test_all_correct_is_only_bounded_below():
    result = estimate_max_range(_frames(100.0, 0.5, [1, 2, 3], 10))
    assert result.max_range_m == 3 and math.isinf(result.high_m)


def test_a_near_failure_zone_does_not_hide_the_far_limit():
    # clipped cores fail at 1-2 m; from 3 m on the usual fall-off: r95 is the far one
    r50, s = 9.0, 0.5
    near = _frames(-100.0, 0.5, [1.0, 2.0], 40)  # every near frame fails
    result = estimate_max_range(near + _frames(r50, s, np.arange(3, 14.01, 0.5), 40, seed=1))
    truth = r50 - s * math.log(19)
    assert result.fitted_from_m == 3.0
    assert result.low_m <= truth <= result.high_m
    assert result.max_range_m == pytest.approx(truth, abs=0.5)


def test_no_range_qualifies_when_the_best_rate_is_low():
    rows = _frames(-100.0, 0.5, [1.0, 2.0], 20) + _frames(2.0, 0.5, [3.0, 4.0, 5.0], 20, seed=2)
    assert estimate_max_range(rows).max_range_m == 0.0


def test_isolated_failures_give_no_extrapolated_range():
    rows = _frames(100.0, 0.5, [2.0, 4.0, 6.0, 8.0], 6)
    rows[7] = {**rows[7], "detected": False, "reason": "no blob"}  # one failure at 4 m
    result = estimate_max_range(rows)
    assert result.max_range_m <= 8.0 and math.isinf(result.high_m)


def test_failure_causes():
    base = {
        "detected": False,
        "failure": "",
        "core_saturated_fraction_mean": 0.0,
        "marker_spacing_px": 50.0,
        "core_diameter_px": 5.0,
    }
    assert failure_cause({**base, "core_saturated_fraction_mean": 0.9}) == "saturation"
    assert failure_cause({**base, "marker_spacing_px": 8.0}) == "resolution / merging"
    assert failure_cause(base) == "signal-to-noise"
    assert failure_cause({**base, "failure": "too-few-blobs"}) == "resolution / merging"
    assert failure_cause({**base, "failure": "no-fit"}) == "signal-to-noise"
    assert failure_cause({**base, "detected": True, "side_correct": False}) == "colour"
