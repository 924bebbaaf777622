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
