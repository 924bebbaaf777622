"""Wheel odometry's error model and the planar EKF against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.ekf import predict, update
from pipeline.odometry import WheelOdometry


def test_slip_over_counts_by_s_over_one_minus_s_and_the_noise_grows_with_the_root_of_distance():
    odo = WheelOdometry(slip=0.2, scale_sd=0.05, heading_sd_rad=0.02)
    d, turn = odo.report(np.full(20000, 0.5), np.zeros(20000), seed=3)
    assert odo.bias == pytest.approx(0.25)
    assert d.mean() == pytest.approx(0.5 * 1.25, abs=4 * 0.05 * math.sqrt(0.5) / math.sqrt(20000))
    assert d.std() == pytest.approx(0.05 * math.sqrt(0.5), rel=0.03)  # σ_d √d
    assert turn.std() == pytest.approx(0.02 * math.sqrt(0.5), rel=0.03)
    assert odo.step_covariance(0.5)[0, 0] == pytest.approx(0.05**2 * 0.5 + (0.25 * 0.5) ** 2)
    with pytest.raises(ValueError, match=r"slip: expected a slip ratio in \[0, 1\), got 1.0"):
        WheelOdometry(slip=1.0)


def test_a_wandering_slip_is_an_ornstein_uhlenbeck_process_of_the_stated_sd_and_correlation():
    """Far from the clip (s̄ = 0.5, σ_s = 0.05): stationary sd σ_s, autocorrelation exp(−Δx/ℓ) at Δx = ℓ and
    2ℓ, and the odometer's report of each step d / (1 − s) for that step's own slip."""
    odo = WheelOdometry(slip=0.5, scale_sd=0.0, heading_sd_rad=0.0, slip_sd=0.05, slip_correlation_m=5.0)
    step, n = 0.25, 200
    runs = np.array([odo.slip_along(np.full(n, step), seed=k) for k in range(2000)])  # 2000 runs of 50 m
    z = (runs - 0.5) / 0.05
    assert z.std() == pytest.approx(1.0, abs=0.02)
    assert abs(z.mean()) < 0.03
    for lag_m in (5.0, 10.0):
        lag = round(lag_m / step)
        assert np.mean(z[:, :-lag] * z[:, lag:]) == pytest.approx(math.exp(-lag_m / 5.0), abs=0.03)
    assert odo.scale_walk_per_m == pytest.approx(2 * 0.05**2 / 5.0)
    d, _ = odo.report(np.full(n, step), np.zeros(n), seed=7)
    assert d == pytest.approx(step / (1 - odo.slip_along(np.full(n, step), seed=7)), rel=1e-12)
    steady = WheelOdometry(slip=0.3, scale_sd=0.05, heading_sd_rad=0.02)
    same = WheelOdometry(slip=0.3, scale_sd=0.05, heading_sd_rad=0.02, slip_correlation_m=3.0)
    steps = np.full(n, step)
    assert (steady.slip_along(steps, seed=1) == 0.3).all() and steady.scale_walk_per_m == 0
    assert np.array_equal(steady.report(steps, np.zeros(n), seed=1)[0], same.report(steps, np.zeros(n), seed=1)[0])
    with pytest.raises(ValueError, match=r"slip_correlation_m: expected a length > 0 m, got 0.0"):
        WheelOdometry(slip_sd=0.1, slip_correlation_m=0.0)


def test_predict_accumulates_a_straight_drive_as_the_sum_of_its_steps():
    """n steps of d along x with length variance q: x = n d, Var x = n q, and a heading variance h per step
    spreads y by Σ (distance still to go)² h (the heading error of step k moves every later step)."""
    x, p = np.zeros(3), np.zeros((3, 3))
    n, d, q, h = 40, 0.25, 1e-4, 1e-5
    for _ in range(n):
        x, p = predict(x, p, d, 0.0, np.diag([q, h]))
    assert x == pytest.approx([n * d, 0.0, 0.0])
    assert p[0, 0] == pytest.approx(n * q)
    # step k's heading noise: half a step's lever on its own step (mid-step heading), then a full lever on the rest
    lever = sum(((k + 0.5) * d) ** 2 for k in range(n))
    assert p[1, 1] == pytest.approx(h * lever, rel=1e-9)
    assert p[2, 2] == pytest.approx(n * h)


def test_a_turn_moves_along_the_mid_step_heading():
    x, _ = predict(np.array([1.0, 2.0, 0.3]), np.zeros((3, 3)), 2.0, 0.4, np.zeros((2, 2)))
    assert x == pytest.approx([1.0 + 2 * math.cos(0.5), 2.0 + 2 * math.sin(0.5), 0.7])


def test_an_update_is_the_information_weighted_mean():
    """With the whole state observed, the posterior is (P⁻¹ + R⁻¹)⁻¹ and its mean the information-weighted
    mean of prior and fix (independent closed form); a heading across ±π is averaged across it."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    p, r = a @ a.T + np.eye(3) * 0.1, b @ b.T + np.eye(3) * 0.1
    x, z = np.array([1.0, 2.0, 0.1]), np.array([1.5, 1.0, -0.2])
    new, cov = update(x, p, z, r)
    info = np.linalg.inv(p) + np.linalg.inv(r)
    assert cov == pytest.approx(np.linalg.inv(info), abs=1e-12)
    assert new == pytest.approx(np.linalg.solve(info, np.linalg.solve(p, x) + np.linalg.solve(r, z)), abs=1e-12)
    wrapped, _ = update(np.array([0.0, 0.0, math.pi - 0.1]), np.eye(3), np.array([0.0, 0.0, -math.pi + 0.1]), np.eye(3))
    assert abs(abs(wrapped[2]) - math.pi) < 1e-12


def test_the_scale_state_learns_the_slip_and_keeps_the_filter_consistent():
    """Straight drive on a planted slip (true length 0.7 of the reported), exact fixes every 2 m: the
    four-state filter's scale converges to 0.7 within 1 %, and between fixes its error stays within
    3σ of its own covariance (the three-state filter's bias-as-noise claim does not)."""
    from pipeline.ekf import mahalanobis2, predict, update
    from pipeline.odometry import scale_prior

    k_true, step = 0.7, 0.25
    mean, sd = scale_prior()
    x, p = np.array([0.0, 0.0, 0.0, mean]), np.diag([1e-6, 1e-6, 1e-8, sd**2])
    truth = np.zeros(3)
    worst = 0.0
    for i in range(1, 81):
        truth = truth + np.array([k_true * step, 0.0, 0.0])
        x, p = predict(x, p, step, 0.0, np.diag([1e-8, 1e-10]))
        if i % 8 == 0:
            worst = max(worst, mahalanobis2(x, p, truth, np.diag([1e-4, 1e-4, 1e-6])))
            x, p = update(x, p, truth, np.diag([1e-4, 1e-4, 1e-6]))
    assert x[3] == pytest.approx(k_true, rel=0.01)
    assert worst < 11.3  # χ²₃ at 0.99
