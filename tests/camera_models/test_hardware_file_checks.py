"""Hardware files (issue 26, hole 9): a key nothing reads is an error naming the nearest valid key,
and sizes and geometry outside what hardware can be are refused before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

from camera_models.camera import load_camera
from scenes.beacon import beacon_design
from scenes.hardware import add_hardware_file
from scenes.view import camera_names
from tests.helpers.cli import assert_one_line_error, invoke

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
CAMERA = EXAMPLES / "rpi-hq-6mm.toml"
BEACON = EXAMPLES / "v2-arms-100mm.toml"
GLARE = """
[optics.glaer]
fraction = { value = 0.02, assumed = "a test" }
knee_um = { value = 10.0, assumed = "a test" }
exponent = { value = 2.0, assumed = "a test" }
outer_radius_mm = { value = 13.4, assumed = "a test" }
"""


def _edited(tmp_path: Path, source: Path, old: str, new: str, name: str = "bad.toml") -> Path:
    text = source.read_text()
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


def _camera_error(path: Path) -> str:
    with pytest.raises(ValueError) as info:
        load_camera(add_hardware_file("camera", path))
    message = str(info.value)
    assert "\n" not in message
    return message


def test_hole9_misspelt_processing_is_an_error_naming_the_nearest_key(tmp_path):
    """``procesing = "in-camera"`` ran "legacy" without a word; now it names the key and ``processing``."""
    path = _edited(tmp_path, CAMERA, 'processing = "legacy"', 'procesing = "in-camera"')
    assert _camera_error(path) == "camera file bad.toml: isp.procesing: unknown field (did you mean 'processing'?)"


def test_hole9_misspelt_glare_table_is_an_error(tmp_path):
    """``[optics.glaer]`` dropped the glare; now it names the table and ``glare``."""
    path = tmp_path / "bad.toml"
    path.write_text(CAMERA.read_text() + GLARE)
    assert _camera_error(path) == "camera file bad.toml: optics.glaer: unknown field (did you mean 'glare'?)"
    path.write_text(CAMERA.read_text() + GLARE.replace("glaer", "glare"))
    assert load_camera(add_hardware_file("camera", path)).lens.glare.fraction == 0.02  # spelt right, it is read


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        # a key of a number's own table
        (
            'value = 1.55, source = "',
            'value = 1.55, unit = "um", source = "',
            "geometry.pixel_pitch_um.unit: unknown field (expected one of assumed, source, value)",
        ),
        (
            'demosaic = "bilinear"',
            'demosaic = "bilinear"\nwhite_balence = "auto"',
            "isp.white_balence: unknown field (did you mean 'white_balance'?)",
        ),
        (
            'mode = "manual"',
            'mode = "manual"\nae_dampng = { value = 0.5, assumed = "a typo" }',
            "exposure.ae_dampng: unknown field (did you mean 'ae_damping'?)",
        ),
        # sensor, ISP and exposure written beside a body (which replaces them) would be ignored
        ('name = "rpi-hq-6mm"', 'name = "rpi-hq-6mm"\nbody = "canon-eos-1300d"', "sensor: unknown field"),
    ],
)
def test_hole9_unknown_keys_anywhere_name_the_key(tmp_path, old, new, message):
    assert message in _camera_error(_edited(tmp_path, CAMERA, old, new))


def test_hole9_unknown_beacon_key_names_the_nearest(tmp_path):
    path = _edited(
        tmp_path, BEACON, "arm_length_mm = {", 'arm_lenght_mm = { value = 90.0, assumed = "a typo" }\narm_length_mm = {'
    )
    with pytest.raises(ValueError, match=r"^beacon file bad\.toml: arm_lenght_mm: unknown field \(did you mean "):
        beacon_design(add_hardware_file("beacon", path))


def test_built_in_hardware_has_no_unknown_keys():
    """Every built-in camera and beacon loads with the check on (their fields are all read)."""
    for name in camera_names():
        load_camera(name)
    for name in ("v1", "v2"):
        beacon_design(name)


@pytest.mark.parametrize(
    ("width", "height", "message"),
    [
        (
            100_000,
            100_000,
            "geometry.width_px: expected an integer >= 16 and <= 20000 (<= 20000 px: the largest image sensors "
            "made are 14204 x 10652 px), got 100000",
        ),
        (
            19_000,
            19_000,
            "geometry.height_px: expected width_px x height_px <= 2.5e+08 pixels (above the largest image sensors "
            "made), got 19000 x 19000 = 3.61e+08",
        ),
    ],
)
def test_hole9_a_sensor_larger_than_any_made_is_refused(tmp_path, width, height, message):
    """A 100000 x 100000 sensor was accepted and ran unbounded; now the field, value and range are named."""
    path = _edited(tmp_path, CAMERA, "value = 4056,", f"value = {width},")
    path.write_text(path.read_text().replace("value = 3040,", f"value = {height},", 1))
    assert _camera_error(path).endswith(message)


def test_hole9_a_node_wider_than_the_beacon_is_refused(tmp_path):
    """A 5 m node radius (the camera at 3 m would stand inside it) was accepted; the node must stand
    behind the targets' backs: d_t - out_of_plane - housing depth - arm width = 71 mm for V2."""
    path = _edited(tmp_path, BEACON, "node_radius_mm = { value = 50.0", "node_radius_mm = { value = 5000.0")
    with pytest.raises(ValueError) as info:
        beacon_design(add_hardware_file("beacon", path))
    assert str(info.value).startswith(
        "beacon file bad.toml: node_radius_mm: expected a number > 0 and <= 71 (d_t_mm - out_of_plane_mm"
    )
    assert str(info.value).endswith("got 5000.0")


def test_hole9_bounds_and_unknown_keys_are_one_line_before_any_work(work, tmp_path):
    node = _edited(tmp_path, BEACON, "node_radius_mm = { value = 50.0", "node_radius_mm = { value = 5000.0", "n.toml")
    code, _out, err = invoke(["render", "--beacon-file", str(node), "--range-m", "3", "--out", "o"])
    assert "node_radius_mm: expected a number > 0 and <= 71" in assert_one_line_error(code, err)
    typo = _edited(tmp_path, CAMERA, 'processing = "legacy"', 'procesing = "in-camera"', "t.toml")
    code, _out, err = invoke(["capture", "--camera-file", str(typo), "--out", "o"])
    assert assert_one_line_error(code, err).endswith("isp.procesing: unknown field (did you mean 'processing'?)")
    assert not (work / "o").exists()
