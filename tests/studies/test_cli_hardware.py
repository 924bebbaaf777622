"""Hardware files on the command line: anywhere, filled in where a command takes that hardware."""

from __future__ import annotations

from pathlib import Path

import pytest

from studies.cli.app import click_command
from studies.cli.hardware import use_hardware_files
from tests.helpers.cli import assert_one_line_error, invoke

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
CAMERA = str(EXAMPLES / "rpi-hq-6mm.toml")
BEACON = str(EXAMPLES / "v2-arms-100mm.toml")


def _use(args: list[str]) -> list[str]:
    return use_hardware_files(args, click_command().commands)


def test_files_are_taken_out_and_their_names_filled_in():
    commands = click_command().commands
    assert _use(["render", "--camera-file", CAMERA, "--out", "o"]) == ["render", "--out", "o", "--camera", "rpi-hq-6mm"]
    assert _use(["--beacon-file=" + BEACON, "detect", "x.jpg", "--camera", "logitech-c270"]) == [
        "detect", "x.jpg", "--camera", "logitech-c270", "--beacon", "v2-arms-100mm",
    ]  # fmt: skip
    # a command that takes several cameras gets them as one list; one naming its own keeps it
    assert _use(["study", "range-limit", "--camera-file", CAMERA, "--out", "o"])[-2:] == ["--cameras", "rpi-hq-6mm"]
    assert "rpi-hq-6mm" not in _use(["study", "range-limit", "--cameras", "logitech-c270", "--camera-file", CAMERA])
    # a command that takes no camera only learns the name (listing it)
    assert _use(["cameras", "--camera-file", CAMERA]) == ["cameras"]
    assert "--camera" not in {o for p in commands["cameras"].params for o in getattr(p, "opts", ())}


def test_the_listing_shows_the_users_camera(capsys):
    code, out, _err = invoke(["--camera-file", CAMERA, "cameras", "--json"])
    assert code == 0 and '"name": "rpi-hq-6mm"' in out and '"width_px": 4056' in out


@pytest.mark.parametrize(
    ("args", "start"),
    [
        (["render", "--out", "o", "--camera-file"], "camera-file: expected a path to a TOML file"),
        (["render", "--out", "o", "--camera-file", "nope.toml"], "camera-file: expected a TOML file"),
        (["render", "--out", "o", "--beacon-file", CAMERA], "beacon file rpi-hq-6mm.toml: arm_length_mm: expected"),
        (["render", "--out", "o", "--camera", "../data/canon-t6-18mm"], "camera: expected one of canon-t6-10mm"),
    ],
)
def test_bad_hardware_is_one_line_before_any_work(work, args, start):
    code, _out, err = invoke(args)
    line = assert_one_line_error(code, err)
    assert line.startswith(f"beacon-sim: error: {start}") or start in line, line
    assert not (work / "o").exists()


def test_a_bad_field_names_file_and_field(work, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(Path(CAMERA).read_text().replace("value = 1.55,", "value = -1.5,"))
    code, _out, err = invoke(["capture", "--camera-file", str(bad), "--out", "o"])
    line = assert_one_line_error(code, err)
    assert line.endswith(
        "camera file bad.toml: geometry.pixel_pitch_um: expected a number >= 0.5 and <= 100 (the smallest pixels "
        "made are 0.56 um, the largest near 100 um), got -1.5"
    )
    assert not (work / "o").exists()


def test_a_good_file_reaches_the_work(work):
    code, _out, err = invoke(["--beacon-file", BEACON, "capture", "--camera-file", CAMERA, "--out", "o"])
    assert code == "work", err


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("\narm_length_mm", "\n# arm_length_mm"),
         "arm_length_mm: expected a number > 0 and <= 2000, got 'nothing (missing)'"),
        (lambda t: t.replace("lit_face_diameter_mm = { value = 12.0", "lit_face_diameter_mm = { value = -12.0"),
         "lit_face_diameter_mm: expected a number > 0"),
        (lambda t: t + '\n[leds]\nred = "cree-c503t-nope"\n', "leds.red: expected one of red, green"),
        (lambda t: t + '\n[leds]\nred = "cree-c503t-gan"\n', "leds.red: expected a red part for the red side"),
    ],
)  # fmt: skip
def test_a_bad_design_file_is_one_line_naming_the_field_and_nothing_is_written(work, tmp_path, edit, message):
    """A candidate beacon (missing field, negative size, unknown LED part, a part of another colour) given
    to a study: one line naming the file's field, before any work, no output folder."""
    bad = tmp_path / "bad.toml"
    bad.write_text(edit(Path(BEACON).read_text()))
    code, _out, err = invoke(["study", "range-limit", "--beacon-file", str(bad), "--out", "o"])
    line = assert_one_line_error(code, err)
    assert f"beacon file bad.toml: {message}" in line, line
    assert not (work / "o").exists()
