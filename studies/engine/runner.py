"""Run a sweep of independent tasks: local process pool or Dask cluster, resumable.

A task is a JSON-able dict; its key is a SHA-256 of the task, the worker function's
name and its version. Every finished task's rows are written atomically to
``<out>/tasks/<key[:2]>/<key>.json`` (with a digest of the rows), so a run killed at any
point — even by SIGKILL — loses at most the tasks in flight; running it again skips the
stored ones. The table is assembled from the store in the order of the task list, never
in completion order, so an interrupted-and-resumed run, a local pool and a Dask cluster
all produce the same table byte for byte.

Tasks that share expensive state (frames of one render) can be sent to a worker
together: ``batch_key`` labels them, and a batch runs its tasks one after another in one
process, where the render and the lens work are computed once and kept in memory.
Results are still stored task by task.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np

from scenes.render_cache import atomic_write_bytes, content_key

TaskFunction = Callable[[dict], list[dict]]
"""A worker function: one JSON-able task in, its result rows out. It must be a module-level
function (process pools and Dask send it by its qualified name)."""

Progress = Callable[[str, int, int], AbstractContextManager[Callable[[], None]]]
"""A progress display: called with (description, total, already done), it gives a context
manager whose value is called once per finished task. The command line passes a rich bar."""


def no_progress(description: str, total: int, done: int) -> AbstractContextManager[Callable[[], None]]:
    """A :data:`Progress` that shows nothing."""
    return nullcontext(lambda: None)


def function_name(function: TaskFunction) -> str:
    """``module:qualname`` of a worker function (part of every task key)."""
    return f"{function.__module__}:{function.__qualname__}"


def run_one(function: TaskFunction, task: dict) -> list[dict]:
    """Worker entry point (top level, so process pools and Dask can pickle it)."""
    return run_batch(function, [task])[0]


def run_batch(function: TaskFunction, tasks: list[dict]) -> list[list[dict]]:
    """Worker entry point for a batch: each task's rows, in order."""
    threads = os.environ.get("BEACON_SIM_THREADS")
    if threads:
        cv2.setNumThreads(max(1, int(threads)))  # share the cores with the other workers
    return [function(task) for task in tasks]


@dataclass
class ResultStore:
    """Finished tasks' rows on disk, one JSON file per task."""

    root: Path

    def path(self, key: str) -> Path:
        """File of ``key``."""
        return Path(self.root) / key[:2] / f"{key}.json"

    def get(self, key: str) -> list[dict] | None:
        """The stored rows, or None when missing or damaged (then the file is removed)."""
        path = self.path(key)
        try:
            record = json.loads(path.read_text())
            rows = record["rows"]
            if record["sha256"] != _digest(rows) or record["key"] != key:
                raise ValueError("digest")
            return rows
        except FileNotFoundError:
            return None
        except (ValueError, KeyError, TypeError):
            path.unlink(missing_ok=True)
            return None

    def put(self, key: str, rows: list[dict]) -> None:
        """Store ``rows`` for ``key`` atomically."""
        path = self.path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        record = {"key": key, "sha256": _digest(rows), "rows": rows}
        atomic_write_bytes(path, json.dumps(record, sort_keys=True, allow_nan=True).encode())


def _digest(rows: list[dict]) -> str:
    return hashlib.sha256(json.dumps(rows, sort_keys=True, allow_nan=True).encode()).hexdigest()


def task_key(function: TaskFunction, task: dict, version: int) -> str:
    """Content key of a task."""
    return content_key("task", function_name(function), version, task)


def run_tasks(
    tasks: Sequence[dict],
    out_dir: Path,
    function: TaskFunction,
    version: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    description: str = "tasks",
    progress: Progress = no_progress,
    batch_key: Callable[[dict], str] | None = None,
    max_batch: int = 32,
    threads_per_worker: int | None = None,
    isolated: bool = False,
) -> list[dict]:
    """Run ``tasks`` (skipping stored ones) and return all rows in task order.

    Parameters
    ----------
    tasks
        JSON-able task dicts.
    out_dir
        Study output directory; finished tasks go to ``out_dir/tasks``.
    function
        The worker function mapping a task to its rows (:data:`TaskFunction`).
    version
        Version of ``function``'s output (part of every key); default its module's
        ``FRAME_VERSION`` or 1.
    workers
        Local worker processes (default: CPU count); 1 runs in this process.
    scheduler
        Address of a Dask distributed scheduler; runs the same tasks there instead.
    description
        What the progress display calls the run.
    progress
        Progress display (:data:`Progress`); default none.
    batch_key
        Label of a task's batch (tasks with equal labels run together in one worker,
        at most ``max_batch`` at a time); default every task alone.
    threads_per_worker
        Threads each local worker process may use (``BEACON_SIM_THREADS``); default the
        cores shared out among the workers.
    isolated
        Run in worker processes even with one worker (as a pool does; for timing).
    """
    if version is None:
        version = getattr(sys.modules[function.__module__], "FRAME_VERSION", 1)
    store = ResultStore(Path(out_dir) / "tasks")
    keys = [task_key(function, t, version) for t in tasks]
    pending: dict[str, dict] = {}
    for key, task in zip(keys, tasks, strict=True):
        if key not in pending and store.get(key) is None:
            pending[key] = task
    batches = _batches(pending, batch_key, max_batch)
    with progress(description, len(set(keys)), len(set(keys)) - len(pending)) as advance:
        if pending:
            if scheduler:
                _run_dask(scheduler, function, batches, store, advance)
            elif not isolated and ((workers or os.cpu_count() or 1) == 1 or len(batches) == 1):
                for batch in batches:
                    _store_batch(store, batch, run_batch(function, list(batch.values())), advance)
            else:
                _run_pool(workers or os.cpu_count() or 1, function, batches, store, advance, threads_per_worker)
    rows: list[dict] = []
    for key in keys:
        stored = store.get(key)
        if stored is None:
            raise RuntimeError(f"task {key[:12]}: result missing after the run")
        rows.extend(stored)
    return rows


def _batches(pending: dict[str, dict], batch_key, max_batch: int) -> list[dict[str, dict]]:
    """Pending tasks (key → task) grouped by ``batch_key``, in order of first appearance."""
    if batch_key is None:
        return [{key: task} for key, task in pending.items()]
    groups: dict[str, dict[str, dict]] = {}
    for key, task in pending.items():
        groups.setdefault(batch_key(task), {})[key] = task
    out = []
    for group in groups.values():
        items = list(group.items())
        out += [dict(items[i : i + max_batch]) for i in range(0, len(items), max_batch)]
    return out


def _store_batch(store: ResultStore, batch: dict[str, dict], results: list[list[dict]], advance) -> None:
    for key, rows in zip(batch, results, strict=True):
        store.put(key, rows)
        advance()


def _run_pool(
    workers: int,
    function: TaskFunction,
    batches: list[dict[str, dict]],
    store: ResultStore,
    advance,
    threads_per_worker: int | None = None,
) -> None:
    # spawn, not fork: Dr.Jit's LLVM backend keeps threads that must not be forked; each
    # worker renders with its share of the cores (BEACON_SIM_THREADS, read at start-up)
    n = min(workers, len(batches))
    with (
        worker_threads(n, threads_per_worker),
        ProcessPoolExecutor(max_workers=n, mp_context=get_context("spawn")) as pool,
    ):
        futures = {pool.submit(run_batch, function, list(batch.values())): batch for batch in batches}
        for future in as_completed(futures):
            _store_batch(store, futures[future], future.result(), advance)


class worker_threads:
    """Set BEACON_SIM_THREADS = cores / workers for processes started inside the block."""

    def __init__(self, workers: int, threads: int | None = None):
        self.value = str(threads or max(1, (os.cpu_count() or 1) // max(workers, 1)))

    def __enter__(self):
        self.saved = os.environ.get("BEACON_SIM_THREADS")
        os.environ.setdefault("BEACON_SIM_THREADS", self.value)
        return self

    def __exit__(self, *exc):
        if self.saved is None:
            os.environ.pop("BEACON_SIM_THREADS", None)
        return False


def _run_dask(
    address: str, function: TaskFunction, batches: list[dict[str, dict]], store: ResultStore, advance
) -> None:
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    with Client(address) as client:
        futures = {
            client.submit(
                run_batch, function, list(batch.values()), key=f"beacon-sim-{next(iter(batch))}", pure=False
            ): batch
            for batch in batches
        }
        for future in dask_completed(list(futures)):
            _store_batch(store, futures[future], future.result(), advance)


def selftest_task(task: dict) -> list[dict]:
    """A cheap deterministic task for testing the runner itself: sums a seeded random
    walk of ``task["n"]`` steps after sleeping ``task.get("sleep_s", 0)`` seconds."""
    time.sleep(float(task.get("sleep_s", 0.0)))
    walk = np.random.default_rng(int(task["seed"])).normal(size=int(task["n"])).cumsum()
    return [{"seed": int(task["seed"]), "n": int(task["n"]), "end": float(walk[-1]), "max": float(walk.max())}]
