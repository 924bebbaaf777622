"""Study metrics against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from studies.engine.metrics import (
    confusion_matrix,
    delta_e_2000,
    fisher_d_prime,
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
