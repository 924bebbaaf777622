"""Working-range estimation on synthetic frames with a known rise and fall-off."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.optimize import minimize_scalar

from studies.engine.max_range import (
    LN19,
    estimate_max_range,
    far_interval_text,
    far_limit_text,
    near_failures_text,
    profile_loglik,
    working_range_text,
)
from studies.engine.scoring import failure_cause


def _row(r: float, ok: bool, nominal: float | None = None, why: str = "faint") -> dict:
    """One frame: a success, or a failure of the named kind (faint, colour, merged)."""
    return {
        "range_m": r,
        "nominal_range_m": r if nominal is None else nominal,
        "detected": ok or why == "colour",
        "side_correct": ok,
        "numbering_correct": ok,
        "range_err_m": 0.0,
        "yaw_err_deg": 0.0,
        "failure": "too-few-blobs" if (not ok and why == "merged") else "",
        "core_saturated_fraction_mean": 0.0,
        "marker_spacing_px": 50.0,
        "core_diameter_px": 5.0,
    }


def _frames(r50, s, ranges, per_range, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for r in ranges:
        p = 1 / (1 + math.exp((r - r50) / s))
        rows += [_row(float(r), bool(rng.random() < p)) for _ in range(per_range)]
    return rows


def _counts(spec: dict[float, tuple[int, int]], why: str = "faint") -> list[dict]:
    """Frames from {range: (correct, frames)}."""
    return [_row(r, i < k, why=why) for r, (k, n) in spec.items() for i in range(n)]


def test_recovers_the_true_95_percent_range_within_its_interval():
    r50, s = 8.0, 0.6
    truth = r50 - s * math.log(19)
    result = estimate_max_range(_frames(r50, s, np.arange(2, 14.01, 0.5), 40))
    assert result.low_m <= truth <= result.high_m
    assert result.max_range_m == pytest.approx(truth, abs=0.5)
    assert result.high_m - result.low_m < 1.5  # 1000 frames pin it down
    assert result.limiting_cause == "signal-to-noise"
    assert not result.at_least and result.near_at_most and result.near_failures == 0


def test_continuous_not_a_grid_point():
    result = estimate_max_range(_frames(6.3, 0.4, [2, 4, 6, 8, 10], 60, seed=3))
    assert result.max_range_m not in (2, 4, 6, 8, 10)


def test_all_correct_reads_at_least_the_farthest_range():
    result = estimate_max_range(_frames(100.0, 0.5, [1, 2, 3], 10))
    assert result.max_range_m == 3 and result.at_least and math.isinf(result.high_m)
    assert result.limiting_cause == "not reached by 3 m"
    assert far_limit_text(result.to_dict()) == "≥ 3 m"
    assert working_range_text(result.to_dict()) == "≤ 1 m to ≥ 3 m"
    # 30 correct of 30 cannot show P ≥ 0.95 (P(30 of 30 | p = 0.95) = 0.21 > 0.05): the interval reaches 0
    assert stats.binom.pmf(30, 30, 0.95) > 0.05 and result.low_m == 0.0
    assert far_interval_text(result.to_dict()) == "0 to > 3 m"


def test_perfect_separation_gives_a_wide_interval_not_a_point():
    # every frame correct to 8 m, every one failing from 10 m: the old bootstrap gave a zero-width interval
    rows = _counts({2.0: (3, 3), 4.0: (3, 3), 6.0: (3, 3), 8.0: (3, 3), 10.0: (0, 3), 12.0: (0, 3)}, why="merged")
    result = estimate_max_range(rows)
    assert result.max_range_m == pytest.approx(9.0, abs=0.1)  # the likelihood is flat over 8-10 m: its middle
    assert result.high_m == pytest.approx(10.0, abs=0.05)  # P(10 m) ≥ 0.95 with 0 of 3 correct is excluded
    assert result.low_m < 8.0  # P(8 m) < 0.95 is not excluded by 3 of 3
    assert result.limiting_cause == "resolution / merging"
    assert not result.at_least


def test_three_seeds_cannot_pin_the_fall_off():
    # the C270: 3 of 3 from 4 to 10 m, 2 of 3 at 12 m; the bootstrap said "11.1 (11.1-11.1)"
    rows = _counts({4.0: (3, 3), 6.0: (3, 3), 8.0: (3, 3), 10.0: (3, 3), 12.0: (2, 3)})
    result = estimate_max_range(rows)
    # 2 of 3 at 12 m does not exclude P(12 m) ≥ 0.95 (binomial test), so the interval passes 12 m
    assert stats.binomtest(2, 3, 0.95, alternative="less").pvalue > 0.05
    assert math.isinf(result.high_m)
    assert result.low_m < 10.0 and 10.0 <= result.max_range_m <= 12.0


def test_a_near_failure_zone_is_reported_and_does_not_hide_the_far_limit():
    # clipped cores fail at 1-2 m; from 3 m on the usual fall-off
    r50, s = 9.0, 0.5
    near = [{**x, "detected": True} for x in _frames(-100.0, 0.5, [1.0, 2.0], 40)]  # wrong colour
    result = estimate_max_range(near + _frames(r50, s, np.arange(3, 14.01, 0.5), 40, seed=1))
    truth = r50 - s * math.log(19)
    assert result.fitted_from_m == 3.0
    assert result.low_m <= truth <= result.high_m
    assert result.max_range_m == pytest.approx(truth, abs=0.5)
    assert (result.near_failures, result.near_frames, result.near_cause) == (80, 80, "colour")
    assert 2.0 < result.near_limit_m <= 3.0 and not result.near_at_most
    assert near_failures_text(result.to_dict()) == "80 of 80 frames nearer than 3 m fail (colour)"


def test_near_limit_of_a_known_rise_within_its_interval():
    # P rises as 1/(1 + exp(-(r - 3)/0.3)) and never falls within 2-10 m: near limit 3 + 0.3 ln 19
    rng = np.random.default_rng(7)
    rows = []
    for r in np.arange(2.0, 10.01, 0.5):
        p = 1 / (1 + math.exp(-(r - 3.0) / 0.3))
        rows += [_row(float(r), bool(rng.random() < p)) for _ in range(40)]
    result = estimate_max_range(rows)
    truth = 3.0 + 0.3 * LN19
    assert result.near_low_m <= truth <= result.near_high_m
    assert result.near_limit_m == pytest.approx(truth, abs=0.3)
    assert result.at_least and result.max_range_m == 10.0


def test_no_range_qualifies_when_the_best_rate_is_low():
    rows = _frames(-100.0, 0.5, [1.0, 2.0], 20) + _frames(2.0, 0.5, [3.0, 4.0, 5.0], 20, seed=2)
    result = estimate_max_range(rows)
    assert result.max_range_m == 0.0 and math.isnan(result.near_limit_m)
    assert working_range_text(result.to_dict()).startswith("none (fitted P < 0.95 at every range; best: ")


def test_no_success_at_all_bounds_the_limit_below_the_nearest_range():
    result = estimate_max_range(_counts({2.0: (0, 5), 4.0: (0, 5)}))
    assert result.max_range_m == 0.0 and result.high_m < 2.0
    assert far_interval_text(result.to_dict()) == "< 2 m"


def test_isolated_failures_give_no_extrapolated_range():
    rows = _frames(100.0, 0.5, [2.0, 4.0, 6.0, 8.0], 6)
    rows[7] = {**rows[7], "detected": False}  # one failure at 4 m
    result = estimate_max_range(rows)
    assert result.max_range_m <= 8.0 and math.isinf(result.high_m)


def test_a_correct_farthest_range_beyond_an_isolated_failure_is_said():
    # the main job's T6 at 30°: 3 of 3 to 8 m, 2 of 3 at 10 m (colour), 3 of 3 at 12 m
    rows = _counts({2.0: (3, 3), 4.0: (3, 3), 6.0: (3, 3), 8.0: (3, 3), 12.0: (3, 3)})
    rows += _counts({10.0: (2, 3)}, why="colour")
    result = estimate_max_range(rows).to_dict()
    assert (result["farthest_successes"], result["farthest_frames"]) == (3, 3)
    # the monotone fit ends between the last clean range and the failure; the text keeps the 12 m successes
    assert not result["at_least"] and 8.0 <= result["max_range_m"] < 10.0
    # plain words, no contradiction: 3 of 3 correct is likely even where P < 0.95 (0.9³ = 0.73 > 0.05),
    # so the 12 m frames cannot show P ≥ 0.95 there
    assert 0.9**3 > 0.05
    assert far_limit_text(result) == (
        f"{result['max_range_m']:.1f} m (failures between it and 12 m end it; the 3 frames at 12 m were all correct, "
        "too few to show P ≥ 0.95 there)"
    )
    assert math.isinf(result["high_m"])  # 2 of 3 at 10 m cannot exclude P(10 m) ≥ 0.95


def test_interval_coverage_with_three_frames_per_range():
    # 95 % intervals should hold the true near and far limits in about 95 % of studies even with 3 frames per point
    far_true, near_true = 7.5 - 0.5 * LN19, 1.5 + 0.2 * LN19
    hits_far = hits_near = 0
    reps = 60
    for seed in range(reps):
        rng = np.random.default_rng(seed)
        rows = []
        for nom in np.arange(1.0, 10.01, 1.0):
            for _ in range(3):
                r = nom * (1 + rng.uniform(-0.005, 0.005))
                p = 1 / (1 + math.exp((r - 7.5) / 0.5)) / (1 + math.exp(-(r - 1.5) / 0.2))
                rows.append(_row(r, bool(rng.random() < p), nominal=float(nom)))
        m = estimate_max_range(rows)
        hits_far += m.low_m <= far_true <= m.high_m
        hits_near += m.near_low_m <= near_true <= m.near_high_m
    # (the plain profile interval alone holds 50 of these 60 far limits: 0.83)
    assert hits_far / reps >= 0.92 and hits_near / reps >= 0.92


def test_profile_matches_a_direct_maximisation():
    rows = _frames(6.0, 0.7, np.arange(2.0, 10.01, 1.0), 8, seed=11)
    x = np.array([r["range_m"] for r in rows])
    y = np.array([r["detected"] for r in rows], dtype=bool)
    scale = float(np.ptp(x))
    limits = np.array([4.0, 4.6, 5.2])
    got, got_pen = profile_loglik(x, y, limits, scale), profile_loglik(x, y, limits, scale, penalised=True)
    for lim, value, value_pen in zip(limits, got, got_pen, strict=True):

        def loglik(log_s, lim=lim, penalised=False):
            p = 1 / (1 + np.exp(-((lim - x) / np.exp(log_s) + math.log(19))))
            ll = float(np.sum(np.where(y, np.log(p), np.log1p(-p))))
            if penalised:  # Firth: ½ log det of XᵀWX, X = [1, x], W = p(1 - p)
                design = np.column_stack([np.ones_like(x), x])
                ll += 0.5 * math.log(np.linalg.det(design.T @ (design * (p * (1 - p))[:, None])))
            return ll

        for pen, expected in ((False, value), (True, value_pen)):
            best = minimize_scalar(lambda t, pen=pen: -loglik(t, penalised=pen), bounds=(-4, 3), method="bounded")
            assert expected == pytest.approx(-best.fun, abs=1e-4)


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
    assert failure_cause({**base, "failure": "no-fit"}) == "colour box"  # no blob of the side's colour
    assert failure_cause({**base, "failure": "no-fit", "side_blobs": 9}) == "false blobs"
    assert failure_cause({**base, "failure": "no-blobs"}) == "signal-to-noise"
    assert failure_cause({**base, "detected": True, "side_correct": False}) == "colour"


@pytest.mark.parametrize("p_working", [0.8, 0.99])
def test_recovers_the_far_limit_at_another_working_level(p_working):
    """At level p the far limit is where the fall-off crosses p, r₅₀ − s·logit p (0.99: nearer than
    the 0.95 point, 0.8: farther); the record states its level and its words use it."""
    r50, s = 8.0, 0.6
    truth = r50 - s * math.log(p_working / (1 - p_working))
    rows = _frames(r50, s, np.arange(2, 14.01, 0.5), 40)
    result = estimate_max_range(rows, p_working=p_working)
    assert result.low_m <= truth <= result.high_m and result.max_range_m == pytest.approx(truth, abs=0.5)
    assert (result.max_range_m < estimate_max_range(rows).max_range_m) == (p_working > 0.95)
    assert result.to_dict()["p_working"] == p_working
    none = estimate_max_range(_counts({2.0: (1, 3), 4.0: (0, 3)}), p_working=p_working).to_dict()
    assert f"fitted P < {p_working:g} at every range" in working_range_text(none)
    with pytest.raises(ValueError, match=r"^p_working: expected a probability between 0.5 and 1"):
        estimate_max_range(rows, p_working=1.0)


def test_the_profile_at_another_level_matches_a_direct_maximisation():
    rows = _frames(6.0, 0.7, np.arange(2.0, 10.01, 1.0), 8, seed=12)
    x = np.array([r["range_m"] for r in rows])
    y = np.array([r["detected"] for r in rows], dtype=bool)
    limits = np.array([4.0, 5.0])
    for lim, value in zip(limits, profile_loglik(x, y, limits, float(np.ptp(x)), p_working=0.9), strict=True):

        def loglik(log_s, lim=lim):
            p = 1 / (1 + np.exp(-((lim - x) / np.exp(log_s) + math.log(9))))
            return float(np.sum(np.where(y, np.log(p), np.log1p(-p))))

        best = minimize_scalar(lambda t: -loglik(t), bounds=(-4, 3), method="bounded")
        assert value == pytest.approx(-best.fun, abs=1e-4)
