"""beacon-sim detect / calibrate on image files: JSON fields, formats, one-line errors; evaluate_detection."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from pipeline.angles import Intrinsics
from pipeline.calibration import Calibration
from pipeline.evaluate import evaluate_detection
from scenes.view import camera_geometry
from tests.helpers.synthetic import draw_markers, hsv_to_bgr, marker_pixels

CLI = [sys.executable, "-c", "from studies.cli.app import main; main()"]
CAMERA = "logitech-c270"
RED_LED = (0.03, 0.06, 1.0)


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def run(capsys, monkeypatch):
    """The console script in-process (the imports are paid once); one subprocess test checks the real thing."""
    from studies.cli.app import main

    def _run(*args):
        monkeypatch.setattr(sys, "argv", ["beacon-sim", *args])
        capsys.readouterr()
        try:
            main()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        out, err = capsys.readouterr()
        return Result(code, out, err)

    return _run


def test_console_script_in_a_subprocess(png):
    proc = subprocess.run([*CLI, "detect", str(png[0]), "--camera", CAMERA, "--json"], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0 and json.loads(proc.stdout)["side"] == "red"
    proc = subprocess.run([*CLI, "detect", str(png[0]) + ".missing", "--camera", CAMERA], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 2 and proc.stderr.startswith("beacon-sim: error: image: no such file")


def _frame(range_m=2.0, yaw=12.0, colour=RED_LED, size=1.5, peak=20.0, profile="gaussian", dtype=np.uint8):
    g = camera_geometry(CAMERA)
    uv, _ = marker_pixels(CAMERA, range_m, yaw)
    return draw_markers((g.height_px, g.width_px), uv, colour, size, peak=peak, profile=profile, dtype=dtype), uv


@pytest.fixture(scope="module")
def png(tmp_path_factory):
    img, uv = _frame()
    path = tmp_path_factory.mktemp("img") / "frame.png"
    cv2.imwrite(str(path), img)
    return path, uv


def test_detect_json_fields_on_png(run, png, tmp_path):
    path, uv = png
    cal = Calibration(camera_geometry(CAMERA).intrinsics(), np.zeros(5), 1280, 720, 0.0, 0)
    cal_file = cal.save(tmp_path / "cal.json")
    for extra in ([], ["--calibration", str(cal_file), "--alpha", "0"]):
        proc = run("detect", str(path), "--camera", CAMERA, "--json", *extra)
        assert proc.returncode == 0, proc.stderr
        out = json.loads(proc.stdout)
        assert out["side"] == "red" and out["reason"] is None
        assert [m["id"] for m in out["markers"]] == [1, 2, 3, 4, 5]
        got = np.array([[m["u"], m["v"]] for m in out["markers"]])
        assert np.abs(got - uv).max() < 0.1
        assert math.isclose(out["range_m"], 2.0, rel_tol=2e-3)
        assert abs(out["yaw_deg"] - 12.0) < 0.5 and abs(out["pitch_deg"]) < 0.5 and abs(out["roll_deg"]) < 0.5
        assert math.isclose(np.linalg.norm(out["quaternion_wxyz"]), 1.0, rel_tol=1e-9)
        assert set(out["global"]) == {"x_m", "y_m", "z_m", "yaw_deg", "pitch_deg", "roll_deg"}
        # red side: target at 180°, camera 2 m out at 12° toward the target's +y
        assert math.isclose(out["global"]["x_m"], -0.14 - 2.0 * math.cos(math.radians(12)), abs_tol=0.01)
        m1 = out["markers"][0]
        assert abs(m1["azimuth_rad"]) < 1e-3 and abs(m1["elevation_rad"]) < 1e-3


def test_detect_16bit_tiff_with_the_study_chain(run, tmp_path):
    img, uv = _frame(range_m=0.8, yaw=10.0, colour=hsv_to_bgr(78, 100, 255), size=9.0, peak=1.0, profile="disc",
                     dtype=np.uint16)  # fmt: skip
    path = tmp_path / "frame16.tif"
    cv2.imwrite(str(path), img)
    proc = run("detect", str(path), "--camera", CAMERA, "--json", "--tracker", "thesis", "--estimator", "thesis")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["side"] == "green" and len(out["markers"]) == 5
    got = np.array([[m["u"], m["v"]] for m in out["markers"]])
    assert np.abs(got - uv).max() < 6.0  # the study's erosion shifts centres by a pixel or two
    assert math.isclose(out["range_m"], 0.8, rel_tol=0.02)
    proc = run("detect", str(path), "--camera", CAMERA, "--tracker", "thesis")  # the table form
    assert proc.returncode == 0 and "side green" in proc.stdout


@pytest.mark.parametrize(
    ("name", "content", "camera", "expect"),
    [
        ("bad.jpg", b"not a jpeg", CAMERA, "beacon-sim: error: image: cannot decode bad.jpg"),
        ("IMG_0001.CR2", b"not a raw file", CAMERA, "beacon-sim: error: image: cannot read camera raw IMG_0001.CR2"),
        ("ok.png", None, "canon-t6-18mm", "beacon-sim: error: image: 1280×720 px is not the camera's 5184×3456 px"),
        ("ok.png", None, "nikon", "beacon-sim: error: camera:"),
    ],
)
def test_detect_bad_files_one_line_errors(run, tmp_path, png, name, content, camera, expect):
    path = tmp_path / name
    if content is None:
        path = png[0]
    else:
        path.write_bytes(content)
    proc = run("detect", str(path), "--camera", camera)
    assert proc.returncode == 2
    assert proc.stderr.startswith(expect) and proc.stderr.count("\n") == 1, proc.stderr


def test_calibrate_command_errors_and_output(run, tmp_path):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((60, 80, 3), 127, np.uint8))
    proc = run("calibrate", str(blank), str(blank), str(blank), "--out", str(tmp_path / "c.json"))
    assert proc.returncode == 2 and proc.stderr.startswith("beacon-sim: error: images: the board")
    proc = run("calibrate", str(blank), "--out", str(tmp_path / "c.json"), "--pattern", "eight")
    assert proc.returncode == 2 and proc.stderr.startswith("beacon-sim: error: pattern:")
    # a real (synthetic) board: three views of a flat, undistorted board
    obj = np.mgrid[-1:10, -1:8].T.reshape(-1, 2)
    files = []
    for k, (rx, ry) in enumerate([(0.3, 0.0), (-0.25, 0.2), (0.1, -0.35), (0.0, 0.3)]):
        img = np.full((480, 640), 200, np.uint8)
        rvec, tvec = np.array([rx, ry, 0.05 * k]), np.array([-0.1, -0.07, 0.45])
        for x, y in obj:
            if (x + y) % 2 == 0 and 0 <= x < 9 and 0 <= y < 7:
                sq = np.array([[x, y, 0], [x + 1, y, 0], [x + 1, y + 1, 0], [x, y + 1, 0]], float) * 0.0244
                sq -= [0.0244, 0.0244, 0]
                pts, _ = cv2.projectPoints(sq, rvec, tvec, np.array([[600, 0, 320], [0, 600, 240], [0, 0, 1.0]]), None)
                cv2.fillConvexPoly(img, np.round(pts.reshape(-1, 2) * 16).astype(np.int32), 20, cv2.LINE_AA, 4)
        files.append(tmp_path / f"board{k}.png")
        cv2.imwrite(str(files[-1]), img)
    out = tmp_path / "sub" / "cal.json"
    proc = run("calibrate", *map(str, files), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    assert data["n_images"] == 4 and data["pattern"] == [8, 6]
    assert abs(data["camera_matrix"][0][0] - 600) < 15


def test_evaluate_detection_scores_a_known_frame():
    img, uv = _frame(range_m=3.0, yaw=-8.0, colour=(1.0, 0.3, 0.02), size=1.2, peak=0.8)
    truth = {"markers_px": uv.tolist(), "range_m": 3.0, "yaw_deg": -8.0, "side": "blue"}
    res = evaluate_detection(img, Intrinsics.from_geometry(camera_geometry(CAMERA)), truth)
    assert res["detected"] and res["side_correct"] and res["numbering_correct"]
    assert res["centroid_rms_px"] < 0.1 and abs(res["range_error_m"]) < 0.01 and abs(res["yaw_error_deg"]) < 0.5
    # render.json form, and a truth whose markers 2 and 3 are swapped: numbering is then wrong
    render_json = {
        "scenario": {"range_m": 3.0, "yaw_deg": -8.0, "side": "red"},
        "markers_ground_truth_px": [{"id": i + 1, "u": u, "v": v} for i, (u, v) in enumerate(uv[[0, 2, 1, 3, 4]])],
    }
    res = evaluate_detection(img, Intrinsics.from_geometry(camera_geometry(CAMERA)), render_json, tracker="thesis")
    assert res["detected"] is False and res["numbering_correct"] is False and res["reason"]
    res = evaluate_detection(img, Intrinsics.from_geometry(camera_geometry(CAMERA)), render_json)
    assert res["numbering_correct"] is False and res["side_correct"] is False
