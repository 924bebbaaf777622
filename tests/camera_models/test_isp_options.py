"""ISP stage options: legacy bytes, noise reduction, highlight handling, tone curve, sharpening."""

from __future__ import annotations

import dataclasses

import colour
import cv2
import numpy as np
import pytest

from camera_models.camera import BODY_DIR, load_camera, with_overrides
from camera_models.isp import (
    check_isp_options,
    daylight_gains,
    encode_jpeg,
    noise_reduction_strength,
    process,
    reduce_noise,
    tone_curve,
    unsharp_mask,
)
from camera_models.isp_reference import reference_rgb8
from scenes.sourced import load_sourced

CASES = [(name, x0, y0) for name in ("canon-t6-18mm", "logitech-c270", "spedal-920") for x0, y0 in ((0, 0), (3, 1))]


SAME_CODES = 1e-4
"""Share of bytes the 16-bit ISP may set one code off the float32 path: values within float32
rounding of a code step."""


def _seeded_raw(cam) -> np.ndarray:
    s = cam.sensor
    rng = np.random.default_rng(20240611)
    raw = rng.integers(int(s.black_level_DN) - 50, int(s.white_level_DN) + 1, size=(300, 64))
    return raw.clip(0, 2**s.adc_bits - 1).astype(np.uint16)


def _with(cam, **isp):
    return dataclasses.replace(cam, isp=dataclasses.replace(cam.isp, **isp))


def _hsv(rgb):
    return cv2.cvtColor(np.asarray(rgb, np.uint8).reshape(1, 1, 3)[..., ::-1].copy(), cv2.COLOR_BGR2HSV)[0, 0]


def _code_differences(a: np.ndarray, b: np.ndarray) -> tuple[int, float]:
    """(largest |difference| in 8-bit codes, fraction of bytes that differ)."""
    d = np.abs(a.astype(int) - b.astype(int))
    return int(d.max()), float(np.mean(d > 0))


@pytest.mark.parametrize(("name", "x0", "y0"), CASES)
def test_legacy_is_the_default_and_matches_the_float_path(name, x0, y0):
    """The 16-bit OpenCV ISP against the float path it replaced (camera_models/isp_reference.py):
    the same codes but where float32 rounding sits on a code step (≤ 10⁻⁴ of the bytes, one
    code), on a raw spanning black to past the clip."""
    cam = load_camera(name)
    assert cam.isp.processing == "legacy" and cam.isp.highlight == "clip"
    assert cam.isp.noise_reduction == "none" and cam.isp.tone_curve == "srgb" and cam.isp.sharpening_amount == 0.0
    raw = _seeded_raw(cam)
    img = process(raw, cam, x0, y0)
    largest, share = _code_differences(img.rgb8, reference_rgb8(raw, cam, x0, y0))
    assert largest <= 1 and share <= SAME_CODES, (largest, share)
    assert img.jpeg == encode_jpeg(img.rgb8, cam)


@pytest.mark.parametrize("highlight", ["clip", "unclip", "blend"])
@pytest.mark.parametrize("tone", ["srgb", "picture-standard", "linear"])
def test_every_highlight_mode_and_tone_curve_matches_the_float_path(highlight, tone):
    cam = _with(load_camera("canon-t6-18mm"), highlight=highlight, tone_curve=tone, tone_contrast=0.4)
    raw = _seeded_raw(cam)
    largest, share = _code_differences(process(raw, cam, 1, 0).rgb8, reference_rgb8(raw, cam, 1, 0))
    assert largest <= 1 and share <= SAME_CODES, (largest, share)


def _dark_webcam_raw(cam) -> np.ndarray:
    """A C270 dark frame's noise (Gaussian about the black level, as at the webcam's top gain)."""
    s = cam.sensor
    rng = np.random.default_rng(7)
    return np.clip(np.rint(rng.normal(s.black_level_DN + 6.0, 9.0, size=(480, 640))), 0, 1023).astype(np.uint16)


def test_dark_frame_codes_match_the_float_path_and_rounding_alone_would_not(monkeypatch):
    """On dark noise, where a webcam's false blobs are made, the codes match the float path.
    Rounding the transform's output to 16 bits without re-encoding the values next to a code
    step (the path before this check) moves more than 0.1 % of the bytes, more up than down."""
    import camera_models.isp as isp

    cam = load_camera("logitech-c270")
    raw = _dark_webcam_raw(cam)
    ref = reference_rgb8(raw, cam).astype(int)
    largest, share = _code_differences(process(raw, cam).rgb8, ref)
    assert largest <= 1 and share <= SAME_CODES, (largest, share)
    monkeypatch.setattr(isp, "_encode_near_steps", lambda *args: None)
    moved = process(raw, cam).rgb8.astype(int) - ref
    assert np.mean(moved != 0) > 0.001 and np.sum(moved > 0) > np.sum(moved < 0)


def test_the_equivalence_check_fails_on_a_planted_change():
    """Gains 2 % off (a wrong white balance) break the tolerance the tests above hold."""
    cam = load_camera("canon-t6-18mm")
    raw = _seeded_raw(cam)
    from camera_models.isp import white_balance_gains

    off = white_balance_gains(raw, cam) * np.array([1.02, 1.0, 1.0])
    _largest, share = _code_differences(process(raw, cam).rgb8, reference_rgb8(raw, cam, gains=off))
    assert share > 0.01


def test_noise_reduction_is_opencv_nonlocal_means():
    rng = np.random.default_rng(1)
    img = np.clip(rng.normal(90, 12, (64, 80, 3)), 0, 255).astype(np.uint8)
    direct = cv2.fastNlMeansDenoisingColored(np.ascontiguousarray(img[..., ::-1]), None, 4.0, 15.0, 7, 21)[..., ::-1]
    assert np.array_equal(reduce_noise(img, 4.0, 15.0), direct)


def test_process_applies_noise_reduction_at_the_frames_gain():
    cam = load_camera("canon-t6-18mm")
    nr = _with(
        cam, noise_reduction="nlmeans", nr_analog_gain=(1.0, 64.0), nr_luma_h=(1.0, 3.0), nr_chroma_h=(3.0, 16.0)
    )
    assert noise_reduction_strength(nr, 64.0) == (3.0, 16.0)
    assert noise_reduction_strength(nr, 8.0) == pytest.approx((2.0, 9.5))  # halfway in log(gain)
    assert noise_reduction_strength(nr, 500.0) == (3.0, 16.0)  # held beyond the table
    raw = _seeded_raw(cam)[:64]
    legacy = process(raw, cam).rgb8
    assert np.array_equal(process(raw, nr, analog_gain=64.0).rgb8, reduce_noise(legacy, 3.0, 16.0))
    with pytest.raises(ValueError, match=r"^analog_gain: "):
        process(raw, nr)


@pytest.mark.parametrize(
    ("name", "body_name"), [("canon-t6-18mm", "canon-eos-1300d"), ("logitech-c270", "logitech-c270")]
)
def test_noise_reduction_switched_on_alone_uses_the_bodys_strengths(name, body_name):
    # the unknowns registry turns noise reduction on by itself ("isp.noise_reduction"): the strengths by
    # gain are the body's, the same whichever processing option is chosen
    legacy = load_camera(name)
    on = with_overrides(legacy, {"isp.noise_reduction": "nlmeans"})
    body = load_sourced(BODY_DIR / f"{body_name}.toml")[0]["isp"]["processing_options"]["in-camera"]
    assert on.isp.nr_analog_gain == tuple(body["nr_analog_gain"]) and on.isp.highlight == legacy.isp.highlight
    gain = body["nr_analog_gain"][-1]
    raw = _seeded_raw(legacy)[:64]
    expected = reduce_noise(process(raw, legacy).rgb8, body["nr_luma_h"][-1], body["nr_chroma_h"][-1])
    assert np.array_equal(process(raw, on, analog_gain=gain).rgb8, expected)


def test_noise_reduction_lowers_chroma_noise_of_a_flat_patch():
    """Flat grey patch with chroma noise (std 6 codes in Cr, Cb): NR cuts it ≥ 3x; the mean stays within 1 code."""
    rng = np.random.default_rng(2)
    ycc = np.empty((128, 128, 3))
    ycc[..., 0] = 110 + rng.normal(0, 2, (128, 128))
    ycc[..., 1:] = 128 + rng.normal(0, 6, (128, 128, 2))
    img = cv2.cvtColor(np.clip(np.rint(ycc), 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2RGB)
    out = reduce_noise(img, 2.0, 20.0)
    before = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb).reshape(-1, 3).astype(float)
    after = cv2.cvtColor(out, cv2.COLOR_RGB2YCrCb).reshape(-1, 3).astype(float)
    assert np.all(after[:, 1:].std(0) < before[:, 1:].std(0) / 3)
    assert np.abs(out.reshape(-1, 3).mean(0) - img.reshape(-1, 3).mean(0)).max() < 1.0


def _core_raw(cam, b_fraction: float) -> np.ndarray:
    """RGGB mosaic whose R and G sites sit at the white level, B at a fraction of it."""
    s = cam.sensor
    raw = np.full((16, 16), s.white_level_DN, np.uint16)
    raw[1::2, 1::2] = round(s.black_level_DN + b_fraction * (s.white_level_DN - s.black_level_DN))
    return raw


def test_clipped_red_core_is_pale_yellow_with_clip_and_white_with_blend():
    cam = load_camera("canon-t6-18mm")
    assert cam.sensor.cfa == "RGGB"
    raw = _core_raw(cam, 0.5)
    clip = process(raw, _with(cam, highlight="clip")).rgb8[8, 8]
    blend = process(raw, _with(cam, highlight="blend")).rgb8[8, 8]
    h, s_, v = _hsv(clip)
    assert clip[0] >= 245 and clip[1] >= 245 and clip[2] < 215 and 20 <= h <= 35 and s_ > 40 and v == 255
    assert np.all(blend >= 250)
    # the output pixel's channels follow dcraw -H 2: more neutral than -H 0 even when B is nearly dark
    assert _hsv(process(_core_raw(cam, 0.05), _with(cam, highlight="blend")).rgb8[8, 8])[1] < 128


def test_highlight_mode_leaves_unclipped_pixels_alone():
    cam = load_camera("canon-t6-18mm")
    s = cam.sensor
    assert daylight_gains(cam).max() < 2.5
    rng = np.random.default_rng(4)
    raw = rng.integers(
        int(s.black_level_DN), int(s.black_level_DN + 0.4 * (s.white_level_DN - s.black_level_DN)), (40, 40)
    )
    raw = raw.astype(np.uint16)
    ref = process(raw, cam).rgb8
    for mode in ("unclip", "blend"):
        assert np.array_equal(process(raw, _with(cam, highlight=mode)).rgb8, ref)


def test_tone_curves():
    x = np.linspace(0.0, 1.0, 10001)
    assert np.array_equal(tone_curve(x, "srgb"), colour.cctf_encoding(x, function="sRGB"))
    for c in (0.0, 0.25, 0.5, 1.0):
        y = tone_curve(x, "picture-standard", c)
        assert y[0] == 0.0 and y[-1] == pytest.approx(1.0, abs=1e-12)
        assert np.all(np.diff(y) >= 0)
    # an S-curve about the encoded mid-point: darker below v = 0.5 (mid-grey, v = 0.46), brighter above
    lin = np.array([0.18, 0.5])
    assert np.all(np.sign(tone_curve(lin, "picture-standard", 0.25) - tone_curve(lin, "srgb")) == [-1, 1])
    # the picture-style path with zero contrast is the sRGB curve, to the table's rounding (≤ 1 code)
    cam = load_camera("canon-t6-18mm")
    raw = _seeded_raw(cam)[:64]
    a = process(raw, cam).rgb8.astype(int)
    b = process(raw, _with(cam, tone_curve="picture-standard", tone_contrast=0.0)).rgb8.astype(int)
    assert np.abs(a - b).max() <= 1


def test_sharpening_raises_edge_contrast_and_keeps_flat_areas():
    img = np.full((32, 32, 3), 60, np.uint8)
    img[:, 16:] = 160
    out = unsharp_mask(img, 0.5, 1.0)
    y_in = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb)[..., 0].astype(int)
    y_out = cv2.cvtColor(out, cv2.COLOR_RGB2YCrCb)[..., 0].astype(int)
    assert y_out[:, 15].mean() < y_in[:, 15].mean() - 5 and y_out[:, 16].mean() > y_in[:, 16].mean() + 5
    assert np.abs(out[:, :8].astype(int) - img[:, :8]).max() <= 1


def test_bad_options_name_the_field():
    cam = load_camera("canon-t6-18mm")
    for field, value in [
        ("highlight", "rebuild"),
        ("noise_reduction", "wavelet"),
        ("tone_curve", "log"),
        ("tone_contrast", 2.0),
        ("output", "tiff"),
    ]:
        with pytest.raises(ValueError, match=rf"^isp\.{field}: "):
            check_isp_options(_with(cam, **{field: value}))


@pytest.mark.parametrize("body", ["canon-eos-1300d", "logitech-c270", "spedal-920"])
def test_body_processing_options_are_valid(body):
    """Each body file's processing tables build a valid ISP; the default is legacy."""
    values, _ = load_sourced(BODY_DIR / f"{body}.toml")
    isp = values["isp"]
    assert isp["processing"] == "legacy" and "legacy" in isp["processing_options"]
    cam = load_camera({"canon-eos-1300d": "canon-t6-18mm"}.get(body, body))
    for name, pp in isp["processing_options"].items():
        kw = {k: tuple(v) if isinstance(v, list) else v for k, v in pp.items()}
        check_isp_options(_with(cam, processing=name, **kw))


def test_a_raw_clip_below_the_isps_white_point_turns_a_clipped_core_pale_violet():
    """Every site of the core clipped in the raw. With the ISP's white point at the raw clip (ratio 1)
    the core is white; with the raw clipping 8 % below it, the clipped sites reach only 0.92 of white,
    white balance lifts R and B (gains > 1/0.92) back to white but leaves G at 0.92: a pale
    magenta-violet core (OpenCV hue near 150 of 180), as dcraw warns for a saturation level set too high."""
    cam = load_camera("canon-t6-18mm")
    gains = daylight_gains(cam)
    assert gains[0] > 1 / 0.92 and gains[2] > 1 / 0.92 and gains[1] == 1.0
    raw = np.full((16, 16), cam.sensor.white_level_DN, np.uint16)
    assert np.all(process(raw, cam).rgb8[8, 8] >= 250)
    low = _with(cam, raw_saturation_ratio=0.92)
    core = process(raw, low).rgb8[8, 8]
    h, s_, v = _hsv(core)
    assert core[1] < core[0] == core[2] == 255 and h == 150 and 10 <= s_ <= 20 and v == 255
    seeded = _seeded_raw(low)  # the 16-bit path still matches the float path
    worst, share = _code_differences(process(seeded, low).rgb8, reference_rgb8(seeded, low))
    assert worst <= 1 and share <= SAME_CODES
    with pytest.raises(ValueError, match=r"isp\.raw_saturation_ratio: expected 0\.5 < ratio <= 1"):
        check_isp_options(_with(cam, raw_saturation_ratio=1.1))


def test_a_borrowed_sensitivity_swaps_the_curve_and_refits_only_a_fitted_matrix():
    """``sensor.ssf_csv``: the new curve at the same peak QE; a webcam's matrix (fitted to its curve) is
    fitted again and maps white to white, the T6's published DNG matrix is the body's firmware and stays."""
    from camera_models.camera import builtin_ssf_names, with_overrides
    from camera_models.isp import camera_to_srgb_matrix

    assert {"canon_eos_100d.csv", "canon_eos_m.csv", "nikon_d850.csv"} <= set(builtin_ssf_names())
    c270 = load_camera("logitech-c270")
    other = with_overrides(c270, {"sensor.ssf_csv": "nikon_d850.csv"})
    assert other.sensor.qe_rgb.max() == pytest.approx(c270.sensor.qe_rgb.max(), rel=1e-12)
    assert not np.allclose(other.sensor.qe_rgb, c270.sensor.qe_rgb)
    assert not np.allclose(other.isp.camera_to_xyz, c270.isp.camera_to_xyz)
    np.testing.assert_allclose(camera_to_srgb_matrix(other) @ np.ones(3), 1.0, rtol=1e-9)  # white stays white
    same = with_overrides(c270, {"sensor.ssf_csv": "sony_ilce_6400.csv"})  # its own curve: the same camera
    np.testing.assert_array_equal(same.sensor.qe_rgb, c270.sensor.qe_rgb)
    t6 = load_camera("canon-t6-18mm")
    assert t6.isp.colour_matrix == "published"
    swapped = with_overrides(t6, {"sensor.ssf_csv": "canon_eos_200d.csv"})
    np.testing.assert_array_equal(swapped.isp.camera_to_xyz, t6.isp.camera_to_xyz)
    with pytest.raises(ValueError, match=r"camera override 'sensor\.ssf_csv': expected one of .*got 'nope\.csv'"):
        with_overrides(t6, {"sensor.ssf_csv": "nope.csv"})
