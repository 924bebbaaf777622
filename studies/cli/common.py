"""What every command shares: the console, one-line usage errors, output folders, the
progress bar handed to long runs, and tables that never truncate names."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

console = Console(stderr=True)
"""Messages, status spinners and progress bars go to stderr; results go to stdout."""


class UsageError(ValueError):
    """Bad command-line input (one-line message)."""


def prepare_out_dir(out: Path) -> Path:
    """Create ``out`` and check it is writable, or raise :class:`UsageError`."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UsageError(f"out: cannot write to {out} ({exc.strerror or exc})") from None
    return out


def parse_list(name: str, text: str | None, convert=str) -> tuple | None:
    """A comma-separated option as a tuple, or None when not given."""
    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    try:
        return tuple(convert(t) for t in items)
    except ValueError:
        raise UsageError(f"{name}: expected a comma-separated list of numbers, got {text!r}") from None


@contextlib.contextmanager
def rich_progress(description: str, total: int, done: int) -> Iterator[Callable[[], None]]:
    """A progress bar with an ETA (a :data:`studies.engine.runner.Progress`)."""
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task(description, total=total, completed=done)
        yield lambda: bar.advance(task)


def print_table(title: str, columns: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    """A table on stdout. In a terminal, a rich table whose first column (the names) is never
    truncated or wrapped (in a narrow one the other columns wrap instead); piped, plain
    tab-separated lines with a header, for scripts (``--json`` gives every field)."""
    if not sys.stdout.isatty():
        for line in (columns, *rows):
            print("\t".join(cell.replace("\t", " ") for cell in line))
        return
    table = Table(title=title)
    width = max([len(columns[0]), *(len(r[0]) for r in rows)])
    table.add_column(columns[0], no_wrap=True, min_width=width)
    for col in columns[1:]:
        table.add_column(col, overflow="fold")
    for r in rows:
        table.add_row(*r)
    Console().print(table)
