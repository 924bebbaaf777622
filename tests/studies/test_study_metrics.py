"""Study metrics against independent references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import quad
from scipy.optimize import brentq

from studies.engine.metrics import (
    bayes_error,
    confusion_matrix,
    delta_e_2000,
    fisher_d_prime,
    jeffreys_interval,
    mahalanobis_separability,
    merge_margin_px,
    wilson_interval,
)


@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (10, 10), (95, 100), (1, 1)])
def test_wilson_matches_scipy(k, n):
    p, lo, hi = wilson_interval(k, n)
    ref = stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert p == k / n and lo == pytest.approx(ref.low, abs=1e-12) and hi == pytest.approx(ref.high, abs=1e-12)


def test_separability_of_known_gaussians():
    rng = np.random.default_rng(1)
    a = rng.normal([0.0, 0.0], 1.0, size=(20000, 2))
    b = rng.normal([3.0, 4.0], 1.0, size=(20000, 2))
    assert mahalanobis_separability(a, b) == pytest.approx(5.0, rel=0.02)
    assert fisher_d_prime(a[:, 0], b[:, 0]) == pytest.approx(3.0, rel=0.02)
    assert mahalanobis_separability(a[:, :1], b[:, :1]) == pytest.approx(fisher_d_prime(a[:, 0], b[:, 0]), rel=1e-3)


def test_perfectly_separated_samples_are_infinitely_apart():
    # two colours that never vary: a pseudo-inverse of the zero covariance would call them 0 apart
    a, b = np.tile([0.6, 0.3], (10, 1)), np.tile([0.2, 0.7], (10, 1))
    assert mahalanobis_separability(a, b) == math.inf
    assert fisher_d_prime(a[:, 0], b[:, 0]) == math.inf and fisher_d_prime(a[:, 0], a[:, 0]) == 0.0
    # varying only along x but differing along y (where neither varies): still perfectly separated
    rng = np.random.default_rng(2)
    a = np.column_stack([rng.normal(0, 1, 50), np.zeros(50)])
    b = np.column_stack([rng.normal(0, 1, 50), np.ones(50)])
    assert mahalanobis_separability(a, b) == math.inf
    # differing only along the varying x: the 1-D distance, the flat y direction ignored
    b = np.column_stack([rng.normal(3, 1, 50), np.zeros(50)])
    assert mahalanobis_separability(a, b) == pytest.approx(fisher_d_prime(a[:, 0], b[:, 0]), rel=1e-9)
    assert mahalanobis_separability(a[:1], b) != mahalanobis_separability(a[:1], b)  # nan: one point


def test_bayes_error_of_gaussian_classes():
    # two unit-variance 1-D Gaussians 2 apart, threshold midway: error = P(N(0,1) > 1) = 0.158655…
    assert bayes_error(2.0) == pytest.approx(0.15865525393145707, rel=1e-12)
    assert bayes_error(0.0) == pytest.approx(0.5) and bayes_error(math.inf) == 0.0


@pytest.mark.parametrize(("k", "n"), [(0, 3), (2, 3), (3, 3), (14, 15), (7, 40)])
def test_jeffreys_interval_against_the_integrated_posterior(k, n):
    # the posterior density ∝ p^(k − ½) (1 − p)^(n − k − ½), integrated numerically; its 2.5 / 97.5 % points
    def density(p):
        return p ** (k - 0.5) * (1 - p) ** (n - k - 0.5)

    total = quad(density, 0, 1)[0]

    def quantile(q):
        return brentq(lambda x: quad(density, 0, x)[0] / total - q, 1e-12, 1 - 1e-12)

    mean, low, high = (float(v) for v in jeffreys_interval(k, n))
    assert mean == pytest.approx(quad(lambda p: p * density(p), 0, 1)[0] / total, rel=1e-6)
    assert low == (0.0 if k == 0 else pytest.approx(quantile(0.025), abs=1e-6))
    assert high == (1.0 if k == n else pytest.approx(quantile(0.975), abs=1e-6))


def test_jeffreys_interval_rejects_impossible_counts():
    with pytest.raises(ValueError, match="successes"):
        jeffreys_interval(4, 3)


def test_delta_e_2000_reference_pair():
    # Sharma, Wu & Dalal (2005) test data, pair 1: Lab (50, 2.6772, -79.7751) vs (50, 0, -82.7485): ΔE00 = 2.0425
    import colour

    lab1, lab2 = np.array([50.0, 2.6772, -79.7751]), np.array([50.0, 0.0, -82.7485])
    srgb = [colour.XYZ_to_sRGB(colour.Lab_to_XYZ(lab)) for lab in (lab1, lab2)]
    assert delta_e_2000(*srgb) == pytest.approx(2.0425, abs=2e-3)


def test_confusion_matrix_counts_misses_in_last_column():
    m = confusion_matrix(["red", "red", "green"], ["red", None, "red"], ["red", "green"])
    assert m.tolist() == [[1, 0, 1], [1, 0, 0]]


def test_merge_margin():
    uv = [[0, 0], [10, 0], [0, 25]]
    assert merge_margin_px(uv, 4.0) == pytest.approx(6.0)
