"""Hardware files: built-in and user cameras and beacons, resolved by name only, checked field by field."""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest

from camera_models.camera import camera_template, load_camera
from scenes.beacon import beacon_design, beacon_names, beacon_template
from scenes.hardware import add_hardware_file, hardware_file, user_hardware_digest
from scenes.view import camera_geometry, camera_names

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"


def _same(a, b, path=""):
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            if f.name not in ("name", "description"):
                _same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, tuple | list):
        assert len(a) == len(b), path
        for x, y in zip(a, b, strict=True):
            _same(x, y, path)
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, dict):
        assert a == b, path
    else:
        assert a == b, (path, a, b)


@pytest.mark.parametrize("name", ["canon-t6-18mm", "logitech-c270", "raspberry-pi-hq-16mm", "mvbluefox3-2016c-8mm"])
def test_camera_template_is_complete(tmp_path, name):
    """The template of a built-in camera loads as that camera (its body written into the file)."""
    path = tmp_path / "mine.toml"
    path.write_text(camera_template(name))
    mine = add_hardware_file("camera", path)
    assert mine == "my-camera"
    _same(load_camera(name), load_camera(mine))


def test_beacon_template_is_complete(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(beacon_template("v1"))
    _same(beacon_design("v1"), beacon_design(add_hardware_file("beacon", path)))


def test_names_never_reach_paths(tmp_path):
    """A name is looked up in the registry only: path tricks name no file, even an existing one."""
    (tmp_path / "x.toml").write_text((EXAMPLES / "rpi-hq-6mm.toml").read_text())
    relative = os.path.relpath(tmp_path / "x", hardware_file("camera", "canon-t6-18mm").parent)
    for name in (relative, str(tmp_path / "x"), str(tmp_path / "x.toml"), "bodies/canon-eos-1300d"):
        with pytest.raises(ValueError, match=r"^camera: expected one of canon-t6-10mm, .*, got") as info:
            camera_geometry(name)
        assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match=r"^beacon: expected one of v1, v2, got '\.\./beacons/v2'"):
        beacon_design("../beacons/v2")


def test_user_camera_from_the_data_sheet():
    """The Raspberry Pi HQ example: field of view from its data-sheet grid and focal length."""
    name = add_hardware_file("camera", EXAMPLES / "rpi-hq-6mm.toml")
    assert name in camera_names() and camera_names()[:4] == sorted(camera_names()[:4])
    g = camera_geometry(name)
    assert g.horizontal_fov_deg == pytest.approx(math.degrees(2 * math.atan(4056 * 1.55e-3 / 2 / 6.0)))
    cam = load_camera(name)
    # the two published read-noise figures are reproduced by the two-stage model
    assert cam.sensor.read_noise_e(1.0) == pytest.approx(3.0)
    assert cam.sensor.read_noise_e(16.0) == pytest.approx(1.5)
    assert cam.sensor.saturation_e(1.0) == pytest.approx(min((4095 - 256) / 0.47, 8180))


def test_user_beacon_with_long_arms():
    name = add_hardware_file("beacon", EXAMPLES / "v2-arms-100mm.toml")
    assert beacon_names() == ["v1", "v2", name]
    positions = beacon_design(name).marker_positions_m()
    assert np.abs(positions[1:, 1:]).max() == pytest.approx(0.100)
    assert positions[1, 0] == pytest.approx(-0.046)


def _edited(tmp_path, source: Path, old: str, new: str) -> Path:
    text = source.read_text()
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "value = 4056,",
            "value = -4,",
            r"camera file bad\.toml: geometry\.width_px: expected an integer >= 16 .*got -4$",
        ),
        ('cfa = "BGGR"', 'cfa = "RGBX"', r"sensor\.cfa: expected one of RGGB, BGGR, GRBG, GBRG, got 'RGBX'$"),
        ("full_well_e = {", "full_well = {", r"sensor\.full_well_e: expected a number > 0, got 'nothing \(missing\)'$"),
        (
            'ssf_csv = "sony_ilce_6400.csv"',
            'ssf_csv = "../../x.csv"',
            r"sensor\.ssf_csv: expected one of .*'\.\./\.\./x\.csv'",
        ),
        ("value = 93,", "value = 930,", r"isp\.jpeg_quality: expected an integer >= 1 and <= 100, got 930$"),
        ("value = 1.2, source", "value = 1.2, sauce", r"optics\.f_number: needs exactly one of 'source' or 'assumed'"),
    ],
)
def test_bad_camera_field_is_one_line_naming_it(tmp_path, old, new, message):
    path = _edited(tmp_path, EXAMPLES / "rpi-hq-6mm.toml", old, new)
    with pytest.raises(ValueError, match=message) as info:
        load_camera(add_hardware_file("camera", path))
    assert "\n" not in str(info.value)


def test_bad_beacon_field_and_names(tmp_path):
    path = _edited(
        tmp_path, EXAMPLES / "v2-arms-100mm.toml", '\nin_plane_leds_face = "viewer"', '\nin_plane_leds_face = "up"'
    )
    with pytest.raises(ValueError, match=r"beacon file bad\.toml: in_plane_leds_face: expected one of viewer, outward"):
        beacon_design(add_hardware_file("beacon", path))
    clash = _edited(tmp_path, EXAMPLES / "v2-arms-100mm.toml", 'name = "v2-arms-100mm"', 'name = "v2"')
    with pytest.raises(ValueError, match=r"name: 'v2' is a built-in beacon; give your file another name"):
        add_hardware_file("beacon", clash)
    odd = _edited(tmp_path, EXAMPLES / "v2-arms-100mm.toml", 'name = "v2-arms-100mm"', 'name = "../v2"')
    with pytest.raises(ValueError, match=r"name: expected lower-case letters"):
        add_hardware_file("beacon", odd)


def test_a_file_is_read_once_and_a_new_command_reads_it_again(tmp_path):
    """Registered contents stay as read (an edit changes nothing until the file is added again, as
    the next command does); the digest follows the contents."""
    path = tmp_path / "cam.toml"
    path.write_text((EXAMPLES / "rpi-hq-6mm.toml").read_text())
    assert user_hardware_digest() == ""
    name = add_hardware_file("camera", path)
    before = user_hardware_digest()
    path.write_text(path.read_text().replace("value = 4056,", "value = 4000,"))
    assert camera_geometry(name).width_px == 4056 and user_hardware_digest() == before
    path.unlink()
    assert load_camera(name).geometry.width_px == 4056  # the file is no longer needed
    path.write_text((EXAMPLES / "rpi-hq-6mm.toml").read_text().replace("value = 4056,", "value = 4000,"))
    assert add_hardware_file("camera", path) == name
    assert user_hardware_digest() not in ("", before)
    assert camera_geometry(name).width_px == 4000


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('green = "cree-c503t-gan"', None),
        ('green = "nope"', r"leds\.green: expected one of red, green, blue, yellow, cree-c503t-gan"),
        ('red = "cree-c503t-gan"', r"leds\.red: expected a red part for the red side \(red\), got 'cree-c503t-gan'"),
        ('purple = "red"', r"leds\.purple: expected a side colour \(red, green, blue, yellow\)"),
    ],
)
def test_a_beacon_file_names_its_led_parts(tmp_path, table, message):
    """A beacon's [leds] table picks a part per side from the catalogue (scenes/data/led_parts.toml);
    an unknown part, a part of another colour or a key that is no side is one line naming the field."""
    path = tmp_path / "leds.toml"
    path.write_text((EXAMPLES / "v2-arms-100mm.toml").read_text().replace('"v2-arms-100mm"', '"v2-leds"')
                    + f"\n[leds]\n{table}\n")  # fmt: skip
    if message is None:
        d = beacon_design(add_hardware_file("beacon", path))
        assert d.led("green").part.startswith("Cree C503T-GAN") and d.led("red") == beacon_design("v2").led("red")
        return
    with pytest.raises(ValueError, match=message) as info:
        beacon_design(add_hardware_file("beacon", path))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('green = { value = 505.0, source = "a cyan-green lamp" }', None),
        (
            'green = { value = 560.0, assumed = "x" }',
            r"dominant_wavelength_nm\.green: expected a number >= 500 and <= 540 \(the band of green",
        ),
        ('purple = { value = 500.0, source = "x" }', r"dominant_wavelength_nm\.purple: expected a side colour"),
        ("green = 505.0", r"dominant_wavelength_nm\.green: number 505\.0 has no 'source' or 'assumed' note"),
    ],
)
def test_a_beacon_file_gives_a_side_another_colour_of_its_band(tmp_path, table, message):
    """A beacon's [dominant_wavelength_nm] table moves a side's LED within its colour's band
    (scenes.led.HUE_BANDS_NM), the part's other figures kept; the renderer and the better tracker take
    the LED from the design (Scenario.led, ColourModel.for_beacon). Bad tables are one line naming the field."""
    from pipeline.tracker import ColourModel
    from scenes.scenario import Scenario

    path = tmp_path / "hue.toml"
    path.write_text((EXAMPLES / "v2-arms-100mm.toml").read_text().replace('"v2-arms-100mm"', '"v2-hue"')
                    + f"\n[dominant_wavelength_nm]\n{table}\n")  # fmt: skip
    if message is None:
        name = add_hardware_file("beacon", path)
        led, default = beacon_design(name).led("green"), beacon_design("v2").led("green")
        assert led.dominant_wavelength_nm == 505.0 and led.luminous_intensity_cd == default.luminous_intensity_cd
        assert Scenario(beacon=name, side="green").led == led
        model = ColourModel.for_beacon(name)
        assert model.means["red"] == ColourModel.default().means["red"]
        assert model.means["green"] != ColourModel.default().means["green"]
        return
    with pytest.raises(ValueError, match=message) as info:
        beacon_design(add_hardware_file("beacon", path))
    assert "\n" not in str(info.value)
