"""The ``beacon-sim`` command line, assembled in one place.

Each command module (:mod:`studies.cli.hardware`, ``scene``, ``camera``, ``pipeline``,
``study``, ``experiments``, ``checks``) defines plain functions and a ``COMMANDS`` table; this
module registers them on one typer app, in the order ``--help`` lists them. Every
command that writes results writes JSON beside its pictures. Bad input ends the program
with one line on stderr naming the field and what was expected (exit code 2).
"""

from __future__ import annotations

import logging
import os
import sys
from typing import Annotated

import typer
from rich.logging import RichHandler

from studies.cli import camera, checks, experiments, hardware, pipeline, scene, study, unknowns
from studies.cli.common import console

COMMAND_MODULES = (hardware, scene, camera, pipeline, study, experiments, checks, unknowns)
"""Where the commands are defined, in the order ``--help`` lists them."""

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Simulate how cameras see self-lit LED beacons.",
)
for _module in COMMAND_MODULES:
    for _name, _function in _module.COMMANDS.items():
        app.command(_name)(_function)


@app.callback()
def _root(verbose: Annotated[bool, typer.Option("--verbose", "-v", help="More log output.")] = False) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(message)s",
        handlers=[RichHandler(console=console, show_path=False, show_time=False)],
    )
    logging.getLogger("beacon_sim").setLevel(logging.INFO)


def main() -> None:
    """Console-script entry point: turn bad input into one line on stderr."""
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    try:
        app(standalone_mode=False)
    except ValueError as exc:  # UsageError, ScenarioError, DataFileError, other validation
        _fail(str(exc))
    except Exception as exc:
        if hasattr(exc, "format_message"):  # click/typer usage errors (NoSuchOption, ...)
            _fail(exc.format_message().replace("\n", " "))
        raise


def _fail(message: str) -> None:
    print(f"beacon-sim: error: {message}", file=sys.stderr)
    sys.exit(2)
