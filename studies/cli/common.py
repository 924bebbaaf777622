"""What every command shares: the console, one-line usage errors, the ``--out`` parser (the
folders themselves: :mod:`studies.cli.out_folder`), the render cache check, the execution of
sweeps, the progress bar handed to long runs, and tables that never truncate names."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import socket
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from scenes.assemble import crop_box
from scenes.render_cache import ENV_CACHE_DIR, default_cache_dir
from scenes.scenario import Scenario
from studies.engine.sweep import Execution

__all__ = [
    "MAX_FILM_SUBPIXELS",
    "MAX_RENDER_SAMPLES",
    "MAX_SEEDS",
    "UsageError",
    "check_finite",
    "check_render_cache",
    "check_render_work",
    "check_scheduler",
    "check_seeds",
    "check_workers",
    "console",
    "execution",
    "out_path",
    "parse_list",
    "physics_points",
    "physics_source",
    "print_table",
    "progress_lines",
    "rich_progress",
]

log = logging.getLogger("beacon_sim")

console = Console(stderr=True)
"""Messages, status spinners and progress bars go to stderr; results go to stdout."""

MAX_SEEDS = 10_000
"""Most noise seeds per condition a command accepts: every seed is a frame per grid point,
so 10 000 already multiplies the grid's work ten-thousandfold (beyond it a run never ends)."""


class UsageError(ValueError):
    """Bad command-line input (one-line message)."""


def out_path(text: str | Path) -> Path:
    """Parse an ``--out`` value: a non-empty path (an empty one would silently mean the current
    folder); a default given as a :class:`Path` passes as it is."""
    if isinstance(text, Path):
        return text
    if not text.strip():
        raise UsageError(f"expected a folder path, got {text!r} (use --out . for the current folder)")
    if "\x00" in text:
        raise UsageError(f"expected a path without NUL characters, got {text!r}")
    return Path(text)


def check_render_cache() -> Path:
    """The render cache folder, created and checked writable before any work, or :class:`UsageError`
    (a render that cannot be stored would otherwise fail only after it finished)."""
    root = default_cache_dir()
    field = ENV_CACHE_DIR if os.environ.get(ENV_CACHE_DIR) else "cache"
    try:
        root.mkdir(parents=True, exist_ok=True)
        probe = root / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UsageError(
            f"{field}: expected a writable folder for the render cache, got {root} ({exc.strerror or exc})"
        ) from None
    return root


MAX_FILM_SUBPIXELS = 2**28
"""Most rendered sub-pixels (crop × oversampling²) a command accepts: 2^28 float32 values are
1 GiB per image, and a render holds one image per light group (up to five) besides Dr.Jit's
buffers. The full 18 MP frame of the T6 fits at oversampling 3."""

MAX_RENDER_SAMPLES = 2**36
"""Most Monte-Carlo samples (crop × oversampling² × spp) per light group a command accepts:
about 6.9e10, hours of path tracing at the 10^7-10^8 samples/s of a CPU backend. The defaults
(spp 16, oversampling 3) use 7e6 at 5 m and 1.5e8 at 1 m on the T6."""


def check_render_work(scenario: Scenario) -> Scenario:
    """Refuse, before any work, a scenario whose camera sees no beacon or whose render could
    not finish: more than :data:`MAX_FILM_SUBPIXELS` sub-pixels (memory) or
    :data:`MAX_RENDER_SAMPLES` samples (time)."""
    crop = crop_box(scenario)  # raises ScenarioError when the camera is inside the beacon or sees none of it
    s, spp = scenario.render.oversampling, scenario.render.spp
    film = crop.width * crop.height * s * s
    what = f"{crop.width}×{crop.height} px crop × {s}²"
    if film > MAX_FILM_SUBPIXELS:
        raise UsageError(
            f"oversampling: expected at most 2^28 rendered sub-pixels (1 GiB per float32 image), "
            f"got {what} = {film:.3g} at {scenario.range_m:g} m"
        )
    if film * spp > MAX_RENDER_SAMPLES:
        raise UsageError(
            f"spp: expected at most 2^36 ≈ 6.9e10 samples per render (hours of path tracing), "
            f"got {what} × spp {spp} = {film * spp:.3g} at {scenario.range_m:g} m"
        )
    return scenario


def check_workers(workers: int | None) -> int | None:
    """Validate ``--workers``: 1 to 4 per CPU (each worker process holds its own renderer and
    render in memory; more only thrash)."""
    most = 4 * (os.cpu_count() or 1)
    if workers is not None and not 1 <= workers <= most:
        raise UsageError(f"workers: expected an integer in [1, {most}] (4 per CPU), got {workers}")
    return workers


def check_scheduler(address: str | None, timeout_s: float = 5.0) -> str | None:
    """Validate ``--scheduler``: a Dask scheduler address (``tcp://host:port``) that accepts a
    connection, checked before any work."""
    if address is None:
        return None
    m = re.fullmatch(r"(?:tcp://|tls://)?\[?([A-Za-z0-9_.:-]+?)\]?:(\d{1,5})", address.strip())
    if m is None or not 0 < int(m.group(2)) < 65536:
        raise UsageError(f"scheduler: expected a Dask scheduler address tcp://HOST:PORT, got {address!r}")
    try:
        with socket.create_connection((m.group(1), int(m.group(2))), timeout=timeout_s):
            pass
    except (OSError, UnicodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise UsageError(f"scheduler: expected a reachable Dask scheduler, got {address!r} ({reason})") from None
    return address


def check_seeds(name: str, seeds: int | None) -> int | None:
    """Validate a seed count: 1 to :data:`MAX_SEEDS`."""
    if seeds is not None and not 1 <= seeds <= MAX_SEEDS:
        raise UsageError(f"{name}: expected an integer >= 1 and <= {MAX_SEEDS}, got {seeds}")
    return seeds


def check_finite(name: str, value: float, low: float, high: float, unit: str = "") -> float:
    """Validate a number: finite and in ``[low, high]``."""
    if not (math.isfinite(value) and low <= value <= high):
        raise UsageError(f"{name}: expected a number in [{low:g}, {high:g}]{unit}, got {value!r}")
    return value


def execution(workers: int | None, scheduler: str | None = None, cache: bool = True) -> Execution:
    """How a sweep runs (local workers or a Dask scheduler, rich progress), validated before any
    work; ``cache``: the sweep renders, so the render cache must be writable."""
    check_workers(workers)
    check_scheduler(scheduler)
    if cache:
        check_render_cache()
    return Execution(workers=workers, scheduler=scheduler, progress=rich_progress)


def parse_list(name: str, text: str | None, convert=str) -> tuple | None:
    """A comma-separated option as a tuple, or None when not given.

    Repeated values are refused (one line naming the option and the value): a study's grid
    would count the one frame each value stands for once per repeat (``--ranges-m 4,4,4``
    reported one stored frame as three and narrowed its intervals), and merging them in
    silence would run a different grid from the one asked for. More frames per value are
    ``--seeds``.
    """
    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    try:
        values = tuple(convert(t) for t in items)
    except ValueError:
        raise UsageError(f"{name}: expected a comma-separated list of numbers, got {text!r}") from None
    seen: dict = {}
    for item, value in zip(items, values, strict=True):
        if value in seen:
            same = item if item == seen[value] else f"{seen[value]} and {item}"
            raise UsageError(
                f"{name}: expected each value once (more frames per value: --seeds), got {same} more than once"
            )
        seen[value] = item
    return values


@contextlib.contextmanager
def rich_progress(description: str, total: int, done: int) -> Iterator[Callable[[], None]]:
    """A progress bar with an ETA (a :data:`studies.engine.runner.Progress`); where stderr is no
    terminal (a log file), :func:`progress_lines` instead."""
    if not console.is_terminal:
        with progress_lines(description, total, done, write=console.file.write) as advance:
            yield advance
        return
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task(description, total=total, completed=done)
        yield lambda: bar.advance(task)


@contextlib.contextmanager
def progress_lines(
    description: str,
    total: int,
    done: int,
    *,
    write: Callable[[str], object],
    every_s: float = 60.0,
    clock: Callable[[], float] = time.monotonic,
) -> Iterator[Callable[[], None]]:
    """Progress for a log: one line at the start, then at most one per ``every_s`` seconds
    (s) and one at the end, each with the tasks done, the elapsed time and an ETA from this
    run's own rate (tasks already stored do not count towards it).

    >>> lines, ticks = [], iter(range(0, 100, 10))  # a clock ticking 10 s per reading
    >>> with progress_lines("frames", 4, 1, write=lines.append, every_s=0.0, clock=ticks.__next__) as advance:
    ...     advance(); advance(); advance()
    >>> print("".join(lines), end="")
    frames: 1/4 stored, 3 to run
    frames: 2/4 (50 %), 10 s, about 20 s left
    frames: 3/4 (75 %), 20 s, about 10 s left
    frames: 4/4 (100 %), 30 s, about 0 s left
    frames: 4/4 done in 40 s
    """
    start = last = clock()
    count = done
    write(f"{description}: {done}/{total} stored, {total - done} to run\n")

    def advance() -> None:
        nonlocal count, last
        count += 1
        now = clock()
        if now - last >= every_s or count == total:
            last = now
            rate = (count - done) / max(now - start, 1e-9)
            write(
                f"{description}: {count}/{total} ({100 * count / max(total, 1):.0f} %), {now - start:.0f} s, "
                f"about {(total - count) / rate:.0f} s left\n"
            )

    yield advance
    write(f"{description}: {count}/{total} {'done' if count == total else 'stopped'} in {clock() - start:.0f} s\n")


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


def physics_source(physics_from: str) -> Path | None:
    """``--physics-from`` as a file (``calibration``: the project's own set) or None (``registry``); a
    UsageError naming the option when it names no file."""
    from studies.catalog import prediction_set  # the catalog is imported by the commands that use it

    source = {"registry": None, "calibration": prediction_set.reference_set()}.get(physics_from, Path(physics_from))
    if source is not None and not source.is_file():
        raise UsageError(f"physics-from: expected a calibration's nroy.csv or 'registry', {source} is not a file")
    return source


def physics_points(uncertainty: int | None, physics_from: str) -> tuple[tuple[dict, ...], str]:
    """The points of ``--uncertainty N`` from ``--physics-from`` and their description; empty without
    it. A UsageError naming the option, before any work, for a bad N or source."""
    from studies.catalog import prediction_set

    if uncertainty is None:
        return (), ""
    if uncertainty < 1:
        raise UsageError(f"uncertainty: expected an integer >= 1 (points of the unknowns), got {uncertainty}")
    source = physics_source(physics_from)
    try:
        return prediction_set.physics_points(uncertainty, calibration=source)
    except ValueError as e:
        raise UsageError(f"physics-from: {e}") from None
