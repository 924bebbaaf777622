"""A sweep: frame tasks run through the runner and written as result tables.

:func:`run_frames` sends a study's frame tasks (:mod:`studies.engine.tasks`) to
:func:`studies.engine.runner.run_tasks` with the frames of each render batched;
:func:`sweep` and :func:`sweep_in_chunks` turn their rows into the study's tables
(:mod:`studies.engine.tables`). :func:`sweep_screened` spends a grid's later seeds only on the
settings its first frames have not already ruled out.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd

from scenes.hardware import user_hardware
from scenes.render_cache import atomic_write_bytes, content_key
from studies.engine.frame import FRAME_VERSION, render_batch_key, simulate_frame
from studies.engine.runner import MACHINE_COLUMNS, Progress, no_progress, run_tasks
from studies.engine.scoring import detection_success
from studies.engine.tables import parquet_bytes, write_tables
from studies.engine.tasks import StudyOptions, frame_task, frame_tasks

__all__ = ["Execution", "Screening", "run_frames", "sweep", "sweep_in_chunks", "sweep_screened"]


@dataclass(frozen=True)
class Execution:
    """Where a sweep's frames run and how progress is shown (see
    :func:`studies.engine.runner.run_tasks`): ``workers`` local processes (default: one
    per CPU), or the Dask ``scheduler`` at that address; ``progress`` display."""

    workers: int | None = None
    scheduler: str | None = None
    progress: Progress = no_progress


def run_frames(
    tasks: Sequence[dict], out: Path, execution: Execution = Execution(), description: str = "frames"
) -> list[dict]:
    """Run frame tasks (:func:`studies.engine.frame.simulate_frame`) with the frames of each
    render batched into one worker; rows in task order."""
    return run_tasks(
        tasks,
        out,
        simulate_frame,
        workers=execution.workers,
        scheduler=execution.scheduler,
        description=description,
        progress=execution.progress,
        batch_key=render_batch_key,
    )


def sweep(
    name: str,
    conditions: Iterable[dict],
    options: StudyOptions,
    out: Path,
    estimators: Sequence[str] | None = None,
    execution: Execution = Execution(),
) -> pd.DataFrame:
    """Frame tasks of ``conditions`` run (:func:`run_frames`) and written as result
    tables; returns the DataFrame."""
    tasks = frame_tasks(conditions, options, estimators=estimators)
    return write_tables(out, run_frames(tasks, out, execution, description=name))


@dataclass(frozen=True)
class Screening:
    """What a screened sweep (:func:`sweep_screened`) spent: ``frames`` run of the full grid's
    ``grid_frames``; ``units`` settings screened by their first frames, of which ``confirmed`` passed
    every one and got the remaining seeds."""

    frames: int
    grid_frames: int
    units: int
    confirmed: int

    def to_dict(self) -> dict:
        """The record as plain numbers (for summary.json)."""
        return asdict(self)


def sweep_screened(
    name: str,
    conditions: Sequence[dict],
    options: StudyOptions,
    out: Path,
    unit: Callable[[dict], Hashable | None],
    estimators: Sequence[str] | None = None,
    execution: Execution = Execution(),
) -> tuple[pd.DataFrame, Screening]:
    """:func:`sweep` for a verdict that one failed frame already decides.

    A study whose verdict on a setting needs *every* frame of it to succeed (brightness-diffuser's
    window: P̂ ≥ 0.95 from 4 frames is 4 of 4) learns all it will from the setting's first failure.
    So every condition first runs its seed 0 only; the settings whose seed-0 frames were all
    detection successes (:func:`studies.engine.scoring.detection_success`, best tracker) then run
    seeds 1 … ``options.seeds`` − 1 at every condition. ``unit`` names a condition's setting from
    fields that a condition and its frames' rows share (e.g. camera, side, LED drive, diffuser: one
    setting at all ranges); conditions whose ``unit`` is None run every seed at once. A setting's
    frames are the full grid's own tasks (same keys, same stored frames), so a setting that passes
    has exactly the full grid's frames and one that fails has at least one failure: any all-or-nothing
    verdict per setting is the full grid's. Returns the table (first frames, then the rest) and what
    was spent.
    """
    screened = [c for c in conditions if unit(c) is not None]
    unscreened = [c for c in conditions if unit(c) is None]
    first = [frame_task(c, 0, options, estimators=estimators) for c in screened]
    first += frame_tasks(unscreened, options, estimators=estimators)
    rows = run_frames(first, out, execution, description=f"{name}: first frames")
    units = {unit(c) for c in screened}
    failed = {unit(r) for r in rows if r.get("tracker") == "best" and not detection_success(r)} & units
    passed = units - failed
    later = [frame_task(c, s, options, estimators=estimators) for c in screened if unit(c) in passed
             for s in range(1, options.seeds)]  # fmt: skip
    rows += run_frames(later, out, execution, description=f"{name}: the settings that passed")
    screening = Screening(len(first) + len(later), len(conditions) * options.seeds, len(units), len(passed))
    return write_tables(out, rows), screening


def sweep_in_chunks(
    name: str,
    chunks: Sequence[list[dict]],
    options: StudyOptions,
    out: Path,
    estimators: Sequence[str] | None = None,
    execution: Execution = Execution(),
    frames: Callable[..., list[dict]] | None = None,
) -> pd.DataFrame:
    """:func:`sweep` for grids too large to hold as row dicts (millions of frames).

    Each chunk of conditions (whole geometries, so no render batch straddles two chunks)
    is made into tasks, run and reduced to a DataFrame with categorical text columns
    before the next one starts, so the parent holds one chunk's tasks and rows at a time
    (about 4 kB per row as dicts, about 0.5 kB as columns). A finished chunk's table is
    stored under ``out/chunks`` keyed by the content of its tasks (and of the user's hardware
    files, as each task's key), so a re-run whose
    results are all stored reads 1 file per chunk instead of one per frame. ``frames``
    runs a chunk's tasks (default :func:`run_frames`; the benchmark passes stand-ins).
    """
    parts = []
    digest = user_hardware().digest  # the user's hardware files, as for each task's key
    hardware = (digest,) if digest else ()
    for i, conditions in enumerate(chunks):
        tasks = frame_tasks(conditions, options, estimators=estimators)
        path = Path(out) / "chunks" / f"{content_key('chunk', FRAME_VERSION, tasks, *hardware)}.parquet"
        if path.is_file():
            parts.append(_read_chunk(path))
            continue
        rows = (frames or run_frames)(tasks, out, execution, description=f"{name} {i + 1}/{len(chunks)}")
        part = pd.DataFrame(rows)
        del rows
        for column in part.select_dtypes(include=["object", "str"]).columns:
            part[column] = part[column].astype("category")
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, parquet_bytes(part))
        parts.append(_read_chunk(path))  # as a re-run reads it: cold and warm runs agree
    frame = pd.concat(parts, ignore_index=True)
    for column in frame.select_dtypes(include="category").columns:  # back to the dtype of its values
        frame[column] = frame[column].astype(frame[column].cat.categories.dtype)
    return write_tables(out, frame)


def _read_chunk(path: Path) -> pd.DataFrame:
    """A stored chunk's table, without machine measurements (chunks stored before they moved to
    machine.csv still hold them)."""
    return pd.read_parquet(path).drop(columns=list(MACHINE_COLUMNS), errors="ignore")
