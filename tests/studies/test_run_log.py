"""The run log: parts of a resumed command add up, and frames are counted from the store."""

from __future__ import annotations

import json

import pytest

from studies.engine.run_log import read_parts, record_part, stored_frames, total_seconds


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


def test_a_runs_file_without_a_list_of_parts_is_refused(tmp_path):
    (tmp_path / "runs.json").write_text(json.dumps({"parts": {"elapsed_s": 1}}))
    with pytest.raises(ValueError, match=r"^parts: expected a list in .*runs.json, got dict$"):
        read_parts(tmp_path)
