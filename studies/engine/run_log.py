"""A command's wall time, kept beside its outputs so a resumed run's parts add up.

Every study, ``validate`` and the main job append one *part* to ``<out>/runs.json`` when
they finish: when it ended (UTC), its wall time, the frames stored in the output folder
at that moment and the machine (:func:`host`: its CPU, cores and vector extensions, which
decide its times and, before the LLVM target was pinned, a render's last bits). A run cut by
a session end and resumed has two parts; its time is their sum. ``beacon-sim bench`` reads
these records (it cannot re-run hours of studies); they measure the machine, so they are kept
out of the result tables, which stay deterministic.

Example
-------
>>> import tempfile
>>> out = Path(tempfile.mkdtemp())
>>> record_part(out, "range-limit", 12.5, frames=96)["elapsed_s"]
12.5
>>> with timed_part(out, "range-limit"):
...     pass
>>> [p["complete"] for p in read_parts(out)]
[True, True]
>>> total_seconds(read_parts(out)) >= 12.5
True
>>> _ = record_part(out, "design", 30.0, complete=False)  # a search stopped, then resumed
>>> resumed_seconds(out, "design")
30.0
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json

__all__ = [
    "RUNS_FILE",
    "host",
    "read_parts",
    "record_part",
    "resumed_seconds",
    "stored_frames",
    "timed_part",
    "total_seconds",
]

RUNS_FILE = "runs.json"
"""File name of the parts record in a command's output folder."""


def host(cpuinfo: str | None = None) -> dict:
    """The machine: CPU model, logical CPUs, and whether it has AVX2 and AVX-512 (from
    ``/proc/cpuinfo``, or the ``cpuinfo`` text given; elsewhere the platform's processor name).

    >>> host("flags : sse avx avx2 fma")["avx2"], host("flags : sse avx avx2 fma")["avx512"]
    (True, False)
    """
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            cpuinfo = ""
    fields = {}
    for line in cpuinfo.splitlines():
        name, _, value = line.partition(":")
        fields.setdefault(name.strip(), value.strip())
    flags = set(fields.get("flags", "").split())
    return {
        "cpu": fields.get("model name") or platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "avx2": "avx2" in flags,
        "avx512": "avx512f" in flags,
    }


def stored_frames(out: Path) -> int:
    """Frame tasks stored under ``out`` (every ``tasks/`` store in it, a study's resumable
    store or those of the studies of a main job), 0 when there is none."""
    return sum(1 for _ in Path(out).rglob("tasks/*/*.json"))


def read_parts(out: Path) -> list[dict]:
    """The parts recorded in ``out/runs.json`` (oldest first); empty when there is none."""
    path = Path(out) / RUNS_FILE
    if not path.is_file():
        return []
    try:
        record = json.loads(path.read_text())
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"runs: expected the run log beacon-sim wrote in {path}, got {type(exc).__name__}") from None
    parts = record.get("parts", []) if isinstance(record, dict) else None
    if not isinstance(parts, list):
        raise ValueError(f"parts: expected a list in {path}, got {type(parts).__name__}")
    return parts


def record_part(out: Path, command: str, elapsed_s: float, frames: int | None = None, *, complete: bool = True) -> dict:
    """Append one part of ``command`` (wall time ``elapsed_s``, s) to ``out/runs.json``; returns
    it. ``frames``: frame tasks stored at its end (default: counted under ``out``);
    ``complete``: whether the command finished (False: interrupted, to be resumed)."""
    part = {
        "command": command,
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "elapsed_s": round(float(elapsed_s), 1),
        "frames": stored_frames(out) if frames is None else int(frames),
        "complete": bool(complete),
        "host": host(),
    }
    parts = [*read_parts(out), part]
    Path(out).mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(Path(out) / RUNS_FILE, strict_json.dumps({"parts": parts}, indent=2).encode())
    return part


@contextmanager
def timed_part(out: Path, command: str) -> Iterator[None]:
    """Record the enclosed work as one part of ``command`` in ``out/runs.json``, complete or
    (on an exception, Ctrl-C included) interrupted; the exception propagates."""
    t0 = time.perf_counter()
    complete = False
    try:
        yield
        complete = True
    finally:
        record_part(out, command, time.perf_counter() - t0, complete=complete)


def total_seconds(parts: list[dict]) -> float:
    """Wall time of a run made of ``parts``, s (their sum)."""
    return float(sum(p["elapsed_s"] for p in parts))


def resumed_seconds(out: Path, command: str) -> float:
    """Wall time of the interrupted parts of ``command`` in ``out/runs.json`` since its last
    complete one, s: what a resumed run adds to its own time (0 for a run that starts afresh)."""
    earlier = 0.0
    for part in read_parts(out):
        if part.get("command") != command:
            continue
        earlier = 0.0 if part.get("complete") else earlier + float(part["elapsed_s"])
    return earlier
