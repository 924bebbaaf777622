"""Output folders (``--out``): checked, claimed and locked before any work, released after.

:func:`prepare_out_dir` is the one door every command that writes a folder goes through:

* **Not a system folder.** ``/`` and the system's top-level folders (``/etc``, ``/usr``, ...,
  and anything under ``/proc``, ``/sys``, ``/dev``) are refused, ``--force`` or not.
* **No links inside.** A symbolic link anywhere inside the folder is refused (writing through
  it would truncate or fill whatever it points at). The folder itself may be a link: it is
  the place the user named. The files written in place rather than by rename (the lock, the
  machine log) are opened with ``O_NOFOLLOW`` and refused when they have other hard links.
* **This command's folder.** A folder holds a record of the command that wrote it
  (:data:`MARKER_NAME`, e.g. ``study range-limit``). A folder that is empty, or holds this
  command's record, is used (a re-run resumes); one that holds another command's record, or
  files beacon-sim did not write, is refused unless ``--force``. Folders written before the
  record existed are recognised by the lock file, ``runs.json`` or a ``tasks/`` store and
  adopted, unless ``runs.json`` names another command.
* **One run at a time.** ``fcntl.flock`` on :data:`LOCK_NAME` (holding the pid), released and
  the file removed at the end of the command, Ctrl-C included (:func:`release_out_dirs`).
  Removal is safe for the lock's purpose: a run that took the lock checks the name still
  refers to the file it locked, and starts over when it does not.

``--force`` is added to every command whose ``--out`` is a folder by :func:`folder_command`
(``studies.cli.app`` applies it when it registers the commands), which also names the command
for the record.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import inspect
import json
import logging
import os
import stat
import tempfile
import typing
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from inspect import Parameter
from pathlib import Path
from typing import Annotated

import typer

from scenes.render_cache import atomic_write_bytes
from studies.cli.common import UsageError, out_path
from studies.engine.run_log import RUNS_FILE

__all__ = [
    "LOCK_NAME",
    "MARKER_NAME",
    "SYSTEM_FOLDERS",
    "Force",
    "command_context",
    "first_link_inside",
    "folder_command",
    "prepare_out_dir",
    "release_out_dirs",
]

log = logging.getLogger("beacon_sim")

LOCK_NAME = ".beacon-sim.lock"
"""Lock file inside every output folder while a run uses it (``fcntl.flock``, holding the pid)."""

MARKER_NAME = ".beacon-sim.json"
"""Record of the command whose results a folder holds (``{"command": "study range-limit"}``)."""

SYSTEM_FOLDERS = frozenset(
    "/ /bin /boot /dev /etc /home /lib /lib32 /lib64 /libx32 /media /mnt /opt /proc /root /run "
    "/sbin /srv /sys /tmp /usr /var".split()
)
"""Folders never used as ``--out`` (``--force`` or not); anything under :data:`PSEUDO_FOLDERS` neither."""

PSEUDO_FOLDERS = ("/proc", "/sys", "/dev")
"""File systems of the kernel, not of files."""

OWN_NAMES = (LOCK_NAME, MARKER_NAME)
"""Entries that do not make a folder hold results."""

Force = Annotated[
    bool,
    typer.Option(
        "--force",
        help="Write into an --out folder that holds other results (another command's, or files "
        "beacon-sim did not write); without it such a folder is refused.",
    ),
]


@dataclass
class _Command:
    name: str = "beacon-sim"
    force: bool = False


_command = _Command()
"""The command being run (set by :func:`command_context`)."""


@dataclass
class _Lock:
    path: Path
    fd: int


_LOCKS: dict[Path, _Lock] = {}
"""Output folders this process holds, resolved path → its lock."""


@contextlib.contextmanager
def command_context(name: str, force: bool = False) -> Iterator[None]:
    """Within the block, output folders are claimed for command ``name`` (``--force``: ``force``)."""
    saved = (_command.name, _command.force)
    _command.name, _command.force = name, force
    try:
        yield
    finally:
        _command.name, _command.force = saved


def writes_folder(function: Callable) -> bool:
    """Whether ``function`` (a command) has an ``out`` option parsed as a folder (:func:`out_path`)."""
    hint = typing.get_type_hints(function, include_extras=True).get("out")
    return any(getattr(m, "parser", None) is out_path for m in getattr(hint, "__metadata__", ()))


def folder_command(name: str, function: Callable) -> Callable:
    """``function`` with a ``--force`` option, run inside :func:`command_context` for ``name``,
    when it writes a folder (:func:`writes_folder`); otherwise ``function`` unchanged."""
    if not writes_folder(function):
        return function
    hints = typing.get_type_hints(function, include_extras=True)
    params = [
        p.replace(annotation=hints.get(p.name, p.annotation)) for p in inspect.signature(function).parameters.values()
    ]
    force = Parameter("force", Parameter.KEYWORD_ONLY, default=False, annotation=Force)

    @functools.wraps(function)
    def command(*args, force: bool = False, **kwargs):
        with command_context(name, force):
            return function(*args, **kwargs)

    command.__signature__ = inspect.Signature([*params, force], return_annotation=None)
    command.__annotations__ = {**{p.name: p.annotation for p in params}, "force": Force}
    return command


def prepare_out_dir(out: Path, lock: bool = True, part: str | None = None) -> Path:
    """Check, create, claim and lock ``out`` for this run, or raise :class:`UsageError`.

    Parameters
    ----------
    out
        The output folder.
    lock
        Hold its lock until :func:`release_out_dirs` (a folder this process holds is not
        locked again).
    part
        What the command runs, when its name alone does not say (``study``'s study name):
        part of the record that lets a re-run resume and refuses other commands.
    """
    _check_not_system(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        before = set(os.listdir(out))
        fd, probe = tempfile.mkstemp(dir=out, prefix=".write-test-")  # O_EXCL: never an existing file
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"out: cannot write to {out} ({exc.strerror or exc})") from None
    link = first_link_inside(out)
    if link is not None:
        raise UsageError(
            f"out: expected no symbolic links inside the output folder, got {link} -> {os.readlink(link)} "
            "(remove it or choose another --out)"
        )
    key = out.resolve()
    held = key in _LOCKS
    if lock and not held:
        _lock(out, key)
    if not held:
        try:
            _claim(out, before, " ".join(n for n in (_command.name, part) if n), part or _command.name)
        except BaseException:
            _release(key)
            raise
    return out


def _check_not_system(out: Path) -> None:
    try:
        where = out.resolve()
    except RuntimeError:  # Python 3.11's resolve() on a loop of symbolic links
        raise UsageError(
            f"out: expected a folder or a new name, got {out} (a loop of symbolic links; remove the link)"
        ) from None
    text = str(where)
    if text in SYSTEM_FOLDERS or any(text.startswith(p + "/") for p in PSEUDO_FOLDERS):
        raise UsageError(
            f"out: expected a folder of your own, got {out} "
            f"({text} is a system folder; choose a new folder, e.g. out/run)"
        )


def first_link_inside(folder: Path) -> Path | None:
    """The first symbolic link found inside ``folder`` (at any depth, never followed), or None."""
    stack = [str(folder)]
    while stack:
        with os.scandir(stack.pop()) as entries:
            for entry in entries:
                if entry.is_symlink():
                    return Path(entry.path)
                if entry.is_dir(follow_symlinks=False):
                    stack.append(entry.path)
    return None


def _claim(out: Path, before: set[str], command: str, legacy_name: str) -> None:
    """Refuse ``out`` when it holds other results (unless ``--force``); record ``command``."""
    marker = out / MARKER_NAME
    owner = _recorded_command(marker) if MARKER_NAME in before else None
    if owner == command:
        return
    if not _command.force:
        advice = "add --force to write there anyway, or choose another --out"
        if owner is not None:
            raise UsageError(
                f"out: expected an empty folder or one this command wrote, got {out} "
                f"(it holds the results of '{owner}'; {advice})"
            )
        others = sorted(n for n in before if n not in OWN_NAMES and not n.startswith(".write-test"))
        if others:
            earlier = _earlier_commands(out, before)
            if earlier is None:
                shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
                raise UsageError(
                    f"out: expected an empty folder or one this command wrote, got {out} "
                    f"(it holds files beacon-sim did not write: {shown}; {advice})"
                )
            if earlier and legacy_name not in earlier:
                raise UsageError(
                    f"out: expected an empty folder or one this command wrote, got {out} "
                    f"(its runs.json records {', '.join(sorted(earlier))}; {advice})"
                )
            log.info("out: %s was written by an earlier beacon-sim; resuming it as '%s'", out, command)
    record = {"command": command, "format": 1}
    try:
        atomic_write_bytes(marker, (json.dumps(record, indent=2, allow_nan=False) + "\n").encode())
    except OSError as exc:
        raise UsageError(f"out: cannot write {marker} ({exc.strerror or exc})") from None


def _recorded_command(marker: Path) -> str:
    """The command recorded in ``marker`` (a description when it cannot be read)."""
    try:
        command = json.loads(marker.read_text(encoding="utf-8"))["command"]
        return command if isinstance(command, str) else "an unreadable record"
    except (OSError, ValueError, KeyError, TypeError):
        return f"an unreadable record in {MARKER_NAME}"


def _earlier_commands(out: Path, before: set[str]) -> set[str] | None:
    """For a folder without a record: the commands its ``runs.json`` names (empty when it has
    none) when it looks like an earlier beacon-sim's folder (lock file, ``runs.json`` or a
    ``tasks/`` store), None when it does not."""
    if not ({LOCK_NAME, RUNS_FILE} & before or (out / "tasks").is_dir()):
        return None
    try:
        parts = json.loads((out / RUNS_FILE).read_text(encoding="utf-8")).get("parts", [])
        return {p["command"] for p in parts if isinstance(p, dict) and isinstance(p.get("command"), str)}
    except (OSError, ValueError, AttributeError, TypeError):
        return set()


def _lock(out: Path, key: Path, attempts: int = 10) -> None:
    path = out / LOCK_NAME
    for _ in range(attempts):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
        except OSError as exc:
            raise UsageError(f"out: cannot create the lock file {path} ({exc.strerror or exc})") from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
            os.close(fd)
            raise UsageError(
                f"out: expected the lock file {path} to be beacon-sim's own, got a file with "
                f"{st.st_nlink} hard links (remove it)"
            )
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise UsageError(
                f"out: expected a folder no other run is using, got {out} (in use by beacon-sim pid {other}; "
                "wait for it to finish or choose another --out)"
            ) from None
        except OSError as exc:  # a file system without locks (some network mounts): run unlocked
            os.close(fd)
            log.warning("out: cannot lock %s (%s); another run on it would not be stopped", out, exc.strerror or exc)
            return
        if _same_file(path, fd):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            _LOCKS[key] = _Lock(path, fd)
            return
        os.close(fd)  # the run that held it removed it as it ended: lock the file now there
    raise UsageError(f"out: cannot take the lock {path} (it keeps being replaced; is another run starting?)")


def _same_file(path: Path, fd: int) -> bool:
    try:
        here = os.lstat(path)
    except OSError:
        return False
    held = os.fstat(fd)
    return (here.st_dev, here.st_ino) == (held.st_dev, held.st_ino)


def _release(key: Path) -> None:
    lock = _LOCKS.pop(key, None)
    if lock is None:
        return
    with contextlib.suppress(OSError):
        if _same_file(lock.path, lock.fd):
            os.unlink(lock.path)  # while still locked: a run waiting on this file starts over
    with contextlib.suppress(OSError):
        os.close(lock.fd)  # closing the only descriptor releases the flock


def release_out_dirs() -> None:
    """Release the locks of every output folder this process holds and remove their lock
    files (the end of a command, Ctrl-C included)."""
    for key in list(_LOCKS):
        _release(key)
