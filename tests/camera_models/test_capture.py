"""Whole-camera behaviour: determinism, bad input, automatic exposure in the dark, JPEG chroma subsampling."""

from __future__ import annotations

import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.capture import capture
from camera_models.exposure import manual_exposure
from camera_models.isp import encode_jpeg
from camera_models.sensor import SensorSettings
from camera_models.sensor_paths import expose
from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance


def spot_radiance(name: str, L: float = 50.0) -> SpectralRadiance:
    g = load_camera(name).geometry
    cx, cy = (int(c) for c in g.principal_point_px)
    grid = PixelGrid(g.width_px, g.height_px, g.focal_length_px, g.principal_point_px, cx - 20, cy - 20, 40, 40, 2)
    image = np.zeros(grid.shape, np.float32)
    image[36:44, 36:44] = L
    shape = spectra.led_shape(630.0, 20.0)
    return SpectralRadiance(grid, (RadianceComponent("led:red", image, np.asarray(shape)),), {}, "synthetic")


def test_same_seed_same_bytes():
    cam = load_camera("logitech-c270")
    a = capture(spot_radiance("logitech-c270"), cam, seed=5)
    b = capture(spot_radiance("logitech-c270"), cam, seed=5)
    c = capture(spot_radiance("logitech-c270"), cam, seed=6)
    assert a.image.jpeg == b.image.jpeg and a.raw.tobytes() == b.raw.tobytes()
    assert a.raw.tobytes() != c.raw.tobytes()


def test_dark_frame_drives_webcam_auto_exposure_to_its_limits():
    """A tiny bright spot in a black frame: exposure and gain climb to the maxima, the spot saturates."""
    cam = load_camera("logitech-c270")
    cap = capture(spot_radiance("logitech-c270", L=5.0), cam, seed=1)
    assert cap.exposure.exposure_s == pytest.approx(cam.exposure.max_exposure_s)
    assert cap.exposure.gain_code == cam.sensor.gain_code_max
    assert cap.raw.max() == cam.sensor.white_level_DN


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"exposure_s": -1.0}, "exposure_s"),
        ({"exposure_s": 100.0}, "exposure_s"),
        ({"iso": 50}, "iso"),
        ({"iso": 25600}, "iso"),
    ],
)
def test_impossible_settings_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}: "):
        manual_exposure(load_camera("canon-t6-18mm"), **kwargs)


def test_unknown_camera_and_bad_sensor_settings():
    with pytest.raises(ValueError, match=r"^camera: "):
        load_camera("nikon-d1")
    with pytest.raises(ValueError, match=r"^exposure_s: "):
        expose(np.zeros((2, 2)), load_camera("canon-t6-18mm").sensor, SensorSettings(-1.0, 1.0), 0)
    with pytest.raises(ValueError, match=r"^gain: "):
        load_camera("logitech-c270").sensor.analog_gain(gain_code=300)


def test_jpeg_uses_the_cameras_chroma_subsampling():
    """The SOF0 header's luma sampling factors are 2x1 for 4:2:2."""
    cam = load_camera("logitech-c270")
    jpeg = encode_jpeg(np.zeros((16, 16, 3), np.uint8), cam)
    sof = jpeg.index(b"\xff\xc0")
    ncomp = jpeg[sof + 9]
    factors = [jpeg[sof + 10 + 3 * i + 1] for i in range(ncomp)]
    assert cam.isp.chroma_subsampling == "4:2:2"
    assert factors == [0x21, 0x11, 0x11]


def test_bayer_pixel_sees_only_its_colour():
    """Red light reaches R pixels far more than B pixels (CFA × QE), full well clips and blooms."""
    from camera_models.sensor import bloom

    e = bloom(np.array([[0.0, 0.0, 0.0], [0.0, 3e4 + 4000.0, 0.0], [0.0, 0.0, 0.0]]), 3e4, 0.4)
    assert e[1, 1] == 3e4 and e[0, 1] == pytest.approx(400.0)
    cam = load_camera("canon-t6-18mm")
    qe = cam.sensor.qe_rgb @ spectra.led_shape(630.0, 20.0)
    assert qe[0] > 5 * qe[2]


def test_srgb_8bit_table_matches_colour_science():
    """The ISP's table-driven sRGB encoding gives exactly round(255 · sRGB(x)) of colour-science, clipped."""
    import colour

    from camera_models.isp import srgb_encode_8bit

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-0.2, 1.2, 200_000), rng.uniform(0.0, 0.005, 100_000), np.linspace(0, 1, 100_001)])
    ref = np.rint(colour.cctf_encoding(np.clip(x, 0.0, 1.0), function="sRGB") * 255.0).astype(np.uint8)
    assert np.array_equal(srgb_encode_8bit(x.copy()), ref)


def test_srgb_8bit_float32_input_gets_the_codes_of_its_exact_value():
    """float32 input is compared with float32 thresholds rounded up: the same codes as the
    float64 path on the same values, including values one float32 step either side of
    every code threshold."""
    import colour

    from camera_models.isp import srgb_encode_8bit

    t = np.asarray(colour.cctf_decoding((np.arange(255) + 0.5) / 255.0, function="sRGB"), dtype=np.float64)
    t32 = t.astype(np.float32)
    near = np.concatenate([t32, np.nextafter(t32, np.float32(0)), np.nextafter(t32, np.float32(1))])
    x = np.concatenate([near, np.random.default_rng(4).uniform(-0.1, 1.1, 300_000).astype(np.float32)])
    ref = np.rint(colour.cctf_encoding(np.clip(x.astype(np.float64), 0.0, 1.0), function="sRGB") * 255.0)
    assert np.array_equal(srgb_encode_8bit(x.copy()), ref.astype(np.uint8))


def test_sensor_bytes_do_not_depend_on_the_block_size(monkeypatch):
    """The sensor works in blocks of rows; its draws split into blocks equal one draw of
    the whole, so the raw frame is the same for any block size (here 256 and 7 rows)."""
    from camera_models import sensor

    s = load_camera("canon-t6-18mm").sensor
    mean = np.random.default_rng(0).gamma(0.5, 4e4, size=(300, 64))  # some pixels over the full well: blooming
    settings = SensorSettings(1 / 60, 8.0)
    a = expose(mean, s, settings, seed=9, x0=3, y0=5)
    monkeypatch.setattr(sensor, "_ROWS", 7)
    b = expose(mean, s, settings, seed=9, x0=3, y0=5)
    assert a.dtype == np.uint16 and np.array_equal(a, b)
    assert (a == min(s.white_level_DN, 2**s.adc_bits - 1)).any()


def test_full_frame_mosaic_is_the_mosaic_of_the_full_frame():
    """The whole-frame mean electrons equal :func:`mosaic` of the three-channel frame built
    explicitly: the background upsampled by nearest neighbour, the crop pasted in."""
    import math

    from camera_models.capture import full_frame_mosaic
    from camera_models.sensor import cfa_channels, mosaic

    cam = load_camera("logitech-c270")
    g = cam.geometry
    rng = np.random.default_rng(2)
    bg = rng.uniform(0, 50, size=(g.height_px // 16 + 1, g.width_px // 16, 3))
    crop = rng.uniform(0, 900, size=(31, 45, 3))
    x0, y0 = 101, 58  # odd: the crop starts on another CFA phase
    scale = math.ceil(g.width_px / bg.shape[1])
    frame = np.repeat(np.repeat(bg.astype(np.float32), scale, axis=0), scale, axis=1)[: g.height_px, : g.width_px]
    frame[y0 : y0 + 31, x0 : x0 + 45] = crop
    ref = np.take_along_axis(frame, cfa_channels(cam.sensor.cfa, 0, 0, *frame.shape[:2])[..., None], axis=2)[..., 0]
    assert np.array_equal(mosaic(frame, cam.sensor.cfa), ref)
    assert np.array_equal(full_frame_mosaic(crop, x0, y0, cam, bg), ref)
    assert np.array_equal(
        full_frame_mosaic(crop, x0, y0, cam, None)[y0 : y0 + 31, x0 : x0 + 45], ref[y0 : y0 + 31, x0 : x0 + 45]
    )
