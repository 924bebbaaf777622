"""studies.engine.uncertainty: the noise + physics interval covers a planted truth at the rate it states."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from studies.engine.uncertainty import interval_text, order_for, physics_interval


def _coverage(n_points: int, trials: int, noise_m: float, seed: int) -> tuple[float, float]:
    """A toy study: the far limit is L(θ) = 4 + 8 θ² m of one planted unknown θ ~ U(0, 1); at each of
    ``n_points`` drawn θ_i the study estimates L(θ_i) with normal noise (sd ``noise_m``, its frames');
    the truth is one more draw θ*. Returns (how often the interval held L(θ*), its rate)."""
    rng = np.random.default_rng(seed)
    held, rate = 0, math.nan
    for _ in range(trials):
        theta = rng.random(n_points)
        truth = 4 + 8 * rng.random() ** 2
        estimate = 4 + 8 * theta**2 + rng.normal(0.0, noise_m, n_points)
        iv = physics_interval(estimate)
        held += iv.low <= truth <= iv.high
        rate = iv.rate
    return held / trials, rate


@pytest.mark.parametrize(("n_points", "rate"), [(16, 1 - 2 / 17), (39, 0.95), (79, 0.95)])
def test_the_interval_covers_a_planted_truth_at_its_stated_rate(n_points, rate):
    trials = 3000
    covered, stated = _coverage(n_points, trials, noise_m=0.3, seed=n_points)
    assert stated == pytest.approx(rate)
    se = math.sqrt(rate * (1 - rate) / trials)
    # at least the stated rate (within 3 standard errors), and not far above it: the estimates' noise
    # spreads them a little (the ranks alone give exactly the rate)
    assert rate - 3 * se <= covered <= rate + 0.03


def test_without_noise_the_ranks_alone_give_the_rate_exactly():
    covered, rate = _coverage(39, 4000, noise_m=1e-9, seed=1)
    assert abs(covered - rate) < 3 * math.sqrt(rate * (1 - rate) / 4000)


def test_order_and_censored_ends():
    assert [order_for(n) for n in (1, 16, 38, 39, 79, 119)] == [1, 1, 1, 1, 2, 3]
    iv = physics_interval([2.0, math.inf, 5.0, math.inf])
    assert iv.high == math.inf and iv.to_dict()["high"] is None and iv.low == 2.0
    many = physics_interval(np.arange(79.0)[::-1])
    assert (many.low, many.high, many.order) == (1.0, 77.0, 2)  # 2nd smallest, 2nd largest
    assert many.rate == pytest.approx(1 - 4 / 80)


@pytest.mark.parametrize(
    ("limits", "message"),
    [([], r"limits: expected a non-empty sequence"), ([1.0, math.nan], r"no NaN"), ([[1.0]], r"shape \(1, 1\)")],
)
def test_bad_input_is_one_line(limits, message):
    with pytest.raises(ValueError, match=message) as err:
        physics_interval(limits)
    assert "\n" not in str(err.value)


def test_range_limit_states_the_noise_and_the_noise_plus_physics_intervals(monkeypatch, tmp_path):
    """range-limit at points of a planted unknown (the red LEDs' intensity bin) on fake frames whose
    logistic fall-off moves with it: the nominal run keeps its own frames and interval, and the noise +
    physics interval spans the points' limits (their known truth) at the rate it states."""
    from studies.catalog import range_limit
    from studies.engine import sequential
    from studies.engine.max_range import LN19
    from studies.engine.tasks import StudyOptions
    from studies.engine.unknowns import load_unknowns, sample
    from tests.helpers.planted_frames import planted_rows, red_bin

    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 8.0 + 3.0 * (red_bin(t) - 5.1)))
    registry = load_unknowns()
    points = tuple(
        {"led_intensity_red": p["led_intensity_red"]}
        for p in sample({"led_intensity_red": registry["led_intensity_red"]}, 16, seed=3)
    )
    base = StudyOptions(cameras=("canon-t6-18mm",), ranges_m=(2.0, 4.0, 6.0, 8.0, 10.0, 12.0), seeds=3)
    design = sequential.SequentialDesign(target_relative=0.2, max_range_m=20.0)
    nominal = range_limit.run(tmp_path / "nominal", base, design=design)["max_range"][0]
    with_points = base.with_overrides(physics=points, physics_source="16 planted points")
    summary = range_limit.run(tmp_path / "physics", with_points, design=design)
    rec = summary["max_range"][0]
    assert summary["physics"] == {"points": 16, "source": "16 planted points"}
    assert summary["outcomes"] == range_limit.run(tmp_path / "nominal", base, design=design)["outcomes"]  # nominal only
    page = (tmp_path / "physics" / "report.html").read_text()
    assert f"{nominal['successes']} of {nominal['frames']}" in page  # the answer table: the nominal frames
    assert "far limit, noise + physics" in page and "each condition also ran at 16 planted points" in page
    assert {k: rec[k] for k in ("max_range_m", "low_m", "high_m", "frames")} == {
        k: nominal[k] for k in ("max_range_m", "low_m", "high_m", "frames")
    }  # the nominal run is the same frames with or without the points
    truths = sorted(8.0 + 3.0 * (p["led_intensity_red"] - 5.1) - 0.4 * LN19 for p in points)
    iv = rec["far_physics"]
    assert iv["points"] == 16 and iv["rate"] == pytest.approx(1 - 2 / 17)
    assert iv["low"] == pytest.approx(truths[0], abs=1.0) and iv["high"] == pytest.approx(truths[-1], abs=1.0)
    assert iv["low"] < nominal["low_m"] and iv["high"] > nominal["high_m"]  # physics widens it
    planted = [8.0 + 3.0 * (p["led_intensity_red"] - 5.1) - 0.4 * LN19 for p in points]
    at_points = iv["at_points_m"]  # each point's far limit, in point order: they follow the planted truths
    assert (min(at_points), max(at_points)) == (iv["low"], iv["high"])  # order 1 of 16: the extremes
    assert stats.spearmanr(at_points, planted).statistic > 0.9
    assert "(88 %, 16 points)" in rec["far_interval_physics"]
    with pytest.raises(ValueError, match=r"physics\[0\]\.led_intensity_red: 99 is outside"):
        base.with_overrides(physics=({"led_intensity_red": 99},)).validate()


def test_the_near_limit_has_its_noise_plus_physics_interval_too(monkeypatch, tmp_path):
    """A planted near limit that moves with the red LEDs' bin (brighter: blinded nearer out, so the near
    limit moves out by 1 m per cd) and a far limit past the farthest range: the near limit's noise +
    physics interval spans the points' truths, its far one says "≥", and both reach the report."""
    from studies.catalog import range_limit
    from studies.engine import sequential
    from studies.engine.max_range import LN19
    from studies.engine.tasks import StudyOptions
    from tests.helpers.planted_frames import FALL_OFF_M, planted_rows, red_bin

    near50 = lambda t: 3.0 + (red_bin(t) - 5.1)  # noqa: E731
    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 40.0, near50=near50))
    points = _red_points(8, seed=5)
    base = StudyOptions(cameras=("canon-t6-18mm",), ranges_m=(2.0, 4.0, 6.0, 8.0, 10.0, 12.0), seeds=3,
                        physics=points, physics_source="8 planted points")  # fmt: skip
    design = sequential.SequentialDesign(target_relative=0.2)
    rec = range_limit.run(tmp_path, base, design=design)["max_range"][0]
    truths = sorted(3.0 + (p["led_intensity_red"] - 5.1) + FALL_OFF_M * LN19 for p in points)
    iv = rec["near_physics"]
    assert iv["points"] == 8 and iv["rate"] == pytest.approx(1 - 2 / 9)
    low = -math.inf if iv["low"] is None else iv["low"]  # "≤ the nearest tried" when below 2 m
    assert (low == -math.inf and truths[0] < 2.5) or low == pytest.approx(truths[0], abs=1.0)
    assert iv["high"] == pytest.approx(truths[-1], abs=1.0)
    assert rec["far_physics"]["high"] is None and "≥ the farthest tried" in rec["far_interval_physics"]
    page = (tmp_path / "report.html").read_text()
    assert "near limit, noise + physics" in page and rec["near_interval_physics"] in page


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["study", "replication", "--uncertainty", "4"],
         r"uncertainty: expected a study that states it \(range-limit, webcam-vs-dslr, brightness-diffuser; "
         r"replication re-runs the source study's own configurations\), got replication"),
        (["study", "range-limit", "--uncertainty", "0"], r"uncertainty: expected an integer >= 1"),
        (["study", "range-limit", "--uncertainty", "4", "--physics-from", "none.csv"],
         r"physics-from: expected a calibration's nroy.csv or 'registry', none.csv is not a file"),
        (["main-job", "--uncertainty", "-2"], r"uncertainty: expected an integer >= 1"),
        (["main-job", "--point-budget-grids", "2"], r"point-budget-grids: expected --uncertainty N as well"),
        (["study", "range-limit", "--quick", "--uncertainty", "2", "--physics-from", "registry",
          "--target-relative", "0.2", "--point-budget-grids", "0.5"],
         r"point-budget-grids: expected a number >= 1 \(coarse grids per point\), got 0.5"),
        (["study", "range-limit", "--quick", "--uncertainty", "2", "--physics-from", "registry",
          "--point-budget-grids", "3"], r"point-budget-grids: expected a sequential design as well"),
    ],
)  # fmt: skip
def test_the_command_line_refuses_bad_uncertainty_before_any_work(monkeypatch, tmp_path, args, message):
    import re

    from tests.helpers.cli import assert_one_line_error, invoke, patch_work

    patch_work(monkeypatch)
    monkeypatch.chdir(tmp_path)
    code, _, err = invoke([*args, "--out", str(tmp_path / "o")])
    assert re.search(message, assert_one_line_error(code, err))
    assert not (tmp_path / "o").exists()


def test_the_command_line_gives_the_study_its_points(monkeypatch, tmp_path):
    from studies.catalog import range_limit
    from tests.helpers.cli import invoke

    seen = {}
    monkeypatch.setattr(range_limit, "run", lambda out, options, execution, design=None: seen.update(o=options))
    monkeypatch.chdir(tmp_path)
    code, _, err = invoke(["study", "range-limit", "--quick", "--out", "o", "--uncertainty", "3",
                           "--physics-from", "registry"])  # fmt: skip
    assert code == 0, err
    assert len(seen["o"].physics) == 3 and "from their registry ranges" in seen["o"].physics_source


def test_the_main_job_gives_each_point_its_budget_and_the_user_may_change_it(monkeypatch, tmp_path):
    from studies.catalog import STUDIES
    from studies.cli import study as study_cli
    from studies.engine.uncertainty import POINT_BUDGET_GRIDS
    from tests.helpers.cli import invoke

    seen = {}
    for name, module in STUDIES.items():
        monkeypatch.setattr(module, "run", lambda out, options, execution, design=None, n=name: seen.update(
            {n: design}))  # fmt: skip
    monkeypatch.setattr(study_cli, "write_index", lambda *a, **k: None)
    monkeypatch.chdir(tmp_path)
    for args, grids in (([], POINT_BUDGET_GRIDS), (["--point-budget-grids", "3.5"], 3.5)):
        seen.clear()
        code, _, err = invoke(["main-job", "--out", f"o{grids}", "--uncertainty", "2", "--physics-from", "registry",
                               *args])  # fmt: skip
        assert code == 0, err
        assert seen["range-limit"].point_budget_grids == grids  # the main job's one sequential design
    code, _, err = invoke(["main-job", "--out", "o-none"])
    assert code == 0, err
    assert seen["range-limit"].point_budget_grids is None  # no points, no point budget


def test_physics_points_take_what_the_calibration_covered_from_its_nroy_set(tmp_path):
    import pandas as pd

    from studies.catalog import calibration, prediction_set
    from studies.engine.unknowns import sample

    space = calibration.search_space(calibration.load_observations())
    nroy = pd.DataFrame(sample(space, 2, seed=9))
    nroy.to_csv(tmp_path / "nroy.csv", index=False)
    points, which = prediction_set.physics_points(4, calibration=tmp_path / "nroy.csv")
    assert len(points) == 4 and "from the calibration's NROY set (nroy.csv, 2 of its points, reused)" in which
    rows = prediction_set.load(tmp_path / "nroy.csv").points
    assert [r["led_intensity_red"] for r in rows] == pytest.approx(list(nroy.led_intensity_red))
    for i, point in enumerate(points):  # the NROY points in turn, for every unknown both know
        assert {k: point[k] for k in set(point) & set(space)} == {k: rows[i % 2][k] for k in set(point) & set(space)}
    assert "led_drive" not in points[0] and not any("iterations" in k for k in points[0])  # a study's axes stay its own
    alone, which = prediction_set.physics_points(4, calibration=None)
    assert "from their registry ranges" in which and alone != points
    with pytest.raises(ValueError, match=r"uncertainty: expected an integer >= 1"):
        prediction_set.physics_points(0)


def test_the_main_jobs_design_budget_grows_with_the_points(monkeypatch, tmp_path):
    """A budget of frames is the nominal grid's; with N points each repeats it (else the coarse grid alone
    would exceed it and the run would be refused)."""
    from studies.catalog import range_limit
    from studies.engine import sequential
    from tests.helpers.planted_frames import planted_rows

    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 6.0))
    options = range_limit.default_options(True).with_overrides(
        cameras=("logitech-c270",), yaws_deg=(0.0,), physics=({"led_intensity_red": 4.0}, {"led_intensity_red": 6.0})
    )
    design = range_limit.default_design(True).with_overrides(budget_frames=40)
    summary = range_limit.run(tmp_path, options, design=design)
    assert summary["design"]["budget_frames"] == 120 and summary["design"]["frames"] <= 120


def test_each_point_stops_at_its_own_budget_while_the_nominal_keeps_the_designs(monkeypatch, tmp_path):
    """point_budget_grids = 1.5: a unit at a point spends at most 1.5 of its coarse grids (6 ranges × 3
    seeds = 18 frames: 27), the nominal unit more where its limit is still open; each point's limit
    is still estimated near its planted truth (far limit r₅₀ − s ln 19)."""
    import math

    import pandas as pd

    from studies.catalog import range_limit
    from studies.engine import sequential
    from studies.engine.uncertainty import far_limits_at_points, point_rows
    from tests.helpers.planted_frames import FALL_OFF_M, planted_rows, red_bin

    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 3.0 + red_bin(t)))  # far: 7.3-9.7 m
    points = ({"led_intensity_red": 5.5}, {"led_intensity_red": 6.5})
    options = range_limit.default_options(True).with_overrides(cameras=("logitech-c270",), yaws_deg=(0.0,),
                                                               physics=points)  # fmt: skip
    design = range_limit.default_design(True).with_overrides(target_relative=0.05, point_budget_grids=1.5)
    summary = range_limit.run(tmp_path, options, design=design)
    units = {u["key"][-1]: u for u in summary["design"]["units"]}
    assert units[None]["frames"] > 27  # ±5 %: the nominal cannot decide it within 27 frames
    (limits,) = far_limits_at_points(point_rows(pd.read_parquet(tmp_path / "results.parquet")),
                                     range_limit.GROUP).values()  # fmt: skip
    for i, p in enumerate(points):
        assert units[i]["frames"] <= 27 and units[i]["stop"] == "unit budget"
        truth = 3.0 + p["led_intensity_red"] - FALL_OFF_M * math.log(19)
        assert limits[i] == pytest.approx(truth, abs=1.0)  # within half a coarse step of 2 m
    assert summary["design"]["design"]["point_budget_grids"] == 1.5


def _red_points(n: int, seed: int) -> tuple[dict, ...]:
    from studies.engine.unknowns import load_unknowns, sample

    space = {"led_intensity_red": load_unknowns()["led_intensity_red"]}
    return tuple({"led_intensity_red": p["led_intensity_red"]} for p in sample(space, n, seed=seed))


def _red_chroma(task: dict) -> tuple[float, float]:
    """Planted colours: the red side's r chromaticity moves with the red LEDs' bin (0.4 at 3 cd, + 0.05
    per cd), the green side sits at r = 0.3; both at g = 0.3, so the closest pair's Mahalanobis
    distance is (r_red − 0.3) / CHROMA_SD."""
    from tests.helpers.planted_frames import red_bin

    return (0.4 + 0.05 * (red_bin(task) - 3.0), 0.3) if task["scenario"]["side"] == "red" else (0.3, 0.3)


def test_webcam_vs_dslr_states_far_limit_and_colour_separability_with_the_physics(monkeypatch, tmp_path):
    """webcam-vs-dslr at points of a planted unknown: the far limit's and the closest pair's noise + physics
    intervals span the points' known truths, while every other number is the nominal point's."""
    from studies.catalog import webcam_vs_dslr
    from studies.engine import sequential
    from studies.engine.max_range import LN19
    from studies.engine.tasks import StudyOptions
    from tests.helpers.planted_frames import CHROMA_SD, planted_rows, red_bin

    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 8.0 + 1.5 * (red_bin(t) - 5.1), _red_chroma))
    monkeypatch.setattr(webcam_vs_dslr, "mosaic_png", lambda options, out: None)
    points = _red_points(16, seed=5)
    base = StudyOptions(cameras=("canon-t6-18mm",), sides=("red", "green"), ranges_m=(2.0, 6.0, 10.0, 14.0), seeds=3)
    design = sequential.SequentialDesign(target_relative=0.2, max_range_m=20.0)
    nominal = webcam_vs_dslr.run(tmp_path / "nominal", base, design=design)
    summary = webcam_vs_dslr.run(
        tmp_path / "physics", base.with_overrides(physics=points, physics_source="16 planted points"), design=design
    )
    sep, sep0 = summary["colour_separability"][0], nominal["colour_separability"][0]
    assert sep["min_mahalanobis"] == sep0["min_mahalanobis"] and sep["frames"] == sep0["frames"]  # nominal alone
    assert sep0["min_mahalanobis"] == pytest.approx((0.4 + 0.05 * 2.1 - 0.3) / CHROMA_SD, rel=0.1)  # 5.1 cd
    d = sorted((0.1 + 0.05 * (p["led_intensity_red"] - 3.0)) / CHROMA_SD for p in points)
    iv = sep["separability_physics"]
    assert iv["low"] == pytest.approx(d[0], rel=0.1) and iv["high"] == pytest.approx(d[-1], rel=0.1)
    assert sep["separability_interval_physics"].endswith("(88 %, 16 points)")
    # the far limit: a planted fall-off like range-limit's test (half as steep: every point's limit lies
    # beyond the first range), pooled over the two sides
    far = sorted(8.0 + 1.5 * (p["led_intensity_red"] - 5.1) - 0.4 * LN19 for p in points)
    best = next(r for r in summary["max_range"] if r["tracker"] == "best")
    assert best["far_physics"]["low"] == pytest.approx(far[0], abs=1.0)
    assert best["far_physics"]["high"] == pytest.approx(far[-1], abs=1.0)
    top = summary["ranking"][0]
    assert top["far_interval_physics"] == best["far_interval_physics"]
    assert top["separability_interval_physics"] == sep["separability_interval_physics"]
    page = (tmp_path / "physics" / "report.html").read_text()
    assert "closest pair, noise + physics" in page and "each condition also ran at 16 planted points" in page


def test_brightness_diffuser_states_how_often_its_setting_stays_in_the_window(monkeypatch, tmp_path):
    """brightness-diffuser at points of a planted unknown whose fall-off crosses its one range: the
    recommended setting's lowest P(correct) over the points, and at how many points it stays in the
    window, follow the planted truth (at 5 m the frames all succeed where r50 ≥ 7 m and all fail where
    r50 ≤ 3 m)."""
    from studies.catalog import brightness_diffuser
    from studies.engine import sweep
    from studies.engine.tasks import StudyOptions
    from tests.helpers.planted_frames import planted_rows, red_bin

    monkeypatch.setattr(sweep, "run_frames", planted_rows(lambda t: 9.0 if red_bin(t) > 5.0 else 1.0, _red_chroma))
    points = ({"led_intensity_red": 3.5}, {"led_intensity_red": 4.5}, {"led_intensity_red": 6.0})
    options = StudyOptions(
        cameras=("logitech-c270",), ranges_m=(5.0,), currents_mA=(2.0,), diffusers=((True, 1, "white"),), seeds=8,
        physics=points, physics_source="3 planted points",
    )  # fmt: skip
    rec = brightness_diffuser.run(tmp_path, options)["recommended"][0]
    assert rec["p_detect"] == 1.0  # the nominal point: 5.1 cd, r50 = 9 m
    assert rec["window_points"] == "1 of 3"
    assert (rec["p_physics"]["low"], rec["p_physics"]["high"]) == (0.0, 1.0)
    assert "in the window at 1 of 3 points" in brightness_diffuser.recommendation_text(rec)


@pytest.mark.parametrize(
    ("limits", "text"),
    [
        ([0.0] * 16, "none (88 %, 16 points)"),  # 0 = no range worked: "none", not "0 to 0 m"
        ([0.0] * 15 + [7.0], "none to 7 m (88 %, 16 points)"),
        ([0.0] * 2 + [math.inf] * 14, "none to ≥ the farthest tried (88 %, 16 points)"),
        ([4.0] * 2 + [math.inf] * 14, "4 m to ≥ the farthest tried (88 %, 16 points)"),
        ([3.0, 6.0] + [4.5] * 14, "3 to 6 m (88 %, 16 points)"),
    ],
)
def test_a_far_limit_interval_reads_none_where_no_range_worked(limits, text):
    """The smallest to the largest of 16 (k = 1: 1 − 2/17 = 88 %), in words; with ``zero`` a far limit
    of 0 reads "none"."""
    assert interval_text(physics_interval(limits), zero="none") == text
    assert interval_text(physics_interval([0.0] * 16)) == "0 to 0 m (88 %, 16 points)"  # without it: a number


def test_a_point_leaves_the_axes_the_study_sweeps_as_the_grid_sets_them():
    """The unknown paper colour is V2's paper as built: a range-limit task (one diffuser) takes the
    point's; brightness-diffuser sweeps white against matched paper, so its tasks keep the grid's."""
    from studies.engine.tasks import StudyOptions, frame_task, grid_conditions

    point = ({"paper_colour": "matched", "housing": "white"},)
    one = StudyOptions(cameras=("logitech-c270",), diffusers=((True, 1, "white"),), physics=point)
    swept = one.with_overrides(diffusers=((True, 1, "white"), (True, 1, "matched"), (False, 0, "white")))
    assert one.swept_fields() == frozenset({"range_m"}) and {"paper_colour", "foam"} <= swept.swept_fields()
    for options, expected in ((one, {"matched"}), (swept, {"white", "matched"})):
        at_point = [c for c in grid_conditions(options) if c.get("point") == 0]
        tasks = [frame_task(c, 0, options) for c in at_point]
        assert {t["scenario"]["paper_colour"] for t in tasks} == expected
        assert all(t["scenario"]["housing"] == "white" for t in tasks)  # not an axis: the point's
        for c, t in zip(at_point, tasks, strict=True):
            if options is swept:
                assert t["scenario"]["paper_colour"] == c["paper_colour"] and t["scenario"]["foam"] == c["foam"]
