"""beacon-sim detect / calibrate on image files: JSON fields, formats, any image size (explicit intrinsics, own
calibrations, resized copies, --resize), one-line errors that come before any work and write nothing;
evaluate_detection."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import skimage.data

from pipeline.angles import Intrinsics
from pipeline.calibration import Calibration
from pipeline.detect import REAL_PHOTO_FALSE_POSITIVES
from pipeline.evaluate import evaluate_detection
from pipeline.frames import pose_from_scenario
from scenes.scenario import Scenario
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
        ("ok.png", None, "canon-t6-18mm", "beacon-sim: error: image: 1280×720 px is neither canon-t6-18mm's 5184×3456"),
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
    blanks = []
    for level in (100, 127, 150):
        blanks.append(str(tmp_path / f"blank{level}.png"))
        cv2.imwrite(blanks[-1], np.full((60, 80, 3), level, np.uint8))
    proc = run("calibrate", *blanks, "--out", str(tmp_path / "c.json"))
    assert proc.returncode == 2 and proc.stderr.startswith("beacon-sim: error: images: the board")
    proc = run("calibrate", *blanks, "--out", str(tmp_path / "c.json"), "--pattern", "eight")
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


# --- any image size: explicit intrinsics, own calibrations, resized copies, --resize ---------------------------

K_OWN = np.array([[700.0, 0.0, 410.0], [0.0, 700.0, 290.0], [0.0, 0.0, 1.0]])
SIZE_OWN = (801, 600)
D_OWN = np.array([-0.25, 0.08, 0.001, -0.001, 0.0])


def _project(k, dist=None, turn_deg=(0.0, 0.0), range_m=2.0, yaw=12.0):
    """Markers 1..5 seen by a camera (K, distortion) turned by (about x, about y) degrees from the target."""
    sc = Scenario(camera=CAMERA, range_m=range_m, yaw_deg=yaw)
    pose = pose_from_scenario(sc)
    turn = cv2.Rodrigues(np.radians([turn_deg[0], turn_deg[1], 0.0]))[0]
    rvec = cv2.Rodrigues(turn @ pose.cv_from_t)[0]
    uv, _ = cv2.projectPoints(sc.design.marker_positions_m(), rvec, turn @ pose.t_cv_m, k, dist)
    return uv.reshape(-1, 2)


def _write(path, image):
    cv2.imwrite(str(path), image)
    return str(path)


def _markers(run, *args):
    proc = run("detect", *args, "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    return out, np.array([[m["u"], m["v"]] for m in out["markers"]])


def test_projection_helper_is_the_scenario_projection():
    uv, _ = marker_pixels(CAMERA, 2.0, 12.0)
    assert np.abs(_project(camera_geometry(CAMERA).intrinsics()) - uv).max() < 1e-6


def test_detect_own_photo_size_with_explicit_intrinsics_or_own_calibration(run, tmp_path):
    w, h = SIZE_OWN
    uv = _project(K_OWN)
    plain = _write(tmp_path / "plain.png", draw_markers((h, w), uv, RED_LED, 1.5, peak=20.0))
    out, got = _markers(run, plain, "--fx", "700", "--cx", "410", "--cy", "290")
    assert out["side"] == "red" and out["camera"] is None and np.abs(got - uv).max() < 0.1
    assert math.isclose(out["range_m"], 2.0, rel_tol=2e-3) and abs(out["yaw_deg"] - 12.0) < 0.5
    assert out["intrinsics"] == {"source": "explicit", "fx": 700.0, "fy": 700.0, "cx": 410.0, "cy": 290.0,
                                 "width_px": 801, "height_px": 600, "dist_coeffs": None}  # fmt: skip
    # a distorting lens, the target far off-centre: a calibration file made for this 801×600 camera
    uv_d = _project(K_OWN, D_OWN, turn_deg=(11.0, 20.0))
    assert uv_d[:, 0].max() > 620 and uv_d[:, 1].min() < 170
    lens = _write(tmp_path / "lens.png", draw_markers((h, w), uv_d, RED_LED, 1.5, peak=20.0))
    cal = str(Calibration(K_OWN, D_OWN, w, h, 0.1, 12).save(tmp_path / "own.json"))
    with_cal, got = _markers(run, lens, "--calibration", cal)
    assert with_cal["intrinsics"]["source"].startswith("calibration") and np.abs(got - uv_d).max() < 0.15
    assert abs(with_cal["range_m"] - 2.0) < 0.006
    # the same lens given as numbers
    with_dist, _ = _markers(run, lens, "--fx", "700", "--cx", "410", "--cy", "290", "--dist", ",".join(map(str, D_OWN)))
    assert with_dist["range_m"] == pytest.approx(with_cal["range_m"], abs=1e-9)
    assert with_dist["intrinsics"]["dist_coeffs"] == D_OWN.tolist()
    without, _ = _markers(run, lens, "--fx", "700", "--cx", "410", "--cy", "290")
    assert abs(without["range_m"] - 2.0) > 5 * abs(with_cal["range_m"] - 2.0)


def test_detect_resized_copy_of_a_camera_frame(run, tmp_path):
    """A 640×360 copy of the C270's 1280×720 frame: the camera's (or its calibration's) intrinsics halved."""
    uv, _ = marker_pixels(CAMERA, 2.0, 12.0)
    half_uv = (uv + 0.5) * 0.5 - 0.5  # where cv2.resize puts them
    half = _write(tmp_path / "half.png", draw_markers((360, 640), half_uv, RED_LED, 1.0, peak=20.0))
    g = camera_geometry(CAMERA)
    cal = str(Calibration(g.intrinsics(), np.zeros(5), 1280, 720, 0.1, 9).save(tmp_path / "c270.json"))
    for source in (["--camera", CAMERA], ["--calibration", cal], ["--camera", CAMERA, "--calibration", cal]):
        out, got = _markers(run, half, *source)
        assert out["notes"][0].startswith("the image is a 50 % copy of ") and "1280×720 px frame" in out["notes"][0]
        assert np.abs(got - half_uv).max() < 0.1
        assert (out["intrinsics"]["fx"], out["intrinsics"]["cx"]) == pytest.approx((g.focal_length_px / 2, 319.5))
        assert math.isclose(out["range_m"], 2.0, rel_tol=3e-3) and abs(out["yaw_deg"] - 12.0) < 0.5


def test_detect_resize_option_reports_full_size_pixels(run, tmp_path):
    uv, _ = marker_pixels(CAMERA, 2.0, 12.0)
    g = camera_geometry(CAMERA)
    path = _write(tmp_path / "full.png", draw_markers((g.height_px, g.width_px), uv, RED_LED, 3.0, peak=20.0))
    out, got = _markers(run, path, "--camera", CAMERA, "--resize", "0.5")
    assert out["resize"] == 0.5 and "tracked on a 50 % copy of the image" in out["notes"]
    assert np.abs(got - uv).max() < 0.15  # in the full-size image's pixels
    assert math.isclose(out["range_m"], 2.0, rel_tol=3e-3)
    # the study's tracker resizes inside, as the study did for the T6: blobs must stay over ~13 px tall at 50 %
    uv, _ = marker_pixels(CAMERA, 0.6, 10.0)
    green = draw_markers((g.height_px, g.width_px), uv, hsv_to_bgr(78, 100, 255), 16.0, peak=1.0, profile="disc")
    path = _write(tmp_path / "green.png", green)
    out, got = _markers(run, path, "--camera", CAMERA, "--tracker", "thesis", "--resize", "0.5")
    assert out["side"] == "green" and np.abs(got - uv).max() < 6.0
    assert math.isclose(out["range_m"], 0.6, rel_tol=0.03)
    # discs of 9 px radius survive the study's erosion at full size but not at 50 % (9 px tall < ~13 px)
    small = draw_markers((g.height_px, g.width_px), uv, hsv_to_bgr(78, 100, 255), 9.0, peak=1.0, profile="disc")
    path = _write(tmp_path / "small.png", small)
    assert _markers(run, path, "--camera", CAMERA, "--tracker", "thesis")[0]["side"] == "green"
    out, _ = _markers(run, path, "--camera", CAMERA, "--tracker", "thesis", "--resize", "0.5")
    assert out["markers"] == [] and out["blob_counts"]["green"] == 0


@pytest.fixture(scope="module")
def c270_cal(tmp_path_factory):
    g = camera_geometry(CAMERA)
    return str(
        Calibration(g.intrinsics(), np.zeros(5), 1280, 720, 0.1, 9).save(tmp_path_factory.mktemp("c") / "c.json")
    )


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        ([], "camera: expected the intrinsics: --camera NAME, --calibration FILE or --fx"),
        (["--camera", CAMERA, "--fx", "900"], "fx: expected the intrinsics from one source, --camera or --fx"),
        (["--calibration", "CAL", "--fx", "900"], "fx: expected the intrinsics from one source, --calibration or"),
        (["--calibration", "CAL", "--dist", "0,0,0,0"], "dist: expected the distortion from one source"),
        (["--cy", "300"], "fx: expected --fx (focal length, px) with --cy, got none"),
        (["--fx", "900", "--crop-origin", "10,10"], "crop-origin: expected --camera or --calibration with it"),
        (["--camera", "canon-t6-18mm", "--calibration", "CAL"], "calibration: made for 1280×720 px, not for canon-t6"),
        (["--camera", CAMERA, "--resize", "0"], "resize: expected a scale in (0, 1], got 0.0"),
        (["--camera", CAMERA, "--resize", "1.5"], "resize: expected a scale in (0, 1], got 1.5"),
        (["--fx", "-5"], "fx: expected a focal length > 0 px, got -5.0"),
        (["--fx", "900", "--fy", "nan"], "fy: expected a focal length > 0 px"),
        (["--fx", "900", "--dist", "0.1,0.2"], "dist: expected 4, 5, 8, 12, 14 finite coefficients"),
        (["--fx", "900", "--dist", "a,b,c,d"], "dist: expected comma-separated coefficients"),
        (["--camera", CAMERA, "--ring-camera", "6"], "ring-camera: expected 0..5, got 6"),
        (["--camera", CAMERA, "--tracker", "magic"], "tracker: expected one of thesis, best"),
        (["--camera", CAMERA, "--alpha", "2"], "alpha: expected a value in [0, 1]"),
        (["--camera", CAMERA, "--crop-origin", "-1,0"], "crop-origin: expected U,V ≥ 0 px"),
    ],
)
def test_detect_option_errors_come_before_reading_the_image(run, tmp_path, c270_cal, args, expect):
    missing = str(tmp_path / "not-read.png")  # never opened: the options are refused first
    proc = run("detect", missing, *[c270_cal if a == "CAL" else a for a in args])
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.startswith(f"beacon-sim: error: {expect}") and proc.stderr.count("\n") == 1, proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_detect_other_frame_sizes_need_their_own_intrinsics(run, tmp_path):
    vga = _write(tmp_path / "vga.png", np.zeros((480, 640, 3), np.uint8))
    proc = run("detect", vga, "--camera", CAMERA)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert proc.stderr.startswith(
        "beacon-sim: error: image: 640×480 px is neither logitech-c270's 1280×720 px frame nor a resized copy of it "
        "(for a crop give --crop-origin; for another image size give --calibration or --fx/--fy/--cx/--cy)"
    )
    proc = run("detect", vga, "--fx", "600", "--cx", "700")
    assert proc.returncode == 2 and proc.stderr.startswith(
        "beacon-sim: error: cx: expected a principal point in the image"
    )
    proc = run("detect", vga, "--fx", "600", "--json")  # its own intrinsics: a black image, no target
    assert proc.returncode == 0 and json.loads(proc.stdout)["markers"] == []


def test_detect_thesis_tracker_carries_its_false_positive_note(run, tmp_path):
    """The study's tracker finds a red side in scikit-image's coffee photo; the output says such finds can be false."""
    coffee = _write(tmp_path / "coffee.png", skimage.data.coffee()[..., ::-1])
    out, _ = _markers(run, coffee, "--fx", "600", "--tracker", "thesis")
    assert out["side"] == "red" and out["notes"][-1] == REAL_PHOTO_FALSE_POSITIVES.note("thesis")
    assert "false-positive rate on real photos: it reported a beacon in 2 of 9 colour photographs" in out["notes"][-1]
    proc = run("detect", coffee, "--fx", "600", "--tracker", "thesis")
    assert proc.returncode == 0 and "note: the study's (thesis) tracker has a false-positive rate" in proc.stdout
    best, _ = _markers(run, coffee, "--fx", "600")
    assert best["markers"] == [] and best["notes"] == []
    proc = run("detect", coffee, "--fx", "600")
    assert proc.returncode == 0 and proc.stdout.startswith("no target:")


# --- calibrate: degenerate sets refused, warnings, any size -------------------------------------------------------

K_BOARD = np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]])
TILTS = [(0.3, 0.0, 0.0), (-0.25, 0.2, 0.05), (0.1, -0.35, 0.1), (0.0, 0.3, 0.15), (-0.3, -0.2, -0.1)]


def _board(rvec, tvec, k=K_BOARD, size=(640, 480)):
    """The study's 8 × 6 inner-corner board (24.4 mm squares, a white border) drawn through a pinhole camera."""
    img = np.full((size[1], size[0]), 200, np.uint8)
    for x in range(9):
        for y in range(7):
            if (x + y) % 2 == 0:
                sq = (
                    np.array([[x, y, 0], [x + 1, y, 0], [x + 1, y + 1, 0], [x, y + 1, 0]], float) - [1, 1, 0]
                ) * 0.0244
                pts, _ = cv2.projectPoints(sq, np.asarray(rvec, float), np.asarray(tvec, float), k, None)
                cv2.fillConvexPoly(img, np.round(pts.reshape(-1, 2) * 16).astype(np.int32), 20, cv2.LINE_AA, 4)
    return img


def _boards(tmp_path, poses, k=K_BOARD, size=(640, 480), prefix="b"):
    return [_write(tmp_path / f"{prefix}{i}.png", _board(r, t, k, size)) for i, (r, t) in enumerate(poses)]


T_BOARD = np.array([-0.085, -0.06, 0.45])


def _error(run, *args):
    proc = run("calibrate", *args)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    return proc.stderr.removeprefix("beacon-sim: error: ")


def test_calibrate_refuses_bad_input_and_degenerate_sets_writing_nothing(run, tmp_path):
    good = _boards(tmp_path, [(r, T_BOARD) for r in TILTS])
    out = tmp_path / "new" / "cal.json"  # its folder does not exist yet: nothing may create it
    assert _error(run, *good, "--out", str(out), "--pattern", "1x1").startswith("pattern: expected COLSxROWS inner")
    assert _error(run, *good, "--out", str(out), "--pattern", "2x9").startswith("pattern: expected COLSxROWS")
    assert _error(run, *good, "--out", str(tmp_path)).startswith(
        f"out: expected a file name for the calibration (JSON), got the directory {tmp_path}"
    )
    assert _error(run, *good[:2], "--out", str(out)) == "images: expected at least 3 checkerboard photos, got 2\n"
    assert _error(run, *good, good[1], "--out", str(out)).startswith(
        f"images: expected distinct photos, got {good[1]} twice (images 1 and 5)"
    )
    copy = tmp_path / "copy.png"
    copy.write_bytes(Path(good[2]).read_bytes())
    assert _error(run, *good, str(copy), "--out", str(out)).startswith(
        f"images: expected distinct photos, got the same file content twice ({good[2]} and {copy}"
    )
    # the same view again as a JPEG: other bytes, the same corners
    jpeg = str(tmp_path / "again.jpg")
    cv2.imwrite(jpeg, cv2.imread(good[0]), [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert _error(run, *good, jpeg, "--out", str(out)).startswith(
        f"images: views 0 and 5 ({good[0]}, {jpeg}) show the board in the same place (corners "
    )
    # boards all tilted alike, only shifted: one orientation
    shifts = np.array([(0, 0, 0), (0.03, 0, 0.05), (-0.03, 0.02, 0.1), (0.02, -0.02, -0.03)])
    parallel = _boards(tmp_path, [((0.3, 0.1, 0.0), T_BOARD + d) for d in shifts], prefix="p")
    assert _error(run, *parallel, "--out", str(out)).startswith(
        "images: the board has 1 distinct orientation(s) in 4 views (board planes at least 5° apart; need 3)"
    )
    assert not (tmp_path / "new").exists()
    proc = run("calibrate", *good, "--out", str(out))
    assert proc.returncode == 0 and json.loads(out.read_text())["n_images"] == 5


def test_calibrate_warns_about_an_offset_principal_point(run, tmp_path):
    k = K_BOARD.copy()
    k[0, 2] = 420.0  # 16 % of the width right of the centre
    files = _boards(tmp_path, [(r, T_BOARD + np.array([-0.06, 0, 0])) for r in TILTS], k)
    out = tmp_path / "cal.json"
    proc = run("calibrate", *files, "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    assert abs(data["camera_matrix"][0][2] - 420.0) < 3.0
    (warning,) = data["warnings"]
    assert warning.startswith("principal point (4") and "16 % of the width" in warning
    assert f"warning: {warning}\n" in proc.stderr


def test_calibrate_and_detect_on_an_own_camera_of_any_size(run, tmp_path):
    """The issue's case: a calibration from one's own 500×375 photos, then detect with it alone."""
    size = (500, 375)
    k = np.array([[480.0, 0.0, 252.0], [0.0, 480.0, 185.0], [0.0, 0.0, 1.0]])
    files = _boards(tmp_path, [(r, T_BOARD + np.array([0.02, 0.01, 0.1])) for r in TILTS], k, size)
    cal = tmp_path / "mine.json"
    proc = run("calibrate", *files, "--out", str(cal), "--resize", "0.5")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(cal.read_text())
    assert (data["width_px"], data["height_px"]) == size and data["warnings"] == []
    assert abs(data["camera_matrix"][0][0] - 480.0) < 10 and abs(data["camera_matrix"][1][2] - 185.0) < 5
    uv = _project(k, range_m=1.5, yaw=-10.0)
    image = _write(tmp_path / "target.png", draw_markers(size[::-1], uv, RED_LED, 1.2, peak=20.0))
    out, got = _markers(run, image, "--calibration", str(cal))
    assert out["side"] == "red" and np.abs(got - uv).max() < 0.15
    assert math.isclose(out["range_m"], 1.5, rel_tol=0.01) and abs(out["yaw_deg"] + 10.0) < 1.0
