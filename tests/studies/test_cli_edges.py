"""The command line at its edges: each input the issue lists gives one line on stderr and exit
code 2 before any work and before any output folder exists; help, version, a lock per output
folder; Ctrl-C stops at once with exit 130 and leaves a state the same command resumes to the
same table.

Commands run in this process through :func:`studies.cli.app.main` with the functions that would
start work replaced by :func:`tests.helpers.cli.patch_work` (they raise :class:`WorkStarted`), so no test renders.
Top-level imports stay light: spawned pool workers import this module for :func:`edge_task`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers.cli import REPO, WorkStarted, assert_one_line_error, invoke

# -- render limits, cache, empty --out: one line, nothing written ----------------------


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--oversampling", "100"], "oversampling"),
        (["--oversampling", "0"], "oversampling"),
        (["--spp", "1000000000"], "spp"),
        (["--spp", "0"], "spp"),
        (["--seed", "600000"], "seed"),
        (["--range-m", "1", "--oversampling", "8", "--spp", "65536"], "spp"),  # 1e13 samples: never ends
        (["--range-m", "0.3", "--oversampling", "8"], "oversampling"),  # 7.5e8 sub-pixels: 3 GB per image
        (["--range-m", "0.05"], "range_m"),  # inside the beacon: found by the crop, before any folder
    ],
)
@pytest.mark.parametrize("command", ["render", "capture"])
def test_impossible_renders_fail_before_any_folder(work, command, args, field):
    code, _, err = invoke([command, "--out", "o", *args])
    assert_one_line_error(code, err, field)
    assert not (work / "o").exists()


def test_render_limits_accept_their_largest_values(work):
    assert invoke(["render", "--out", "o", "--range-m", "20", "--spp", "65536", "--oversampling", "3"])[0] == "work"
    assert invoke(["render", "--out", "o", "--range-m", "20", "--oversampling", "8", "--seed", "542362"])[0] == "work"


@pytest.mark.parametrize(
    "args",
    [
        ["render", "--out", "o"],
        ["capture", "--out", "o"],
        ["study", "range-limit", "--quick", "--out", "o"],
        ["saturation-table", "--out", "o"],
        ["unknowns-search", "--out", "o"],
        ["e2e-detection", "--out", "o", "--quick"],
        ["diffuser-mosaic", "--out", "o"],
    ],
)
def test_unwritable_render_cache_fails_before_any_work(work, monkeypatch, args):
    (work / "file").write_text("x")
    monkeypatch.setenv("BEACON_SIM_CACHE", str(work / "file" / "cache"))
    code, _, err = invoke(args)
    assert_one_line_error(code, err, "BEACON_SIM_CACHE")
    assert not (work / "o").exists()


def test_no_cache_needs_no_writable_cache(work, monkeypatch):
    (work / "file").write_text("x")
    monkeypatch.setenv("BEACON_SIM_CACHE", str(work / "file" / "cache"))
    assert invoke(["render", "--out", "o", "--no-cache"])[0] == "work"


def test_a_cache_that_cannot_be_written_keeps_the_render(tmp_path, caplog):
    import numpy as np

    from scenes.render_cache import RenderCache

    (tmp_path / "file").write_text("x")
    cache = RenderCache(root=tmp_path / "file" / "cache")
    assert cache.store("ab" * 32, {"image": np.ones((2, 2))}) is None  # a warning, not an exception
    assert cache.stats.failed_writes == 1 and "cannot write" in caplog.text
    assert cache.load("ab" * 32) is None


@pytest.mark.parametrize(
    "command",
    [
        ["render"],
        ["capture"],
        ["emva1288"],
        ["study", "range-limit"],
        ["validate", "--nominal"],
        ["main-job"],
        ["e2e-detection"],
        ["saturation-table"],
        ["diffuser-mosaic"],
        ["unknowns-search"],
        ["colour-reach"],
    ],
)
@pytest.mark.parametrize("out", ["", "  "])
def test_empty_out_is_refused_and_nothing_is_written_here(work, command, out):
    code, _, err = invoke([*command, "--out", out])
    assert_one_line_error(code, err, "out")
    assert list(work.iterdir()) == []


# -- exposure settings: refused when the body lacks them, named by their own field -------


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--camera", "canon-t6-18mm", "--gain", "5"], "gain"),  # was ignored and recorded in capture.json
        (["--camera", "logitech-c270", "--iso", "100"], "iso"),  # was reported as exposure_s
        (["--camera", "logitech-c270", "--gain", "10"], "gain"),  # the webcam exposes automatically
        (["--camera", "logitech-c270", "--exposure-s", "0.01"], "exposure_s"),
        (["--camera", "canon-t6-18mm", "--iso", "50"], "iso"),  # below the body's range
    ],
)
def test_capture_exposure_settings_the_camera_lacks_are_refused(work, args, field):
    code, _, err = invoke(["capture", "--out", "o", *args])
    assert_one_line_error(code, err, field)
    assert not (work / "o").exists()


def test_capture_accepts_the_settings_the_camera_has(work):
    assert invoke(["capture", "--out", "o", "--iso", "800", "--exposure-s", "0.01"])[0] == "work"


# -- one spelling per option ------------------------------------------------------------


def _click_commands():
    import typer

    from studies.cli.app import app

    return typer.main.get_command(app).commands


def test_one_spelling_per_option():
    """``--cameras`` (a comma-separated list) wherever a command takes several cameras,
    ``--camera`` (one name, not repeatable) where it takes one; lists carry their unit."""
    seen: dict[str, set[str]] = {}
    for name, command in _click_commands().items():
        for param in command.params:
            for opt in getattr(param, "opts", ()):
                seen.setdefault(opt, set()).add(name)
            if "--camera" in getattr(param, "opts", ()):
                assert not getattr(param, "multiple", False), f"{name}: --camera repeatable"
    assert {"study", "saturation-table", "colour-reach"} <= seen["--cameras"]
    assert not seen["--camera"] & seen["--cameras"]
    assert "--ranges" not in seen and "--currents" not in seen
    assert {"study"} <= seen["--ranges-m"] and {"study"} <= seen["--currents-ma"]


@pytest.mark.parametrize(
    ("args", "outcome"),
    [
        (["study", "range-limit", "--out", "o", "--ranges-m", "2,5", "--currents-ma", "5,20"], "work"),
        (["study", "range-limit", "--out", "o", "--ranges", "2,5"], 2),
        (["study", "range-limit", "--out", "o", "--currents", "5"], 2),
        (["saturation-table", "--out", "o", "--cameras", "canon-t6-18mm,logitech-c270"], "work"),
        (["saturation-table", "--out", "o", "--camera", "canon-t6-18mm"], 2),
        (["colour-reach", "--out", "o", "--cameras", "logitech-c270"], "work"),
        (["colour-reach", "--out", "o", "--camera", "logitech-c270"], 2),
        (["colour-reach", "--out", "o", "--cameras", "logitech-c270,nikon"], 2),
    ],
)
def test_renamed_options(work, args, outcome):
    code, _, err = invoke(args)
    assert code == outcome, err
    if code == 2:
        assert_one_line_error(code, err)


# -- help, version, bare command --------------------------------------------------------


def test_bare_command_prints_help_and_exits_0(work):
    code, out, err = invoke([])
    assert code == 0 and "Usage" in out and "error" not in err


def test_version():
    from importlib.metadata import version

    code, out, _ = invoke(["--version"])
    assert code == 0 and out.strip() == f"beacon-sim {version('beacon-sim')}"


def test_h_and_help_on_every_command(work):
    import typer

    from studies.cli.app import app

    group = typer.main.get_command(app)
    root = group.make_context("beacon-sim", [], resilient_parsing=True)
    assert sorted(group.get_help_option(root).opts) == ["--help", "-h"]
    for name, command in {"": group, **group.commands}.items():
        ctx = command.make_context(name, [], parent=root, resilient_parsing=True)
        assert sorted(command.get_help_option(ctx).opts) == ["--help", "-h"], name
        code, out, err = invoke([name, "-h"] if name else ["-h"])
        assert code == 0 and "Usage" in out, (name, err)
    assert invoke(["study", "--help"])[0] == invoke(["--help"])[0] == 0


def test_help_shows_every_default():
    """Options with a default show it; where the default is None the help says in words what
    happens (``show_default`` text)."""
    missing = []
    for name, command in _click_commands().items():
        for param in command.params:
            if getattr(param, "param_type_name", "") != "option" or param.required or param.name == "help":
                continue
            if getattr(param, "is_flag", False) and param.default is False and not param.secondary_opts:
                continue  # an on/off flag: absent means off
            if param.show_default is False or (param.default is None and not isinstance(param.show_default, str)):
                missing.append(f"{name} {param.opts[0]}")
    assert not missing, missing
    code, out, _ = invoke(["study", "--help"])
    assert code == 0 and "one per CPU" in out and "the study's" in out


# -- one-line usage errors from the parser ---------------------------------------------


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["render", "--out", "o", "--spp", "abc"], "spp"),
        (["render", "--out", "o", "--range-m", "far"], "range-m"),
        (["render", "--out"], "out"),
        (["render"], "out"),
        (["render", "--out", "o", "--bogus"], "option"),
        (["rendr"], "command"),
        (["cameras", "extra"], "arguments"),
        (["cameras", "--json=yes"], "json"),
        (["study"], "name"),
        (["study", "nope", "--out", "o"], "study"),
        (["study", "range-limit", "--out", "o", "--ranges-m", "1,nan"], "ranges_m"),
        (["study", "range-limit", "--out", "o", "--seeds", "1000000000"], "seeds"),
        (["study", "range-limit", "--out", "o", "--workers", "0"], "workers"),
        (["study", "range-limit", "--out", "o", "--workers", "100000"], "workers"),
        (["study", "range-limit", "--out", "o", "--scheduler", "nowhere"], "scheduler"),
        (["study", "range-limit", "--out", "o", "--scheduler", "tcp://127.0.0.1:1"], "scheduler"),
        (["estimator-montecarlo", "--sigma-px", "inf"], "sigma-px"),
        (["estimator-montecarlo", "--range-m", "-3"], "range_m"),
        (["two-stage-check", "--view-deg", "nan"], "view-deg"),
        (["lens-calibration", "--scale", "1000"], "scale"),
        (["lens-calibration", "--model", "pinhole"], "model"),
        (["unknowns-search", "--out", "o", "--seed", "-1"], "seed"),
    ],
)
def test_bad_input_is_one_line_before_any_folder(work, args, field):
    code, _, err = invoke(args)
    assert_one_line_error(code, err, field)
    assert not (work / "o").exists()


# -- one run per output folder ----------------------------------------------------------


def test_a_second_run_on_the_same_out_refuses_naming_the_folder_and_pid(work):
    out = work / "o"
    out.mkdir()
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT);"
            "fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, f'{os.getpid()}\\n'.encode()); print('locked', flush=True);"
            "time.sleep(60)",
            str(out / ".beacon-sim.lock"),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        code, _, err = invoke(["study", "range-limit", "--quick", "--out", "o"])
        line = assert_one_line_error(code, err, "out")
        assert "o" in line and f"pid {holder.pid}" in line
        assert sorted(p.name for p in out.iterdir()) == [".beacon-sim.lock"]
    finally:
        holder.kill()
        holder.wait()
    assert invoke(["study", "range-limit", "--quick", "--out", "o"])[0] == "work"  # free again


def test_the_lock_is_held_during_the_run_and_released_after(work, monkeypatch):
    from studies.catalog import STUDIES

    held = []

    def run(out, options, execution):
        fd = os.open(out / ".beacon-sim.lock", os.O_RDWR)
        try:
            with pytest.raises(BlockingIOError):
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            held.append(os.pread(fd, 32, 0).decode().strip())
        finally:
            os.close(fd)
        raise WorkStarted()

    monkeypatch.setattr(STUDIES["range-limit"], "run", run)
    assert invoke(["study", "range-limit", "--quick", "--out", "o"])[0] == "work"
    assert held == [str(os.getpid())]
    assert not (work / "o" / ".beacon-sim.lock").exists()  # released and removed when the command ended


# -- Ctrl-C ------------------------------------------------------------------------------


def test_keyboard_interrupt_exits_130_with_how_to_resume(work, monkeypatch):
    from studies.catalog import STUDIES

    def run(out, options, execution):
        raise KeyboardInterrupt

    monkeypatch.setattr(STUDIES["range-limit"], "run", run)
    code, _, err = invoke(["study", "range-limit", "--quick", "--out", "o"])
    assert code == 130
    assert err.strip().splitlines()[-1] == (
        "beacon-sim: interrupted; finished tasks are stored, re-run the same command to resume"
    )


def edge_task(task: dict) -> list[dict]:
    """A sweep task for the interrupt test: slow ones sleep ``$EDGE_SLOW_S``; the row carries a
    machine measurement (the worker's pid) that must stay out of the results table."""
    if task["slow"]:
        time.sleep(float(os.environ.get("EDGE_SLOW_S", "0")))
    if task.get("fail"):
        raise ValueError(f"task {task['i']} fails")
    return [{"i": task["i"], "square": task["i"] ** 2, "worker_peak_rss_MiB": float(os.getpid())}]


EDGE_TASKS = [{"i": i, "slow": i >= 2} for i in range(6)]

_INTERRUPTED_STUDY = """
import sys
from studies.catalog import STUDIES
from studies.engine.runner import run_tasks
from studies.engine.tables import write_tables
from tests.studies.test_cli_edges import EDGE_TASKS, edge_task

def run(out, options, execution):
    write_tables(out, run_tasks(EDGE_TASKS, out, edge_task, workers=execution.workers))

for module in STUDIES.values():
    module.run = run
from studies.cli.app import main
sys.argv = ["beacon-sim", "study", "range-limit", "--quick", "--out", sys.argv[1], "--workers", "2"]
main()
"""


def _live_processes_in_group(pgid: int) -> list[int]:
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                pids.append(int(stat.parent.name))
    return pids


def test_ctrl_c_stops_the_pool_at_once_and_the_resumed_table_is_identical(tmp_path):
    """SIGINT to the process group (what a terminal's Ctrl-C sends) while two workers sleep in
    long tasks: exit 130 within seconds (the workers are terminated, not waited for), the
    finished tasks stored, no table written; resuming gives the uninterrupted run's table byte
    for byte, with the machine measurement in machine.csv only."""
    from studies.engine.runner import MACHINE_LOG, run_tasks
    from studies.engine.tables import write_tables

    out = tmp_path / "out"
    env = {**os.environ, "EDGE_SLOW_S": "120", "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, "-c", _INTERRUPTED_STUDY, str(out)],
        cwd=REPO,
        env=env,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while len(list((out / "tasks").rglob("*.json"))) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, "the fast tasks never finished"
            time.sleep(0.1)
        time.sleep(0.5)  # the slow tasks are running
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        elapsed = time.monotonic() - t0
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("beacon-sim: interrupted;"), err
    assert elapsed < 10, f"took {elapsed:.1f} s to stop"
    deadline = time.monotonic() + 5
    while _live_processes_in_group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _live_processes_in_group(proc.pid), "worker processes left running"
    assert len(list((out / "tasks").rglob("*.json"))) == 2
    assert not (out / "results.csv").exists() and not list(out.rglob("*.tmp"))

    write_tables(out, run_tasks(EDGE_TASKS, out, edge_task, workers=1))  # resume (slow tasks now quick)
    reference = tmp_path / "reference"
    write_tables(reference, run_tasks(EDGE_TASKS, reference, edge_task, workers=1))
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()
    assert (out / "results.parquet").read_bytes() == (reference / "results.parquet").read_bytes()
    assert "worker_peak_rss_MiB" not in (out / "results.csv").read_text()
    log = (out / MACHINE_LOG).read_text().splitlines()
    assert log[0] == "task,row,field,value" and len(log) == 1 + len(EDGE_TASKS)
    assert {line.split(",")[2] for line in log[1:]} == {"worker_peak_rss_MiB"}


def test_a_failed_task_drops_the_queue_keeps_the_running_and_leaves_no_worker(tmp_path, monkeypatch):
    """One task fails at once while 24 more sleep 1.5 s each: the error reaches the caller once the
    tasks already handed to the two workers end (stored, for the resume), not after the queue (the
    pool had run every queued task, 18 s here, storing none, and a Ctrl-C in that wait left its
    workers running)."""
    import multiprocessing

    from studies.engine.runner import run_tasks

    monkeypatch.setenv("EDGE_SLOW_S", "1.5")
    tasks = [{"i": 0, "slow": False, "fail": True}] + [{"i": i, "slow": True} for i in range(1, 25)]
    t0 = time.monotonic()
    with pytest.raises(ValueError, match=r"^task 0 fails$"):
        run_tasks(tasks, tmp_path, edge_task, workers=2)
    elapsed = time.monotonic() - t0
    stored = len(list((tmp_path / "tasks").rglob("*.json")))
    # running, or in the pool's call queue (workers + 1 deep) when the failure arrived
    assert 1 <= stored <= 2 * 2 + 1, stored
    assert elapsed < 14, elapsed
    assert not multiprocessing.active_children()


def test_ctrl_c_during_native_code_ends_the_process_after_a_grace(tmp_path):
    """A render inside Mitsuba holds the main thread in native code, where KeyboardInterrupt
    cannot arrive: the watchdog ends the process with 130 after its grace period. A long
    PBKDF2 (native, GIL released, no signal checks) stands in for the render."""
    code = (
        "import hashlib, sys\n"
        "from studies.cli.app import InterruptGuard\n"
        "guard = InterruptGuard(grace_s=0.5)\n"
        "print('ready', flush=True)\n"
        "hashlib.pbkdf2_hmac('sha256', b'x', b'y', 200_000_000)\n"
        "print('finished', flush=True)\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.2)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "finished" not in out
    assert time.monotonic() - t0 < 5
    assert "beacon-sim: interrupted;" in err


# -- machine measurements stay out of result tables ----------------------------------------


def test_machine_columns_are_logged_not_returned(tmp_path):
    from studies.engine.runner import MACHINE_LOG, run_tasks

    rows = run_tasks(EDGE_TASKS[:3], tmp_path, edge_task, workers=1)
    assert rows == [{"i": i, "square": i * i} for i in range(3)]
    log = (tmp_path / MACHINE_LOG).read_text().splitlines()
    assert len(log) == 4 and log[1].endswith(f",0,worker_peak_rss_MiB,{float(os.getpid())!r}")
    assert run_tasks(EDGE_TASKS[:3], tmp_path, edge_task, workers=1) == rows  # stored: nothing logged again
    assert len((tmp_path / MACHINE_LOG).read_text().splitlines()) == 4


def test_progress_in_a_log_is_plain_lines(monkeypatch):
    """Where stderr is a file, not a terminal, a long run's progress is lines a log keeps (rich's
    bar would show nothing until the end): the start, the count after each task here, the end."""
    import io

    from rich.console import Console

    from studies.cli import common

    log = io.StringIO()
    monkeypatch.setattr(common, "console", Console(file=log, force_terminal=False))
    with common.rich_progress("frames", 3, 1) as advance:
        advance()
        advance()
    lines = log.getvalue().splitlines()
    assert lines[0] == "frames: 1/3 stored, 2 to run"
    assert lines[-2].startswith("frames: 3/3 (100 %)")
    assert lines[-1].startswith("frames: 3/3 done in ")
