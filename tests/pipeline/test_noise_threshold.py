"""The best tracker's noise-aware threshold on frames of known noise: estimates against the analytic values.

:func:`pipeline.tracker.noise_threshold` takes the background's median and the upper half of
its interquartile range as σ, and puts the threshold k·σ above the median with
k = Φ⁻¹(1 − α/N). On Gaussian noise of known σ these have closed forms; the mean number of
noise pixels above the threshold is N·Q(z) for the threshold's distance z from the mean in σ
(after the 8-bit rounding), which a set of pure-noise frames checks as a Poisson count.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ndtri
from scipy.stats import norm, poisson

from pipeline.tracker import TrackerSettings, find_blobs, noise_threshold

MEAN, SIGMA = 30.0, 8.0  # codes
SHAPE = (1000, 1500)


def _noise(rng: np.random.Generator, grey: bool) -> np.ndarray:
    """A BGR uint8 frame of Gaussian noise (MEAN, SIGMA codes): one draw for all channels (grey) or one each."""
    if grey:
        x = np.rint(rng.normal(MEAN, SIGMA, SHAPE)).clip(0, 255).astype(np.uint8)
        return np.repeat(x[..., None], 3, axis=2)
    return np.rint(rng.normal(MEAN, SIGMA, (*SHAPE, 3))).clip(0, 255).astype(np.uint8)


def _analytic(grey: bool) -> tuple[float, float, float]:
    """Median, σ estimate and threshold the estimator should give: for the maximum of three
    independent channels the CDF is Φ³, so its quantile p is at Φ⁻¹(p^(1/3))."""
    q = (lambda p: norm.ppf(p)) if grey else (lambda p: norm.ppf(p ** (1 / 3)))
    med = MEAN + SIGMA * q(0.5)
    sigma = SIGMA * (q(0.75) - q(0.5)) / norm.ppf(0.75)
    k = ndtri(1 - 1 / (SHAPE[0] * SHAPE[1]))
    return med, sigma, med + k * sigma


@pytest.mark.parametrize("grey", [True, False], ids=["grey", "independent-channels"])
def test_threshold_estimate_and_planted_blobs(grey):
    rng = np.random.default_rng(3 if grey else 4)
    img = _noise(rng, grey)
    med, sigma, thr = _analytic(grey)
    got = noise_threshold(img.max(axis=2), 1.0)
    assert got[0] == pytest.approx(med, rel=0.01)
    assert got[1] == pytest.approx(sigma, rel=0.02)
    assert got[2] == pytest.approx(thr, rel=0.02)
    assert ndtri(1 - 1 / (5184 * 3456)) == pytest.approx(5.31, abs=0.005)  # the k quoted for the T6
    # K planted Gaussian spots, 60 codes above the mean at their peak, away from each other
    k_blobs = 12
    centres = np.column_stack([150 + 100 * np.arange(k_blobs) + 0.3, 200 + 50 * (np.arange(k_blobs) % 5) + 0.6])
    vv, uu = np.mgrid[: SHAPE[0], : SHAPE[1]]
    spots = np.zeros(SHAPE)
    for u, v in centres:
        spots += 60.0 * np.exp(-((uu - u) ** 2 + (vv - v) ** 2) / (2 * 2.0**2))
    img = np.clip(img.astype(np.float64) + spots[..., None] * [0.2, 0.3, 1.0], 0, 255).round().astype(np.uint8)
    blobs, reason = find_blobs(img, TrackerSettings())
    assert reason is None
    uv = np.array([(b.u, b.v) for b in blobs])
    dist = np.hypot(*(uv[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    assert np.all(dist.min(axis=0) < 0.5)  # every planted blob, at its centre
    # the rest are noise pixels above the threshold: a Poisson count of mean N·P(max > threshold)
    z = (np.floor(got[2]) + 0.5 - MEAN) / SIGMA
    p_above = norm.sf(z) if grey else 1 - norm.cdf(z) ** 3
    extra = len(blobs) - k_blobs
    assert extra <= poisson.ppf(0.999, img.shape[0] * img.shape[1] * p_above), (extra, p_above)


def test_false_alarm_count_is_the_gaussian_tail():
    """20 grey noise frames: noise pixels above the threshold, summed, against the Poisson count
    of mean Σ N·Q(z), z = (last code below the threshold + ½ − mean)/σ (the codes are rounded)."""
    rng = np.random.default_rng(11)
    counts, expected = 0, 0.0
    for _ in range(20):
        img = _noise(rng, True)
        y = img[..., 0]
        _, _, thr = noise_threshold(y, 1.0)
        counts += int((y > np.floor(thr)).sum())
        expected += y.size * norm.sf((np.floor(thr) + 0.5 - MEAN) / SIGMA)
    lo, hi = poisson.ppf([0.005, 0.995], expected)
    assert lo <= counts <= hi, (counts, expected)
    assert 5 < expected < 40  # about α = 1 per frame, less the rounding up to the next code


def test_a_lit_scene_is_not_taken_for_noise():
    """A lit room: the brightness varies across the frame (a ramp of 100 codes and a bright
    window) on top of Gaussian noise of σ = 8 codes. σ is the noise's (2 %), and LEDs clipped
    at code 255 are found at their centres; measured over the whole image, σ is the scene's
    spread (~40 codes, as on a lit-room Spedal 920 frame) and the threshold lies above full scale: no blob at all."""
    rng = np.random.default_rng(5)
    vv, uu = np.mgrid[: SHAPE[0], : SHAPE[1]]
    scene = 100.0 * uu / SHAPE[1] + 60.0 * ((uu > 1100) & (vv < 300))
    centres = np.column_stack([200 + 110 * np.arange(10) + 0.4, 500 + 60 * (np.arange(10) % 4) + 0.7])
    for u, v in centres:
        scene = np.maximum(scene, 400.0 * np.exp(-((uu - u) ** 2 + (vv - v) ** 2) / (2 * 2.5**2)))
    y = np.rint(scene + rng.normal(MEAN, SIGMA, SHAPE)).clip(0, 255).astype(np.uint8)
    _, sigma, _ = noise_threshold(y, 1.0)
    assert sigma == pytest.approx(SIGMA, rel=0.02)
    upper = np.quantile(y, 0.75) - np.quantile(y, 0.5)
    assert upper / norm.ppf(0.75) > 4 * SIGMA  # the whole image's spread: what frame versions 6-9 took for σ
    blobs, reason = find_blobs(np.repeat(y[..., None], 3, axis=2), TrackerSettings())
    assert reason is None
    uv = np.array([(b.u, b.v) for b in blobs])
    dist = np.hypot(*(uv[:, None, :] - centres[None, :, :]).transpose(2, 0, 1))
    assert np.all(dist.min(axis=0) < 0.5)
