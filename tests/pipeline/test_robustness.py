"""The detector never crashes on odd images; bad files and bad arguments give one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from pipeline.angles import Intrinsics
from pipeline.detect import detect
from pipeline.failures import Failure
from pipeline.image_io import as_bgr, load_image
from scenes.led import SIDE_COLOURS
from scenes.view import camera_geometry

CAMERA = Intrinsics.from_geometry(camera_geometry("logitech-c270"))  # 1280 × 720


def _check_no_crash(image, **kwargs):
    for tracker in ("thesis", "best"):
        for estimator in ("thesis", "best"):
            out = detect(image, CAMERA, tracker=tracker, estimator=estimator, **kwargs).to_dict()
            if not out["markers"]:
                assert out["side"] is None and isinstance(out["reason"], str) and out["reason"]
                assert "\n" not in out["reason"]
            else:
                assert len(out["markers"]) == 5


dtypes = st.sampled_from([np.uint8, np.uint16, np.float32, np.float64, np.int32, np.bool_])
shapes = st.one_of(
    st.tuples(st.integers(0, 40), st.integers(0, 40)),
    st.tuples(st.integers(0, 40), st.integers(0, 40), st.sampled_from([0, 1, 2, 3, 4, 5])),
    st.tuples(st.integers(0, 3)),
    st.tuples(st.integers(1, 3), st.integers(1, 3), st.integers(1, 3), st.integers(1, 3)),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(image=arrays(dtypes, shapes), origin=st.tuples(st.integers(-5, 1300), st.integers(-5, 800)))
def test_random_arrays_never_crash(image, origin):
    _check_no_crash(image, crop_origin_px=origin)
    _check_no_crash(image)  # as a full frame: wrong size, so "no target" with a reason


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    kind=st.sampled_from(["uniform", "spots", "saturated", "dark", "stripes"]),
    dtype=st.sampled_from([np.uint8, np.uint16, np.float32]),
    channels=st.sampled_from([1, 3, 4]),
)
def test_adversarial_images_never_crash(seed, kind, dtype, channels):
    rng = np.random.default_rng(seed)
    h, w = 90, 120
    if kind == "uniform":
        img = rng.uniform(0, 1, (h, w, channels))
    elif kind == "spots":  # many random bright dots of random colours
        img = np.zeros((h, w, channels))
        for _ in range(rng.integers(1, 60)):
            img[rng.integers(0, h), rng.integers(0, w)] = rng.uniform(0.2, 1, channels)
    elif kind == "saturated":
        img = np.ones((h, w, channels))
    elif kind == "dark":
        img = np.zeros((h, w, channels))
    else:
        img = np.tile((np.arange(w) % 7 < 2)[None, :, None], (h, 1, channels)).astype(float)
    scale = {np.uint8: 255, np.uint16: 65535, np.float32: 1.0}[dtype]
    img = (img * scale).astype(dtype)
    if channels == 1:
        img = img[..., 0]
    _check_no_crash(img, crop_origin_px=(600, 300))


def test_full_frame_noise_and_huge_images():
    rng = np.random.default_rng(0)
    noise = rng.integers(0, 256, (720, 1280, 3), dtype=np.uint8)
    _check_no_crash(noise)
    huge = np.zeros((1, 300_000_000), np.uint8)  # one row, 300 Mpx: refused before any work
    out = detect(huge, CAMERA).to_dict()
    assert out["side"] is None and "too large" in out["reason"]
    big = np.zeros((3456, 5184, 3), np.uint16)  # the T6 frame, 16 bit, dark
    out = detect(big, Intrinsics.from_geometry(camera_geometry("canon-t6-18mm"))).to_dict()
    assert out["side"] is None and out["reason"].startswith("no bright blobs")


def test_as_bgr_normalises_types():
    grey16 = np.full((4, 5), 1000, np.uint16)
    bgr, reason = as_bgr(grey16)
    assert reason is None and bgr.shape == (4, 5, 3) and bgr.dtype == np.uint16
    bgr, reason = as_bgr(np.full((2, 2, 4), 0.5, np.float64))
    assert reason is None and bgr.shape == (2, 2, 3) and bgr.dtype == np.float32
    assert as_bgr(np.array([[np.nan]]))[1] == "image: non-finite pixel values"
    assert as_bgr("not an image")[1].startswith("image:")


@pytest.mark.parametrize("arg", [{"tracker": "magic"}, {"estimator": "x"}, {"alpha": 2.0}])
def test_bad_arguments_name_the_field(arg):
    from pipeline.calibration import Calibration

    cal = Calibration(np.diag([1000.0, 1000.0, 1.0]), np.zeros(5), 1280, 720, 0.1, 10)
    field = next(iter(arg))
    with pytest.raises(ValueError, match=rf"^{field}:"):
        detect(np.zeros((720, 1280, 3), np.uint8), CAMERA, calibration=cal, **arg)
    small = Calibration(np.diag([500.0, 500.0, 1.0]), np.zeros(5), 640, 480, 0.1, 10)
    with pytest.raises(ValueError, match=r"^calibration: made for 640×480 px, the frame is 1280×720 px"):
        detect(np.zeros((720, 1280, 3), np.uint8), CAMERA, calibration=small)


@pytest.mark.parametrize(
    ("name", "content"),
    [("empty.png", b""), ("junk.jpg", b"\x00\x01not a jpeg"), ("junk.tif", b"II*\x00garbage"), ("fake.CR2", b"junk")],
)
def test_bad_files_give_one_line_image_errors(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError) as exc:
        load_image(path)
    assert str(exc.value).startswith("image: ") and "\n" not in str(exc.value)
    with pytest.raises(ValueError, match=r"^image: no such file"):
        load_image(tmp_path / "missing.png")


def test_failures_carry_a_code_beside_the_message():
    """What went wrong is a code a program can act on, not only a sentence."""
    dark = np.zeros((720, 1280, 3), np.uint8)
    best = detect(dark, CAMERA, tracker="best")
    assert best.failure is Failure.NO_BLOBS and best.reason.startswith("no bright blobs")
    study = detect(dark, CAMERA, tracker="thesis")
    assert study.failure is Failure.NO_COLOUR_WITH_FIVE and study.blob_counts == dict.fromkeys(SIDE_COLOURS, 0)
    outside = detect(dark[:10, :10], CAMERA, crop_origin_px=(1275, 0))
    assert outside.failure is Failure.IMAGE and outside.to_dict()["failure"] == "image"
