"""The study's morphology computed only in windows around in-range pixels equals the whole image's, bit for bit.

:func:`pipeline.thesis_tracker.windowed_morphology` runs the study's close and erosion (its
kernels and iterations) in windows grown by the morphology's reach. The reference is the same
OpenCV calls on the whole mask (``_morphology``, the code as it was). The frames are built to
catch a window one pixel too small: blobs straddling tile and window edges, clusters that sit
just inside each other's windows, the image border, noise-only dark frames, and frames from
HSV images through :func:`pipeline.thesis_tracker.colour_mask`.
"""

from __future__ import annotations

from functools import cache

import cv2
import numpy as np

from pipeline import thesis_tracker
from pipeline.angles import Intrinsics
from pipeline.thesis_tracker import (
    STUDY_HSV_RANGES,
    ThesisTrackerSettings,
    _morphology,
    colour_mask,
    in_range_mask,
    mask_windows,
    morphology_reach,
    thesis_track,
    windowed_morphology,
)
from scenes.view import camera_geometry
from tests.helpers.synthetic import draw_markers, hsv_to_bgr, marker_pixels

SETTINGS = ThesisTrackerSettings()


def _blob(mask: np.ndarray, rng: np.random.Generator, cx: float, cy: float) -> None:
    """An ellipse (1-40 px semi-axes, any angle), a filled rectangle or a ragged speckle cluster at (cx, cy)."""
    kind = rng.integers(0, 3)
    if kind == 0:
        axes = (int(rng.integers(1, 41)), int(rng.integers(1, 41)))
        cv2.ellipse(mask, (int(cx), int(cy)), axes, float(rng.uniform(0, 180)), 0, 360, 255, -1)
    elif kind == 1:
        w, h = rng.integers(1, 60, 2)
        cv2.rectangle(mask, (int(cx), int(cy)), (int(cx + w), int(cy + h)), 255, -1)
    else:
        pts = (np.array([cx, cy]) + rng.normal(size=(int(rng.integers(3, 80)), 2)) * rng.uniform(1, 15)).astype(int)
        ok = (pts[:, 0] >= 0) & (pts[:, 0] < mask.shape[1]) & (pts[:, 1] >= 0) & (pts[:, 1] < mask.shape[0])
        mask[pts[ok, 1], pts[ok, 0]] = 255


def _frame(rng: np.random.Generator) -> np.ndarray:
    """A random mask: blobs near tile edges, pairs of clusters a window's reach apart, blobs at the border."""
    h, w = int(rng.integers(150, 700)), int(rng.integers(150, 900))
    mask = np.zeros((h, w), np.uint8)
    rx, ry = morphology_reach(SETTINGS)
    t = 32
    for _ in range(int(rng.integers(1, 12))):
        where = rng.integers(0, 4)
        if where == 0:  # on a tile edge
            cx = t * rng.integers(0, w // t + 1) + rng.integers(-3, 4)
            cy = t * rng.integers(0, h // t + 1) + rng.integers(-3, 4)
        elif where == 1:  # at the border
            cx = rng.choice([rng.integers(-5, 6), w - 1 + rng.integers(-5, 6), rng.integers(0, w)])
            cy = rng.choice([rng.integers(-5, 6), h - 1 + rng.integers(-5, 6), rng.integers(0, h)])
        else:
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        _blob(mask, rng, cx, cy)
        if where >= 2:  # a neighbour about one or two reaches away: inside the first cluster's window
            reach = np.array([rx, ry]) * rng.choice([1, 2]) + rng.integers(-4, 5, 2) + rng.choice([0, t], 2)
            sign = rng.choice([-1, 1], 2)
            _blob(mask, rng, cx + sign[0] * reach[0], cy + sign[1] * reach[1])
    _speckles(mask, rng)
    return mask


def _speckles(mask: np.ndarray, rng: np.random.Generator) -> None:
    """Noise speckles (lone pixels), bars about the smallest size that survives (5 × 13) and
    pairs of bars about the largest gap the close fills (20 px) apart."""
    h, w = mask.shape
    n = int(rng.integers(0, 200))
    mask[rng.integers(0, h, n), rng.integers(0, w, n)] = 255
    for _ in range(int(rng.integers(0, 6))):
        bw, bh = int(rng.integers(1, 8)), int(rng.integers(9, 16))
        if rng.uniform() < 0.5:
            bw, bh = bh, bw
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        mask[y : y + bh, x : x + bw] = 255
        if rng.uniform() < 0.5:  # a twin across a gap the close may fill
            gap = int(rng.integers(18, 24))
            if rng.uniform() < 0.5:
                mask[y : y + bh, x + bw + gap : x + 2 * bw + gap] = 255
            else:
                mask[y + bh + gap : y + 2 * bh + gap, x : x + bw] = 255


def _edge_cases() -> list[np.ndarray]:
    """Hand-made masks: a thin band, a gap of 20 rows (the most the close fills: 5 dilations of
    2 px from each side) and a block, and the same turned 90°; bars about the smallest size
    that survives, alone or beside a twin across a gap the close fills or not; a single pixel,
    a full and a striped mask."""
    out = []
    for shift in range(-2, 3):
        mask = np.zeros((256, 256), np.uint8)
        top = 99 + shift
        mask[top, 40:200] = 255
        mask[top + 21 : top + 100, 40:200] = 255
        out += [mask, np.ascontiguousarray(mask.T)]
    for bw, bh in ((4, 13), (5, 12), (5, 13), (13, 5), (2, 13)):  # bars about the survivor size (5 × 13)
        for gap in (None, 19, 20, 21):  # alone, or beside a twin across a gap the close fills or not
            mask = np.zeros((200, 200), np.uint8)
            mask[90 : 90 + bh, 60 : 60 + bw] = 255
            if gap is not None:
                mask[90 : 90 + bh, 60 + bw + gap : 60 + 2 * bw + gap] = 255
                mask[150 : 150 + bw, 60 : 60 + bh] = 255  # and turned, across the gap down
                mask[150 + bw + gap : 150 + 2 * bw + gap, 60 : 60 + bh] = 255
            out.append(mask)
    single = np.zeros((100, 100), np.uint8)
    single[50, 50] = 255
    stripes = np.zeros((200, 300), np.uint8)
    stripes[:, ::7] = 255
    return [*out, single, np.full((64, 64), 255, np.uint8), stripes]


def _mismatches(masks, tracker_path: bool = True) -> int:
    """Masks whose windowed morphology (windows always, and as the tracker runs it) differs from the whole mask's."""
    bad = 0
    for m in masks:
        truth = _truth(m)
        bad += not np.array_equal(windowed_morphology(m, SETTINGS, whole_when_cheaper=False), truth) or (
            tracker_path and not np.array_equal(windowed_morphology(m, SETTINGS), truth)
        )
    return bad


_TRUTHS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _truth(mask: np.ndarray) -> np.ndarray:
    """The whole mask's morphology (the reference), remembered per mask."""
    got = _TRUTHS.get(id(mask))
    if got is None or got[0] is not mask:
        got = _TRUTHS[id(mask)] = (mask, _morphology(mask, SETTINGS))
    return got[1]


@cache
def _random_masks(n: int = 200, seed: int = 24) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [_frame(rng) for _ in range(n)]


def test_windowed_morphology_equals_the_whole_image_bit_for_bit():
    masks = _random_masks() + _edge_cases()
    windows = [len(mask_windows(m, SETTINGS) or []) for m in masks]
    assert _mismatches(masks) == 0
    # the frames exercise windows: several per frame, and many frames where they beat the whole mask
    assert np.median(windows) >= 3, np.median(windows)
    cheaper = sum(
        sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1, *_ in mask_windows(m, SETTINGS) or [(0, 0, *m.shape[::-1])])
        < m.size
        for m in masks
    )
    assert cheaper > 50, cheaper
    survivors = [bool(windowed_morphology(m, SETTINGS).any()) for m in _edge_cases()]
    assert 10 < sum(survivors) < len(survivors) - 10, sum(survivors)  # masks that leave something and nothing


def test_the_reach_is_that_of_the_study_kernels():
    # close: 5 dilations + 5 erosions of the 5×5 ellipse (2 px each way); erode: 4 of the (2, 4) ellipse
    # anchored at (1, 2): 1 px across, 2 px up
    assert morphology_reach(SETTINGS) == (2 * 5 * 2 + 4 * 1, 2 * 5 * 2 + 4 * 2) == (24, 28)
    assert morphology_reach(ThesisTrackerSettings(close_iterations=1, erode_iterations=0)) == (4, 4)


_EDGE_CASES = _edge_cases()


def _planted_mismatches(monkeypatch, name: str, value) -> int:
    """Mismatches of the windowed morphology with a planted bug: ``thesis_tracker.<name>`` returning ``value``."""
    masks = _random_masks() + _EDGE_CASES
    monkeypatch.setattr(thesis_tracker, name, lambda s: value)
    return _mismatches(masks, tracker_path=False)


def test_windows_grown_too_little_are_caught(monkeypatch):
    """Planted bugs: windows not grown by the morphology's reach along x, or along y, or
    grown by only the erosions' reach (the closing's dilations left out). A window needs less
    than the full reach here (24 px across, 28 down, kept as the safe bound): the kept box is
    already grown 10 px past its group, and other groups are more than 21 px away, so the few
    pixels the last rows of a window could add are empty; measured on these frames, windows
    grown by at least 1 px across and 23 px down still give identical masks."""
    rx, ry = morphology_reach(SETTINGS)
    assert _planted_mismatches(monkeypatch, "morphology_reach", (0, ry)) > 0
    assert _planted_mismatches(monkeypatch, "morphology_reach", (rx, 10)) > 0


def test_groups_split_too_early_or_small_groups_dropped_are_caught(monkeypatch):
    """Planted bugs in the grouping of :func:`pipeline.thesis_tracker.mask_windows`: regions 21 px
    apart put in different groups (the close joins them), or groups one pixel wider or taller
    than needed dropped."""
    gap = thesis_tracker._group_gap(SETTINGS)
    assert gap == (21, 21)
    assert _planted_mismatches(monkeypatch, "_group_gap", (gap[0] - 1, gap[1] - 1)) > 0
    need = thesis_tracker.survivor_size(SETTINGS)
    assert need == (5, 13)
    assert _planted_mismatches(monkeypatch, "survivor_size", (need[0] + 1, need[1])) > 0
    assert _planted_mismatches(monkeypatch, "survivor_size", (need[0], need[1] + 1)) > 0


def test_noise_only_dark_frames_and_hsv_images():
    """Dark frames of sensor-like noise (in range nowhere or in scattered speckles), and drawn
    markers of each study colour near each other and near the border, through the HSV boxes."""
    rng = np.random.default_rng(7)
    masks = []
    for level in (5.0, 20.0, 60.0):
        noise = np.clip(rng.normal(level, level, (480, 640, 3)), 0, 255).astype(np.uint8)
        hsv = cv2.cvtColor(noise, cv2.COLOR_BGR2HSV)
        masks += [in_range_mask(hsv, boxes) for boxes in STUDY_HSV_RANGES.values()]
    colours = {"red": (170, 25, 255), "green": (78, 100, 255), "blue": (110, 200, 255), "yellow": (19, 220, 255)}
    camera = "logitech-c270"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    for range_m, yaw in ((0.8, 0.0), (2.0, 25.0), (4.0, -30.0)):
        uv, _ = marker_pixels(camera, range_m, yaw)
        for shift in (np.zeros(2), -uv.min(axis=0) + 3, np.array([1279.0, 719.0]) - uv.max(axis=0) - 3):
            for colour, hsv_c in colours.items():
                img = draw_markers(
                    (720, 1280),
                    uv + shift,
                    hsv_to_bgr(*hsv_c),
                    6.0,
                    profile="disc",
                    noise_sigma=4 / 255,
                    rng=rng,
                    supersample=2,
                )
                hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
                mask = in_range_mask(hsv, STUDY_HSV_RANGES[colour])
                assert np.array_equal(colour_mask(hsv, STUDY_HSV_RANGES[colour], SETTINGS), _morphology(mask, SETTINGS))
                masks.append(mask)
    # the whole tracker still finds the side in a drawn frame
    uv, _ = marker_pixels(camera, 0.8, 10.0)
    img = draw_markers((720, 1280), uv, hsv_to_bgr(*colours["green"]), 9.0, profile="disc")
    assert thesis_track(img, intr).side == "green"
    assert sum(m.any() for m in masks) > 40
    assert _mismatches(masks) == 0


def test_a_dense_mask_is_processed_whole_without_labelling(monkeypatch):
    """A mask with at least :data:`~pipeline.thesis_tracker.DENSE_MASK_FRACTION` of its pixels
    set (thresholds that pass a frame's noise) is processed whole without labelling it (the same
    result); a sparser one is still searched for windows."""
    step = int(1 / thesis_tracker.DENSE_MASK_FRACTION)
    dense, sparse = np.zeros((256, 256), np.uint8), np.zeros((256, 256), np.uint8)
    dense.flat[:: step - 4] = 255
    sparse.flat[:: step + 4] = 255
    calls = []
    searched = thesis_tracker.mask_windows
    monkeypatch.setattr(thesis_tracker, "mask_windows", lambda m, s: calls.append(m.shape) or searched(m, s))
    assert np.array_equal(windowed_morphology(dense, SETTINGS), _morphology(dense, SETTINGS))
    assert calls == []
    assert np.array_equal(windowed_morphology(sparse, SETTINGS), _morphology(sparse, SETTINGS))
    assert calls == [(256, 256)]
