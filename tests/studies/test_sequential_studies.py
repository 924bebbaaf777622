"""range-limit, webcam-vs-dslr and the main job with a sequential design, on fake frames of known
truth (no rendering): summaries and reports say how many frames decided each limit, and the
command line takes the design's options."""

from __future__ import annotations

import hashlib
import json
import math

import pandas as pd
import pytest

from studies.catalog import SEQUENTIAL, range_limit, webcam_vs_dslr
from studies.catalog.index import write_index
from studies.engine import sequential
from studies.engine.max_range import LN19
from studies.engine.sequential import SequentialDesign
from tests.helpers.cli import assert_one_line_error, invoke, patch_work

T6, C270 = "canon-t6-18mm", "logitech-c270"
TRUTH = {T6: (14.0, 0.6), "canon-t6-10mm": (9.0, 0.4), C270: (8.0, 0.5), "spedal-920": (5.0, 0.3)}
"""(r₅₀, s) of each camera's fake logistic fall-off, m: far limits 12.2, 7.8, 6.5 and 4.1 m."""
CHROMA = {"red": (0.6, 0.3), "green": (0.2, 0.7)}


def far_truth(camera: str) -> float:
    r50, s = TRUTH[camera]
    return r50 - s * LN19


def fake_rows(tasks, out, execution, description=""):
    """Both trackers' rows of each task: the best tracker succeeds with the camera's known
    probability, the study's never (drawn from the task's content)."""
    rows = []
    for task in tasks:
        sc = task["scenario"]
        r50, s = TRUTH[sc["camera"]]
        u = int.from_bytes(hashlib.sha256(json.dumps(task, sort_keys=True).encode()).digest()[:8], "little") / 2**64
        for tracker in ("best", "thesis"):
            ok = tracker == "best" and u < 1 / (1 + math.exp((sc["range_m"] - r50) / s))
            r, g = CHROMA[sc["side"]]
            row = {
                **sc,
                "nominal_range_m": task["nominal"]["range_m"],
                "nominal_yaw_deg": task["nominal"]["yaw_deg"],
                "seed": task["seed"],
                "tracker": tracker,
                "estimator": "best",
                "detected": ok,
                "side_correct": ok,
                "numbering_correct": ok,
                "side_detected": sc["side"] if ok else None,
                "range_err_m": 0.01 if ok else math.nan,
                "yaw_err_deg": 0.1 if ok else math.nan,
                "failure": "" if ok else "no-blobs",
                "reason": "",
                "core_saturated_fraction_mean": 0.05,
                "marker_spacing_px": 40.0,
                "core_diameter_px": 5.0,
            }
            for i in range(1, 6):
                row[f"marker{i}_r_chroma"], row[f"marker{i}_g_chroma"] = r, g
                row[f"marker{i}_R"], row[f"marker{i}_G"], row[f"marker{i}_B"] = r, g, 1 - r - g
            rows.append(row)
    return rows


@pytest.fixture
def fake(monkeypatch):
    monkeypatch.setattr(sequential, "run_frames", fake_rows)
    monkeypatch.setattr(webcam_vs_dslr, "mosaic_png", lambda options, out: b"")


def test_range_limit_decides_each_far_limit_and_says_with_how_many_frames(fake, tmp_path):
    options = range_limit.default_options(True)
    design = range_limit.default_design(True)
    assert design.target_relative == 0.2 and design.budget_frames == 120 * 8
    summary = range_limit.run(tmp_path, options, design=design)
    assert summary["design"]["frames"] <= 960 and (tmp_path / "design.json").is_file()
    frames = pd.read_parquet(tmp_path / "results.parquet")
    assert len(frames) == 2 * summary["design"]["frames"]  # both trackers' rows of every frame
    for rec in summary["max_range"]:
        truth = far_truth(rec["camera"])
        assert rec["low_m"] <= truth <= rec["high_m"], rec["camera"]
        assert (
            rec["far_decided"]
            and rec["low_m"] >= 0.8 * rec["max_range_m"]
            and rec["high_m"] <= 1.2 * rec["max_range_m"]
        )
        assert rec["decision"] == f"{rec['frames']} frames: decided (interval within ±20 % of the limit)"
    for rec in summary["max_range_thesis_tracker"]:
        assert rec["decision"] == f"{rec['frames']} frames (placed for the best tracker)"
    page = (tmp_path / "report.html").read_text()
    assert "frames that decided it" in page and "8 of 8 far limits decided" in page
    # the fixed-grid path is unchanged: no design fields
    fixed = range_limit.analyse(frames)
    assert "design" not in fixed and "decision" not in fixed["max_range"][0]


def test_webcam_vs_dslr_and_the_index_say_how_many_frames_decided_each_limit(fake, tmp_path):
    options = webcam_vs_dslr.default_options(True).with_overrides(cameras=(T6, C270))
    design = webcam_vs_dslr.default_design(True).with_overrides(budget_frames=1000)
    summary = webcam_vs_dslr.run(tmp_path / "webcam-vs-dslr", options, design=design)
    best = [r for r in summary["max_range"] if r["tracker"] == "best"]
    assert len(best) == 4  # 2 cameras × 2 drives, both sides pooled
    for rec in best:
        assert rec["low_m"] <= far_truth(rec["camera"]) <= rec["high_m"] and rec["far_decided"]
        assert rec["frames"] % 2 == 0  # one slot is a frame of each side
    assert "frames that decided it" in (tmp_path / "webcam-vs-dslr" / "report.html").read_text()
    range_limit.run(
        tmp_path / "range-limit", range_limit.default_options(True), design=range_limit.default_design(True)
    )
    write_index(tmp_path)
    page = (tmp_path / "index.html").read_text()
    assert "range-limit: from the coarse grid" in page and "frames: decided (interval within ±20 %" in page


def test_a_tight_target_ends_on_the_budget_and_says_so(fake, tmp_path):
    options = range_limit.default_options(True).with_overrides(cameras=(C270,), yaws_deg=(0.0,))
    summary = range_limit.run(tmp_path, options, design=SequentialDesign(target_width_m=0.05, budget_frames=60))
    rec = summary["max_range"][0]
    assert rec["frames"] == summary["design"]["frames"] <= 60 and not rec["far_decided"]
    assert rec["decision"].startswith(f"{rec['frames']} frames: not decided (budget spent; interval ")


def test_both_studies_are_registered_with_a_design():
    assert set(SEQUENTIAL) == {"range-limit", "webcam-vs-dslr"}


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["study", "range-limit", "--quick", "--budget-frames", "10"], "budget-frames"),
        (["study", "range-limit", "--target-width-m", "-1"], "target-width-m"),
        (["study", "webcam-vs-dslr", "--target-relative", "2"], "target-relative"),
        (["study", "brightness-diffuser", "--budget-frames", "500"], "budget-frames"),
        (["study", "range-limit", "--ranges-m", "4", "--budget-frames", "500"], "ranges-m"),
        (["main-job", "--budget-frames", "20"], "budget-frames"),
    ],
)
def test_bad_design_options_are_refused_in_one_line_before_any_work(monkeypatch, tmp_path, args, field):
    patch_work(monkeypatch)
    monkeypatch.chdir(tmp_path)
    code, _, err = invoke([*args, "--out", str(tmp_path / "o")])
    assert_one_line_error(code, err, field)
    assert not (tmp_path / "o").exists()


def test_the_design_options_reach_the_study(monkeypatch, tmp_path):
    seen = {}

    def run(out, options, execution, design=None):
        seen["design"] = design

    monkeypatch.setattr(range_limit, "run", run)
    code, _, err = invoke(["study", "range-limit", "--quick", "--target-width-m", "1.5", "--out", str(tmp_path / "o")])
    assert code == 0, err
    assert seen["design"] == range_limit.default_design(True).with_overrides(target_width_m=1.5)
    code, _, _ = invoke(["study", "range-limit", "--quick", "--out", str(tmp_path / "p")])
    assert code == 0 and seen["design"] is None  # no design option: the fixed grid


def test_brightness_diffuser_screens_settings_by_their_first_frames_to_the_full_grids_window(monkeypatch, tmp_path):
    """brightness-diffuser's screened sweep against the full grid on planted frames whose far
    fall-off (r₅₀ from 5.5 to 9.7 m) puts many settings near P = 0.95 at 7 m: the same settings in
    the window, the same recommendation per camera and side, every passing setting with all its
    frames, and fewer frames in all (the planted change "a setting passes on any first success"
    would admit settings with a failure)."""
    from studies.catalog import brightness_diffuser as bd
    from studies.engine import sweep
    from studies.engine.tasks import StudyOptions, grid_conditions
    from tests.helpers.planted_frames import planted_rows

    def r50(task):
        sc = task["scenario"]
        return 5.5 + 0.3 * sc["led_current_mA"] + 0.6 * sc["paper_sheets"] + 0.4 * sc["foam"]

    monkeypatch.setattr(sweep, "run_frames", planted_rows(r50, lambda t: (0.6, 0.3)))
    options = StudyOptions(
        cameras=("logitech-c270", "canon-t6-18mm"), sides=("red", "green"), ranges_m=(3.0, 7.0),
        currents_mA=(1.0, 2.0, 5.0), diffusers=((False, 0, "white"), (True, 1, "white"), (True, 3, "matched")),
        seeds=4,
    )  # fmt: skip
    full = bd.configuration_table(sweep.sweep("bd", grid_conditions(options), options, tmp_path / "full"))
    frame, spent = sweep.sweep_screened("bd", grid_conditions(options), options, tmp_path / "s", bd.setting_of)
    screened = bd.configuration_table(frame)

    def window(table):
        per = table.groupby(list(bd.SETTING)).in_window.all()
        return set(per[per].index)

    assert 0 < len(window(full)) < len(full) // 2  # the planted truth leaves settings on both sides
    assert window(screened) == window(full)
    assert bd.recommend(screened) == bd.recommend(full)
    kept = screened[screened.set_index(list(bd.SETTING)).index.isin(window(full))]
    assert (kept.frames == options.seeds).all()
    assert spent.grid_frames == len(grid_conditions(options)) * options.seeds == len(full) * options.seeds
    assert spent.frames == len(frame) < spent.grid_frames
    assert spent.units == len(full) // 2 and len(window(full)) <= spent.confirmed < spent.units
