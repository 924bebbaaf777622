"""The benchmark's frame measurement runs the study's frame path and reports consistent figures."""

from __future__ import annotations

from camera_models.camera import load_camera
from studies.experiments.bench import BENCH_SCENARIO, frame_vs_memcpy, hugepage_advice


def test_frame_vs_memcpy_times_a_whole_saved_frame():
    scenario = {**BENCH_SCENARIO, "camera": "logitech-c270", "foam": False, "paper_sheets": 0, "range_m": 8.0}
    out = frame_vs_memcpy(repeats=1, scenario=scenario)
    g = load_camera("logitech-c270").geometry
    assert out["frame_bytes"] == g.width_px * g.height_px * 3  # the whole frame, 8-bit RGB
    assert out["ratio"] == out["frame_s"] / out["memcpy_s"]
    assert out["frame_s"] >= out["camera_s"] + out["detect_s"] > 0


def test_hugepage_advice_changes_no_byte_and_leaves_numpy_as_it_found_it():
    from numpy._core.multiarray import _get_madvise_hugepage

    scenario = {**BENCH_SCENARIO, "camera": "logitech-c270", "foam": False, "paper_sheets": 0, "range_m": 8.0}
    before = _get_madvise_hugepage()
    out = hugepage_advice(repeats=1, scenario=scenario)
    assert out["same_bytes"] is True  # memory backing only: the saved frame is the same
    assert out["ratio"] == out["advice_on_s"] / out["advice_off_s"]
    assert out["advice_on_kernel_s"] >= 0 and out["advice_off_kernel_s"] >= 0
    assert _get_madvise_hugepage() == before


def test_grid_hours_is_the_student_t_interval_of_the_mean_batch():
    import numpy as np
    from scipy import stats

    from studies.experiments.bench import _grid_hours

    per_batch = np.array([3.0, 5.0, 4.5, 9.0, 2.5])
    low, high = stats.t.interval(0.95, len(per_batch) - 1, loc=per_batch.mean(), scale=stats.sem(per_batch))
    got = _grid_hours(per_batch, 1000, 360.0)
    np.testing.assert_allclose(got, [(low * 1000 + 360.0) / 3600.0, (high * 1000 + 360.0) / 3600.0], rtol=1e-12)


def test_grid_sample_resumes_and_extrapolates(tmp_path, monkeypatch):
    """With the frames and near fields replaced by fakes of known cost, the summary adds the
    segments up, counts each near field once and scales by the grid's batches; another
    fraction in the same folder is refused."""
    import json

    import numpy as np
    import pytest

    from studies.experiments import bench

    batches = {f"b{k}": {"foam": k % 2 == 0, "paper_sheets": k % 3, "side": "front"} for k in range(100)}
    monkeypatch.setattr(bench, "_grid_batches", lambda: (list(batches.values()), batches))
    monkeypatch.setattr(bench, "_batch_tasks", lambda keys, _: {k: [{"batch": k}] * 4 for k in keys})
    near = iter([[2.0, 4.0], [], [6.0]] + [[]] * 100)  # the second run finds them cached
    monkeypatch.setattr(bench, "_task_near_field_seconds", lambda task: next(near))
    monkeypatch.setattr(bench, "_batch_seconds", lambda out, groups: np.arange(1.0, len(groups) + 1))
    walls = iter([0.25, 20.5])
    clock = {"t": 0.0}
    on_disk = []

    def fake_run(work, out, execution, description):
        with execution.progress(description, len(work), 0) as advance:
            clock["t"] += next(walls)
            advance()  # a finished frame: the segment's time so far is saved (at most every 10 s)
            on_disk.append(json.loads((tmp_path / "segments.json").read_text())["frames_wall_s"][-1])

    monkeypatch.setattr(bench, "run_frames", fake_run)
    monkeypatch.setattr(bench.time, "perf_counter", lambda: clock["t"])
    first = bench.grid_sample(tmp_path, 0.05)
    second = bench.grid_sample(tmp_path, 0.05)
    assert first["render_batches"] == 5 and first["frames"] == 20 and first["segments"] == 1
    assert second["segments"] == 2 and second["frames_wall_s"] == pytest.approx(20.75)
    assert on_disk == [0.0, pytest.approx(20.5)]  # what a run killed after that frame would have kept
    assert second["near_fields"] == 3 and second["near_fields_s"] == pytest.approx(12.0)
    grid_near_fields = len({(g["foam"], g["paper_sheets"], g["side"]) for g in batches.values()})  # 6
    expected_h = (20.75 * 100 / 5 + 4.0 * grid_near_fields) / 3600.0
    assert second["grid_cold_h"] == pytest.approx(expected_h)
    assert second["grid_cold_h_95"][0] < expected_h < second["grid_cold_h_95"][1]
    with pytest.raises(ValueError, match="other batches"):
        bench.grid_sample(tmp_path, 0.1)
