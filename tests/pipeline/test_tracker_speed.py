"""The best tracker's pruned 5-subset search: its lower bounds hold and its answers are the full search's.

:func:`pipeline.tracker.best_five` skips the PnP fit of candidates whose image-space lower
bound on the reprojection RMS (:func:`pipeline.tracker.rms_lower_bounds`) shows they cannot
change the answer. The tests check the bound against poses projected by OpenCV, and the
answers against the full search (``TrackerSettings(prune=False)``, the code before pruning)
on random synthetic frames and on drawn images; the study frames are compared by
:mod:`studies.experiments.tracker_pruning`.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import cv2
import numpy as np
import pytest

from pipeline import tracker
from pipeline.angles import Intrinsics
from pipeline.markers import Blob, cross_candidates_many
from pipeline.tracker import TrackerSettings, best_five, cross_dimensions, rms_lower_bounds, track
from scenes.beacon import beacon_design
from scenes.view import camera_geometry
from tests.helpers.synthetic import draw_markers, marker_pixels

FACING = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
"""Target axes (toward the viewer, viewer's left, down) in OpenCV camera axes (right, down,
forward) when the target faces the camera."""

LED_BGR = (0.03, 0.06, 1.0)  # a red LED, linear BGR


def _axis_rotation(axis: int, deg: float) -> np.ndarray:
    """Rotation by ``deg`` about coordinate axis ``axis`` (0 x, 1 y, 2 z)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [a for a in range(3) if a != axis]
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _project(obj: np.ndarray, k: np.ndarray, rot: np.ndarray, range_m: float, pixel) -> np.ndarray:
    """Pixels (5, 2) of target points ``obj`` (m) rotated by ``rot`` (target → camera), with
    marker 1 ``range_m`` from the camera on the ray through ``pixel``; projected by OpenCV."""
    ray = np.linalg.solve(k, [pixel[0], pixel[1], 1.0])
    tvec = range_m * ray / np.linalg.norm(ray)
    uv, _ = cv2.projectPoints(obj, cv2.Rodrigues(rot)[0], tvec, k, None)
    return uv.reshape(-1, 2)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _cross(arm_m: float, out_m: float) -> np.ndarray:
    """Markers 1..5 of a cross in the target frame (as :mod:`scenes.beacon` places them), m."""
    return np.array([[0, 0, 0], [-out_m, -arm_m, 0], [-out_m, arm_m, 0], [-out_m, 0, -arm_m], [-out_m, 0, arm_m]])


CAMERAS = {
    "canon-t6-10mm": Intrinsics.from_geometry(camera_geometry("canon-t6-10mm")).matrix(),
    "logitech-c270": Intrinsics.from_geometry(camera_geometry("logitech-c270")).matrix(),
    # unequal focal lengths, principal point off centre: the bound normalises each axis
    "anamorphic": np.array([[900.0, 0.0, 700.0], [0.0, 1300.0, 300.0], [0.0, 0.0, 1.0]]),
}


@pytest.mark.parametrize("camera", list(CAMERAS))
@pytest.mark.parametrize(("arm_m", "out_m"), [(0.070, 0.046), (0.045, 0.045), (0.100, 0.020)], ids=["v2", "v1", "flat"])
def test_lower_bound_never_exceeds_the_rms_of_the_true_pose(camera, arm_m, out_m):
    """Any orientation (also seen from behind), 0.15-30 m, anywhere in the frame, noise 0.001-10 px:
    the bound stays below the RMS to the true pose's projection, which is at least the RMS of
    the best pose. Swapping markers 1 and 2 of the same points makes the bound large."""
    k = CAMERAS[camera]
    obj = _cross(arm_m, out_m)
    size = 2 * np.array([k[0, 2], k[1, 2]]) + 1
    rng = np.random.default_rng(int(1000 * arm_m + 100 * out_m) + len(camera))
    n = 1500
    exact, noisy = np.empty((n, 5, 2)), np.empty((n, 5, 2))
    for i in range(n):
        range_m = float(np.exp(rng.uniform(np.log(0.15), np.log(30.0))))
        exact[i] = _project(obj, k, _random_rotation(rng), range_m, rng.uniform(0, 1, 2) * size)
        noisy[i] = exact[i] + rng.normal(size=(5, 2)) * np.exp(rng.uniform(np.log(1e-3), np.log(10.0)))
    rms_true = np.sqrt(np.mean((noisy - exact) ** 2, axis=(1, 2)))
    bound = rms_lower_bounds(noisy, k, arm_m, out_m)
    assert np.all(bound <= rms_true), np.max(bound / rms_true)
    assert np.all(rms_lower_bounds(exact, k, arm_m, out_m) == 0.0)
    # not vacuous: marker 1 and marker 2 swapped (a wrong numbering) is bounded away from any pose
    swapped = exact[:, [1, 0, 2, 3, 4]]
    spread = np.ptp(exact, axis=1).max(axis=1)
    wrong = rms_lower_bounds(swapped, k, arm_m, out_m)
    assert np.median(wrong / spread) > 0.02, np.median(wrong / spread)


def _synthetic_blobs(rng: np.random.Generator, design_name: str, k: np.ndarray, frame_wh) -> tuple[list[Blob], list]:
    """The five markers of a random pose (0.3-15 m, yaw ±60°, pitch and roll ±15°, centroid
    noise up to 0.5 px) and 0-40 false blobs (reflections near markers, stray lights around
    the target), with random fluxes; returns the blobs and the true markers' blobs (1..5)."""
    design = beacon_design(design_name)
    range_m = float(np.exp(rng.uniform(np.log(0.3), np.log(15.0))))
    yaw, pitch, roll = rng.uniform(-60, 60), rng.uniform(-15, 15), rng.uniform(-15, 15)
    rot = FACING @ _axis_rotation(2, yaw) @ _axis_rotation(1, pitch) @ _axis_rotation(0, roll)
    pixel = (0.2 + 0.6 * rng.uniform(0, 1, 2)) * np.asarray(frame_wh)
    uv = _project(design.marker_positions_m(), k, rot, range_m, pixel)
    uv += rng.normal(size=uv.shape) * rng.uniform(0, 0.5)
    truth = [Blob(float(u), float(v), 10.0, "red", float(rng.uniform(0.5, 1.5))) for u, v in uv]
    extent = max(float(np.ptp(uv, axis=0).max()), 4.0)
    n_false = int(rng.integers(0, 41))
    near = uv[rng.integers(0, 5, n_false)] + rng.normal(size=(n_false, 2)) * 0.1 * extent
    around = uv.mean(axis=0) + rng.uniform(-2, 2, (n_false, 2)) * extent
    false_uv = np.where(rng.uniform(size=(n_false, 1)) < 0.4, near, around)
    bright = rng.uniform(size=n_false) < 0.1  # most false blobs are dimmer than the markers
    flux = np.where(bright, rng.uniform(0.5, 2.0, n_false), rng.uniform(0.01, 0.6, n_false))
    false = [Blob(float(u), float(v), 4.0, "red", float(f)) for (u, v), f in zip(false_uv, flux, strict=True)]
    blobs = truth + false
    order = rng.permutation(len(blobs))
    return [blobs[i] for i in order], truth


def _old_best_five(blobs, design, intrinsics, s):
    """:func:`pipeline.tracker.best_five` as it was before pruning (verbatim): the reference."""
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
        if not tracker._plausible(numbered):
            continue
        rms = tracker._fit(numbered, design, k)
        if best is None or rms < best.rms_px:
            best = tracker._Fit(rms, numbered, [cands[subset[i]] for i in idx])
    if best is None:
        return None
    size = float(np.ptp(best.uv, axis=0).max())
    return best if best.rms_px <= max(s.fit_rms_px, s.fit_rms_rel * size) else tracker._Fit(best.rms_px, best.uv, [])


def _same_answer(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return (
        a.rms_px == b.rms_px
        and np.array_equal(a.uv, b.uv)
        and len(a.blobs) == len(b.blobs)
        and all(x is y for x, y in zip(a.blobs, b.blobs, strict=True))
    )


@pytest.fixture
def fit_counter(monkeypatch):
    """Counts the tracker's PnP fits."""
    count = [0]
    original = tracker._fit

    def counted(*args):
        count[0] += 1
        return original(*args)

    monkeypatch.setattr(tracker, "_fit", counted)
    return count


@pytest.mark.parametrize("design_name", ["v2", pytest.param("v1", marks=pytest.mark.slow)])  # v1: 24 s, slow
def test_pruned_search_returns_the_full_search_answer_on_random_frames(design_name, fit_counter):
    """120 frames per design (:func:`_synthetic_blobs`): the pruned search's answer is the old
    search's (same five, numbering, RMS and blobs); stopping a failed search early never
    changes the decision; the pruned search needs under a fifth of the PnP fits."""
    rng = np.random.default_rng(11 if design_name == "v2" else 12)
    design = beacon_design(design_name)
    settings = TrackerSettings(beacon=design_name)
    full = replace(settings, prune=False)
    fits_full = fits_pruned = fits_early = found_true = accepted = unsettled = 0
    frames = 120
    for i in range(frames):
        camera = ("canon-t6-18mm", "logitech-c270")[i % 2]
        intr = Intrinsics.from_geometry(camera_geometry(camera))
        blobs, truth = _synthetic_blobs(rng, design_name, intr.matrix(), (2 * intr.cx + 1, 2 * intr.cy + 1))
        fit_counter[0] = 0
        reference = _old_best_five(blobs, design, intr, settings)
        fits_full += fit_counter[0]
        if i % 4 == 0:  # the switch that turns pruning off gives the same search
            assert _same_answer(reference, best_five(blobs, design, intr, full)), i
        fit_counter[0] = 0
        pruned = best_five(blobs, design, intr, settings)
        fits_pruned += fit_counter[0]
        assert _same_answer(reference, pruned), i
        fit_counter[0] = 0
        early = best_five(blobs, design, intr, settings, settle=False)  # as track() searches each colour
        fits_early += fit_counter[0]
        if reference is not None and reference.blobs:
            accepted += 1
            found_true += all(x is y for x, y in zip(reference.blobs, truth, strict=True))
            assert _same_answer(reference, early), i
        else:  # no fit: the early stop may leave the least RMS unknown, never the decision
            assert early is None or not early.blobs, i
            if early is None or early.settled:
                assert _same_answer(reference, early), i
            else:
                unsettled += 1
                assert reference is None or early.rms_px >= reference.rms_px, i
    print(
        f"\n{design_name}: {accepted}/{frames} frames with a fit ({found_true} the true five, "
        f"{unsettled} failed searches stopped early); PnP fits: full search {fits_full}, pruned {fits_pruned}, "
        f"pruned with early stop {fits_early}"
    )
    assert found_true > 0.6 * frames  # the frames exercise real detections…
    assert accepted < frames  # … and failed searches
    assert fits_pruned < 0.2 * fits_full


def _drawn(scene: str):
    """A drawn image, its intrinsics and crop origin: ``clean`` (V2, 4 m, yaw 20°),
    ``distractors`` (same-colour blobs around it), ``lost`` (one marker missing, three
    same-colour blobs: a failed search whose reason reports the least RMS) or ``mixed``
    (two markers drawn in another colour: found only by the search over all blobs)."""
    camera = "canon-t6-18mm"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 4.0, 20.0)
    centre = uv.mean(axis=0)
    extra = centre + np.array([[90.0, 110.0], [-120.0, 60.0], [40.0, -130.0], [-70.0, -90.0]])
    u0, v0 = (int(np.floor(x)) - 200 for x in uv.min(axis=0))
    shape = (int(np.ptp(uv[:, 1])) + 400, int(np.ptp(uv[:, 0])) + 400)
    origin = (u0, v0)

    def draw(points, bgr=LED_BGR):
        return draw_markers(shape, points, bgr, 2.0, peak=5.0, origin_px=origin)

    if scene == "clean":
        img = draw(uv)
    elif scene == "distractors":
        img = np.maximum(draw(uv), draw(extra))
    elif scene == "lost":
        img = np.maximum(draw(uv[[0, 1, 2, 4]]), draw(extra[:3]))
    else:
        img = np.maximum(draw(uv[[0, 1, 3]]), draw(uv[[2, 4]], (0.25, 1.0, 0.10)))
    return img, intr, origin


@pytest.mark.parametrize("scene", ["clean", "distractors", "lost", "mixed"])
def test_track_gives_the_same_result_with_and_without_pruning(scene, fit_counter):
    img, intr, origin = _drawn(scene)
    fit_counter[0] = 0
    reference = track(img, intr, TrackerSettings(prune=False), origin)
    fits_full = fit_counter[0]
    fit_counter[0] = 0
    pruned = track(img, intr, TrackerSettings(), origin)
    fits_pruned = fit_counter[0]
    assert (pruned.side, pruned.reason, pruned.notes, pruned.failure) == (
        reference.side,
        reference.reason,
        reference.notes,
        reference.failure,
    )
    assert (pruned.uv is None and reference.uv is None) or np.array_equal(pruned.uv, reference.uv)
    assert [b.to_dict() for b in pruned.blobs] == [b.to_dict() for b in reference.blobs]
    assert fits_pruned < fits_full if scene in ("distractors", "lost") else fits_pruned <= fits_full
    assert (reference.side == "red") == (scene != "lost")
    if scene == "lost":
        assert "best reprojection RMS" in reference.reason  # the least RMS of all candidates, settled
    if scene == "mixed":
        assert any("mixed marker colours" in note for note in reference.notes)


def test_fits_are_shared_through_the_memo(fit_counter):
    rng = np.random.default_rng(5)
    intr = Intrinsics.from_geometry(camera_geometry("logitech-c270"))
    blobs, _ = _synthetic_blobs(rng, "v2", intr.matrix(), (1280, 720))
    blobs += [Blob(float(u), float(v), 4.0, "red", 0.01) for u, v in rng.uniform(0, 700, (5, 2))]
    design, settings, memo = beacon_design("v2"), TrackerSettings(), {}
    first = best_five(blobs, design, intr, settings, memo)
    fitted = fit_counter[0]
    assert fitted > 0 and len(memo) == fitted
    fit_counter[0] = 0
    again = best_five(blobs, design, intr, settings, memo)
    assert fit_counter[0] == 0 and _same_answer(first, again)


def test_cross_dimensions_and_the_full_search_for_other_shapes(fit_counter):
    assert cross_dimensions(beacon_design("v2")) == pytest.approx((0.070, 0.046), abs=1e-12)
    assert cross_dimensions(beacon_design("v1")) == pytest.approx((0.045, 0.045), abs=1e-12)
    v2 = beacon_design("v2")
    moved = replace(v2.markers[0], position_m=np.array([0.0, 0.01, 0.0]))  # centre marker off the normal
    skewed = replace(v2, markers=(moved, *v2.markers[1:]))
    assert cross_dimensions(skewed) is None
    rng = np.random.default_rng(9)
    intr = Intrinsics.from_geometry(camera_geometry("logitech-c270"))
    blobs, _ = _synthetic_blobs(rng, "v2", intr.matrix(), (1280, 720))
    reference = best_five(blobs, skewed, intr, TrackerSettings(prune=False))
    fits_full = fit_counter[0]
    fit_counter[0] = 0
    assert _same_answer(reference, best_five(blobs, skewed, intr, TrackerSettings()))
    assert fit_counter[0] == fits_full  # no bound for this shape: every candidate is fitted


def test_an_accepted_five_must_also_beat_the_candidates_that_cannot_be_accepted():
    """A large five fits within its threshold (2 % of 360 px) at 4.5 px RMS; a small, distorted
    five (52 px, marker 2 moved by 12 px) fits better (2.6 px) but not within its own 1 px. The
    full search's answer is the small one, so no fit; the early-stopping search must not
    return the large one, although the small one's bound exceeds its threshold."""
    intr = Intrinsics.from_geometry(camera_geometry("logitech-c270"))
    k, design = intr.matrix(), beacon_design("v2")
    obj = design.marker_positions_m()
    noise = np.random.default_rng(0).normal(size=(5, 2))
    large = _project(obj, k, FACING @ _axis_rotation(2, 10), 0.5, (400, 360)) + noise * 5.5 / np.sqrt(np.mean(noise**2))
    small = _project(obj, k, FACING @ _axis_rotation(2, 10), 4.0, (1000, 300))
    small[1] += [0.0, 12.0]
    small_bound = rms_lower_bounds(small[None], k, *cross_dimensions(design))[0]
    assert 1.0 < small_bound < tracker._fit(small, design, k) < tracker._fit(large, design, k)
    blobs = [Blob(float(u), float(v), 5.0, "red", 1.0) for u, v in np.vstack([large, small])]
    reference = best_five(blobs, design, intr, TrackerSettings(prune=False))
    assert not reference.blobs and np.array_equal(np.sort(reference.uv, axis=0), np.sort(small, axis=0))
    for settle in (True, False):
        assert _same_answer(reference, best_five(blobs, design, intr, TrackerSettings(), settle=settle))
