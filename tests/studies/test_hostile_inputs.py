"""Issue 26: the holes a hostile user found, each reproduced (these tests failed before the fix).

Hole 5, repeated list values; hole 7, image sizes read from the header before decoding;
hole 8, pool workers that outlive their parent; hole 10, the tracebacks of seven causes
(astronomical ranges, deeply nested files, a resize to nothing, a full disk, a lost Dask
scheduler, forged task records). Hole 4 (a render-cache entry copied over another) is in
``tests/scenes/test_render_cache.py``.

Commands run in this process through :func:`tests.helpers.cli.invoke`; no test
renders. Top-level imports stay light: spawned pool workers import the runner only.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from tests.helpers.cli import assert_one_line_error, invoke

REPO = Path(__file__).parents[2]


# -- hole 5: repeated values in list options -----------------------------------------


@pytest.mark.parametrize(
    ("args", "field", "value"),
    [
        (["study", "range-limit", "--quick", "--ranges-m", "4,4,4,4,4"], "ranges-m", "4"),
        (["study", "range-limit", "--quick", "--ranges-m", "2,4,4.0"], "ranges-m", "4 and 4.0"),
        (["study", "webcam-vs-dslr", "--quick", "--cameras", "logitech-c270,logitech-c270"], "cameras", "c270"),
        (["study", "brightness-diffuser", "--quick", "--currents-ma", "5,20,5"], "currents-ma", "5"),
        (["study", "range-limit", "--quick", "--beacons", "v2,v2"], "beacons", "v2"),
        (["saturation-table", "--cameras", "spedal-920,spedal-920"], "cameras", "spedal-920"),
    ],
)
def test_repeated_list_values_are_refused_before_any_work(work, args, field, value):
    code, out, err = invoke([*args, "--out", "o"])
    line = assert_one_line_error(code, err, field)
    assert "more than once" in line and value in line and out == ""
    assert not (work / "o").exists()


def test_study_options_refuse_a_repeated_grid_value():
    from studies.engine.tasks import StudyOptions

    with pytest.raises(ValueError, match=r"^ranges_m: expected each value once, got 4\.0 more than once"):
        StudyOptions(cameras=("canon-t6-18mm",), ranges_m=(4.0, 6.0, 4.0)).validate()
    with pytest.raises(ValueError, match=r"^cameras: expected each value once"):
        StudyOptions(cameras=("canon-t6-18mm", "canon-t6-18mm")).validate()


# -- hole 7: image dimensions from the header, before decoding ------------------------


def png_header(width: int, height: int, depth: int = 16, colour: int = 2) -> bytes:
    """A PNG that claims ``width`` × ``height`` px and holds a few bytes of image data."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


def jpeg_header(width: int, height: int) -> bytes:
    """A JPEG that claims ``width`` × ``height`` px (an APP0 segment before its frame header)."""
    app0 = b"\xff\xe0" + struct.pack(">H", 16) + b"JFIF\0\x01\x01\0\0\x01\0\x01\0\0"
    sof = b"\xff\xc0" + struct.pack(">HBHHB", 17, 8, height, width, 3) + b"\x01\x11\0\x02\x11\0\x03\x11\0"
    return b"\xff\xd8" + app0 + sof + b"\xff\xd9"


def tiff_header(width: int, height: int) -> bytes:
    """A little-endian TIFF whose first directory claims ``width`` × ``height`` px."""
    entries = struct.pack("<HHII", 256, 4, 1, width) + struct.pack("<HHII", 257, 4, 1, height)
    return b"II*\0" + struct.pack("<I", 8) + struct.pack("<H", 2) + entries + struct.pack("<I", 0)


@pytest.mark.parametrize("make", [png_header, jpeg_header, tiff_header])
def test_a_huge_image_is_refused_from_its_header_before_decoding(tmp_path, monkeypatch, make):
    import pipeline.image_io as image_io

    def no_decoding(*args, **kwargs):
        raise AssertionError("decoded an image its header says is too large")

    monkeypatch.setattr(image_io.cv2, "imdecode", no_decoding)
    path = tmp_path / "bomb.img"
    path.write_bytes(make(25000, 25000))  # 6.25e8 px: 3.75 GB decoded at 16-bit colour
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"^image: too large: bomb\.img is 25000×25000 px") as exc:
        image_io.load_image(path)
    assert time.perf_counter() - t0 < 1.0 and "\n" not in str(exc.value)


def test_images_above_2_30_px_are_one_line_errors_in_detect_and_calibrate(work):
    (work / "big.png").write_bytes(png_header(40000, 40000))  # 1.6e9 px: OpenCV's own limit is 2^30
    code, _, err = invoke(["detect", "big.png", "--camera", "canon-t6-18mm"])
    assert "too large" in assert_one_line_error(code, err, "image")
    code, _, err = invoke(["calibrate", "big.png", "big2.png", "big3.png", "--out", "cal.json"])
    assert code == 2 and "Traceback" not in err and "cv2.error" not in err


@pytest.mark.parametrize(
    ("suffix", "shape", "dtype"),
    [
        (".png", (48, 64, 3), np.uint8),
        (".png", (48, 64, 3), np.uint16),
        (".png", (48, 64), np.uint8),
        (".jpg", (48, 64, 3), np.uint8),
        (".tif", (48, 64, 3), np.uint16),
        (".bmp", (48, 64, 3), np.uint8),
    ],
)
def test_header_size_is_the_decoded_size(tmp_path, suffix, shape, dtype):
    import cv2

    from pipeline.image_header import header_size
    from pipeline.image_io import load_image

    path = tmp_path / f"img{suffix}"
    assert cv2.imwrite(str(path), np.full(shape, 7, dtype))
    header = header_size(path)
    assert (header.height_px, header.width_px) == shape[:2]
    assert load_image(path).shape[:2] == shape[:2]


# -- hole 8: pool workers die with their parent ---------------------------------------

POOL_SCRIPT = """
import sys
from pathlib import Path
from studies.engine.runner import run_tasks, selftest_task
tasks = [{"seed": i, "n": 10, "sleep_s": 120} for i in range(4)]
run_tasks(tasks, Path(sys.argv[1]), selftest_task, workers=2, threads_per_worker=1)
"""


def _pool_workers(parent: int) -> list[int]:
    """Live processes whose parent is ``parent`` and that run a multiprocessing spawn worker."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if int(fields[1]) == parent and b"spawn_main" in cmdline:
            found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_pool_workers_die_when_their_parent_is_killed(tmp_path, sig):
    parent = subprocess.Popen([sys.executable, "-c", POOL_SCRIPT, str(tmp_path / "out")], cwd=REPO)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 90
        while len(workers) < 2 and time.monotonic() < deadline and parent.poll() is None:
            time.sleep(0.2)
            workers = _pool_workers(parent.pid)
        assert len(workers) == 2, f"pool did not start: {workers}"
        time.sleep(3.0)  # the workers have run their start-up (imports, initializer) and hold tasks
        parent.send_signal(sig)
        parent.wait(10)
        deadline = time.monotonic() + 5.0
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [pid for pid in workers if _alive(pid)], "pool workers outlived their parent"
    finally:
        parent.kill()
        for pid in workers:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_die_with_parent_exits_when_the_parent_is_already_gone():
    script = "from studies.engine.runner import die_with_parent; die_with_parent(1); print('still here')"
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "still here" not in done.stdout


# -- hole 10: tracebacks of seven causes ----------------------------------------------


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["render", "--out", "o", "--range-m", "1.4e154"], "range_m"),
        (["capture", "--out", "o", "--range-m", "1e300"], "range_m"),
        (["estimator-montecarlo", "--range-m", "1e155"], "range_m"),
        (["study", "range-limit", "--quick", "--out", "o", "--ranges-m", "2,1e155"], "ranges_m"),
        (["render", "--out", "o", "--range-m", "20000"], "range_m"),
    ],
)
def test_astronomical_ranges_are_one_line_errors(work, args, field):
    code, _, err = invoke(args)
    assert "10000 m" in assert_one_line_error(code, err, field)
    assert not (work / "o").exists()


def test_the_range_limit_is_inclusive():
    from scenes.scenario import MAX_RANGE_M, Scenario

    assert Scenario(range_m=MAX_RANGE_M).range_m == 10_000.0


def _deep_toml(kind: str) -> str:
    if kind == "arrays":
        return 'name = "deep"\nx = ' + "[" * 5000 + "]" * 5000 + "\n"
    return 'name = "deep"\n' + ".".join(["a"] * 3000) + " = 1\n"


@pytest.mark.parametrize("kind", ["arrays", "keys"])
@pytest.mark.parametrize(("option", "command"), [("--camera-file", "cameras"), ("--beacon-file", "beacons")])
def test_deeply_nested_hardware_files_are_one_line_errors(work, kind, option, command):
    (work / "deep.toml").write_text(_deep_toml(kind))
    code, _, err = invoke([option, "deep.toml", command])
    assert "nested" in assert_one_line_error(code, err) and "deep.toml" in err


def test_deeply_nested_json_is_a_one_line_error(work):
    (work / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (work / "img.png").write_bytes(png_header(64, 48, 8, 2))
    code, _, err = invoke(["detect", "img.png", "--calibration", "deep.json"])
    assert "nested too deep" in assert_one_line_error(code, err, "calibration")
    from studies.engine.run_log import read_parts

    (work / "runs.json").write_text("{" + '"a":{' * 50_000 + "}" * 50_001)
    with pytest.raises(ValueError, match=r"^runs: expected the run log"):
        read_parts(work)


def test_a_resize_that_leaves_no_pixel_is_a_one_line_error(tmp_path, monkeypatch):
    import cv2

    from pipeline.angles import Intrinsics
    from pipeline.detect import detect

    monkeypatch.chdir(tmp_path)
    assert cv2.imwrite("img.png", np.zeros((48, 64, 3), np.uint8))
    code, _, err = invoke(["detect", "img.png", "--fx", "100", "--resize", "1e-300"])
    assert "at least 1 px" in assert_one_line_error(code, err, "resize")
    intrinsics = Intrinsics(fx=100.0, fy=100.0, cx=32.0, cy=24.0, width_px=64, height_px=48)
    for tracker in ("thesis", "best"):
        with pytest.raises(ValueError, match=r"^resize: expected a scale that leaves the 64×48 px image"):
            detect(np.zeros((48, 64, 3), np.uint8), intrinsics, tracker=tracker, resize=1e-300)
    assert detect(np.zeros((48, 64, 3), np.uint8), intrinsics, resize=1 / 48).side is None  # 1 px: runs


def _full_disk_after(monkeypatch, writes: int) -> None:
    """Every atomic write after the first ``writes`` goes to /dev/full (ENOSPC from the kernel)."""
    real = os.fdopen
    count = [0]

    def fdopen(fd, mode="r", *args, **kwargs):
        if "w" not in mode:
            return real(fd, mode, *args, **kwargs)
        count[0] += 1
        if count[0] <= writes:
            return real(fd, mode, *args, **kwargs)
        os.close(fd)
        return open("/dev/full", mode)

    monkeypatch.setattr(os, "fdopen", fdopen)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_disk_names_the_file_and_the_run_resumes_to_the_same_rows(tmp_path, monkeypatch):
    from studies.engine.runner import RunStopped, run_tasks, selftest_task

    tasks = [{"seed": i, "n": 50} for i in range(5)]
    clean = run_tasks(tasks, tmp_path / "clean", selftest_task, workers=1)
    with monkeypatch.context() as mp:
        _full_disk_after(mp, 2)
        with pytest.raises(RunStopped, match=r"^disk full at .*tasks/.*\.json \(No space left on device\)"):
            run_tasks(tasks, tmp_path / "full", selftest_task, workers=1)
    assert not list((tmp_path / "full").rglob("*.tmp"))
    assert len(list((tmp_path / "full" / "tasks").rglob("*.json"))) == 2
    assert run_tasks(tasks, tmp_path / "full", selftest_task, workers=1) == clean


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_disk_is_one_line_on_the_command_line(work, monkeypatch):
    from scenes.render_cache import atomic_write_bytes
    from studies.catalog import range_limit

    def run(out, *args, **kwargs):
        _full_disk_after(monkeypatch, 0)
        atomic_write_bytes(Path(out) / "summary.json", b"{}")

    monkeypatch.setattr(range_limit, "run", run)
    code, _, err = invoke(["study", "range-limit", "--quick", "--out", "o"])
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1, err
    assert lines[0].startswith("beacon-sim: error: disk full at o/") and "No space left" in lines[0]


def _stored(tmp_path):
    from studies.engine.runner import ResultStore, run_tasks, selftest_task, task_key

    tasks = [{"seed": i, "n": 20} for i in range(3)]
    clean = run_tasks(tasks, tmp_path, selftest_task, workers=1)
    store = ResultStore(tmp_path / "tasks")
    paths = [store.path(task_key(selftest_task, t, 1)) for t in tasks]
    return tasks, clean, paths


def _forge(path: Path, kind: str, other: Path) -> None:
    from studies.engine.runner import _digest

    if kind == "another task's record":
        path.write_bytes(other.read_bytes())
    elif kind == "rows that are not rows":
        rows = [1, "x"]
        path.write_text(json.dumps({"key": json.loads(path.read_text())["key"], "sha256": _digest(rows), "rows": rows}))
    elif kind == "deep nesting":
        path.write_text("[" * 100_000 + "]" * 100_000)
    else:
        path.write_text('{"key": 1')


@pytest.mark.parametrize("kind", ["another task's record", "rows that are not rows", "deep nesting", "cut short"])
def test_a_forged_task_record_is_one_line_naming_the_file_and_computed_again(tmp_path, caplog, kind):
    from studies.engine.runner import run_tasks, selftest_task

    tasks, clean, paths = _stored(tmp_path)
    _forge(paths[1], kind, paths[0])
    assert run_tasks(tasks, tmp_path, selftest_task, workers=1) == clean
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and str(paths[1]) in warnings[0] and "\n" not in warnings[0]


def test_an_unreadable_task_record_stops_the_run_naming_the_file(tmp_path):
    from studies.engine.runner import RunStopped, run_tasks, selftest_task

    tasks, _, paths = _stored(tmp_path)
    paths[2].unlink()
    paths[2].mkdir()
    with pytest.raises(RunStopped, match=rf"^tasks: cannot read the task record {paths[2]}"):
        run_tasks(tasks, tmp_path, selftest_task, workers=1)


def test_a_lost_dask_scheduler_is_one_line_naming_its_address(tmp_path):
    distributed = pytest.importorskip("distributed")
    from studies.engine.runner import RunStopped, run_tasks, selftest_task

    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0", scheduler_port=0
    )
    address = cluster.scheduler_address
    tasks = [{"seed": i, "n": 10, "sleep_s": 0.5} for i in range(20)]
    result: dict = {}

    def go():
        try:
            run_tasks(tasks, tmp_path, selftest_task, scheduler=address)
        except BaseException as exc:  # the finding, examined below
            result["error"] = exc

    thread = threading.Thread(target=go, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not list((tmp_path / "tasks").rglob("*.json")) and time.monotonic() < deadline:
        time.sleep(0.1)
    cluster.close()
    thread.join(60)
    assert not thread.is_alive(), "the run waited on a lost scheduler"
    error = result.get("error")
    assert isinstance(error, RunStopped), repr(error)
    assert str(error).startswith(f"scheduler: lost the Dask scheduler at {address}") and "\n" not in str(error)
