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

Row fields that measure the machine rather than the task (:data:`MACHINE_COLUMNS`, such as
a worker's peak memory) differ between an interrupted-and-resumed run and an uninterrupted
one; they are left out of the returned rows and appended to ``<out>/machine.csv`` as each
task finishes, so result tables depend on the tasks alone.

The user's hardware files travel with the tasks as contents (:class:`scenes.hardware.HardwareSet`,
read once when the command started): every batch carries them, each worker installs them before
its tasks, and their digest is part of every key, so a file edited or removed during a run
changes neither the results nor the key they are stored under, and a Dask worker on another
machine needs no copy of the files.

On a Dask cluster, a sweep whose scheduler has had no worker for :data:`NO_WORKER_TIMEOUT_S`
fails with a one-line error (:class:`NoWorkersError`) instead of waiting for ever; the finished
tasks are stored, so the same command resumes once workers are back.

Interrupting (Ctrl-C, SIGINT) stops a local pool at once: pool workers die on SIGINT (the
terminal sends it to the whole process group) and the parent terminates any that remain
instead of waiting for the queued tasks; finished tasks are already stored, so running the
same sweep again resumes. Pool workers also die with their parent however it ends (SIGTERM,
SIGKILL, a crash): :func:`die_with_parent` in each worker's start-up, so no worker is left
holding its memory after the command is gone.

A run that cannot go on for a reason outside its tasks raises :class:`RunStopped` with a
one-line message: the disk is full (naming the file it could not write), a Dask scheduler
was lost (naming its address), or a stored task record cannot be read (naming the file).
Finished tasks are stored either way, so the same command resumes. A stored record that
is not what its file name says (it does not parse, fails its digest, is another task's, or
holds no rows: made or copied by hand) is reported in one warning line naming the file and
its task computed again.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import json
import logging
import os
import signal
import stat
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed, wait
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np

from scenes.hardware import HardwareSet, install_hardware, user_hardware
from scenes.render_cache import atomic_write_bytes, content_key
from studies.engine.strict_json import decode_non_finite, encode_non_finite

__all__ = [
    "DASK_POLL_S",
    "DISK_FULL",
    "HUGEPAGE_ENV",
    "MACHINE_COLUMNS",
    "MACHINE_LOG",
    "NO_WORKER_TIMEOUT_S",
    "PARENT_POLL_S",
    "PR_SET_PDEATHSIG",
    "SCHEDULER_TIMEOUT_S",
    "MachineLog",
    "NoWorkersError",
    "Progress",
    "ResultStore",
    "RunStopped",
    "TaskFunction",
    "WorkerWatchdog",
    "die_with_parent",
    "disk_full_names",
    "function_name",
    "no_hugepage_advice",
    "no_progress",
    "open_in_place",
    "run_batch",
    "run_one",
    "run_tasks",
    "selftest_task",
    "set_hugepage_advice",
    "stop_pool",
    "task_key",
    "without_machine_columns",
    "worker_start",
    "worker_threads",
]

logger = logging.getLogger("beacon_sim")

TaskFunction = Callable[[dict], list[dict]]
"""A worker function: one JSON-able task in, its result rows out. It must be a module-level
function (process pools and Dask send it by its qualified name)."""

Progress = Callable[[str, int, int], AbstractContextManager[Callable[[], None]]]
"""A progress display: called with (description, total, already done), it gives a context
manager whose value is called once per finished task. The command line passes a rich bar."""


MACHINE_COLUMNS = ("worker_peak_rss_MiB", "frame_s")
"""Row fields that measure the machine a task ran on, not the task (a worker's peak memory,
MiB; a frame's wall time in its worker, s, its render included when it made one): logged to
:data:`MACHINE_LOG`, never part of the rows :func:`run_tasks` returns."""

MACHINE_LOG = "machine.csv"
"""Log of :data:`MACHINE_COLUMNS` in a sweep's output folder: one line per finished task and
field when the task's rows share the value (a frame's measurement, logged on ``row`` 0, so
summing a field sums each frame once), else one line per row (``task``: the key's first 16
hex digits, ``row``: index within the task's rows)."""


def no_progress(description: str, total: int, done: int) -> AbstractContextManager[Callable[[], None]]:
    """A :data:`Progress` that shows nothing."""
    return nullcontext(lambda: None)


def function_name(function: TaskFunction) -> str:
    """``module:qualname`` of a worker function (part of every task key)."""
    return f"{function.__module__}:{function.__qualname__}"


NO_WORKER_TIMEOUT_S = 120.0
"""How long a Dask sweep waits while its scheduler has no worker before it fails, s. A worker
that dies is restarted by its nanny within seconds, and a job-queue cluster adds workers within
a minute or so; two minutes with none means the cluster is gone or was never scaled up."""

DASK_POLL_S = 0.25
"""How often a Dask sweep with nothing finished looks again (and counts the workers), s."""


class NoWorkersError(RuntimeError):
    """A Dask sweep's scheduler has had no worker for longer than the timeout."""


@dataclass
class WorkerWatchdog:
    """Fails a sweep whose cluster has had no worker for ``timeout_s``.

    Call :meth:`observe` with the number of workers now connected whenever the sweep waits;
    it raises :class:`NoWorkersError` once none has been connected for longer than
    ``timeout_s`` (counted from the last time one was, or from the start).
    """

    timeout_s: float
    where: str = "the Dask scheduler"
    clock: Callable[[], float] = time.monotonic

    def __post_init__(self) -> None:
        self._last_seen = self.clock()

    def observe(self, workers: int, unfinished: int = 0) -> None:
        """Note ``workers`` connected now (``unfinished`` tasks still to run, for the message)."""
        now = self.clock()
        if workers > 0:
            self._last_seen = now
        elif now - self._last_seen > self.timeout_s:
            raise NoWorkersError(
                f"scheduler: no worker connected to {self.where} for {self.timeout_s:g} s with {unfinished} "
                "task batches unfinished; the finished tasks are stored: start workers and run the same command "
                "again to resume"
            )


def run_one(function: TaskFunction, task: dict, hardware: HardwareSet | None = None) -> list[dict]:
    """Worker entry point (top level, so process pools and Dask can pickle it)."""
    return run_batch(function, [task], hardware)[0]


class RunStopped(RuntimeError):
    """A run stopped for a reason outside its tasks (disk full, cluster lost, an unreadable
    task record); the message is one line, and the finished tasks are stored."""


DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
"""``errno`` values of a full disk (or quota)."""

PR_SET_PDEATHSIG = 1
"""``prctl`` option (Linux ``<sys/prctl.h>``): the signal a process gets when its parent dies."""

PARENT_POLL_S = 0.5
"""How often a worker's watchdog thread checks that its parent is alive, s."""


def die_with_parent(parent_pid: int) -> None:
    """Make this process end when ``parent_pid`` (its parent) does, however the parent ends.

    On Linux the kernel sends SIGKILL the moment the parent dies (``prctl(PR_SET_PDEATHSIG)``);
    everywhere, a daemon thread checks every :data:`PARENT_POLL_S` whether the process has
    been re-parented and then exits at once. Ends the process now when the parent is already gone.
    """
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watchdog alone
            pass
    if os.getppid() != parent_pid:  # died before the prctl took effect
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="beacon-sim-parent-watch", daemon=True).start()


try:  # numpy's own run-time toggle (private, so guarded; the environment variable is read at import only)
    from numpy._core.multiarray import _set_madvise_hugepage as _madvise_toggle
except ImportError:  # pragma: no cover - another numpy layout
    _madvise_toggle = None

HUGEPAGE_ENV = "NUMPY_MADVISE_HUGEPAGE"
"""numpy's switch for asking Linux for transparent huge pages on arrays of 4 MiB and more
(read when numpy is imported; source: numpy's "Global state" reference, "madvise hugepage on Linux")."""


def no_hugepage_advice() -> bool:
    """Stop numpy asking the kernel for transparent huge pages, in this process and in the
    processes it starts (unless the user set :data:`HUGEPAGE_ENV` to anything but 0: their choice
    stands). Returns whether the advice is off in this process.

    Why: where the kernel's huge-page ``defrag`` setting is ``madvise`` (as on the 2-core test
    machine), every fresh large array numpy advises is compacted and zeroed in 2 MiB pages
    synchronously at first touch. A T6 frame's ~18 Mpx temporaries made that most of its time:
    ``beacon-sim capture --camera canon-t6-18mm`` took 8.6 s of user and 15.4 s of kernel time
    (25.0 s wall) with the advice and 8.9 s and 2.3 s (11.4 s) without it, the same image bytes
    (2026-12-07; `perf` put 60 % of the samples in the kernel's ``clear_page_erms`` under
    ``do_huge_pmd_anonymous_page``). It changes no result: only how the kernel backs memory.

    Examples
    --------
    >>> no_hugepage_advice() in (True, False)
    True
    """
    if os.environ.get(HUGEPAGE_ENV, "0") != "0":
        return False
    os.environ[HUGEPAGE_ENV] = "0"  # spawned workers read it when they import numpy
    set_hugepage_advice(False)  # this process imported numpy already
    return _madvise_toggle is not None


def set_hugepage_advice(on: bool) -> bool:
    """Turn numpy's huge-page advice on or off in this process (for arrays allocated from now on);
    returns the previous setting (False, and nothing changed, where numpy has no such toggle)."""
    return bool(_madvise_toggle(on)) if _madvise_toggle is not None else False


def worker_start(parent_pid: int) -> None:
    """Pool worker start-up: die at once on SIGINT, writing nothing (a Mitsuba render
    cancelled by SIGINT would otherwise return a partial image as if it were complete), die
    with the parent process ``parent_pid`` (:func:`die_with_parent`), and no huge-page advice
    (:func:`no_hugepage_advice`)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    die_with_parent(parent_pid)
    no_hugepage_advice()


def run_batch(function: TaskFunction, tasks: list[dict], hardware: HardwareSet | None = None) -> list[list[dict]]:
    """Worker entry point for a batch: each task's rows, in order.

    ``hardware``: the user's hardware files the tasks were keyed with, installed in this
    process first (:func:`scenes.hardware.install_hardware`); None keeps the process's own.
    """
    threads = os.environ.get("BEACON_SIM_THREADS")
    if threads:
        cv2.setNumThreads(max(1, int(threads)))  # share the cores with the other workers
    if hardware is not None:
        install_hardware(hardware)
    return [function(task) for task in tasks]


@dataclass
class ResultStore:
    """Finished tasks' rows on disk, one JSON file per task."""

    root: Path

    def path(self, key: str) -> Path:
        """File of ``key``."""
        return Path(self.root) / key[:2] / f"{key}.json"

    def get(self, key: str) -> list[dict] | None:
        """The stored rows, or None when missing or not a record of ``key``.

        A record that does not parse, fails its digest (cut short, bit-flipped), names another
        key (copied from another task's file) or holds something other than rows (a list of
        flat records) is reported in one warning line naming the file, removed, and its task
        runs again. A record that cannot be read at all (a folder, no permission) raises
        :class:`RunStopped` naming the file.
        """
        path = self.path(key)
        try:
            text = path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise RunStopped(f"tasks: cannot read the task record {path} ({exc.strerror or exc})") from None
        problem = None
        try:
            record = json.loads(text)  # also reads records written before strict JSON (bare NaN)
            rows = decode_non_finite(record["rows"], record.get("non_finite", []))
            if record["sha256"] != _digest(rows):
                problem = "its digest does not match its rows"
            elif record["key"] != key:
                problem = "it is the record of another task"
            elif not _flat_rows(rows):
                problem = "its rows are not a list of flat records"
        except (ValueError, KeyError, TypeError, IndexError, RecursionError) as exc:
            problem = f"it does not parse as a task record ({type(exc).__name__})"
        if problem is None:
            return rows
        logger.warning("tasks: %s is not a record of task %s (%s); computing the task again", path, key[:12], problem)
        path.unlink(missing_ok=True)
        return None

    def put(self, key: str, rows: list[dict]) -> None:
        """Store ``rows`` for ``key`` atomically."""
        path = self.path(key)
        for folder in (Path(self.root), path.parent):
            if folder.is_symlink():  # the file would be written wherever the link points
                raise ValueError(f"out: expected no symbolic links inside the output folder, got {folder}")
        path.parent.mkdir(parents=True, exist_ok=True)
        clean, places = encode_non_finite(rows)
        record = {"key": key, "sha256": _digest(rows), "rows": clean, "non_finite": places}
        with disk_full_names(path):
            atomic_write_bytes(path, json.dumps(record, sort_keys=True, allow_nan=False).encode())


def _flat_rows(rows: object) -> bool:
    """Whether ``rows`` is what a task function returns: a list of records (dicts keyed by strings;
    a study frame's values are scalars, an experiment's may be lists)."""
    return isinstance(rows, list) and all(isinstance(r, dict) and all(isinstance(k, str) for k in r) for r in rows)


def _digest(rows: list[dict]) -> str:
    """SHA-256 of the rows as Python's JSON writes them (NaN as ``NaN``): the same digest as
    records written before they were stored as strict JSON, so those still resume."""
    return hashlib.sha256(json.dumps(rows, sort_keys=True, allow_nan=True).encode()).hexdigest()


def without_machine_columns(rows: list[dict]) -> list[dict]:
    """``rows`` without :data:`MACHINE_COLUMNS`."""
    return [{k: v for k, v in row.items() if k not in MACHINE_COLUMNS} for row in rows]


@dataclass
class MachineLog:
    """Appends the :data:`MACHINE_COLUMNS` of finished tasks' rows to a CSV file."""

    path: Path

    def record(self, key: str, rows: list[dict]) -> None:
        """Log the machine fields of one finished task's rows (nothing when it has none)."""
        lines = []
        for name in MACHINE_COLUMNS:
            values = [(i, row[name]) for i, row in enumerate(rows) if name in row]
            if values and all(v == values[0][1] for _, v in values):
                values = values[:1]  # one frame's measurement, shared by its rows: logged once
            lines += [f"{key[:16]},{i},{name},{v!r}\n" for i, v in values]
        if not lines:
            return
        with disk_full_names(self.path):
            fd = open_in_place(self.path)
            with os.fdopen(fd, "a", encoding="utf-8") as f:
                f.write(("task,row,field,value\n" if os.fstat(fd).st_size == 0 else "") + "".join(lines))


class disk_full_names:
    """Turn a full disk (:data:`DISK_FULL`) while writing ``path`` into :class:`RunStopped`
    naming it (a failed ``write`` or ``close`` says nothing of the file)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> disk_full_names:
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        if isinstance(exc, OSError) and exc.errno in DISK_FULL:
            raise RunStopped(
                f"disk full at {self.path} ({exc.strerror}); finished tasks are stored: "
                "free some space and re-run the same command to resume"
            ) from None
        return False


def open_in_place(path: Path) -> int:
    """Open ``path`` for appending, created if missing: never through a symbolic link
    (``O_NOFOLLOW``), nor a file with other hard links (appending would write into another
    file), else a one-line ``ValueError`` naming the path."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    except OSError:
        if os.path.islink(path):
            raise ValueError(f"out: expected no symbolic links inside the output folder, got {path}") from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        raise ValueError(
            f"out: expected {path} to be a plain file of this folder, got one with {st.st_nlink} hard links"
        )
    return fd


def task_key(function: TaskFunction, task: dict, version: int, hardware: HardwareSet | None = None) -> str:
    """Content key of a task.

    With user hardware files (``hardware``, default this process's:
    :func:`scenes.hardware.user_hardware`) their contents and those of every file they name
    are part of the key, so a task is never answered from results of other contents of the
    user's files; with none the key is as before.
    """
    digest = (user_hardware() if hardware is None else hardware).digest
    extra = (digest,) if digest else ()
    return content_key("task", function_name(function), version, task, *extra)


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
    no_worker_timeout_s: float = NO_WORKER_TIMEOUT_S,
) -> list[dict]:
    """Run ``tasks`` (skipping stored ones) and return all rows in task order, without
    :data:`MACHINE_COLUMNS` (logged to :data:`MACHINE_LOG` in ``out_dir`` instead).

    Parameters
    ----------
    tasks
        JSON-able task dicts, or records with a ``to_dict()`` that gives one
        (:class:`studies.engine.frame_task.FrameTask`).
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
    no_worker_timeout_s
        With ``scheduler``: fail (:class:`NoWorkersError`) once the cluster has had no worker
        for this long, s.
    """
    if version is None:
        version = getattr(sys.modules[function.__module__], "FRAME_VERSION", 1)
    store = ResultStore(Path(out_dir) / "tasks")
    log = MachineLog(Path(out_dir) / MACHINE_LOG)
    hardware = user_hardware()  # read once: the contents the keys cover are the contents sent
    tasks = [t.to_dict() if hasattr(t, "to_dict") else t for t in tasks]  # typed records travel as plain data
    keys = [task_key(function, t, version, hardware) for t in tasks]
    pending: dict[str, dict] = {}
    for key, task in zip(keys, tasks, strict=True):
        if key not in pending and store.get(key) is None:
            pending[key] = task
    batches = _batches(pending, batch_key, max_batch)
    with progress(description, len(set(keys)), len(set(keys)) - len(pending)) as advance:
        if pending:
            if scheduler:
                watchdog = WorkerWatchdog(no_worker_timeout_s, f"the Dask scheduler at {scheduler}")
                _run_dask(scheduler, function, batches, store, advance, log, hardware, watchdog)
            elif not isolated and ((workers or os.cpu_count() or 1) == 1 or len(batches) == 1):
                for batch in batches:
                    _store_batch(store, batch, run_batch(function, list(batch.values()), hardware), advance, log)
            else:
                n = workers or os.cpu_count() or 1
                _run_pool(n, function, batches, store, advance, threads_per_worker, log, hardware)
    rows: list[dict] = []
    for key in keys:
        stored = store.get(key)
        if stored is None:
            raise RunStopped(f"tasks: the record of task {key[:12]} went missing during the run ({store.path(key)})")
        rows.extend(without_machine_columns(stored))
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


def _store_batch(
    store: ResultStore, batch: dict[str, dict], results: list[list[dict]], advance, log: MachineLog | None = None
) -> None:
    for key, rows in zip(batch, results, strict=True):
        store.put(key, rows)
        if log is not None:
            log.record(key, rows)
        advance()


def _run_pool(
    workers: int,
    function: TaskFunction,
    batches: list[dict[str, dict]],
    store: ResultStore,
    advance,
    threads_per_worker: int | None = None,
    log: MachineLog | None = None,
    hardware: HardwareSet | None = None,
) -> None:
    # spawn, not fork: Dr.Jit's LLVM backend keeps threads that must not be forked; each
    # worker renders with its share of the cores (BEACON_SIM_THREADS, read at start-up)
    n = min(workers, len(batches))
    with worker_threads(n, threads_per_worker):
        pool = ProcessPoolExecutor(
            max_workers=n, mp_context=get_context("spawn"), initializer=worker_start, initargs=(os.getpid(),)
        )
        try:
            futures = {pool.submit(run_batch, function, list(batch.values()), hardware): batch for batch in batches}
            for future in as_completed(futures):
                if future.exception() is not None:
                    # a failed task: drop the queued batches, store those already running, then raise
                    running = [f for f in futures if not f.done() and not f.cancel()]
                    for other in wait(running).done:
                        if other.exception() is None:
                            _store_batch(store, futures[other], other.result(), advance, log)
                    raise future.exception()
                _store_batch(store, futures[future], future.result(), advance, log)
        except BaseException:
            stop_pool(pool)  # Ctrl-C, or a failure: no worker outlives the run; the stored tasks are the state
            raise
        pool.shutdown(wait=True)


def stop_pool(pool: ProcessPoolExecutor, grace_s: float = 1.0) -> None:
    """Terminate a process pool's workers without waiting for their tasks (SIGTERM, then
    SIGKILL for any still alive after ``grace_s``) and drop its queued tasks."""
    table = getattr(pool, "_processes", None) or {}  # the pool's own pid -> process (no public handle)
    manager = getattr(pool, "_executor_manager_thread", None)
    for process in list(table.values()):
        if process.is_alive():
            process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)  # drops the pool's references, not the table
    deadline = time.monotonic() + grace_s
    if manager is not None:  # the pool's manager thread may still start a worker until it ends
        manager.join(grace_s)
    processes = list(table.values())
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.is_alive():
            process.kill()
            process.join()  # SIGKILL cannot be caught: it ends, however loaded the machine


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
    address: str,
    function: TaskFunction,
    batches: list[dict[str, dict]],
    store: ResultStore,
    advance,
    log: MachineLog | None = None,
    hardware: HardwareSet | None = None,
    watchdog: WorkerWatchdog | None = None,
) -> None:
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    watchdog = watchdog or WorkerWatchdog(NO_WORKER_TIMEOUT_S, f"the Dask scheduler at {address}")
    try:
        client = Client(address, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise _scheduler_lost(address, exc) from None
    with client:
        futures = {
            client.submit(
                run_batch, function, list(batch.values()), hardware, key=f"beacon-sim-{next(iter(batch))}", pure=False
            ): batch
            for batch in batches
        }
        try:
            waiting = dask_completed(list(futures))
            while not waiting.is_empty():
                ready = waiting.next_batch(block=False)
                for future in ready:
                    if future.status == "cancelled" or client.status not in ("running", "connecting"):
                        raise _scheduler_lost(address, None)
                    rows = _dask_result(
                        future, client, address, lambda: watchdog.observe(len(client.nthreads()), waiting.count())
                    )
                    _store_batch(store, futures[future], rows, advance, log)
                if not ready:  # nothing finished: is anyone still working on it?
                    _watch(client, address, lambda: watchdog.observe(len(client.nthreads()), waiting.count()))
                    time.sleep(DASK_POLL_S)
        except BaseException:  # Ctrl-C, no workers, a failed task: the cluster stops this sweep's tasks
            client.cancel(list(futures))  # finished ones are stored
            raise


def _dask_result(future, client, address: str, check: Callable[[], None]) -> list[list[dict]]:
    """A finished Dask future's result; while it is unavailable (its result was lost with a
    worker and waits to be computed again) ``check`` runs between tries (the watchdog). A lost
    scheduler is :class:`RunStopped`; a task's own error passes while the cluster is up."""
    while True:
        try:
            return future.result(timeout=DASK_POLL_S)
        except TimeoutError:
            _watch(client, address, check)
        except _cluster_errors() as exc:
            if isinstance(exc, OSError) and client.status == "running":
                raise
            raise _scheduler_lost(address, exc) from None


def _watch(client, address: str, check: Callable[[], None]) -> None:
    """Run the watchdog's ``check``; a scheduler that is gone is :class:`RunStopped`."""
    if client.status not in ("running", "connecting"):
        raise _scheduler_lost(address, None)
    try:
        check()
    except _cluster_errors() as exc:
        raise _scheduler_lost(address, exc) from None


SCHEDULER_TIMEOUT_S = 10.0
"""How long a Dask client waits to (re)connect to its scheduler, s."""


def _cluster_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean the cluster, not a task, failed."""
    from concurrent.futures import CancelledError

    from distributed.comm.core import CommClosedError

    return (CancelledError, CommClosedError, OSError, TimeoutError)


def _scheduler_lost(address: str, exc: BaseException | None) -> RunStopped:
    reason = f" ({type(exc).__name__}{': ' + str(exc) if str(exc) else ''})" if exc is not None else ""
    return RunStopped(
        f"scheduler: lost the Dask scheduler at {address}{reason}; finished tasks are stored: "
        "restart the cluster and re-run the same command to resume"
    )


def selftest_task(task: dict) -> list[dict]:
    """A cheap deterministic task for testing the runner itself: sums a seeded random
    walk of ``task["n"]`` steps after sleeping ``task.get("sleep_s", 0)`` seconds."""
    time.sleep(float(task.get("sleep_s", 0.0)))
    walk = np.random.default_rng(int(task["seed"])).normal(size=int(task["n"])).cumsum()
    return [{"seed": int(task["seed"]), "n": int(task["n"]), "end": float(walk[-1]), "max": float(walk.max())}]
