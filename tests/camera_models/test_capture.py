"""Whole-camera behaviour: determinism, bad input, automatic exposure in the dark, JPEG chroma subsampling."""

from __future__ import annotations

import numpy as np
import pytest

from camera_models.camera import load_camera
from camera_models.capture import capture
from camera_models.exposure import manual_exposure
from camera_models.isp import encode_jpeg
from camera_models.sensor import SensorSettings, expose
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
