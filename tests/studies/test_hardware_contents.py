"""The user's hardware files travel as contents (issue 26, holes 2, 3 and 11).

A file is read once, with every file it names; the workers (this process, a local pool, Dask)
compute with those contents and the results are keyed by them, so an edit during a run, an
edit of a named CSV, a deleted file or a worker on another machine cannot mix two versions.
A Dask cluster left without workers fails in one line after a stated timeout.
"""

from __future__ import annotations

import hashlib
import shutil
import threading
import time
from pathlib import Path

import pytest

from camera_models.camera import load_camera
from scenes.hardware import add_hardware_file
from studies.engine.runner import run_tasks, selftest_task, task_key

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
CAMERA = EXAMPLES / "rpi-hq-6mm.toml"
SSF = Path(__file__).resolve().parents[2] / "camera_models" / "data" / "ssf" / "sony_ilce_6400.csv"


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def edit_then_measure(task: dict) -> list[dict]:
    """A worker function: when told, edits the camera file first (the user editing it while the
    run goes on), then reports the camera the worker computes with."""
    if task.get("edit"):
        path = Path(task["edit"])
        path.write_text(path.read_text().replace("value = 4056,", "value = 4000,"))
    return [{"i": task["i"], "width_px": load_camera(task["camera"]).geometry.width_px}]


def measure_qe(task: dict) -> list[dict]:
    """A worker function: the peak red over peak green quantum efficiency of the worker's camera."""
    qe = load_camera(task["camera"]).sensor.qe_rgb
    return [{"i": task["i"], "red_over_green": float(qe[0].max() / qe[1].max())}]


def measure_camera(task: dict) -> list[dict]:
    """A worker function: what the worker's camera is, and the contents it was made from."""
    from scenes.hardware import hardware_source  # here: main lacked it (the test fails, not the import)

    camera = load_camera(task["camera"])
    source = hardware_source("camera", task["camera"])
    csv = source.named_file("sensor.ssf_csv", task.get("csv", "mine.csv")) or b""
    return [
        {
            "i": task["i"],
            "width_px": camera.geometry.width_px,
            "toml_sha256": _sha(source.data),
            "csv_sha256": _sha(csv),
        }
    ]


def _camera_with_own_csv(folder: Path) -> tuple[Path, Path]:
    """The example camera with its spectral sensitivities in a CSV next to it (``mine.csv``)."""
    folder.mkdir(parents=True, exist_ok=True)
    camera, csv = folder / "cam.toml", folder / "mine.csv"
    text = CAMERA.read_text()
    assert 'ssf_csv = "sony_ilce_6400.csv"' in text
    camera.write_text(text.replace('ssf_csv = "sony_ilce_6400.csv"', 'ssf_csv = "mine.csv"'))
    shutil.copyfile(SSF, csv)
    return camera, csv


def _halve_red(csv: Path) -> None:
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    red = header.index("r")
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[red] = repr(float(cells[red]) / 2)
        out.append(",".join(cells))
    csv.write_text("\n".join(out) + "\n")


def test_hole2_an_edit_during_a_run_is_not_stored_under_the_old_key(tmp_path):
    """The file edited by the first task: every task still computes with the contents the keys
    cover (4056 px wide); the next command reads the edit, under new keys."""
    path = tmp_path / "cam.toml"
    path.write_text(CAMERA.read_text())
    name = add_hardware_file("camera", path)
    tasks = [{"i": 0, "camera": name, "edit": str(path)}, {"i": 1, "camera": name}, {"i": 2, "camera": name}]
    first = run_tasks(tasks, tmp_path / "out", edit_then_measure, version=1, workers=1)
    assert [r["width_px"] for r in first] == [4056, 4056, 4056]
    keys = [task_key(edit_then_measure, t, 1) for t in tasks]
    assert add_hardware_file("camera", path) == name  # the next command reads the edited file
    assert not {task_key(edit_then_measure, t, 1) for t in tasks} & set(keys)
    again = run_tasks(tasks, tmp_path / "out", edit_then_measure, version=1, workers=1)
    assert [r["width_px"] for r in again] == [4000, 4000, 4000]


def test_hole3_the_named_csv_is_part_of_the_key(tmp_path):
    """An edit of the spectral-sensitivity CSV a camera file names changes the key, and the same
    command then computes with the new curves instead of reusing the stored results."""
    camera, csv = _camera_with_own_csv(tmp_path / "hw")
    name = add_hardware_file("camera", camera)
    task = {"i": 0, "camera": name}
    key = task_key(measure_qe, task, 1)
    (before,) = run_tasks([task], tmp_path / "out", measure_qe, version=1, workers=1)
    _halve_red(csv)
    add_hardware_file("camera", camera)  # the same command again
    assert task_key(measure_qe, task, 1) != key
    (after,) = run_tasks([task], tmp_path / "out", measure_qe, version=1, workers=1)
    assert after["red_over_green"] == pytest.approx(before["red_over_green"] / 2, rel=1e-6)
    (seen,) = run_tasks([task], tmp_path / "contents", measure_camera, version=1, workers=1)
    assert seen["csv_sha256"] == _sha(csv.read_bytes())  # the worker's CSV is the file's new bytes


def test_workers_receive_the_contents_not_the_paths(tmp_path):
    """Pool workers (spawned processes) compute with the bytes read when the file was added, even
    with the file and its CSV gone from the disk."""
    camera, csv = _camera_with_own_csv(tmp_path / "hw")
    expected = {"toml_sha256": _sha(camera.read_bytes()), "csv_sha256": _sha(csv.read_bytes()), "width_px": 4056}
    name = add_hardware_file("camera", camera)
    shutil.rmtree(tmp_path / "hw")
    tasks = [{"i": i, "camera": name} for i in range(2)]
    rows = run_tasks(tasks, tmp_path / "out", measure_camera, version=1, workers=2, isolated=True)
    assert [{k: r[k] for k in expected} for r in rows] == [expected, expected]


def test_hole11_dask_workers_get_the_users_camera(tmp_path):
    """``--camera-file`` with ``--scheduler`` failed with "unknown camera" (a Dask worker has no
    copy of the file nor of the registry): the contents now travel with the tasks."""
    distributed = pytest.importorskip("dask.distributed")
    camera, csv = _camera_with_own_csv(tmp_path / "hw")
    expected = {"toml_sha256": _sha(camera.read_bytes()), "csv_sha256": _sha(csv.read_bytes()), "width_px": 4056}
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        name = add_hardware_file("camera", camera)  # after the workers started, as on a remote cluster
        task, address = {"i": 0, "camera": name}, cluster.scheduler_address
        (width,) = run_tasks([task], tmp_path / "width", edit_then_measure, version=1, scheduler=address)
        (seen,) = run_tasks([task], tmp_path / "contents", measure_camera, version=1, scheduler=address)
    assert width["width_px"] == 4056
    assert {k: seen[k] for k in expected} == expected


def test_hole11_a_cluster_without_workers_fails_in_one_line(tmp_path):
    """Every worker lost (here: none at all): the sweep fails after the stated timeout instead of
    waiting silently, with one line saying what happened and how to resume."""
    distributed = pytest.importorskip("dask.distributed")
    from studies.engine.runner import NoWorkersError

    tasks = [{"seed": s, "n": 10} for s in range(3)]
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        start = time.monotonic()
        with pytest.raises(NoWorkersError) as info:
            run_tasks(tasks, tmp_path, selftest_task, scheduler=cluster.scheduler_address, no_worker_timeout_s=1.0)
        assert time.monotonic() - start < 20
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("scheduler: no worker connected to the Dask scheduler at ")
    assert "for 1 s with 3 task batches unfinished" in message and "run the same command again to resume" in message


def test_hole11_every_worker_lost_mid_run_fails_in_one_line_and_resumes(tmp_path):
    """The cluster's only worker leaves after the first tasks: the sweep stops after the timeout
    (it waited silently for ever), the finished tasks stay stored and a later run finishes them."""
    distributed = pytest.importorskip("dask.distributed")
    from studies.engine.runner import NoWorkersError

    tasks = [{"seed": s, "n": 10, "sleep_s": 0.4} for s in range(8)]
    options = {"threads_per_worker": 1, "processes": False, "dashboard_address": None}
    with distributed.LocalCluster(n_workers=1, **options) as cluster:

        def lose_the_worker_after_the_first_task() -> None:
            deadline = time.monotonic() + 60
            while not list(tmp_path.rglob("*.json")) and time.monotonic() < deadline:
                time.sleep(0.05)
            cluster.scale(0)

        threading.Thread(target=lose_the_worker_after_the_first_task, daemon=True).start()
        with pytest.raises(NoWorkersError, match=r"for 2 s with \d task batches unfinished"):
            run_tasks(tasks, tmp_path, selftest_task, scheduler=cluster.scheduler_address, no_worker_timeout_s=2.0)
    stored = len(list((tmp_path / "tasks").rglob("*.json")))
    assert 0 < stored < len(tasks)
    reference = run_tasks(tasks, tmp_path / "ref", selftest_task, workers=1)
    assert run_tasks(tasks, tmp_path, selftest_task, workers=1) == reference


def test_the_watchdog_counts_time_without_any_worker():
    """The timeout runs from the last moment a worker was connected, not from the start."""
    from studies.engine.runner import NoWorkersError, WorkerWatchdog

    now = [0.0]
    watchdog = WorkerWatchdog(10.0, "here", clock=lambda: now[0])
    for t, workers in ((5.0, 0), (9.0, 2), (15.0, 0), (19.0, 0)):  # 10 s since one was seen at 9 s
        now[0] = t
        watchdog.observe(workers, 4)
    now[0] = 19.5
    with pytest.raises(NoWorkersError, match=r"^scheduler: no worker connected to here for 10 s with 4 task batches"):
        watchdog.observe(0, 4)
