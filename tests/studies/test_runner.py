"""Sweep runner: resumable after SIGKILL, local pool and Dask give identical tables."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time

import pytest

from studies.engine.runner import ResultStore, run_tasks, selftest_task, task_key

FN = selftest_task
TASKS = [{"seed": s, "n": 1000 + 17 * s, "sleep_s": 0.4} for s in range(24)]


def _table(rows) -> bytes:
    return json.dumps(rows, sort_keys=True).encode()


def test_sequential_run_and_store(tmp_path):
    rows = run_tasks(TASKS[:5], tmp_path, FN, workers=1)
    assert [r["seed"] for r in rows] == [0, 1, 2, 3, 4]
    store = ResultStore(tmp_path / "tasks")
    key = task_key(FN, TASKS[0], 1)
    assert store.get(key) == rows[:1]
    store.path(key).write_text("{broken")  # a damaged entry is dropped and recomputed
    assert run_tasks(TASKS[:5], tmp_path, FN, workers=1) == rows


def _run_in_subprocess(out):
    code = (
        "import sys, json; from studies.engine.runner import run_tasks;"
        "from tests.studies.test_runner import TASKS, FN;"
        f"rows = run_tasks(TASKS, r'{out}', FN, workers=2);"
        f"open(r'{out}/table.json', 'w').write(json.dumps(rows, sort_keys=True))"
    )
    return subprocess.Popen([sys.executable, "-c", code], cwd=os.getcwd(), start_new_session=True)


def test_sigkill_and_resume_gives_the_same_table(tmp_path):
    reference = _table(run_tasks(TASKS, tmp_path / "ref", FN, workers=2))
    out = tmp_path / "killed"
    out.mkdir()
    rng = random.Random(7)
    for _ in range(3):  # kill the whole process group at random moments
        proc = _run_in_subprocess(out)
        time.sleep(rng.uniform(1.0, 2.0))
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    finished = len(list((out / "tasks").rglob("*.json"))) if (out / "tasks").exists() else 0
    assert finished < len(TASKS), "the kills came too late to test resuming"
    resumed = run_tasks(TASKS, out, FN, workers=2)
    assert _table(resumed) == reference


def test_dask_local_cluster_gives_the_same_table(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    local = _table(run_tasks(TASKS[:8], tmp_path / "pool", FN, workers=2))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        remote = _table(run_tasks(TASKS[:8], tmp_path / "dask", FN, scheduler=cluster.scheduler_address))
    assert remote == local


def test_batched_tasks_give_the_same_table_and_are_stored_one_by_one(tmp_path):
    tasks = [{**t, "sleep_s": 0.0} for t in TASKS]
    single = _table(run_tasks(tasks, tmp_path / "single", FN, workers=2))
    batched = run_tasks(tasks, tmp_path / "batched", FN, workers=2, batch_key=lambda t: str(t["seed"] % 3), max_batch=5)
    assert _table(batched) == single
    store = ResultStore(tmp_path / "batched" / "tasks")
    assert all(store.get(task_key(FN, t, 1)) is not None for t in tasks)


def test_task_keys_follow_the_users_hardware_files(tmp_path):
    """Built-in hardware only: keys as always; a user file, or an edit of it (read again by the
    next command), gives new keys."""
    from pathlib import Path

    from scenes.hardware import add_hardware_file
    from scenes.render_cache import content_key
    from studies.engine.runner import function_name

    task = {"seed": 1}
    plain = task_key(selftest_task, task, 1)
    assert plain == content_key("task", function_name(selftest_task), 1, task)
    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "v2-arms-100mm.toml"
    mine = tmp_path / "beacon.toml"
    mine.write_text(example.read_text())
    add_hardware_file("beacon", mine)
    with_file = task_key(selftest_task, task, 1)
    mine.write_text(example.read_text().replace("value = 100.0", "value = 90.0"))
    add_hardware_file("beacon", mine)
    edited = task_key(selftest_task, task, 1)
    assert len({plain, with_file, edited}) == 3
