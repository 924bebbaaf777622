"""What a careless or hostile ``--out`` can do, and what the program now does instead
(issue 26, holes 1, 6 and 12, and the lock files left behind).

Commands run in this process with their work functions replaced (``tests.helpers.cli``'s
:func:`invoke` and :func:`patch_work`), so no test renders; the cache-placement test runs a
subprocess with ``HOME`` and ``BEACON_SIM_CACHE`` pointed at temporary folders.
"""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.cli import REPO, assert_one_line_error, invoke

LOCK = ".beacon-sim.lock"
MARKER = ".beacon-sim.json"
STUDY = ["study", "range-limit", "--quick", "--out"]
PRECIOUS = b"the user's own file\n"


def _victim(work: Path) -> Path:
    victim = work / "victim"
    victim.write_bytes(PRECIOUS)
    return victim


# -- hole 1: links inside --out ----------------------------------------------------------


@pytest.mark.parametrize("name", [LOCK, ".write-test", "machine.csv", "results.csv", MARKER])
def test_a_file_link_inside_out_is_refused_and_its_target_left_alone(work, name):
    """``ln -s ../victim d/<name>``: one line naming the link, the victim's bytes unchanged."""
    victim = _victim(work)
    (work / "d").mkdir()
    (work / "d" / name).symlink_to("../victim")
    code, _, err = invoke([*STUDY, "d"])
    line = assert_one_line_error(code, err, "out")
    assert f"d/{name}" in line and "symbolic link" in line
    assert victim.read_bytes() == PRECIOUS


def test_a_folder_link_inside_out_is_refused_at_any_depth(work):
    """``d/tasks -> ../elsewhere`` and ``d/tasks/ab -> ../../elsewhere``: refused, nothing
    written into the linked folder."""
    elsewhere = work / "elsewhere"
    elsewhere.mkdir()
    (work / "d").mkdir()
    (work / "d" / "tasks").symlink_to("../elsewhere")
    code, _, err = invoke([*STUDY, "d"])
    assert "d/tasks" in assert_one_line_error(code, err, "out")
    (work / "d" / "tasks").unlink()
    (work / "d" / "tasks").mkdir()
    (work / "d" / "tasks" / "ab").symlink_to("../../elsewhere")
    code, _, err = invoke([*STUDY, "d"])
    assert "d/tasks/ab" in assert_one_line_error(code, err, "out")
    assert list(elsewhere.iterdir()) == []


def test_a_hard_linked_lock_file_is_refused_and_its_other_name_left_alone(work):
    victim = _victim(work)
    (work / "d").mkdir()
    os.link(victim, work / "d" / LOCK)
    code, _, err = invoke([*STUDY, "d"])
    assert "hard links" in assert_one_line_error(code, err, "out")
    assert victim.read_bytes() == PRECIOUS


def test_the_out_folder_itself_may_be_a_link(work):
    """The folder the user named may live elsewhere (another disk): it is used."""
    (work / "real").mkdir()
    (work / "d").symlink_to("real")
    assert invoke([*STUDY, "d"])[0] == "work"
    assert json.loads((work / "real" / MARKER).read_text())["command"] == "study range-limit"


def test_links_made_during_a_run_are_refused_where_files_are_written_in_place(tmp_path):
    """The machine log and the task store refuse a link placed after the start-up check."""
    from studies.engine.runner import MachineLog, ResultStore

    victim = tmp_path / "victim"
    victim.write_bytes(PRECIOUS)
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "machine.csv").symlink_to("../victim")
    with pytest.raises(ValueError, match=r"machine\.csv"):
        MachineLog(tmp_path / "d" / "machine.csv").record("ab" * 32, [{"frame_s": 1.0}])
    assert victim.read_bytes() == PRECIOUS
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "d" / "tasks").symlink_to("../elsewhere")
    with pytest.raises(ValueError, match="tasks"):
        ResultStore(tmp_path / "d" / "tasks").put("ab" * 32, [{"x": 1}])
    assert list((tmp_path / "elsewhere").iterdir()) == []


# -- hole 6: existing results in --out ---------------------------------------------------


def test_another_studys_folder_is_refused_unless_force(work):
    assert invoke([*STUDY, "d"])[0] == "work"
    code, _, err = invoke(["study", "webcam-vs-dslr", "--quick", "--out", "d"])
    line = assert_one_line_error(code, err, "out")
    assert "got d" in line and "'study range-limit'" in line and "--force" in line
    assert invoke(["study", "webcam-vs-dslr", "--quick", "--out", "d", "--force"])[0] == "work"
    assert json.loads((work / "d" / MARKER).read_text())["command"] == "study webcam-vs-dslr"


def test_a_folder_with_the_users_own_results_is_refused_unless_force(work):
    (work / "d").mkdir()
    (work / "d" / "results.csv").write_bytes(PRECIOUS)
    code, _, err = invoke(["capture", "--out", "d"])
    line = assert_one_line_error(code, err, "out")
    assert "results.csv" in line and "did not write" in line
    assert (work / "d" / "results.csv").read_bytes() == PRECIOUS
    assert sorted(p.name for p in (work / "d").iterdir()) == ["results.csv"]
    assert invoke(["capture", "--out", "d", "--force"])[0] == "work"


def test_the_same_command_resumes_its_folder(work):
    """A re-run of the same command (other options too) is the documented resume."""
    assert invoke([*STUDY, "d"])[0] == "work"
    (work / "d" / "tasks").mkdir()
    (work / "d" / "results.csv").write_text("a\n1\n")
    assert invoke([*STUDY, "d", "--seeds", "2"])[0] == "work"


def test_a_folder_from_before_the_record_is_resumed_by_its_command_only(work):
    """Folders an earlier version wrote (no record; lock file, runs.json, tasks/) resume."""
    old = work / "old"
    (old / "tasks" / "ab").mkdir(parents=True)
    (old / "results.csv").write_text("a\n1\n")
    (old / "runs.json").write_text(json.dumps({"parts": [{"command": "range-limit", "elapsed_s": 1.0}]}))
    code, _, err = invoke(["study", "webcam-vs-dslr", "--quick", "--out", "old"])
    assert "range-limit" in assert_one_line_error(code, err, "out")
    assert invoke([*STUDY, "old"])[0] == "work"
    capture = work / "capture"
    capture.mkdir()
    (capture / LOCK).write_text("123\n")
    (capture / "image.jpg").write_bytes(b"jpeg")
    assert invoke(["capture", "--out", "capture"])[0] == "work"


@pytest.mark.parametrize("folder", ["/", "/etc", "/usr", "/proc/self"])
def test_system_folders_are_refused_even_with_force(work, folder):
    code, _, err = invoke([*STUDY, folder, "--force"])
    line = assert_one_line_error(code, err, "out")
    assert "system folder" in line


def test_main_jobs_study_folders_belong_to_the_main_job(work, monkeypatch):
    """The main job's sub-folders are its own: a study run there is refused."""
    from studies.catalog import STUDIES
    from studies.cli import study

    for module in STUDIES.values():
        monkeypatch.setattr(module, "run", lambda out, options, execution, **kwargs: None)
    monkeypatch.setattr(study, "write_index", lambda out, elapsed_s, **kwargs: None)
    assert invoke(["main-job", "--out", "m"])[0] == 0
    sub = work / "m" / "range-limit"
    assert json.loads((sub / MARKER).read_text())["command"] == "main-job"
    assert not list((work / "m").rglob(LOCK))
    code, _, err = invoke([*STUDY, "m/range-limit"])
    assert "'main-job'" in assert_one_line_error(code, err, "out")


# -- lock files --------------------------------------------------------------------------


def test_no_lock_file_is_left_after_a_clean_exit_or_ctrl_c(work, monkeypatch):
    from studies.catalog import STUDIES

    monkeypatch.setattr(STUDIES["range-limit"], "run", lambda out, options, execution: None)
    assert invoke([*STUDY, "ok"])[0] == 0
    assert not (work / "ok" / LOCK).exists()

    def interrupted(out, options, execution):
        raise KeyboardInterrupt

    monkeypatch.setattr(STUDIES["range-limit"], "run", interrupted)
    assert invoke([*STUDY, "stopped"])[0] == 130
    assert not (work / "stopped" / LOCK).exists()
    code, _, _ = invoke(["study", "webcam-vs-dslr", "--quick", "--out", "ok"])  # refused
    assert code == 2 and not (work / "ok" / LOCK).exists()


def test_a_run_that_locked_a_removed_lock_file_sees_it_is_stale(work):
    """The race removal opens: run B opened the lock file before run A removed it and locks
    it after; B must see the name no longer refers to its file (and start over)."""
    from studies.cli import out_folder

    out = work / "d"
    out_folder.prepare_out_dir(out)
    waiter = os.open(out / LOCK, os.O_RDWR)
    try:
        out_folder.release_out_dirs()
        assert not (out / LOCK).exists()
        fcntl.flock(waiter, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the removed file: free
        out_folder.prepare_out_dir(out)  # a third run takes a new file ...
        assert not out_folder._same_file(out / LOCK, waiter)  # ... which the waiter sees is not its own
    finally:
        os.close(waiter)
        out_folder.release_out_dirs()


# -- hole 12: nothing written outside --out and the cache ---------------------------------

_TOOLS = """
import sys
import studies.cli.app  # what the beacon-sim console script imports first
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
plt.figure().savefig(sys.argv[1])
from scenes.mitsuba_variant import select_variant
select_variant("mono")
import drjit as dr
import mitsuba as mi
print(dr.sum(dr.arange(mi.Float, 1000)))  # a kernel compiled: Dr.Jit writes its kernel cache
"""


def test_drjit_and_matplotlib_write_under_the_cache_not_home(tmp_path):
    """With HOME and BEACON_SIM_CACHE pointed at empty folders, a run that draws a figure and
    compiles a Dr.Jit kernel writes nothing under HOME (it wrote ~/.drjit/*.bin and
    ~/.cache/matplotlib/fontlist-*.json, ~/.config/matplotlib before)."""
    home, cache, out = tmp_path / "home", tmp_path / "cache", tmp_path / "out"
    for folder in (home, out):
        folder.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("DRJIT_CACHE_DIR", "MPLCONFIGDIR", "XDG_CACHE_HOME")}
    env.update(HOME=str(home), BEACON_SIM_CACHE=str(cache), PYTHONPATH=str(REPO))
    subprocess.run([sys.executable, "-c", _TOOLS, str(out / "figure.png")], cwd=out, env=env, check=True, timeout=300)
    assert sorted(str(p.relative_to(home)) for p in home.rglob("*")) == []
    written = {p.relative_to(cache).parts[0] for p in cache.rglob("*") if p.is_file()}
    assert written == {"drjit", "matplotlib"}
    assert sorted(p.name for p in out.iterdir()) == ["figure.png"]
