"""The ``beacon-sim`` command line, assembled in one place.

Each command module (:mod:`studies.cli.hardware`, ``scene``, ``camera``, ``pipeline``,
``study``, ``experiments``, ``robot``, ``checks``) defines plain functions and a ``COMMANDS`` table; this
module registers them on one typer app, in the order ``--help`` lists them. Every
command that writes results writes JSON beside its pictures.

At the edges: bad input ends the program with one line on stderr naming the field and what
was expected (exit code 2), before any work; a run stopped by its surroundings (a full disk,
a lost Dask scheduler, an unreadable task record: :class:`studies.engine.runner.RunStopped`)
ends with one line naming the file or address (exit code 1), its finished tasks stored;
``beacon-sim`` alone, ``-h`` and ``--help`` print help (exit 0); Ctrl-C stops at once with
exit code 130, leaving the finished tasks stored so the same command resumes (:class:`InterruptGuard`).
"""

from __future__ import annotations

import contextlib
import functools
import logging
import multiprocessing
import os
import re
import signal
import sys
import threading
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version
from pathlib import Path
from typing import Annotated

import typer
from rich.logging import RichHandler
from typer._click import exceptions as cli_errors  # typer's own (vendored) click

from studies.cli import camera, checks, experiments, hardware, pipeline, robot, scene, study, unknowns
from studies.cli.common import console
from studies.cli.out_folder import folder_command, release_out_dirs
from studies.engine.runner import DISK_FULL, NoWorkersError, RunStopped, no_hugepage_advice

__all__ = [
    "COMMAND_MODULES",
    "EXIT_INTERRUPTED",
    "EXIT_STOPPED",
    "InterruptGuard",
    "app",
    "app_command_names",
    "click_command",
    "main",
    "usage_message",
    "version_text",
]

COMMAND_MODULES = (hardware, scene, camera, pipeline, study, experiments, robot, checks, unknowns)
"""Where the commands are defined, in the order ``--help`` lists them."""

PROG = "beacon-sim"
EXIT_USAGE = 2
EXIT_STOPPED = 1
"""Exit code of a run stopped by its surroundings (disk full, a lost Dask scheduler): one line on stderr."""
EXIT_INTERRUPTED = 130
"""128 + SIGINT, what a shell reports for a program stopped by Ctrl-C."""
INTERRUPTED_MESSAGE = f"{PROG}: interrupted; finished tasks are stored, re-run the same command to resume"

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Simulate how cameras see self-lit LED beacons.",
)
for _module in COMMAND_MODULES:
    for _name, _function in _module.COMMANDS.items():
        app.command(_name)(folder_command(_name, _function))


@functools.cache
def click_command():
    """The app as one command group (typer builds it from the functions' signatures: built
    once, not per call)."""
    return typer.main.get_command(app)


def version_text() -> str:
    """``beacon-sim <version>`` of the installed package."""
    try:
        return f"{PROG} {package_version(PROG)}"
    except PackageNotFoundError:  # run from a source tree without installing
        return f"{PROG} (not installed)"


def _print_version(value: bool) -> None:
    if value:
        print(version_text())
        raise typer.Exit()


@app.callback()
def _root(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="More log output.")] = False,
    version: Annotated[
        bool,
        typer.Option("--version", help="Print the version and exit.", is_eager=True, callback=_print_version),
    ] = False,
    camera_file: Annotated[
        list[Path] | None,
        typer.Option(
            "--camera-file",
            metavar="FILE",
            help="Your own camera file (see 'cameras --template'); allowed anywhere on the command line, "
            "repeatable; commands then take its name, and use it when no --camera/--cameras is given.",
        ),
    ] = None,
    beacon_file: Annotated[
        list[Path] | None,
        typer.Option(
            "--beacon-file",
            metavar="FILE",
            help="Your own beacon file (see 'beacons --template'); as --camera-file, for --beacon/--beacons.",
        ),
    ] = None,
) -> None:
    """Simulate how cameras see self-lit LED beacons."""
    # --camera-file / --beacon-file are taken out of the arguments before parsing
    # (studies.cli.hardware.use_hardware_files); they are declared here for --help only
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(message)s",
        handlers=[RichHandler(console=console, show_path=False, show_time=False)],
    )
    logging.getLogger("beacon_sim").setLevel(logging.INFO)


class InterruptGuard:
    """Ctrl-C handling for one command.

    The first SIGINT raises :class:`KeyboardInterrupt` in the main thread (and sets
    :attr:`interrupted`), so the command unwinds: a process pool is terminated, not waited
    for (:func:`studies.engine.runner.stop_pool`), and nothing half-done is stored. A render
    inside Mitsuba's native code cannot be cancelled and would hold the main thread until it
    ends, so a watchdog thread, woken through :func:`signal.set_wakeup_fd`, ends the process
    with :data:`EXIT_INTERRUPTED` if the command has not unwound ``grace_s`` after the signal
    (every write is atomic, so that leaves at most temporary files). Installed only in the
    main thread; :meth:`close` restores what was there.
    """

    def __init__(self, grace_s: float = 3.0) -> None:
        self.grace_s = grace_s
        self.interrupted = False
        self.finished = threading.Event()
        self._active = threading.current_thread() is threading.main_thread()
        if not self._active:
            return
        self._previous_handler = signal.signal(signal.SIGINT, self._on_sigint)
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)
        self._previous_wakeup_fd = signal.set_wakeup_fd(self._write_fd, warn_on_full_buffer=False)
        self._watchdog = threading.Thread(target=self._watch, name="beacon-sim-interrupt", daemon=True)
        self._watchdog.start()

    def _on_sigint(self, signum: int, frame: object) -> None:
        self.interrupted = True
        raise KeyboardInterrupt

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._read_fd, 64)
            except OSError:
                return
            if not data:  # closed: the command ended
                return
            if signal.SIGINT in data:
                break
        if self.finished.wait(self.grace_s):
            return
        with contextlib.suppress(OSError):
            os.write(2, f"\n{INTERRUPTED_MESSAGE}\n".encode())
        with contextlib.suppress(Exception):
            release_out_dirs()  # no lock file left behind by a render that would not unwind
        for child in multiprocessing.active_children():
            with contextlib.suppress(Exception):
                child.kill()
        os._exit(EXIT_INTERRUPTED)

    def close(self) -> None:
        """The command ended: stop the watchdog and restore the signal handling."""
        self.finished.set()
        if not self._active:
            return
        signal.set_wakeup_fd(self._previous_wakeup_fd)
        signal.signal(signal.SIGINT, self._previous_handler)
        os.close(self._write_fd)  # the watchdog reads end-of-file and returns
        self._watchdog.join(timeout=1.0)
        os.close(self._read_fd)
        self._active = False


def main() -> None:
    """Console-script entry point: run one command; bad input is one line on stderr (exit 2),
    Ctrl-C exit 130 with a line saying how to resume."""
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    no_hugepage_advice()
    args = sys.argv[1:]
    guard = InterruptGuard()
    code = 0
    try:
        args = hardware.use_hardware_files(args, click_command().commands)
        result = click_command().main(args=args, prog_name=PROG, standalone_mode=False)
        # without standalone mode typer returns the code of an Exit (130 for KeyboardInterrupt)
        code = result if isinstance(result, int) else 0
    except cli_errors.NoArgsIsHelpError:
        code = 0  # bare "beacon-sim": the help is already printed
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except NoWorkersError as exc:  # a Dask cluster left without workers: one line, not a traceback
        _fail(str(exc))
        code = 1
    except ValueError as exc:  # UsageError, ScenarioError, DataFileError, other validation
        code = EXIT_INTERRUPTED if guard.interrupted else _fail(str(exc))
    except cli_errors.UsageError as exc:  # typer's parsing errors (NoSuchOption, BadParameter, ...)
        code = _fail(usage_message(exc, args))
    except typer.Abort:  # end of input at a prompt
        code = 1
    except RunStopped as exc:
        code = EXIT_INTERRUPTED if guard.interrupted else _fail(str(exc), EXIT_STOPPED)
    except OSError as exc:
        if exc.errno not in DISK_FULL or guard.interrupted:
            raise
        where = exc.filename or "the output folder"
        code = _fail(f"disk full at {where} ({exc.strerror}); free space and re-run the same command", EXIT_STOPPED)
    except RecursionError:  # input nested too deep for a reader that names no field (those that do say so first)
        code = _fail("input: expected data nested at most a few hundred levels deep, got deeper")
    except Exception:
        if not guard.interrupted:  # e.g. a pool broken by the same Ctrl-C
            raise
        code = EXIT_INTERRUPTED
    finally:
        guard.close()
        release_out_dirs()
    if code == EXIT_INTERRUPTED or guard.interrupted:
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    if code:
        sys.exit(code)


def _fail(message: str, code: int = EXIT_USAGE) -> int:
    text = " ".join(message.split()) or "invalid input (see --help)"
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return code


def usage_message(exc: cli_errors.UsageError, args: list[str]) -> str:
    """A typer usage error as ``<field>: expected ..., got ...`` (one line)."""
    message = exc.format_message()
    param = getattr(exc, "param", None)
    field = _field(param) if param is not None else None
    if isinstance(exc, cli_errors.MissingParameter) and field:
        if param.param_type_name == "option":
            return f"{field}: expected {max(param.opts, key=len)} (required), got nothing"
        return f"{field}: expected a {field} argument (required), got nothing"
    if isinstance(exc, cli_errors.BadParameter) and field:
        text = re.sub(r"^(Value error|Assertion failed), ", "", exc.message)
        if text.startswith("expected"):
            return f"{field}: {text}"
        wanted = re.sub(r"^Input should be ", "", text).split(",")[0].rstrip(".")
        return f"{field}: expected {wanted}, got {_raw_value(args, param)!r}"
    if isinstance(exc, cli_errors.NoSuchOption):
        command = exc.ctx.command_path if exc.ctx is not None else PROG
        hint = f"; did you mean {' or '.join(sorted(exc.possibilities))}?" if exc.possibilities else ""
        return f"option: expected an option of '{command}' (see -h), got {exc.option_name!r}{hint}"
    if isinstance(exc, cli_errors.BadOptionUsage):
        name = exc.option_name.lstrip("-")
        if "requires an argument" in message:
            return f"{name}: expected a value after {exc.option_name}, got none"
        if "does not take a value" in message:
            return f"{name}: expected no value ({exc.option_name} is a flag), got one"
        return f"{name}: {message}"
    m = re.match(r"No such command '(.*)'\.", message)
    if m:
        return f"command: expected one of {', '.join(app_command_names())}, got {m.group(1)!r}"
    m = re.fullmatch(r"Got unexpected extra argument(?:s|\(s\))? \((.*)\)", message)
    if m:
        return f"arguments: expected none beyond the options, got {m.group(1)!r}"
    return f"usage: {message}"


def _field(param) -> str:
    opts = [o for o in getattr(param, "opts", ()) if o.startswith("--")]
    if getattr(param, "param_type_name", "") == "option" and opts:
        return max(opts, key=len).lstrip("-")
    return param.name or "argument"


def _raw_value(args: list[str], param) -> str:
    """What the command line gave ``param`` (its last occurrence), for the error message."""
    value = ""
    opts = set(getattr(param, "opts", ()))
    for i, arg in enumerate(args):
        name, sep, rest = arg.partition("=")
        if name in opts:
            value = rest if sep else (args[i + 1] if i + 1 < len(args) else "")
    return value


def app_command_names() -> list[str]:
    """Names of the registered commands, in ``--help`` order."""
    return [c.name for c in app.registered_commands if c.name]
