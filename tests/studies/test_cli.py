"""Command line: listings, render outputs, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

CLI = [sys.executable, "-c", "from studies.cli.app import main; main()"]


def run(*args, check=True):
    proc = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


def test_beacons_json_lists_v1_and_v2():
    rows = json.loads(run("beacons", "--json").stdout)
    assert [r["name"] for r in rows] == ["v1", "v2"]
    v2 = rows[1]
    assert [m["id"] for m in v2["markers"]] == [1, 2, 3, 4, 5]
    assert v2["markers"][1]["position_mm"] == [-46.0, -70.0, 0.0]


def test_cameras_json():
    rows = json.loads(run("cameras", "--json").stdout)
    t6 = next(r for r in rows if r["name"] == "canon-t6-18mm")
    assert t6["width_px"] == 5184 and t6["focal_length_mm"] == 18.0


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--beacon", "v3"], "beacon:"),
        (["--side", "purple"], "side:"),
        (["--camera", "nikon"], "camera:"),
        (["--range-m", "0"], "range_m:"),
        (["--range-m", "-2"], "range_m:"),
        (["--yaw-deg", "91"], "yaw_deg:"),
        (["--led-current-ma", "-1"], "led_current_mA:"),
        (["--environment", "moon"], "environment:"),
    ],
)
def test_bad_render_input_is_one_line_naming_the_field(tmp_path, args, field):
    proc = run("render", "--out", str(tmp_path / "o"), *args, check=False)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], proc.stderr


def test_unwritable_output_is_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = run("render", "--out", str(blocker / "sub"), check=False)
    assert proc.returncode == 2 and proc.stderr.strip().startswith("beacon-sim: error: out:")
    assert len(proc.stderr.strip().splitlines()) == 1


def test_render_writes_exr_preview_and_json(tmp_path):
    out = tmp_path / "render"
    run(
        "render",
        "--out",
        str(out),
        "--range-m",
        "9",
        "--spp",
        "2",
        "--oversampling",
        "1",
        "--environment",
        "lit-room",
        "--cube",
    )
    meta = json.loads((out / "render.json").read_text())
    assert {p.name for p in out.iterdir()} >= {"radiance.exr", "preview.png", "render.json", "radiance_cube.exr"}
    assert meta["scenario"]["range_m"] == 9.0 and len(meta["markers_ground_truth_px"]) == 5
    assert {c["name"] for c in meta["components"]} == {"ambient", "led:red", "led:green", "led:blue", "led:yellow"}
    grid = meta["pixel_grid"]
    for m in meta["markers_ground_truth_px"]:
        assert grid["x0"] <= m["u"] < grid["x0"] + grid["width"]
    again = run(
        "render", "--out", str(out), "--range-m", "9", "--spp", "2", "--oversampling", "1", "--environment", "lit-room"
    )
    assert json.loads((out / "render.json").read_text())["from_cache"] is True, again.stderr


def _commands(help_text: str) -> set[str]:
    """Command names in a typer --help screen (its Commands box)."""
    box = help_text.split("Commands")[1]
    return {line.split()[1] for line in box.splitlines() if line.startswith("│ ") and not line.startswith("│  ")}


def test_module_and_console_script_list_the_same_commands_and_the_readme_names_only_those():
    from pathlib import Path

    from studies.cli.app import app

    registered = {c.name for c in app.registered_commands}
    as_module = subprocess.run(
        [sys.executable, "-m", "studies.cli", "--help"], capture_output=True, text=True, timeout=120
    )
    assert as_module.returncode == 0, as_module.stderr
    assert _commands(as_module.stdout) == _commands(run("--help").stdout) == registered
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    blocks = readme.split("```")[1::2]  # the code blocks
    named = {
        line.split()[1]
        for block in blocks
        for line in block.splitlines()
        if line.startswith("beacon-sim ") and not line.split()[1].startswith("-")
    }
    named |= {  # "beacon-sim a | b | c" lists several
        word
        for block in blocks
        for line in block.splitlines()
        if " | " in line and line.startswith("beacon-sim ")
        for word in line.split("  ")[0].replace("beacon-sim", "").replace("|", " ").split()
    }
    assert len(named) >= 15 and named <= registered, named - registered


@pytest.mark.parametrize("listing", ["cameras", "beacons"])
def test_piped_listings_are_tab_separated_with_full_names(listing):
    rows = json.loads(run(listing, "--json").stdout)
    lines = [line.split("\t") for line in run(listing).stdout.splitlines()]
    assert lines[0][0] == "name" and len({len(line) for line in lines}) == 1
    assert sorted({line[0] for line in lines[1:]}) == sorted(r["name"] for r in rows)


def test_narrow_terminal_table_keeps_full_names():
    from rich.console import Console

    from studies.cli import common

    names = ["canon-t6-18mm", "logitech-c270"]
    console = Console(width=40, force_terminal=True, record=True)
    rows = [(n, "5184×3456", "a long description that must wrap") for n in names]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(common, "Console", lambda: console)
        mp.setattr(common.sys.stdout, "isatty", lambda: True)
        common.print_table("Cameras", ("name", "resolution", "description"), rows)
    text = console.export_text()
    assert all(n in text for n in names), text
