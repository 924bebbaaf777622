"""The README's render → capture → detect example gives the right answer, and a capture that
cannot show its side's colour says so."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

from studies.cli.camera import capture_warnings

REPO = Path(__file__).resolve().parents[2]
CLI = [sys.executable, "-c", "from studies.cli.app import main; main()"]


def _readme_command(name: str) -> list[str]:
    """The README's ``.venv/bin/beacon-sim NAME ...`` line as arguments (comment removed)."""
    text = (REPO / "README.md").read_text()
    line = next(
        m.group(1) for m in re.finditer(r"^\.venv/bin/beacon-sim (.+)$", text, re.M) if m.group(1).split()[0] == name
    )
    return shlex.split(line, comments=True)


def test_readme_capture_then_detect_names_the_red_side(tmp_path):
    capture = _readme_command("capture")
    detect = _readme_command("detect")
    out = capture[capture.index("--out") + 1]
    assert detect[1] == f"{out}/image.jpg"  # the detect line reads what the capture line wrote
    capture[capture.index("--out") + 1] = str(tmp_path / "capture")
    detect[1] = str(tmp_path / "capture" / "image.jpg")
    done = subprocess.run([*CLI, *capture], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    meta = json.loads((tmp_path / "capture" / "capture.json").read_text())
    assert meta["scenario"]["side"] == "red" and meta["warnings"] == []
    assert "warning" not in done.stdout
    # the cores are not clipped (raw at the clip level), counted independently of the warning
    assert max(m["saturated_fraction"] for m in meta["markers_ground_truth_px"]) <= 0.5
    done = subprocess.run([*CLI, *detect, "--json"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["side"] == "red"


def _markers(fraction: float) -> list[dict]:
    return [{"id": i + 1, "core_pixels": 12, "saturated_fraction": fraction} for i in range(5)]


def test_clipped_cores_and_a_wrong_side_are_each_said_in_one_line():
    lines = capture_warnings(_markers(1.0), "red", "yellow")
    assert len(lines) == 2 and all("\n" not in line for line in lines)
    assert lines[0].startswith("warning: 5 of 5 marker cores clipped (mean 100 %")
    assert "names the side yellow, not red" in lines[1]
    assert capture_warnings(_markers(0.0), "red", "red") == []
    assert "finds no five markers" in capture_warnings(_markers(0.2), "green", None)[0]
