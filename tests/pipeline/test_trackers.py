"""Both trackers on synthetic images: blobs drawn at the projected markers of a known pose."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from pipeline.angles import Intrinsics
from pipeline.thesis_tracker import (
    STUDY_HSV_RANGES,
    ThesisTrackerSettings,
    _percentile_of_counts,
    derive_hsv_ranges,
    hsv_histogram,
    hsv_ranges_from_histogram,
    thesis_track,
)
from pipeline.tracker import ColourModel, TrackerSettings, calibrate_colours, ideal_chroma, track
from scenes.view import camera_geometry
from tests.helpers.synthetic import draw_markers, hsv_to_bgr, marker_pixels

# colours inside the study's HSV boxes (its "red" is a pale, nearly white pink)
STUDY_HSV = {"red": (170, 25, 255), "green": (78, 100, 255), "blue": (110, 200, 255), "yellow": (19, 220, 255)}
# LED-like colours, BGR linear-ish: strong own channel, some crosstalk
LED_BGR = {
    "red": (0.03, 0.06, 1.0),
    "green": (0.25, 1.0, 0.10),
    "blue": (1.0, 0.30, 0.02),
    "yellow": (0.02, 0.60, 1.0),
}


def _crop(uv, margin):
    u0 = int(np.floor(uv[:, 0].min())) - margin
    v0 = int(np.floor(uv[:, 1].min())) - margin
    u0 -= u0 % 2  # even origin: the study's 50 % grid stays aligned with the full frame's
    v0 -= v0 % 2
    w = int(np.ceil(uv[:, 0].max())) + margin - u0
    h = int(np.ceil(uv[:, 1].max())) + margin - v0
    return (u0, v0), (h, w)


def _assert_numbering(found_uv, true_uv, tol_px):
    d = np.hypot(*(found_uv[:, None, :] - true_uv[None, :, :]).transpose(2, 0, 1))
    assert np.all(np.argmin(d, axis=1) == np.arange(5)), d.round(2)
    assert np.all(np.diag(d) < tol_px), np.diag(d)


@pytest.mark.parametrize(
    ("camera", "range_m", "radius_px"), [("canon-t6-18mm", 2.0, 18.0), ("logitech-c270", 0.8, 9.0)]
)
@pytest.mark.parametrize("yaw", [0.0, 25.0, -20.0])
def test_study_tracker_finds_side_and_numbers_markers(camera, range_m, radius_px, yaw):
    """Unclipped discs (the erosion removes blobs under ~13 processed pixels tall)."""
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, range_m, yaw)
    origin, shape = _crop(uv, 120)
    for colour, hsv in STUDY_HSV.items():
        img = draw_markers(shape, uv, hsv_to_bgr(*hsv), radius_px, profile="disc", origin_px=origin)
        res = thesis_track(img, intr, crop_origin_px=origin)
        assert res.side == colour, (colour, res.reason)
        # the erosion's off-centre anchor biases centres by a few full-resolution pixels
        _assert_numbering(res.uv, uv, tol_px=6.0)


def test_study_tracker_calls_clipped_cores_of_other_colours_red():
    """Documented weakness: the red box (S <= 35, H 81-180) catches near-white clipped cores."""
    camera = "logitech-c270"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 0.8, 10.0)
    origin, shape = _crop(uv, 100)
    img = draw_markers(shape, uv, hsv_to_bgr(*STUDY_HSV["green"]), 6.0, peak=3.0, origin_px=origin)
    assert thesis_track(img, intr, crop_origin_px=origin).side == "red"
    unclipped = draw_markers(shape, uv, hsv_to_bgr(*STUDY_HSV["green"]), 9.0, profile="disc", origin_px=origin)
    assert thesis_track(unclipped, intr, crop_origin_px=origin).side == "green"


def test_study_tracker_centre_bias_from_the_erosion_anchor():
    """Documented weakness: the (2, 4) kernel anchored at (1, 2) shifts blob centres right and down."""
    camera = "logitech-c270"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 0.8, 0.0)
    origin, shape = _crop(uv, 100)
    img = draw_markers(shape, uv, hsv_to_bgr(*STUDY_HSV["green"]), 9.0, profile="disc", origin_px=origin)
    res = thesis_track(img, intr, crop_origin_px=origin)
    bias = (res.uv - uv).mean(axis=0)
    print(f"\nstudy tracker centre bias (disc blobs, no resize): du {bias[0]:+.2f} px, dv {bias[1]:+.2f} px")
    assert 0.5 < bias[0] < 3.0 and 0.5 < bias[1] < 3.0


def test_study_tracker_loses_the_side_with_one_extra_blob():
    camera = "logitech-c270"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 0.8, 10.0)
    extra = np.vstack([uv, uv[1] + [0.0, 200.0]])  # a reflection on the floor
    origin, shape = _crop(extra, 100)
    img = draw_markers(shape, extra, hsv_to_bgr(*STUDY_HSV["green"]), 9.0, profile="disc", origin_px=origin)
    res = thesis_track(img, intr, crop_origin_px=origin)
    assert res.side is None and "green: 6" in res.reason
    best = track(img, intr, TrackerSettings(colour_model=_calibrated_model(hsv_colours=True)), origin)
    assert best.side == "green"
    _assert_numbering(best.uv, uv, tol_px=0.3)


def _reference_capture(bgr, size_px=8.0, peak=1.0):
    uv, _ = marker_pixels("logitech-c270", 1.0, 0.0)
    origin, shape = _crop(uv, 40)
    return draw_markers(shape, uv, bgr, size_px, peak=peak, origin_px=origin)


def _calibrated_model(hsv_colours=False) -> ColourModel:
    colours = {c: hsv_to_bgr(*STUDY_HSV[c]) for c in STUDY_HSV} if hsv_colours else LED_BGR
    return calibrate_colours({c: [_reference_capture(bgr)] for c, bgr in colours.items()})


@pytest.mark.parametrize("calibrated", [False, True], ids=["default-colours", "calibrated-colours"])
@pytest.mark.parametrize(
    ("camera", "range_m", "size_px", "peak"),
    [
        ("canon-t6-18mm", 5.0, 2.0, 0.8),  # unsaturated spots
        ("canon-t6-18mm", 10.0, 1.5, 25.0),  # white clipped cores, coloured fringes
        ("logitech-c270", 3.0, 1.2, 0.7),
        ("logitech-c270", 6.0, 1.0, 30.0),
    ],
)
def test_best_tracker_side_numbering_and_subpixel_centroids(camera, range_m, size_px, peak, calibrated):
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    settings = TrackerSettings(colour_model=_calibrated_model() if calibrated else None)
    rng = np.random.default_rng(int(range_m * 10) + (1 if calibrated else 0))
    worst = 0.0
    for yaw in (0.0, 30.0, -15.0):
        uv, _ = marker_pixels(camera, range_m, yaw)
        uv = uv + rng.uniform(-0.5, 0.5, uv.shape)  # arbitrary sub-pixel phases
        origin, shape = _crop(uv, 40)
        for colour, bgr in LED_BGR.items():
            img = draw_markers(shape, uv, bgr, size_px, peak=peak, origin_px=origin)
            res = track(img, intr, settings, origin)
            assert res.side == colour, (yaw, colour, res.reason, [b.chroma for b in res.blobs])
            _assert_numbering(res.uv, uv, tol_px=0.5)
            worst = max(worst, float(np.abs(res.uv - uv).max()))
            if peak > 1:
                assert min(b.saturated_fraction for b in res.blobs) > 0.2
    print(f"\nbest tracker worst centroid error {camera} {range_m} m peak {peak}: {worst:.3f} px")
    assert worst < 0.1


def test_best_tracker_ignores_distractors_of_the_same_and_other_colours():
    camera = "canon-t6-18mm"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 4.0, 12.0)
    origin, shape = _crop(uv, 150)
    distractors = uv.mean(axis=0) + np.array([[90.0, 110.0], [-120.0, 60.0], [40.0, -130.0]])
    img = draw_markers(shape, uv, LED_BGR["blue"], 2.0, peak=5.0, origin_px=origin)
    img = np.maximum(img, draw_markers(shape, distractors, LED_BGR["blue"], 2.0, peak=5.0, origin_px=origin))
    other = uv + np.array([60.0, 250.0])  # another side's markers (yellow), partly inside the crop
    img = np.maximum(img, draw_markers(shape, other, LED_BGR["yellow"], 2.0, peak=5.0, origin_px=origin))
    res = track(img, intr, None, origin)
    assert res.side == "blue", res.reason
    _assert_numbering(res.uv, uv, tol_px=0.1)
    assert any("extra blue" in n for n in res.notes)


def test_best_tracker_reports_lost_and_merged_markers():
    camera = "canon-t6-18mm"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 4.0, 0.0)
    origin, shape = _crop(uv, 60)
    lost = draw_markers(shape, uv[:4], LED_BGR["red"], 2.0, peak=0.8, origin_px=origin)
    res = track(lost, intr, None, origin)
    assert res.side is None and "red: 4 blob(s), 1 marker(s) lost or merged" in res.reason
    merged_uv = np.vstack([uv[[0, 2, 3, 4]], (uv[0] + uv[1]) / 2])
    merged = draw_markers(shape, uv[[0, 2, 3, 4]], LED_BGR["red"], 2.0, peak=0.8, origin_px=origin)
    # markers 1 and 2 blurred into one elongated blob
    for t in np.linspace(0.0, 1.0, 25):
        spot = uv[0] + t * (uv[1] - uv[0])
        merged = np.maximum(merged, draw_markers(shape, [spot], LED_BGR["red"], 2.0, peak=0.8, origin_px=origin))
    res = track(merged, intr, None, origin)
    assert res.side is None and "merged" in res.reason, res.reason
    del merged_uv


def test_default_colour_references_follow_from_the_led_spectra():
    """Recompute DEFAULT_CHROMA: LED spectrum → CIE 1931 XYZ → linear sRGB (clipped) → (r, g)."""
    import colour as colour_science

    from scenes import spectra
    from scenes.led import led_for_side

    cmfs = spectra.cie1931_cmfs().values.T

    def chroma(led):
        xyz = spectra.integrate_nm(led.spectral_shape[None, :] * cmfs)
        rgb = colour_science.XYZ_to_RGB(xyz, colour_science.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False)
        rgb = np.clip(rgb, 0, None)
        return rgb[:2] / rgb.sum()

    for name, (r, g) in ColourModel.default().means.items():
        assert np.allclose([r, g], chroma(led_for_side(name)), atol=1e-4), name
    # a beacon's own references: the study's beacons give exactly the tabulated ones, and a side
    # moved within its colour's band (cyan-green 505 nm, amber 597 nm) its own spectrum's
    assert ColourModel.for_beacon("v2").means == ColourModel.for_beacon("v1").means == ColourModel.default().means
    for side, nm in (("green", 505.0), ("yellow", 597.0), ("blue", 452.0)):
        led = dataclasses.replace(led_for_side(side), dominant_wavelength_nm=nm)
        assert np.allclose(ideal_chroma(led), chroma(led), atol=1e-4), side
        assert np.hypot(*(np.array(ideal_chroma(led)) - ColourModel.default().means[side])) > 0.02, side


def test_study_threshold_procedure_from_close_range_captures():
    """Derive HSV boxes from 150 mm captures of each side, then detect with them at range."""
    rng = np.random.default_rng(7)
    derived = {}
    for colour, (h, s, v) in STUDY_HSV.items():
        captures = []
        for k in range(3):  # a few captures with slightly different hue/saturation
            hsv = (h + rng.uniform(-1, 1), s + rng.uniform(-5, 5), v)
            uv, _ = marker_pixels("logitech-c270", 0.15 + 0.01 * k, 0.0)
            origin, shape = _crop(uv, 60)
            captures.append(draw_markers(shape, uv, hsv_to_bgr(*hsv), 25.0, peak=2.0, origin_px=origin))
        derived[colour] = derive_hsv_ranges(captures, colour)
        for lo, hi in derived[colour]:
            assert all(a <= b for a, b in zip(lo, hi, strict=True))
        hue_ok = any(lo[0] <= h <= hi[0] and lo[1] <= s <= hi[1] for lo, hi in derived[colour])
        assert hue_ok, (colour, derived[colour])
    intr = Intrinsics.from_geometry(camera_geometry("logitech-c270"))
    uv, _ = marker_pixels("logitech-c270", 0.8, 15.0)
    origin, shape = _crop(uv, 100)
    for colour, hsv in STUDY_HSV.items():
        img = draw_markers(shape, uv, hsv_to_bgr(*hsv), 9.0, profile="disc", origin_px=origin)
        res = thesis_track(img, intr, ThesisTrackerSettings(hsv_ranges=derived), origin)
        assert res.side == colour, (colour, res.reason, derived)
    print("\nderived HSV boxes:", derived, "\nstudy's:", STUDY_HSV_RANGES)


def test_derived_red_range_wraps_around_hue_zero():
    captures = [
        _reference_capture(hsv_to_bgr(176, 200, 255), size_px=10.0, peak=2.0),
        _reference_capture(hsv_to_bgr(2, 200, 255), size_px=10.0, peak=2.0),
    ]
    boxes = derive_hsv_ranges(captures, "red")
    assert len(boxes) == 2
    assert {b[0][0] for b in boxes} == {0} | {min(b[0][0] for b in boxes if b[0][0] > 0)}
    assert any(lo[0] <= 176 <= hi[0] for lo, hi in boxes) and any(lo[0] <= 2 <= hi[0] for lo, hi in boxes)


@pytest.mark.parametrize("yaw_deg", [30.0, 56.0, 58.0, 75.0])
def test_numbering_rules_at_large_yaw(yaw_deg):
    """The study's rule (4 highest, 5 lowest, then 2, 1, 3 by azimuth) breaks once marker 1
    passes marker 3 in azimuth, at yaw = atan(70/46) = 56.7° for V2; the cross rule keeps
    the true numbering among its candidates (the better tracker then picks it by fit).
    """
    from pipeline.angles import pinhole_angles
    from pipeline.markers import cross_candidates, number_study

    camera = "canon-t6-18mm"
    intr = Intrinsics.from_geometry(camera_geometry(camera))
    uv, _ = marker_pixels(camera, 3.0, yaw_deg)
    az, el = pinhole_angles(uv[:, 0], uv[:, 1], intr)
    study_ok = bool(np.array_equal(number_study(az, el), np.arange(5)))
    assert study_ok == (yaw_deg < np.degrees(np.arctan(70 / 46)))
    assert any(np.array_equal(cand, np.arange(5)) for cand in cross_candidates(uv))


def _cross_candidates_one_by_one(pts):
    """Reference: the numbering rule written point set by point set, in plain Python."""

    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    out = []
    for centre in range(5):
        others = [i for i in range(5) if i != centre]
        q = pts[others]
        ring = [others[i] for i in np.argsort(np.arctan2(*(q - q.mean(axis=0)).T[::-1]))]
        a, b, c, d = pts[ring[0]], pts[ring[2]], pts[ring[1]], pts[ring[3]]
        if not (orient(a, b, c) * orient(a, b, d) < 0 and orient(c, d, a) * orient(c, d, b) < 0):
            continue
        d1, d2 = (ring[0], ring[2]), (ring[1], ring[3])
        dir1, dir2 = b - a, d - c
        hor, ver = (d1, d2) if abs(dir1[0]) * abs(dir2[1]) >= abs(dir1[1]) * abs(dir2[0]) else (d2, d1)
        two, three = sorted(hor, key=lambda i: -pts[i, 0])
        four, five = sorted(ver, key=lambda i: pts[i, 1])
        out.append([centre, two, three, four, five])
    return out


def test_cross_candidates_of_many_sets_equal_the_one_by_one_rule():
    from pipeline.markers import cross_candidates_many

    rng = np.random.default_rng(7)
    sets = rng.normal(size=(3000, 5, 2)) * 40
    sets[:500] = np.round(sets[:500] / 10)  # ties in x, y and angle on a coarse grid
    which, numbered = cross_candidates_many(sets)
    expected = [(s, c) for s, pts in enumerate(sets) for c in _cross_candidates_one_by_one(pts)]
    assert len(expected) > 3000
    assert [(int(w), list(map(int, n))) for w, n in zip(which, numbered, strict=True)] == expected


def test_derived_boxes_span_the_regions_given_not_the_brightest_pixels():
    """A person draws the box around the markers' cores: with ``regions`` the box spans those pixels'
    colour, even where a brighter patch of another colour would win Otsu's lit pixels."""
    image = np.zeros((60, 80, 3), np.uint8)
    image[10:20, 10:20] = cv2.cvtColor(np.uint8([[[60, 200, 150]]]), cv2.COLOR_HSV2BGR)[0, 0]  # the marker
    image[30:50, 40:70] = cv2.cvtColor(np.uint8([[[120, 200, 255]]]), cv2.COLOR_HSV2BGR)[0, 0]  # a brighter glow
    region = np.zeros(image.shape[:2], bool)
    region[10:20, 10:20] = True
    ((lo, hi),) = derive_hsv_ranges([image], "green", margin=(0, 0, 0), regions=[region])
    assert lo[0] <= 60 <= hi[0] and hi[0] - lo[0] <= 2 and lo[1] >= 195
    ((lo, hi),) = derive_hsv_ranges([image], "green", margin=(0, 0, 0))
    assert lo[0] <= 120 <= hi[0]  # Otsu's lit pixels include the glow
    with pytest.raises(ValueError, match=r"regions\[0\]"):
        derive_hsv_ranges([image], "green", regions=[region[:10]])


def test_percentiles_of_counts_are_numpys_of_the_values():
    """The percentiles of a histogram are NumPy's (linear method) of the values it counts, bit for bit."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        values = rng.integers(0, int(rng.integers(1, 256)), int(rng.integers(1, 3000)))
        q = np.concatenate([rng.uniform(0, 100, 6), [0.0, 1.0, 50.0, 99.0, 100.0]])
        assert np.array_equal(_percentile_of_counts(np.bincount(values, minlength=256), q), np.percentile(values, q))


def test_boxes_from_summed_histograms_are_the_pooled_images_boxes():
    """:func:`derive_hsv_ranges` of several captures equals :func:`hsv_ranges_from_histogram` of their
    histograms summed (how validate derives them, one capture per task), for hues that wrap (red) and not."""
    rng = np.random.default_rng(4)
    for hue in (2, 60, 175):
        images, regions = [], []
        for _ in range(3):
            hsv = np.stack(
                [(hue + rng.integers(-6, 7, (40, 50))) % 180, rng.integers(120, 256, (40, 50)),
                 rng.integers(60, 256, (40, 50))], axis=-1
            ).astype(np.uint8)  # fmt: skip
            images.append(cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR))
            regions.append(rng.random((40, 50)) < 0.3)
        total = sum(hsv_histogram(i, r) for i, r in zip(images, regions, strict=True))
        assert hsv_ranges_from_histogram(total) == derive_hsv_ranges(images, "red", regions=regions)
        assert total.sum() == 3 * sum(r.sum() for r in regions)  # every region pixel counted once per channel
    with pytest.raises(ValueError, match="counts"):
        hsv_ranges_from_histogram(np.zeros((3, 256), np.int64))
