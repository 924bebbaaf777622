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
import importlib
import json
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from scenes.render_cache import atomic_write_bytes, content_key


def resolve(function: str) -> Callable[[dict], list[dict]]:
    """The function named ``package.module:function``."""
    module, _, name = function.partition(":")
    return getattr(importlib.import_module(module), name)


def run_one(function: str, task: dict) -> list[dict]:
    """Worker entry point (top level, so process pools and Dask can pickle it)."""
    return run_batch(function, [task])[0]


def run_batch(function: str, tasks: list[dict]) -> list[list[dict]]:
    """Worker entry point for a batch: each task's rows, in order."""
    threads = os.environ.get("BEACON_SIM_THREADS")
    if threads:
        import cv2

        cv2.setNumThreads(max(1, int(threads)))  # share the cores with the other workers
    fn = resolve(function)
    return [fn(task) for task in tasks]


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


def task_key(function: str, task: dict, version: int) -> str:
    """Content key of a task."""
    return content_key("task", function, version, task)


def run_tasks(
    tasks: Sequence[dict],
    out_dir: Path,
    function: str = "studies.frame:simulate_frame",
    version: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    description: str = "tasks",
    progress: bool = True,
    batch_key: Callable[[dict], str] | None = None,
    max_batch: int = 32,
) -> list[dict]:
    """Run ``tasks`` (skipping stored ones) and return all rows in task order.

    Parameters
    ----------
    tasks
        JSON-able task dicts.
    out_dir
        Study output directory; finished tasks go to ``out_dir/tasks``.
    function
        ``module:function`` mapping a task to its rows.
    version
        Version of ``function``'s output (part of every key); default the module's
        ``FRAME_VERSION`` or 1.
    workers
        Local worker processes (default: CPU count); 1 runs in this process.
    scheduler
        Address of a Dask distributed scheduler; runs the same tasks there instead.
    batch_key
        Label of a task's batch (tasks with equal labels run together in one worker,
        at most ``max_batch`` at a time); default every task alone.
    """
    if version is None:
        version = getattr(importlib.import_module(function.partition(":")[0]), "FRAME_VERSION", 1)
    store = ResultStore(Path(out_dir) / "tasks")
    keys = [task_key(function, t, version) for t in tasks]
    pending: dict[str, dict] = {}
    for key, task in zip(keys, tasks, strict=True):
        if key not in pending and store.get(key) is None:
            pending[key] = task
    batches = _batches(pending, batch_key, max_batch)
    with _progress(progress, description, len(set(keys)), len(set(keys)) - len(pending)) as advance:
        if pending:
            if scheduler:
                _run_dask(scheduler, function, batches, store, advance)
            elif (workers or os.cpu_count() or 1) == 1 or len(batches) == 1:
                for batch in batches:
                    _store_batch(store, batch, run_batch(function, list(batch.values())), advance)
            else:
                _run_pool(workers or os.cpu_count() or 1, function, batches, store, advance)
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
    workers: int, function: str, batches: list[dict[str, dict]], store: ResultStore, advance, force: bool = False
) -> None:
    # spawn, not fork: Dr.Jit's LLVM backend keeps threads that must not be forked; each
    # worker renders with its share of the cores (BEACON_SIM_THREADS, read at start-up)
    n = workers if force else min(workers, len(batches))
    with _worker_threads(n), ProcessPoolExecutor(max_workers=n, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(run_batch, function, list(batch.values())): batch for batch in batches}
        for future in as_completed(futures):
            _store_batch(store, futures[future], future.result(), advance)


class _worker_threads:
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


def _run_dask(address: str, function: str, batches: list[dict[str, dict]], store: ResultStore, advance) -> None:
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


class _progress:
    """A rich progress bar with an ETA (or nothing)."""

    def __init__(self, enabled: bool, description: str, total: int, done: int):
        self.enabled, self.description, self.total, self.done = enabled, description, total, done

    def __enter__(self):
        if not self.enabled:
            return lambda: None
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        from studies.cli import console

        self.bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            console=console,
            transient=False,
        )
        self.bar.__enter__()
        self.id = self.bar.add_task(self.description, total=self.total, completed=self.done)
        return lambda: self.bar.advance(self.id)

    def __exit__(self, *exc):
        if self.enabled:
            self.bar.__exit__(*exc)
        return False


def selftest_task(task: dict) -> list[dict]:
    """A cheap deterministic task for testing the runner itself: sums a seeded random
    walk of ``task["n"]`` steps after sleeping ``task.get("sleep_s", 0)`` seconds."""
    import time

    import numpy as np

    time.sleep(float(task.get("sleep_s", 0.0)))
    walk = np.random.default_rng(int(task["seed"])).normal(size=int(task["n"])).cumsum()
    return [{"seed": int(task["seed"]), "n": int(task["n"]), "end": float(walk[-1]), "max": float(walk.max())}]
