"""A better marker tracker: sub-pixel centroids, saturation-tolerant colour, geometric selection.

Steps, on a BGR image (8-bit values are taken as sRGB-encoded and linearised; 16-bit and
float as linear):

1. Brightness y = max over channels (each colour's strongest channel counts). Background
   = median of y and noise = 1.4826·MAD (on a subsample); pixels above
   background + max(k·noise, min_contrast) and above the noise-aware threshold
   (:func:`noise_threshold`: the median plus k·σ of the pixel noise, σ measured in small
   tiles so the scene's own brightness variation is not taken for noise, k from the
   Gaussian false-alarm rate over the frame's pixels, so a dark ISO 6400 whole frame gives
   its few real blobs instead of ~45 000 noise components) form 8-connected blobs. 8-bit
   images are thresholded on their codes (the same pixels as on the linearised values).
2. Each blob's centroid is the (y − background)-weighted mean of its pixels: unbiased for
   any symmetric spot, including a clipped (flat-topped) one, and sub-pixel accurate.
3. Colour: chromaticity (r, g) = (R, G)/(R + G + B) of the background-subtracted,
   *unsaturated* pixels of the blob and a 3-px ring around it, so a white, clipped core
   is skipped and its coloured fringe decides. Classified by Mahalanobis distance to
   per-colour references (:class:`ColourModel`), which :func:`calibrate_colours` measures
   from reference captures; a blob far from every reference has no colour.
4. Per colour, among its brightest blobs, every 5-subset is numbered as a cross
   (:func:`pipeline.markers.cross_candidates`), screened with cheap image-plane tests and
   fitted by PnP with the camera's intrinsics; the subset with the smallest reprojection
   RMS below ``max(fit_rms_px, fit_rms_rel·size)`` is the target. Extra blobs
   (reflections, other sides, lamps) are thus ignored. The search is a branch and bound:
   a lower bound on each candidate's RMS from its image-space shape alone
   (:func:`rms_lower_bounds`) orders the fits and skips every candidate that cannot beat
   the best fit found (or, for a colour that fails, cannot be accepted), so the answer is
   the full search's with a few PnP fits instead of hundreds; fits are shared by the
   searches of one frame.
5. If no colour fits, every blob is tried regardless of colour (the side is then the
   majority colour of the five, or unknown); otherwise the reason says which colour came
   closest and whether markers look merged (a blob much larger than the others) or lost.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import colour as colour_science
import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtri

from pipeline.angles import Intrinsics
from pipeline.components import components
from pipeline.failures import Failure
from pipeline.image_io import as_bgr, to_float
from pipeline.markers import Blob, TrackResult, cross_candidates_many
from pipeline.pnp import solve_pnp
from scenes import spectra
from scenes.beacon import BeaconDesign, beacon_design
from scenes.led import LED, SIDE_COLOURS

__all__ = [
    "DEFAULT_CHROMA",
    "NOISE_SUBSAMPLE_PX",
    "NOISE_TILE_PX",
    "ColourModel",
    "TrackerSettings",
    "best_five",
    "calibrate_colours",
    "cross_dimensions",
    "find_blobs",
    "ideal_chroma",
    "noise_threshold",
    "rms_lower_bounds",
    "srgb_to_linear",
    "subsample_step",
    "track",
]

DEFAULT_CHROMA = {
    "red": (1.0, 0.0),
    "green": (0.0, 1.0),
    "blue": (0.0, 0.0333),
    "yellow": (0.8361, 0.1639),
}
"""(r, g) chromaticity of each default LED's spectrum (``scenes.led``) through the CIE 1931
observer into linear sRGB, negatives clipped (:func:`ideal_chroma`): what an ideal sRGB camera
would record. Real cameras differ (crosstalk, white balance); calibrate with
:func:`calibrate_colours`."""


@lru_cache(maxsize=64)
def ideal_chroma(led: LED) -> tuple[float, float]:
    """(r, g) = (R, G)/(R + G + B) an ideal sRGB camera records for the LED's light: its spectrum
    (:attr:`scenes.led.LED.spectral_shape`) through the CIE 1931 2° observer to XYZ, to linear sRGB
    (IEC 61966-2-1 primaries and D65 white), negatives clipped; rounded to 4 decimals, as
    :data:`DEFAULT_CHROMA` tabulates the default parts.

    >>> from scenes.led import led_for_side
    >>> ideal_chroma(led_for_side("yellow"))
    (0.8361, 0.1639)
    """
    cmfs = spectra.cie1931_cmfs().values
    xyz = spectra.integrate_nm(led.spectral_shape[:, None] * cmfs, axis=0)
    srgb = colour_science.RGB_COLOURSPACES["sRGB"]
    rgb = np.clip(colour_science.XYZ_to_RGB(xyz, srgb, apply_cctf_encoding=False), 0.0, None)
    r, g = rgb[:2] / rgb.sum()
    return round(float(r), 4), round(float(g), 4)


def srgb_to_linear(values: NDArray) -> NDArray:
    """Decode sRGB-encoded values in [0, 1] to linear."""
    v = np.asarray(values, dtype=np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


@dataclass(frozen=True)
class ColourModel:
    """Reference chromaticities (r, g) per colour, with their spread.

    Attributes
    ----------
    means
        Colour → (r, g) mean.
    covariances
        Colour → 2×2 covariance of (r, g).
    max_distance
        Largest Mahalanobis distance still classified.
    """

    means: dict[str, tuple[float, float]]
    covariances: dict[str, NDArray[np.float64]]
    max_distance: float = 6.0

    @classmethod
    def default(cls) -> ColourModel:
        """The ideal-sRGB references of :data:`DEFAULT_CHROMA` with a loose 0.1 spread."""
        return cls._ideal(dict(DEFAULT_CHROMA))

    @classmethod
    def for_beacon(cls, name: str) -> ColourModel:
        """The ideal-sRGB references (:func:`ideal_chroma`) of the beacon's own LEDs, each side's part at
        its dominant wavelength (:meth:`scenes.beacon.BeaconDesign.led`), with the loose 0.1 spread of
        :meth:`default`; for a beacon of the default parts at their datasheet colours, :meth:`default`."""
        design = beacon_design(name)
        return cls._ideal({side: ideal_chroma(design.led(side)) for side in SIDE_COLOURS})

    @classmethod
    def _ideal(cls, means: dict[str, tuple[float, float]]) -> ColourModel:
        cov = 0.1**2 * np.eye(2)
        return cls(means, {c: cov for c in means}, max_distance=4.0)

    def classify(self, chroma: tuple[float, float] | None) -> tuple[str | None, float]:
        """Nearest colour and its Mahalanobis distance, or (None, distance) when too far."""
        if chroma is None:
            return None, float("inf")
        best, best_d = None, float("inf")
        x = np.asarray(chroma, dtype=np.float64)
        for colour, mean in self.means.items():
            d = x - np.asarray(mean)
            dist = float(np.sqrt(d @ np.linalg.solve(self.covariances[colour], d)))
            if dist < best_d:
                best, best_d = colour, dist
        return (best, best_d) if best_d <= self.max_distance else (None, best_d)

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "means": {c: list(m) for c, m in self.means.items()},
            "covariances": {c: np.asarray(v).tolist() for c, v in self.covariances.items()},
            "max_distance": self.max_distance,
        }


@dataclass(frozen=True)
class TrackerSettings:
    """Parameters of the better tracker.

    Attributes
    ----------
    colour_model
        Chromaticity references; None uses the beacon's (:meth:`ColourModel.for_beacon`).
    beacon
        Target design for the geometric fit.
    threshold_sigma
        Detection threshold above the background, in noise σ.
    min_contrast
        Smallest threshold above the background, units of full scale.
    saturation_level
        A channel at or above this (full-scale units) counts as clipped.
    ring_px
        Width of the ring around a blob used for its colour, px.
    false_alarm_pixels
        The threshold is also at least the background's median plus k·σ of its noise, both
        measured on the image (:func:`noise_threshold`), with k such that a Gaussian background
        puts this many pixels above it per image on average (k = 5.31 for the T6's 17.9-Mpx frame).
    max_blobs
        At most this many blobs (largest first) are measured.
    max_candidates
        Brightest blobs per colour searched for the 5 markers.
    fit_rms_px, fit_rms_rel
        A 5-subset fits the target when its PnP reprojection RMS is at most
        max(fit_rms_px, fit_rms_rel × the target's image size).
    linearise_8bit
        Decode 8-bit images as sRGB before weighting.
    prune
        Skip the PnP fit of 5-subsets whose image-space shape proves they cannot beat the
        best fit found so far (:func:`best_five`); the answer is the same. False fits every
        candidate (the reference search).
    """

    colour_model: ColourModel | None = None
    beacon: str = "v2"
    threshold_sigma: float = 8.0
    min_contrast: float = 0.02
    false_alarm_pixels: float = 1.0
    saturation_level: float = 0.98
    ring_px: int = 3
    max_blobs: int = 400
    max_candidates: int = 10
    fit_rms_px: float = 1.0
    fit_rms_rel: float = 0.02
    linearise_8bit: bool = True
    prune: bool = True

    def model(self) -> ColourModel:
        """The colour model in use."""
        return self.colour_model or ColourModel.for_beacon(self.beacon)


@dataclass
class _Fit:
    rms_px: float
    uv: NDArray[np.float64]
    blobs: list[Blob] = field(default_factory=list)
    settled: bool = True  # False: a failed search stopped early, rms_px is only an upper bound


def _linear_lut(dtype, s: TrackerSettings) -> NDArray[np.float32] | None:
    if dtype == np.uint8:
        lut = np.arange(256, dtype=np.float32) / 255.0
        return srgb_to_linear(lut) if s.linearise_8bit else lut
    if dtype == np.uint16:
        return np.arange(65536, dtype=np.float32) / 65535.0
    return None


def _to_linear(arr: NDArray, lut: NDArray[np.float32] | None) -> NDArray[np.float32]:
    # integer images go through a look-up table with an entry per code (np.take without its bounds
    # check: ~3x faster than lut[arr] on an 18-Mpx frame)
    return np.take(lut, arr, mode="clip") if lut is not None else to_float(arr)


NOISE_TILE_PX = 32
"""Side of the square tiles :func:`noise_threshold` measures the noise in, in pixels of its subsample."""
NOISE_SUBSAMPLE_PX = 500_000
"""About this many pixels (every s-th row and column) are enough for the noise's statistics."""


def subsample_step(pixels: int, target: int) -> int:
    """Take every s-th row and column of an image of ``pixels`` pixels to keep about ``target``;
    s is odd, so the subsample holds all four sites of a 2 × 2 colour filter array (an even s
    keeps only one: on a demosaiced Spedal 920 dark frame the tiles' σ came out 7 % low).

    >>> subsample_step(17_915_904, 500_000), subsample_step(2_073_600, 500_000), subsample_step(921_600, 500_000)
    (5, 3, 1)
    """
    step = max(1, int(np.sqrt(pixels / target)))
    return step if step % 2 else step + 1


def noise_threshold(codes: NDArray, false_alarm_pixels: float) -> tuple[float, float, float]:
    """Background, noise σ and the noise-aware threshold of a brightness image, in its own units.

    The background is the image's median. σ is the noise's, not the scene's: the median over
    tiles (:data:`NOISE_TILE_PX` square, on a subsample of about :data:`NOISE_SUBSAMPLE_PX`
    pixels, :func:`subsample_step`) of each tile's upper half-width (q₇₅ − q₅₀)/Φ⁻¹(0.75), the upper half of a
    Gaussian's interquartile range. A tile holds a patch of nearly constant scene, so its spread
    is the pixel noise; tiles across an edge or a lamp are outvoted. This is the background mesh
    of SExtractor (Bertin & Arnouts 1996, A&AS 117, 393) reduced to one σ. Measured over the
    whole image instead (frame versions 6-9), σ was the lit room's brightness variation (a
    Spedal 920 frame of the lit room at 2 m: 37 codes, the tiles' median 14.7), the threshold went
    above full scale and no blob was found. False blobs are the upper tail's; the lower half of
    a dark frame is squeezed by the maximum over channels and clipped at code 0 (measured on a
    T6 ISO 6400 dark whole frame: lower half-width 10.5 codes, upper 14.1, and above the
    threshold below the upper tail of a Gaussian of that σ to within 4 %). The threshold is the
    median plus k·σ with k = Φ⁻¹(1 − α/N) for the N pixels of the image: a Gaussian background
    then puts α pixels above it on average (α = ``false_alarm_pixels``; k = 5.31 for the T6's
    17.9 Mpx, 4.74 for the C270's 0.92 Mpx at α = 1).

    Integer codes are counted as spread over their unit width, so the quantiles are not stuck on
    integers (the median from the whole image's histogram, each tile's quantiles from its sorted
    codes).

    Parameters
    ----------
    codes
        2-D brightness image (uint8, uint16 or float).
    false_alarm_pixels
        α: the mean number of background pixels above the threshold, pixels per image.

    Returns
    -------
    tuple
        (median, σ, threshold), in the units of ``codes``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> ramp = np.linspace(0.0, 150.0, 1500)[None, :]  # a lit wall: brightness varies across the frame
    >>> y = np.rint(ramp + rng.normal(30.0, 8.0, (1000, 1500))).clip(0, 255).astype(np.uint8)
    >>> median, sigma, threshold = noise_threshold(y, 1.0)
    >>> round(sigma)  # the noise's 8 codes, not the ramp's spread
    8
    """
    n = codes.size
    step = subsample_step(n, NOISE_SUBSAMPLE_PX)
    sub = codes[::step, ::step]
    integer = codes.dtype in (np.uint8, np.uint16)
    if integer:
        bins = 256 if codes.dtype == np.uint8 else 65536
        if codes.dtype == np.uint8:
            hist = cv2.calcHist([codes], [0], None, [256], [0, 256]).ravel()
        else:
            hist = np.bincount(codes.ravel(), minlength=bins).astype(np.float64)
        cdf = np.concatenate([[0.0], np.cumsum(hist)]) / n
        median = float(np.interp(0.5, cdf, np.arange(bins + 1) - 0.5))
    else:
        median = float(np.median(sub))
    t = min(NOISE_TILE_PX, *sub.shape)
    th, tw = sub.shape[0] // t, sub.shape[1] // t
    tiles = np.sort(sub[: th * t, : tw * t].reshape(th, t, tw, t).swapaxes(1, 2).reshape(th * tw, t * t), axis=1)
    quartiles = []
    for p in (0.5, 0.75):
        rank = p * tiles.shape[1]
        if integer:  # the code holding the quantile, and where in its unit width the rank falls
            v = tiles[:, min(tiles.shape[1] - 1, int(rank))][:, None]
            below, at = (tiles < v).sum(axis=1), (tiles == v).sum(axis=1)
            quartiles.append(v[:, 0] - 0.5 + (rank - below) / at)
        else:
            quartiles.append(np.quantile(tiles, p, axis=1))
    sigma = float(np.median(quartiles[1] - quartiles[0])) / float(ndtri(0.75))
    k = float(ndtri(1.0 - min(0.5, false_alarm_pixels / n)))
    return median, sigma, median + k * sigma


def find_blobs(image, settings: TrackerSettings | None = None, crop_origin_px=(0, 0)) -> tuple[list[Blob], str | None]:
    """Bright blobs with sub-pixel centroids, saturation and colour (steps 1–3), or a reason for none."""
    s = settings or TrackerSettings()
    bgr, reason = as_bgr(image)
    if bgr is None:
        return [], reason
    lut = _linear_lut(bgr.dtype, s)
    brightest = np.maximum(bgr[..., 0], bgr[..., 1])  # channel by channel: ndarray.max(axis=2) is 10x slower
    np.maximum(brightest, bgr[..., 2], out=brightest)
    step = subsample_step(brightest.size, 250_000)  # a subsample is enough for the statistics
    sub = _to_linear(brightest[::step, ::step], lut)  # max commutes with the monotonic decoding
    bg = float(np.median(sub))
    noise = 1.4826 * float(np.median(np.abs(sub - bg)))
    thr = bg + max(s.threshold_sigma * noise, s.min_contrast)  # the floor: contrast above the background
    _, _, code_thr = noise_threshold(brightest, s.false_alarm_pixels)  # the noise's own tail
    if lut is not None:  # integer codes: y > thr ⟺ code > the last code whose linear value is ≤ thr
        floor_code = int(np.searchsorted(lut, thr, side="right")) - 1
        code = max(floor_code, int(np.floor(code_thr)))
        if code != floor_code:
            thr = float(lut[code]) if code < len(lut) else 1.0
    else:
        thr = max(thr, code_thr)
    if thr >= 1.0:
        return [], f"no bright blobs: background {bg:.3g} and noise {noise:.3g} leave no headroom below full scale"
    if lut is None:
        mask = (_to_linear(brightest, lut) > thr).view(np.uint8)
    elif brightest.dtype == np.uint8:
        mask = cv2.threshold(brightest, code, 1, cv2.THRESH_BINARY)[1] if code >= 0 else np.ones_like(brightest)
    else:
        mask = (brightest > code).view(np.uint8)
    comps = components(mask)
    if comps is None:
        return [], f"no bright blobs above the threshold {thr:.3g} (background {bg:.3g}, full scale 1)"
    xs, ys, label, stats = comps
    order = np.argsort(-stats[:, 4], kind="stable")[: s.max_blobs]
    chan_bg = np.median(_to_linear(bgr[::step, ::step], lut).reshape(-1, 3), axis=0)
    # centroids of every blob at once: (y − background)-weighted means of its pixels
    weight = _to_linear(brightest[ys, xs], lut).astype(np.float64) - bg
    total = np.bincount(label, weight, len(stats))
    with np.errstate(invalid="ignore", divide="ignore"):
        cu_all = np.bincount(label, weight * xs, len(stats)) / total
        cv_all = np.bincount(label, weight * ys, len(stats)) / total
    starts = np.concatenate([[0], np.cumsum(stats[:, 4])])  # points are grouped by label
    model = s.model()
    blobs = []
    h, w = brightest.shape
    r = s.ring_px
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    for lab in order.tolist():
        if total[lab] <= 0:
            continue
        x0, y0, bw, bh, area = stats[lab].tolist()
        xa, ya, xb, yb = max(0, x0 - r), max(0, y0 - r), min(w, x0 + bw + r), min(h, y0 + bh + r)
        lab_win = np.zeros((yb - ya, xb - xa), bool)
        lab_win[ys[starts[lab] : starts[lab + 1]] - ya, xs[starts[lab] : starts[lab + 1]] - xa] = True
        y_win = _to_linear(brightest[ya:yb, xa:xb], lut)
        pix = _to_linear(bgr[ya:yb, xa:xb], lut)
        clipped = np.any(pix >= s.saturation_level, axis=2)
        region = cv2.dilate(lab_win.view(np.uint8), kernel) > 0
        use = region & ~clipped & (y_win > bg + 0.5 * (thr - bg))
        chroma = None
        if use.any():
            rgb = np.clip(pix[use] - chan_bg, 0.0, None).sum(axis=0)  # B, G, R
            if rgb.sum() > 0:
                chroma = (float(rgb[2] / rgb.sum()), float(rgb[1] / rgb.sum()))
        colour, _ = model.classify(chroma)
        blobs.append(
            Blob(
                float(cu_all[lab]) + crop_origin_px[0],
                float(cv_all[lab]) + crop_origin_px[1],
                float(area),
                colour,
                float(total[lab]),
                float(clipped[lab_win].mean()),
                chroma,
            )
        )
    return blobs, None


def _plausible(pts: NDArray[np.float64]) -> bool:
    # image-plane screen of a numbered cross: diagonals cross near their middles, 1 near the crossing
    p1, p2, p3, p4, p5 = pts
    d23, d45 = p3 - p2, p5 - p4
    den = d23[0] * d45[1] - d23[1] * d45[0]
    if abs(den) < 1e-12:
        return False
    diff = p4 - p2
    t = (diff[0] * d45[1] - diff[1] * d45[0]) / den
    u = (diff[0] * d23[1] - diff[1] * d23[0]) / den
    if not (0.2 < t < 0.8 and 0.2 < u < 0.8):
        return False
    a, b = np.linalg.norm(d23), np.linalg.norm(d45)
    if not 0.2 < a / b < 5.0:
        return False
    return bool(np.linalg.norm(p1 - (p2 + t * d23)) < 0.9 * min(a, b))


def _fit(uv: NDArray[np.float64], design: BeaconDesign, k: NDArray[np.float64]) -> float:
    obj = design.marker_positions_m()
    solved = solve_pnp(obj, uv, k)
    if solved is None:  # degenerate point sets
        return float("inf")
    rvec, tvec = solved
    rot = cv2.Rodrigues(rvec)[0]
    cam_t = -rot.T @ tvec.reshape(3)
    if tvec[2, 0] <= 0 or cam_t[0] <= 0:  # target behind the camera, or seen from behind
        return float("inf")
    proj, _ = cv2.projectPoints(obj, rvec, tvec, k, None)
    return float(np.sqrt(np.mean((proj.reshape(5, 2) - uv) ** 2)))


def cross_dimensions(design: BeaconDesign) -> tuple[float, float] | None:
    """Arm length a and out-of-plane offset d of a cross-shaped design, m; None for another shape.

    A cross: markers 2-3 and 4-5 are perpendicular diagonals of equal length 2a with a
    common midpoint C, and marker 1 lies at distance d from C on their plane's normal
    (V1, V2 and every design :mod:`scenes.beacon` builds). :func:`rms_lower_bounds`
    holds only for such a design.
    """
    p = design.marker_positions_m()
    centre = 0.5 * (p[1] + p[2])
    u, w, n = 0.5 * (p[2] - p[1]), 0.5 * (p[4] - p[3]), p[0] - centre
    arm, out = float(np.linalg.norm(u)), float(np.linalg.norm(n))
    tol = 1e-9 * max(arm, out, 1e-3)
    is_cross = (
        arm > 0
        and out > 0
        and np.allclose(0.5 * (p[3] + p[4]), centre, rtol=0, atol=tol)
        and abs(np.linalg.norm(w) - arm) <= tol
        and max(abs(u @ w), abs(u @ n), abs(w @ n)) <= tol * max(arm, out)
    )
    return (arm, out) if is_cross else None


_BOUND_SHAVE = 1e-6
"""Relative amount taken off every lower bound, so rounding cannot lift one above the exact value."""


def rms_lower_bounds(
    numbered: NDArray[np.float64],
    k: NDArray[np.float64],
    arm_m: float,
    out_m: float,
    limit: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Lower bounds on the reprojection RMS that any pose of a cross target can reach, px.

    For each numbered five (markers 1..5) the bound is at most the RMS (over the ten
    coordinates, as :func:`_fit` measures it) between the five image points and the
    pinhole projection of the target (:func:`cross_dimensions`: arm ``a``, offset ``d``)
    under *any* rigid pose that puts all five markers in front of the camera, so also at
    most the RMS the PnP fit reaches (its pose has marker 1 in front; one with another
    marker behind the camera, i.e. marker 1 within 8 cm of the camera plane, would project
    that marker mirrored and far out of any frame). It is computed from the image-space
    shape alone, with no limit on range, yaw, pitch, roll or where the target is in the frame.

    Geometry (normalised coordinates x = K⁻¹·(u, v, 1), centre C of the arms at depth Z,
    ε = a/Z, μ = d/a, arm directions u, w and normal n = u × w in camera axes, c₀ the image
    of C, J = [I | −c₀]). Projecting C + v gives c₀ + (J·v/Z)/(1 + v_z/Z), hence exactly

    * half-diagonals A = (x₃ − x₂)/2 = ε·J·u/(1 − ε²u_z²), B = (x₅ − x₄)/2 likewise with w;
    * diagonal midpoints (x₂ + x₃)/2 = c₀ − ε·u_z·A, (x₄ + x₅)/2 = c₀ − ε·w_z·B;
    * marker 1: x₁ − c₀ = μ·ε·J·n/(1 + μ·ε·n_z).

    Since |J·u|² + |J·w|² ≥ 1 (u, w, n orthonormal; J·Jᵀ = I + c₀c₀ᵀ), ε ≤ H = (|A|² + |B|²)^½.
    Two statistics follow:

    1. *Parallelogram*: the diagonals' midpoints differ by at most ε·H ≤ H² (u_z² + w_z² ≤ 1).
       A square seen from afar is a parallelogram; perspective bends it by at most this.
    2. *Isotropy*: with E = (x₁ − m)/μ (m the mean of markers 2-5), the 2×3 matrix
       V = [A, B, E] equals ε·J·[u, w, n] up to perspective terms of order ε, and
       ε²·J·[u, w, n]·[u, w, n]ᵀ·Jᵀ = ε²(I + c₀c₀ᵀ): whitened by P = (I + mmᵀ)^-½, V·Vᵀ
       is a multiple of the identity. Its eigenvalue gap is bounded by Weyl's inequality
       from the perspective terms (each bounded through ε ≤ H) and the whitening error.

    Moving the five points by δ (Frobenius norm, normalised units) changes the midpoint
    difference by at most δ, H by at most δ/√2, A, B and E by at most max(1/√2, √1.25/μ)·δ
    and m by δ/2. Each statistic's bound is thus an increasing function of δ; the smallest
    δ that reaches the observed statistic bounds the distance of the points from every
    exact projection, and δ·min(f_x, f_y)/√10 the RMS in pixels. The larger of the two
    is returned (0 where the shape is consistent with the target).

    Parameters
    ----------
    numbered
        (N, 5, 2) image points of markers 1..5, full-frame px.
    k
        3×3 camera matrix (no skew), px.
    arm_m, out_m
        Arm length a and out-of-plane offset d of the target, m.
    limit
        Optional (N,) px: the isotropy bound is computed only where the parallelogram bound
        is at most ``limit`` (elsewhere the parallelogram bound alone is returned, a valid but
        weaker bound); saves time where the caller discards larger bounds anyway.

    Returns
    -------
    NDArray
        (N,) lower bounds, px (0 where the shape fits the target).
    """
    pts = np.asarray(numbered, dtype=np.float64)
    x = (pts - k[[0, 1], [2, 2]]) / k[[0, 1], [0, 1]]
    to_px = min(k[0, 0], k[1, 1]) / np.sqrt(10.0) * (1.0 - _BOUND_SHAVE)
    half_a, half_b = 0.5 * (x[:, 2] - x[:, 1]), 0.5 * (x[:, 4] - x[:, 3])
    mid_a, mid_b = 0.5 * (x[:, 1] + x[:, 2]), 0.5 * (x[:, 3] + x[:, 4])
    h = np.sqrt((half_a**2).sum(axis=1) + (half_b**2).sum(axis=1))
    # 1. parallelogram: |mid_a − mid_b| ≤ (H + δ/√2)² + δ; the root of δ²/2 + (√2·H + 1)·δ + H² − gap = 0
    gap = np.linalg.norm(mid_a - mid_b, axis=1)
    b, c = np.sqrt(2.0) * h + 1.0, h * h - gap
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(c < 0, -2.0 * c / (b + np.sqrt(b * b - 2.0 * c)), 0.0)
    bound = np.nan_to_num(delta, nan=0.0, posinf=0.0) * to_px
    # 2. isotropy, where still needed
    need = np.isfinite(bound) if limit is None else bound <= np.asarray(limit)
    if need.any():
        bound[need] = np.maximum(bound[need], _isotropy_delta(x[need], out_m / arm_m) * to_px)
    return bound


def _isotropy_delta(x: NDArray[np.float64], mu: float, steps: int = 24) -> NDArray[np.float64]:
    """Smallest perturbation δ (normalised, Frobenius) that can explain the isotropy gap, from below."""
    half_a, half_b = 0.5 * (x[:, 2] - x[:, 1]), 0.5 * (x[:, 4] - x[:, 3])
    m = x[:, 1:].mean(axis=1)
    e = (x[:, 0] - m) / mu
    v = np.stack([half_a, half_b, e], axis=2)  # (N, 2, 3)
    s = v @ v.transpose(0, 2, 1)
    m2 = (m**2).sum(axis=1)
    m_unit = m / np.sqrt(np.where(m2 > 0, m2, 1.0))[:, None]
    shrink = 1.0 / np.sqrt(1.0 + m2) - 1.0
    p = np.eye(2) + shrink[:, None, None] * m_unit[:, :, None] * m_unit[:, None, :]  # (I + mmᵀ)^-½
    wt = p @ s @ p
    gap = np.hypot(wt[:, 0, 0] - wt[:, 1, 1], 2.0 * wt[:, 0, 1])
    h0 = np.sqrt((half_a**2).sum(axis=1) + (half_b**2).sum(axis=1))
    e0, m0 = np.linalg.norm(e, axis=1), np.sqrt(m2)
    lip = max(1.0 / np.sqrt(2.0), np.sqrt(1.25) / mu)

    def reach(d: NDArray[np.float64]) -> NDArray[np.float64]:
        eps = h0 + d / np.sqrt(2.0)  # ≥ H of the exact projection ≥ ε
        e_max = e0 + np.sqrt(1.25) * d / mu
        dc = 0.5 * eps * eps + 0.5 * d  # ≥ |c₀ − m|
        c0 = m0 + dc
        dv = eps * (1.5 * eps * eps + mu * e_max + eps / (2.0 * mu)) + lip * d  # ≥ ‖V − ε·J·[u, w, n]‖
        return 2.0 * eps * eps * dc * (c0 + m0) + 2.0 * (2.0 * eps * np.sqrt(1.0 + c0 * c0) * dv + dv * dv)

    lo, hi = np.zeros(len(x)), np.ones(len(x))
    for _ in range(steps):  # bisection; lo stays below the root
        mid = 0.5 * (lo + hi)
        reached = gap <= reach(mid)
        hi, lo = np.where(reached, mid, hi), np.where(reached, lo, mid)
    return np.where(gap <= reach(np.zeros(len(x))), 0.0, np.nan_to_num(lo, nan=0.0))


def best_five(
    blobs: list[Blob],
    design: BeaconDesign,
    intrinsics: Intrinsics,
    s: TrackerSettings,
    memo: dict | None = None,
    settle: bool = True,
) -> _Fit | None:
    """The 5-subset of ``blobs`` (brightest ``max_candidates``) that best fits the target, numbered.

    Every numbering of every 5-subset that passes the cross and image-plane screens is a
    candidate; the answer is the first (in subset order) with the least PnP reprojection
    RMS, marked as a fit (``blobs`` set) when that RMS is within the acceptance threshold.
    With ``s.prune`` the answer is the same, found with fewer PnP fits: candidates are
    visited in order of :func:`rms_lower_bounds`, and one whose bound exceeds the least
    RMS found so far is never fitted (it cannot be the answer); fits are looked up in
    ``memo`` first.

    Parameters
    ----------
    blobs, design, intrinsics, s
        Blobs to search, target design, full-frame intrinsics and tracker settings.
    memo
        Optional cache of fits (numbered points → RMS) shared by the searches of one frame.
    settle
        False lets a failed search stop early: its candidates whose bound exceeds their own
        acceptance threshold are not fitted, so an accepted answer is still exactly the
        full search's, and so is the absence of one, but a failed result's ``rms_px`` is
        then only an upper bound (``settled`` False; search again with ``settle`` to get it).
    """
    cands = sorted(blobs, key=lambda b: -b.flux)[: s.max_candidates]
    if len(cands) < 5:
        return None
    k = intrinsics.matrix()
    uv = np.array([[c.u, c.v] for c in cands])
    subsets = np.array(list(itertools.combinations(range(len(cands)), 5)))
    which, idx = cross_candidates_many(uv[subsets])
    chosen = subsets[which[:, None], idx] if len(which) else np.zeros((0, 5), dtype=np.int64)
    numbered = uv[chosen]  # (N, 5, 2), markers 1..5 of every candidate, as the full search numbers them
    dims = cross_dimensions(design) if s.prune else None
    found = None if dims is None else _pruned_search(numbered, dims, design, k, s, memo, settle)
    if found is None:  # the full search
        best_i, best_rms = None, float("inf")
        for i in range(len(numbered)):
            if not _plausible(numbered[i]):
                continue
            rms = _fit(numbered[i], design, k)
            if best_i is None or rms < best_rms:
                best_i, best_rms = i, rms
        found = best_i, best_rms, True
    best_i, best_rms, settled = found
    if best_i is None:
        return None if settled else _Fit(best_rms, np.full((5, 2), np.nan), [], settled=False)
    best = _Fit(best_rms, numbered[best_i], [cands[i] for i in chosen[best_i]])
    size = float(np.ptp(best.uv, axis=0).max())
    if best.rms_px <= max(s.fit_rms_px, s.fit_rms_rel * size):
        return best
    return _Fit(best.rms_px, best.uv, [], settled=settled)


def _pruned_search(
    numbered: NDArray[np.float64],
    dims: tuple[float, float],
    design: BeaconDesign,
    k: NDArray[np.float64],
    s: TrackerSettings,
    memo: dict | None,
    settle: bool,
) -> tuple[int | None, float, bool] | None:
    """Branch and bound over the candidates: (index of the answer or None, its RMS, settled).

    None when a fit is not a number (the full search's order then decides; it never
    happens with finite points). Exactness: every candidate i left unfitted has a lower
    bound L_i > the returned RMS, so its RMS is larger and it can neither be the answer nor
    tie with it; among the fitted ones the least RMS, then the lowest index, wins, as in
    the full search's sequential strict comparison. Without ``settle``, candidates with
    L_i above their own acceptance threshold are deferred: the full search's answer, if
    accepted, has L ≤ RMS ≤ its threshold, so it is never deferred and is found in the
    first pass; the deferred ones are then fitted as needed (branch and bound again) only
    when the first pass's answer is accepted, so that it is also the least RMS of all.
    """
    n = len(numbered)
    if n == 0:
        return None, float("inf"), True
    size = np.ptp(numbered, axis=1).max(axis=1)
    limit = np.maximum(s.fit_rms_px, s.fit_rms_rel * size)  # each candidate's acceptance threshold, px
    bounds = rms_lower_bounds(numbered, k, *dims, limit=None if settle else limit)
    order = np.argsort(bounds, kind="stable")
    key0 = k.tobytes() + design.marker_positions_m().tobytes()
    memo = {} if memo is None else memo
    best_i, best_rms = None, float("inf")
    deferred = []

    def visit(i: int) -> bool:
        nonlocal best_i, best_rms
        if not _plausible(numbered[i]):
            return True
        key = key0 + numbered[i].tobytes()
        rms = memo.get(key)
        if rms is None:
            rms = memo[key] = _fit(numbered[i], design, k)
        if np.isnan(rms):
            return False
        if best_i is None or rms < best_rms or (rms == best_rms and i < best_i):
            best_i, best_rms = i, rms
        return True

    for i in order.tolist():
        if bounds[i] > best_rms:
            break  # so are all later ones
        if not settle and bounds[i] > limit[i]:
            deferred.append(i)  # cannot be accepted; needed only to settle
            continue
        if not visit(i):
            return None
    accepted = best_i is not None and best_rms <= limit[best_i]
    if deferred and accepted:  # an accepted answer must also beat the deferred candidates
        for i in deferred:
            if bounds[i] > best_rms:
                break
            if not visit(i):
                return None
        deferred = []
    settled = not any(bounds[i] <= best_rms for i in deferred)
    return best_i, best_rms, settled


def track(image, intrinsics: Intrinsics, settings: TrackerSettings | None = None, crop_origin_px=(0, 0)) -> TrackResult:
    """Find and number the five markers of one side (see the module doc).

    Parameters
    ----------
    image
        BGR image (any array :func:`pipeline.image_io.as_bgr` accepts), the full frame or
        a crop starting at ``crop_origin_px``; undistorted if the intrinsics are.
    intrinsics
        Full-frame intrinsics for the geometric fit.
    settings
        Tracker parameters.
    crop_origin_px
        Full-frame pixel (u, v) of the image's top-left pixel.
    """
    s = settings or TrackerSettings()
    bgr, reason = as_bgr(image)
    if bgr is None:
        return TrackResult(None, None, reason, failure=Failure.IMAGE)
    blobs, reason = find_blobs(bgr, s, crop_origin_px)
    if not blobs:
        return TrackResult(None, None, reason or "no bright blobs", failure=Failure.NO_BLOBS)
    design = beacon_design(s.beacon)
    by_colour = {c: [b for b in blobs if b.colour == c] for c in SIDE_COLOURS}
    memo: dict = {}  # PnP fits of this frame, shared by its searches
    fits = {}
    for colour in SIDE_COLOURS:
        if len(by_colour[colour]) >= 5:
            fit = best_five(by_colour[colour], design, intrinsics, s, memo, settle=False)
            if fit is not None:
                fits[colour] = fit
    good = {c: f for c, f in fits.items() if f.blobs}
    if good:
        colour = min(good, key=lambda c: good[c].rms_px)
        fit = good[colour]
        notes = [f"{len(by_colour[colour]) - 5} extra {colour} blob(s) ignored"] if len(by_colour[colour]) > 5 else []
        return TrackResult(colour, fit.uv, None, blobs, notes)
    fit = best_five(blobs, design, intrinsics, s, memo, settle=False) if len(blobs) >= 5 else None
    if fit is not None and fit.blobs:
        colours = [b.colour for b in fit.blobs]
        top = max(SIDE_COLOURS, key=colours.count)
        counts = ", ".join(f"{c}: {colours.count(c)}" for c in [*SIDE_COLOURS, None] if colours.count(c))
        if colours.count(top) >= 3:
            return TrackResult(top, fit.uv, None, blobs, [f"mixed marker colours ({counts}); side by majority"])
        reason = f"target found but its colour is unclear ({counts})"
        return TrackResult(None, fit.uv, reason, blobs, failure=Failure.COLOUR_UNCLEAR)
    failure, reason = _why_not(by_colour, fits, blobs, lambda c: best_five(by_colour[c], design, intrinsics, s, memo))
    return TrackResult(None, None, reason, blobs, failure=failure)


def _why_not(
    by_colour: dict[str, list[Blob]],
    fits: dict[str, _Fit],
    blobs: list[Blob],
    settle: Callable[[str], _Fit | None] | None = None,
) -> tuple[Failure, str]:
    colour = max(SIDE_COLOURS, key=lambda c: (len(by_colour[c]), -SIDE_COLOURS.index(c)))
    found = by_colour[colour]
    n = len(found)
    if n == 0:
        return Failure.NO_SIDE_COLOUR, f"no blob has a side colour ({len(blobs)} blob(s) of unknown colour)"
    if n < 5:
        areas = np.array([b.area_px for b in found])
        big = [b for b in found if n > 1 and b.area_px > 1.8 * np.median(areas)]
        what = f"{colour}: {n} blob(s), {5 - n} marker(s) lost or merged"
        if big:
            b = big[0]
            what += f"; blob at ({b.u:.0f}, {b.v:.0f}) is {b.area_px / np.median(areas):.1f}× the median area: merged"
        return Failure.TOO_FEW_BLOBS, what
    fit = fits.get(colour)
    if fit is not None and not fit.settled and settle is not None:
        fit = settle(colour)  # the least RMS of all candidates, as the reason reports it
    rms = fit.rms_px if fit is not None else float("inf")
    return (
        Failure.NO_FIT,
        f"{colour}: {n} blobs but no 5 of them fit the target geometry (best reprojection RMS {rms:.2g} px)",
    )


def calibrate_colours(
    images_by_colour: dict[str, list], settings: TrackerSettings | None = None, min_sigma: float = 0.02
) -> ColourModel:
    """Measure the chromaticity references from reference captures of each side.

    Parameters
    ----------
    images_by_colour
        Colour → BGR images in which only that colour's markers are lit (e.g. the
        study's 150 mm captures, or any range).
    settings
        Tracker settings (threshold, saturation level).
    min_sigma
        Floor on each reference's (r, g) standard deviation, so a few consistent
        captures do not make the class needle-thin.
    """
    s = settings or TrackerSettings()
    means, covs = {}, {}
    for colour, images in images_by_colour.items():
        if colour not in SIDE_COLOURS:
            raise ValueError(f"colour: expected one of {', '.join(SIDE_COLOURS)}, got {colour!r}")
        chromas = []
        for k, image in enumerate(images):
            blobs, reason = find_blobs(image, s)
            got = [b.chroma for b in blobs if b.chroma is not None]
            if not got:
                raise ValueError(f"images[{colour}][{k}]: no coloured blob found ({reason or 'all clipped'})")
            chromas += got
        c = np.array(chromas)
        means[colour] = (float(c[:, 0].mean()), float(c[:, 1].mean()))
        cov = np.cov(c.T) if len(c) > 2 else np.zeros((2, 2))
        covs[colour] = cov + min_sigma**2 * np.eye(2)
    return ColourModel(means, covs)
