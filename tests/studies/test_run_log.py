"""The run log: parts of a resumed command add up, and frames are counted from the store."""

from __future__ import annotations

import json
import os

import pytest

from studies.engine.run_log import (
    host,
    read_parts,
    record_part,
    resumed_seconds,
    stored_frames,
    timed_part,
    total_seconds,
)


def test_parts_of_a_resumed_run_add_up_and_count_the_stored_frames(tmp_path):
    assert read_parts(tmp_path) == [] and stored_frames(tmp_path) == 0
    for k in range(3):  # two studies' stores under one main job
        for study in ("a", "b"):
            task = tmp_path / study / "tasks" / f"{k:02x}" / f"{k}.json"
            task.parent.mkdir(parents=True)
            task.write_text("{}")
    first = record_part(tmp_path, "main-job", 61.25)
    second = record_part(tmp_path, "main-job", 30.0, frames=7)
    parts = read_parts(tmp_path)
    assert parts == [first, second] and first["frames"] == 6 and second["frames"] == 7
    assert total_seconds(parts) == pytest.approx(61.2 + 30.0)  # stored to 0.1 s
    assert first["host"]["cpus"] == os.cpu_count() and isinstance(first["host"]["cpu"], str)


def test_the_host_is_read_from_the_cpus_description():
    """An AVX-512 host is told apart (its native LLVM width rendered other bytes before the pin)."""
    text = "processor\t: 0\nmodel name\t: Intel Xeon\nflags\t\t: sse avx avx2 fma avx512f\n\nprocessor\t: 1\n"
    assert host(text) | {"cpus": 0} == {"cpu": "Intel Xeon", "cpus": 0, "avx2": True, "avx512": True}
    assert host("model name : AMD EPYC\nflags : sse avx avx2 fma\n")["avx512"] is False


def test_a_runs_file_without_a_list_of_parts_is_refused(tmp_path):
    (tmp_path / "runs.json").write_text(json.dumps({"parts": {"elapsed_s": 1}}))
    with pytest.raises(ValueError, match=r"^parts: expected a list in .*runs.json, got dict$"):
        read_parts(tmp_path)


def test_an_interrupted_part_is_recorded_as_such_and_the_error_propagates(tmp_path):
    with pytest.raises(KeyboardInterrupt), timed_part(tmp_path, "validate"):
        raise KeyboardInterrupt
    with timed_part(tmp_path, "validate"):
        pass
    assert [p["complete"] for p in read_parts(tmp_path)] == [False, True]


def test_a_resumed_command_adds_the_interrupted_parts_since_its_last_complete_one(tmp_path):
    assert resumed_seconds(tmp_path, "design") == 0.0
    record_part(tmp_path, "design", 100.0, frames=0)  # a search that finished
    record_part(tmp_path, "design", 30.0, frames=0, complete=False)  # a later one, stopped twice
    record_part(tmp_path, "sensitivity", 500.0, frames=0, complete=False)  # another command's
    record_part(tmp_path, "design", 20.0, frames=0, complete=False)
    assert resumed_seconds(tmp_path, "design") == pytest.approx(50.0)
    record_part(tmp_path, "design", 5.0, frames=0)  # ended: the next run starts afresh
    assert resumed_seconds(tmp_path, "design") == 0.0
    assert resumed_seconds(tmp_path, "sensitivity") == pytest.approx(500.0)


def test_the_benchmark_sums_the_recorded_full_studies_only_when_all_finished(tmp_path):
    from studies.experiments.bench import FULL_STUDIES, recorded_runs

    (tmp_path / "full").mkdir()
    for k, name in enumerate(FULL_STUDIES):
        scratch = tmp_path / name
        record_part(scratch, name, 100.0 * (k + 1), frames=10, complete=k != 0)
        (tmp_path / "full" / f"{name}.runs.json").write_text((scratch / "runs.json").read_text())
    runs = recorded_runs(tmp_path)
    assert runs["main_job"] is None and runs["full_studies_s"] is None  # the first is interrupted
    first = tmp_path / FULL_STUDIES[0]
    record_part(first, FULL_STUDIES[0], 50.0, frames=12)  # resumed to completion
    (tmp_path / "full" / f"{FULL_STUDIES[0]}.runs.json").write_text((first / "runs.json").read_text())
    runs = recorded_runs(tmp_path)
    assert runs["full_studies"][FULL_STUDIES[0]] | {"finished_utc": None} == {
        "s": 150.0,
        "parts": 2,
        "frames": 12,
        "finished_utc": None,
        "complete": True,
    }
    assert runs["full_studies_s"] == 150.0 + 200.0 + 300.0 + 400.0
