"""Metrics of the studies, each defined in its docstring.

All functions are pure: arrays or plain rows in, numbers out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import beta, norm

__all__ = [
    "bayes_error",
    "confusion_matrix",
    "delta_e_2000",
    "fisher_d_prime",
    "jeffreys_interval",
    "mahalanobis_separability",
    "marker_snr",
    "merge_margin_px",
    "rgb_chromaticity",
    "wilson_interval",
    "wilson_intervals",
]


# -- detection ---------------------------------------------------------------------------
def wilson_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float, float]:
    """Proportion with its Wilson score interval.

    p̂ = k/n; interval (p̃ ± z√(p̂(1−p̂)/n + z²/4n²)) / (1 + z²/n) with p̃ = p̂ + z²/2n and z
    the normal quantile of (1 + confidence)/2. Good coverage even for p near 0 or 1,
    unlike the Wald interval. Returns (p̂, low, high); (nan, 0, 1) for n = 0.
    """
    if trials < 0 or not 0 <= successes <= trials:
        raise ValueError(f"successes: expected 0 <= successes <= trials, got {successes}/{trials}")
    p, low, high = wilson_intervals(np.array([successes]), np.array([trials]), confidence)
    return float(p[0]), float(low[0]), float(high[0])


def wilson_intervals(
    successes: ArrayLike, trials: ArrayLike, confidence: float = 0.95
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`wilson_interval` for arrays of counts (checked by the caller): (p̂, low, high)."""

    k = np.asarray(successes, dtype=np.float64)
    n = np.asarray(trials, dtype=np.float64)
    z = float(norm.ppf(0.5 + confidence / 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        denom = 1 + z * z / n
        centre = (p + z * z / (2 * n)) / denom
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    empty = n == 0
    return (
        np.where(empty, np.nan, p),
        np.where(empty, 0.0, np.maximum(0.0, centre - half)),
        np.where(empty, 1.0, np.minimum(1.0, centre + half)),
    )


def jeffreys_interval(
    successes: ArrayLike, trials: ArrayLike, confidence: float = 0.95
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Posterior of a success probability per point: Beta(k + ½, n − k + ½), the posterior
    under Jeffreys' prior Beta(½, ½), with its equal-tailed credible interval (Brown, Cai
    & DasGupta 2001: low = 0 when k = 0, high = 1 when k = n).

    Parameters
    ----------
    successes, trials : counts k and n per point (arrays or scalars, 0 ≤ k ≤ n).
    confidence : probability inside the interval.

    Returns
    -------
    (posterior mean, low, high) per point; (nan, 0, 1) where n = 0.
    """
    k = np.asarray(successes, dtype=np.float64)
    n = np.asarray(trials, dtype=np.float64)
    if np.any(k < 0) or np.any(k > n):
        raise ValueError(f"successes: expected 0 <= successes <= trials, got {k.tolist()}/{n.tolist()}")
    a, b = k + 0.5, n - k + 0.5
    tail = (1.0 - confidence) / 2
    empty = n == 0
    mean = np.where(empty, np.nan, a / (a + b))
    low = np.where((k == 0) | empty, 0.0, beta.ppf(tail, a, b))
    high = np.where((k == n) | empty, 1.0, beta.ppf(1.0 - tail, a, b))
    return mean, low, high


# -- colour ------------------------------------------------------------------------------
def rgb_chromaticity(rgb_linear: ArrayLike) -> NDArray[np.float64]:
    """Chromaticity (r, g) = (R, G) / (R + G + B) of linear RGB values, shape (..., 2)."""
    rgb = np.asarray(rgb_linear, dtype=np.float64)
    total = rgb.sum(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        chroma = np.where(total > 0, rgb[..., :2] / total, np.nan)
    return chroma


def fisher_d_prime(a: ArrayLike, b: ArrayLike) -> float:
    """Fisher's discriminability d′ of two 1-D samples: |μa − μb| / √((σa² + σb²)/2);
    inf when both samples are constant (σ below 1e-12 of their magnitude) and differ, 0
    when they are constant and equal."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    pooled = math.sqrt((a.var(ddof=1) + b.var(ddof=1)) / 2)
    diff = abs(a.mean() - b.mean())
    if pooled > 1e-12 * max(float(np.abs(a).max()), float(np.abs(b).max()), 1.0):
        return diff / pooled
    return math.inf if diff > 0 else 0.0


def mahalanobis_separability(a: ArrayLike, b: ArrayLike) -> float:
    """Mahalanobis distance between the means of two samples (n, d) under their pooled
    covariance: √((μa − μb)ᵀ Σ⁻¹ (μa − μb)). Equal to d′ in 1-D; the Bayes error of two
    equal-covariance Gaussians is Φ(−distance/2) (:func:`bayes_error`).

    A direction in which neither sample varies (a zero eigenvalue of Σ, below 1e-12 of the
    largest or of 1) separates them perfectly if their means differ along it: the distance
    is then inf, not the 0 a pseudo-inverse would give. nan with fewer than 2 points in a
    sample.
    """
    a, b = np.atleast_2d(np.asarray(a, float)), np.atleast_2d(np.asarray(b, float))
    if a.shape[0] < 2 or b.shape[0] < 2:
        return math.nan
    diff = a.mean(axis=0) - b.mean(axis=0)
    pooled = ((a.shape[0] - 1) * np.cov(a, rowvar=False) + (b.shape[0] - 1) * np.cov(b, rowvar=False)) / (
        a.shape[0] + b.shape[0] - 2
    )
    values, vectors = np.linalg.eigh(np.atleast_2d(pooled))
    along = vectors.T @ diff  # the mean difference in the covariance's eigenbasis
    flat = values <= 1e-12 * max(float(values.max()), 1.0)
    scale = max(float(np.abs(a).max()), float(np.abs(b).max()), 1.0)
    if np.any(np.abs(along[flat]) > 1e-9 * scale):
        return math.inf
    return float(math.sqrt(np.sum(along[~flat] ** 2 / values[~flat])))


def bayes_error(distance: float) -> float:
    """Error rate of the best classifier of two equal-covariance Gaussian classes with equal
    priors whose means are ``distance`` apart in Mahalanobis units: Φ(−distance/2)
    (0 for an infinite distance)."""
    return float(norm.cdf(-distance / 2)) if math.isfinite(distance) else 0.0


def delta_e_2000(srgb_a: ArrayLike, srgb_b: ArrayLike) -> float:
    """CIEDE2000 colour difference between two mean sRGB colours (components 0-1, encoded),
    through CIE XYZ and L*a*b* (D65) with colour-science."""

    lab = [colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.asarray(c, float))) for c in (srgb_a, srgb_b)]
    return float(colour.delta_E(lab[0], lab[1], method="CIE 2000"))


def confusion_matrix(true: Sequence[str], predicted: Sequence[str | None], labels: Sequence[str]) -> NDArray[np.int64]:
    """Counts[i, j] of frames of true class labels[i] classified as labels[j]; a last
    column counts frames with no (or an unknown) class."""
    index = {c: i for i, c in enumerate(labels)}
    out = np.zeros((len(labels), len(labels) + 1), dtype=np.int64)
    for t, p in zip(true, predicted, strict=True):
        out[index[t], index.get(p, len(labels)) if p is not None else len(labels)] += 1
    return out


# -- marker signal -----------------------------------------------------------------------
def marker_snr(signal_e: float, pixels: int, read_noise_e: float, dark_e: float = 0.0) -> float:
    """Signal-to-noise ratio of a marker's summed signal: S / √(S + n·(σ_read² + dark)),
    with S the electrons above background summed over ``pixels`` pixels (shot noise of
    the signal, read noise and dark shot noise of every pixel)."""
    noise = math.sqrt(max(signal_e, 0.0) + pixels * (read_noise_e**2 + dark_e))
    return signal_e / noise if noise > 0 else math.inf


def merge_margin_px(marker_uv: ArrayLike, blob_diameter_px: float) -> float:
    """Smallest centre-to-centre distance between markers minus the blob diameter, px:
    negative when neighbouring blobs touch (the study's morphology merges them)."""
    uv = np.asarray(marker_uv, float)
    d = np.hypot(*(uv[:, None, :] - uv[None, :, :]).transpose(2, 0, 1))
    d[np.eye(len(uv), dtype=bool)] = np.inf
    return float(d.min() - blob_diameter_px)
