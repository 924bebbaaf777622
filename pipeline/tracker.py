"""A better marker tracker: sub-pixel centroids, saturation-tolerant colour, geometric selection.

Steps, on a BGR image (8-bit values are taken as sRGB-encoded and linearised; 16-bit and
float as linear):

1. Brightness y = max over channels (each colour's strongest channel counts). Background
   = median of y and noise = 1.4826·MAD (on a subsample); pixels above
   background + max(k·noise, min_contrast) form 8-connected blobs.
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
   (reflections, other sides, lamps) are thus ignored.
5. If no colour fits, every blob is tried regardless of colour (the side is then the
   majority colour of the five, or unknown); otherwise the reason says which colour came
   closest and whether markers look merged (a blob much larger than the others) or lost.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.angles import Intrinsics
from pipeline.failures import Failure
from pipeline.image_io import as_bgr, to_float
from pipeline.markers import Blob, TrackResult, cross_candidates_many
from scenes.beacon import BeaconDesign, beacon_design
from scenes.led import SIDE_COLOURS

DEFAULT_CHROMA = {
    "red": (1.0, 0.0),
    "green": (0.0, 1.0),
    "blue": (0.0, 0.0333),
    "yellow": (0.8361, 0.1639),
}
"""(r, g) chromaticity of each LED's spectrum (``scenes.led``) through the CIE 1931 observer
into linear sRGB, negatives clipped: what an ideal sRGB camera would record. Real cameras
differ (crosstalk, white balance); calibrate with :func:`calibrate_colours`."""


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
        cov = 0.1**2 * np.eye(2)
        return cls(dict(DEFAULT_CHROMA), {c: cov for c in DEFAULT_CHROMA}, max_distance=4.0)

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
        Chromaticity references; None uses :meth:`ColourModel.default`.
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
    max_blobs
        At most this many blobs (largest first) are measured.
    max_candidates
        Brightest blobs per colour searched for the 5 markers.
    fit_rms_px, fit_rms_rel
        A 5-subset fits the target when its PnP reprojection RMS is at most
        max(fit_rms_px, fit_rms_rel × the target's image size).
    linearise_8bit
        Decode 8-bit images as sRGB before weighting.
    """

    colour_model: ColourModel | None = None
    beacon: str = "v2"
    threshold_sigma: float = 8.0
    min_contrast: float = 0.02
    saturation_level: float = 0.98
    ring_px: int = 3
    max_blobs: int = 400
    max_candidates: int = 10
    fit_rms_px: float = 1.0
    fit_rms_rel: float = 0.02
    linearise_8bit: bool = True

    def model(self) -> ColourModel:
        """The colour model in use."""
        return self.colour_model or ColourModel.default()


@dataclass
class _Fit:
    rms_px: float
    uv: NDArray[np.float64]
    blobs: list[Blob] = field(default_factory=list)


def _linear_lut(dtype, s: TrackerSettings) -> NDArray[np.float32] | None:
    if dtype == np.uint8:
        lut = np.arange(256, dtype=np.float32) / 255.0
        return srgb_to_linear(lut) if s.linearise_8bit else lut
    if dtype == np.uint16:
        return np.arange(65536, dtype=np.float32) / 65535.0
    return None


def _to_linear(arr: NDArray, lut: NDArray[np.float32] | None) -> NDArray[np.float32]:
    # integer images go through a look-up table: cheap on an 18-Mpx frame
    return lut[arr] if lut is not None else to_float(arr)


def find_blobs(image, settings: TrackerSettings | None = None, crop_origin_px=(0, 0)) -> tuple[list[Blob], str | None]:
    """Bright blobs with sub-pixel centroids, saturation and colour (steps 1–3), or a reason for none."""
    s = settings or TrackerSettings()
    bgr, reason = as_bgr(image)
    if bgr is None:
        return [], reason
    lut = _linear_lut(bgr.dtype, s)
    y = _to_linear(bgr.max(axis=2), lut)  # max commutes with the monotonic decoding
    step = max(1, int(np.sqrt(y.size / 250_000)))  # a subsample is enough for the statistics
    sub = y[::step, ::step]
    bg = float(np.median(sub))
    noise = 1.4826 * float(np.median(np.abs(sub - bg)))
    thr = bg + max(s.threshold_sigma * noise, s.min_contrast)
    if thr >= 1.0:
        return [], f"no bright blobs: background {bg:.3g} and noise {noise:.3g} leave no headroom below full scale"
    mask = (y > thr).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return [], f"no bright blobs above the threshold {thr:.3g} (background {bg:.3g}, full scale 1)"
    order = 1 + np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable")[: s.max_blobs]
    chan_bg = np.median(_to_linear(bgr[::step, ::step], lut).reshape(-1, 3), axis=0)
    model = s.model()
    blobs = []
    h, w = y.shape
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * s.ring_px + 1, 2 * s.ring_px + 1))
    for lab in order:
        x0, y0, bw, bh, area = stats[lab]
        r = s.ring_px
        xa, ya, xb, yb = max(0, x0 - r), max(0, y0 - r), min(w, x0 + bw + r), min(h, y0 + bh + r)
        lab_win = labels[ya:yb, xa:xb] == lab
        wy = np.where(lab_win, y[ya:yb, xa:xb] - bg, 0.0)
        total = float(wy.sum())
        if total <= 0:
            continue
        vv, uu = np.mgrid[ya:yb, xa:xb]
        cu, cv_ = float((wy * uu).sum() / total), float((wy * vv).sum() / total)
        pix = _to_linear(bgr[ya:yb, xa:xb], lut)
        clipped = np.any(pix >= s.saturation_level, axis=2)
        region = cv2.dilate(lab_win.astype(np.uint8), kernel) > 0
        use = region & ~clipped & (y[ya:yb, xa:xb] > bg + 0.5 * (thr - bg))
        chroma = None
        if use.any():
            rgb = np.clip(pix[use] - chan_bg, 0.0, None).sum(axis=0)  # B, G, R
            if rgb.sum() > 0:
                chroma = (float(rgb[2] / rgb.sum()), float(rgb[1] / rgb.sum()))
        colour, _ = model.classify(chroma)
        blobs.append(
            Blob(
                cu + crop_origin_px[0],
                cv_ + crop_origin_px[1],
                float(area),
                colour,
                total,
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
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, uv, k, None, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            return float("inf")
        rvec, tvec = cv2.solvePnPRefineLM(obj, uv, k, None, rvec, tvec)
    except cv2.error:  # degenerate point sets (SQPnP asserts on near-coincident points)
        return float("inf")
    rot = cv2.Rodrigues(rvec)[0]
    cam_t = -rot.T @ tvec.reshape(3)
    if tvec[2, 0] <= 0 or cam_t[0] <= 0:  # target behind the camera, or seen from behind
        return float("inf")
    proj, _ = cv2.projectPoints(obj, rvec, tvec, k, None)
    return float(np.sqrt(np.mean((proj.reshape(5, 2) - uv) ** 2)))


def best_five(blobs: list[Blob], design: BeaconDesign, intrinsics: Intrinsics, s: TrackerSettings) -> _Fit | None:
    """The 5-subset of ``blobs`` (brightest ``max_candidates``) that best fits the target, numbered."""
    cands = sorted(blobs, key=lambda b: -b.flux)[: s.max_candidates]
    if len(cands) < 5:
        return None
    k = intrinsics.matrix()
    uv = np.array([[c.u, c.v] for c in cands])
    subsets = np.array(list(itertools.combinations(range(len(cands)), 5)))
    best = None
    for which, idx in zip(*cross_candidates_many(uv[subsets]), strict=True):
        subset = subsets[which]
        numbered = uv[subset][idx]
        if not _plausible(numbered):
            continue
        rms = _fit(numbered, design, k)
        if best is None or rms < best.rms_px:
            best = _Fit(rms, numbered, [cands[subset[i]] for i in idx])
    if best is None:
        return None
    size = float(np.ptp(best.uv, axis=0).max())
    return best if best.rms_px <= max(s.fit_rms_px, s.fit_rms_rel * size) else _Fit(best.rms_px, best.uv, [])


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
    fits = {}
    for colour in SIDE_COLOURS:
        if len(by_colour[colour]) >= 5:
            fit = best_five(by_colour[colour], design, intrinsics, s)
            if fit is not None:
                fits[colour] = fit
    good = {c: f for c, f in fits.items() if f.blobs}
    if good:
        colour = min(good, key=lambda c: good[c].rms_px)
        fit = good[colour]
        notes = [f"{len(by_colour[colour]) - 5} extra {colour} blob(s) ignored"] if len(by_colour[colour]) > 5 else []
        return TrackResult(colour, fit.uv, None, blobs, notes)
    fit = best_five(blobs, design, intrinsics, s) if len(blobs) >= 5 else None
    if fit is not None and fit.blobs:
        colours = [b.colour for b in fit.blobs]
        top = max(SIDE_COLOURS, key=colours.count)
        counts = ", ".join(f"{c}: {colours.count(c)}" for c in [*SIDE_COLOURS, None] if colours.count(c))
        if colours.count(top) >= 3:
            return TrackResult(top, fit.uv, None, blobs, [f"mixed marker colours ({counts}); side by majority"])
        reason = f"target found but its colour is unclear ({counts})"
        return TrackResult(None, fit.uv, reason, blobs, failure=Failure.COLOUR_UNCLEAR)
    failure, reason = _why_not(by_colour, fits, blobs)
    return TrackResult(None, None, reason, blobs, failure=failure)


def _why_not(by_colour: dict[str, list[Blob]], fits: dict[str, _Fit], blobs: list[Blob]) -> tuple[Failure, str]:
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
    rms = fits[colour].rms_px if colour in fits else float("inf")
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
