"""Studies end to end on tiny grids: files, tables, reports that render in Chromium."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from pipeline.thesis_tracker import hsv_ranges_from_histogram
from studies.catalog import brightness_diffuser, range_limit, replication, unknowns_search, validate, webcam_vs_dslr
from studies.catalog.unknowns_search import WEBCAMS
from studies.engine.metrics import wilson_interval
from studies.engine.sweep import Execution
from studies.engine.unknowns import sample

pytestmark = pytest.mark.usefixtures("mitsuba_variant")
TINY = {"spp": 2, "oversampling": 1, "crop": "target", "near_field_spp": 64}


def _check_outputs(out, summary_keys=()):
    for name in ("report.html", "results.csv", "results.parquet", "summary.json"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    for key in summary_keys:
        assert key in summary
    csv = pd.read_csv(out / "results.csv")
    parquet = pd.read_parquet(out / "results.parquet")
    assert len(csv) == len(parquet) > 0
    return summary, csv


def test_webcam_vs_dslr_tiny(tmp_path):
    o = webcam_vs_dslr.default_options(True).with_overrides(
        cameras=("logitech-c270",), sides=("red", "green"), ranges_m=(4.0,), seeds=1, render=TINY
    )
    webcam_vs_dslr.run(tmp_path, o, Execution(workers=1))
    _, csv = _check_outputs(tmp_path, ("ranking", "max_range", "colour_separability"))
    assert set(csv.tracker) == {"thesis", "best"} and set(csv.estimator) == {"thesis", "best"}
    assert (tmp_path / "mosaic.png").stat().st_size > 1000


def test_brightness_diffuser_tiny(tmp_path):
    o = brightness_diffuser.default_options(True).with_overrides(
        cameras=("logitech-c270",), currents_mA=(2.0, 20.0), diffusers=((True, 1, "white"),), seeds=1, render=TINY
    )
    summary = brightness_diffuser.run(tmp_path, o, Execution(workers=1))
    _check_outputs(tmp_path, ("recommended",))
    powers = {c["led_current_mA"]: c["led_power_mW"] for c in summary["configurations"]}
    assert powers[20.0] == pytest.approx(10 * powers[2.0], rel=1e-9)  # red LED, γ = 1


def test_range_limit_tiny(tmp_path):
    o = range_limit.default_options(True).with_overrides(
        cameras=("logitech-c270",), yaws_deg=(0.0,), ranges_m=(3.0, 6.0), seeds=1, render=TINY
    )
    summary = range_limit.run(tmp_path, o, Execution(workers=1))
    _check_outputs(tmp_path, ("max_range",))
    rec = summary["max_range"][0]
    assert set(rec) >= {"camera", "beacon", "side", "yaw_deg", "max_range_m", "low_m", "high_m", "limiting_cause"}


def test_replication_grid_is_the_issues_grid_and_runs_tiny(tmp_path):
    full = replication.default_options(False)
    # V1/V2 × 4 colours × 1-10 m × 0-30° in 5° × 4 cameras × 0-5 sheets ± foam × 8 drives × 10 seeds
    assert len(replication.conditions(full)) * full.seeds == 2 * 4 * 10 * 7 * 4 * 12 * 8 * 10
    assert len(set(full.currents_mA)) == 8 and len(set(full.diffusers)) == 12
    o = replication.default_options(True).with_overrides(
        cameras=("logitech-c270",), ranges_m=(3.0, 6.0), yaws_deg=(0.0,), currents_mA=(2.0,), seeds=1, render=TINY
    )
    summary = replication.run(tmp_path, o, Execution(workers=1))
    _check_outputs(tmp_path, ("max_range",))
    assert len(summary["max_range"]) == len(o.diffusers)  # one camera, beacon and drive
    assert (tmp_path / "configurations.csv").is_file()


@pytest.mark.slow  # 53 s; test_validate_runs_every_test_at_each_calibrated_point covers validate by default
def test_validate_tiny(tmp_path, monkeypatch):
    pairs = validate.test_conditions(True)
    subset = [next(p for p in pairs if p[0] == "preliminary" and p[1]["side"] == "red")]
    subset += [next(p for p in pairs if p[0] == "range" and p[1]["range_m"] == 10.0)]
    subset += [next(p for p in pairs if p[0] == "primary")]
    subset += [next(p for p in pairs if p[0] == "weights")]
    monkeypatch.setattr(validate, "test_conditions", lambda quick: subset)
    monkeypatch.setattr(validate, "StudyOptions", _tiny_options)
    rows = validate.run(tmp_path, True, Execution(workers=1), seeds=1)
    table = pd.read_csv(tmp_path / "validation.csv")
    assert list(table.columns[:12]) == [
        "test",
        "camera",
        "beacon",
        "side",
        "environment",
        "range_m",
        "yaw_deg",
        "detected_fraction",
        "merged_or_lost_fraction",
        "colour_correct_fraction",
        "range_est_m",
        "yaw_est_deg",
    ]
    assert list(table.columns[12:]) == [
        "core_saturation", "thresholds", "weights", "rectification", "detected_low", "detected_high",
        "yaw_est_low", "yaw_est_high", "range_est_low", "range_est_high", "extra_blobs_fraction",
        "merged_fraction", "lost_fraction", "focus_distance_m_low", "focus_distance_m_high", "points",
    ]  # fmt: skip
    t6 = table[table.camera == "canon-t6-18mm"]
    assert (t6.focus_distance_m_low == 3.0).all() and (t6.focus_distance_m_high == 3.0).all()  # nominal, one point
    assert table[table.camera == "logitech-c270"].focus_distance_m_low.isna().all()  # fixed focus
    for cause in ("extra_blobs_fraction", "merged_fraction", "lost_fraction"):  # causes of missed frames only
        assert (table[cause] <= 1 - table.detected_fraction + 1e-9).all()
    assert (table.points == 1).all()  # no calibration: the unknowns at nominal, one point
    assert (table.detected_low <= table.detected_fraction).all() and (
        table.detected_fraction <= table.detected_high
    ).all()
    # the preliminary test once; the later tests with the study's and the derived thresholds; the weight
    # experiment (its first condition: 18 mm, 0°) as 2 weight sets × 3 rectifications
    assert len(rows) == len(table) == 1 + 2 * 2 + 2 * 6
    assert {(c["camera"], c["yaw_deg"]) for t, c in pairs if t == "weights"} == {
        (cam, y) for cam in ("canon-t6-18mm", "canon-t6-10mm") for y in (0.0, 30.0)
    }  # over yaw with both lenses (0° and 30° in the quick form)
    weights = table[table.test == "weights"]
    assert set(zip(weights.weights, weights.rectification, strict=True)) == {
        (w, r) for w in ("tuned", "equal") for r in ("none", "alpha 0", "alpha 1")
    }
    flux = pd.read_csv(tmp_path / "v1_vs_v2.csv")
    assert list(flux.beacon) == ["v1", "v2"] and flux.side_to_centre_flux[0] < 0.2 * flux.side_to_centre_flux[1]
    assert flux.side_to_centre_flux[1] > 0.5  # V2's side markers face the camera
    assert set(table.thresholds) == {"study", "derived"}
    derived = json.loads((tmp_path / "derived_thresholds.json").read_text())
    assert derived["red"] and not derived["blue"]  # only red was captured here
    verdicts = json.loads((tmp_path / "summary.json").read_text())["conclusions"]
    assert {v["thresholds"] for v in verdicts} == {"study", "derived"}
    assert all(v["simulation"] in ("agree", "disagree", "no evidence") for v in verdicts)
    assert any("QUEST weights" in v["conclusion"] for v in verdicts)


def test_validate_runs_every_test_at_each_calibrated_point(tmp_path, monkeypatch):
    space = unknowns_search.search_space()
    table = pd.DataFrame(sample(space, 2, seed=5)).assign(tuning_webcam="logitech-c270")  # one row per condition
    for c in unknowns_search.CONDITIONS:
        for side in ("red", "green", "blue", "yellow"):
            table[f"{c}_{side}"] = True
        table[f"consistent_{c}"] = True
    table["consistent"] = True
    table.to_csv(tmp_path / "samples.csv", index=False)
    # one webcam range condition: whole webcam frames are cheap (a T6 frame is 18 MP)
    webcam = next(p for p in validate.test_conditions(True) if p[0] == "range" and p[1]["camera"] in WEBCAMS)
    monkeypatch.setattr(validate, "test_conditions", lambda quick: [webcam])
    monkeypatch.setattr(validate, "StudyOptions", _tiny_options)
    monkeypatch.setattr(validate, "v1_vs_v2", lambda render: pd.DataFrame({"beacon": [], "side_to_centre_flux": []}))
    out = tmp_path / "out"
    validate.run(out, True, Execution(workers=1), seeds=1, calibration=tmp_path / "samples.csv")
    frames = pd.read_csv(out / "results.csv")
    assert sorted(set(frames.point)) == [0, 1]
    assert sorted(frames.led_current_mA.unique()) == pytest.approx(sorted(table.led_drive_v2_red))
    rows = pd.read_csv(out / "validation.csv")
    assert (rows.points == 2).all() and len(rows) == 2  # study and derived thresholds
    summary = json.loads((out / "summary.json").read_text())
    assert summary["calibrated_set"].startswith("2 of 2 points consistent at every close-range condition")


def test_validation_table_spans_the_calibrated_points():
    base = {
        "test": "primary", "thresholds": "study", "camera": "canon-t6-18mm", "beacon": "v2", "side": "red",
        "environment": "dark-room", "nominal_range_m": 3.0, "nominal_yaw_deg": 0.0, "weights": "tuned",
        "rectification": "none", "side_blobs": 5, "core_saturated_fraction_mean": 0.5, "yaw_est_deg": 1.0,
    }  # fmt: skip
    frames = [  # point 0: 4 of 4 detected, focused at 2 m; point 1: 1 of 4, at 40 m
        {**base, "point": p, "detected": d, "side_correct": d, "range_est_m": r if d else np.nan,
         "camera.effects.focus_distance_m": f}
        for p, ds, r, f in ((0, [True] * 4, 3.1, 2.0), (1, [True, False, False, False], 2.5, 40.0))
        for d in ds
    ]  # fmt: skip
    table = validate.validation_table(pd.DataFrame(frames))
    assert len(table) == 1
    row = table.iloc[0]
    assert row.points == 2 and row.detected_fraction == pytest.approx((1.0 + 0.25) / 2)
    assert row.detected_low == pytest.approx(wilson_interval(1, 4)[1])  # the worse point's lower bound
    assert row.detected_high == pytest.approx(wilson_interval(4, 4)[2])
    assert (row.range_est_low, row.range_est_high) == (2.5, 3.1)
    assert (row.focus_distance_m_low, row.focus_distance_m_high) == (2.0, 40.0)  # the lens focus over the points


def _tiny_options(**kw):
    from studies.engine.tasks import StudyOptions

    kw["render"] = TINY
    return StudyOptions(**kw)


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian's chromium is installed by scripts/setup.sh")
def test_report_renders_in_headless_chromium(tmp_path):
    playwright = pytest.importorskip("playwright.sync_api")
    o = range_limit.default_options(True).with_overrides(
        cameras=("logitech-c270",), yaws_deg=(0.0,), ranges_m=(3.0, 6.0), seeds=1, render=TINY
    )
    range_limit.run(tmp_path, o, Execution(workers=1))
    errors = []
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=shutil.which("chromium"),
            args=["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"],
        )
        page = browser.new_page()
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((tmp_path / "report.html").as_uri())
        images = page.eval_on_selector_all("img", "els => els.map(e => [e.complete, e.naturalWidth])")
        title = page.title()
        browser.close()
    assert title.startswith("Range limit")
    assert images and all(done and width > 0 for done, width in images)
    assert errors == []


def test_threshold_overlap_detection():
    from pipeline.thesis_tracker import ThesisTrackerSettings

    study = {c: [[list(lo), list(hi)] for lo, hi in b] for c, b in ThesisTrackerSettings().ranges().items()}
    # red and blue share hues but not saturations; the study's blue and green boxes do meet (H 84-85, S 64-143)
    assert validate.overlapping_colours(study) == ["blue/green"]
    wide = {"red": [[[0, 0, 100], [179, 255, 255]]], "green": [[[60, 50, 100], [80, 255, 255]]]}
    assert validate.overlapping_colours(wide) == ["green/red"]


def _fake_rows(tasks):
    """Rows as simulate_frame shapes them (text, None, bool, int, float, NaN), per task."""
    rows = []
    for t in tasks:
        sc, seed = t["scenario"], t["seed"]
        for tracker in ("thesis", "best"):
            r = sc["range_m"]  # all at 2 m, half at 5 m, none at 9 m: a finite logistic fit
            ok = tracker == "best" and (r < 4 or (r < 7 and seed % 2 == 0))
            rows.append(
                {
                    **sc,
                    "seed": seed,
                    "nominal_range_m": t["nominal"]["range_m"],
                    "tracker": tracker,
                    "detected": ok,
                    "side_correct": ok,
                    "numbering_correct": ok,
                    "side_detected": sc["side"] if ok else None,
                    "range_err_m": 0.01 * seed if ok else float("nan"),
                    "yaw_err_deg": 0.1 * seed if ok else float("nan"),
                    "reason": "" if ok else "red: 3 blob(s), 2 marker(s) lost or merged",
                }
            )
    return rows


def test_chunked_sweep_equals_one_sweep_and_rereads_only_chunk_tables(tmp_path, monkeypatch):
    from studies.engine import sweep as common
    from studies.engine import tables

    o = replication.default_options(True).with_overrides(ranges_m=(2.0, 5.0, 9.0), seeds=3)
    calls = []
    monkeypatch.setattr(
        common, "run_frames", lambda tasks, out, *args, **kw: calls.append(len(tasks)) or _fake_rows(tasks)
    )
    whole = common.sweep("x", replication.conditions(o), o, tmp_path / "whole")
    chunked = common.sweep_in_chunks("x", replication.chunks(o), o, tmp_path / "chunked")
    assert len(replication.chunks(o)) == 4 and sum(calls[1:]) == calls[0] == len(whole) // 2
    pd.testing.assert_frame_equal(whole, chunked, check_exact=True)
    # a re-run with every chunk stored reads 4 tables and runs no frame, and gives the same bytes
    before = (tmp_path / "chunked" / "results.parquet").read_bytes()
    calls.clear()
    again = common.sweep_in_chunks("x", replication.chunks(o), o, tmp_path / "chunked")
    assert calls == [] and (tmp_path / "chunked" / "results.parquet").read_bytes() == before
    pd.testing.assert_frame_equal(again, chunked, check_exact=True)
    # above CSV_MAX_ROWS only parquet is written, and an older CSV is removed
    monkeypatch.setattr(tables, "CSV_MAX_ROWS", 10)
    common.sweep_in_chunks("x", replication.chunks(o), o, tmp_path / "chunked")
    assert not (tmp_path / "chunked" / "results.csv").exists()
    assert len(pd.read_parquet(tmp_path / "chunked" / "results.parquet")) == len(whole)


def test_replication_max_range_fits_in_a_pool_equal_the_fits_in_process(tmp_path, monkeypatch):
    from studies.engine import sweep as common

    o = replication.default_options(True).with_overrides(
        cameras=("logitech-c270",), diffusers=((True, 1, "matched"),), ranges_m=(2.0, 5.0, 9.0), seeds=3
    )
    monkeypatch.setattr(common, "run_frames", lambda tasks, out, *args, **kw: _fake_rows(tasks))
    frame = common.sweep_in_chunks("x", replication.chunks(o), o, tmp_path)
    one, two = replication.max_range_table(frame, workers=1), replication.max_range_table(frame, workers=2)
    assert len(one) == 2 and np.all((one.max_range_m > 2) & (one.max_range_m < 9))  # one per drive
    pd.testing.assert_frame_equal(one, two, check_exact=True)


def test_colour_reach_spans_in_words_group_equal_spans():
    spans = {("clip", "matched"): (0.02, 200.0), ("clip", "white"): (0.02, 200.0), ("unclip", "white"): (20.0, 22.4)}
    words = validate._spans_in_words(spans, tried=6, levels=(0.01, 300.0))  # spans inside the exposures tried
    assert words == (
        "highlight clip, matched paper / highlight clip, white paper: 0.02-200× the clip level; "
        "highlight unclip, white paper: 20-22.4× the clip level"
    )
    assert validate._spans_in_words({("clip", "white"): (0.02, 200.0)}, tried=1, levels=(0.01, 300.0)) == (
        "every setting: 0.02-200× the clip level"
    )


def test_colour_reach_spans_at_the_ends_of_the_exposures_tried_say_so():
    ends = (0.02, 200.0)  # the lowest and highest exposure tried

    def say(span):
        return validate._spans_in_words({("clip", "white"): span}, tried=1, levels=ends)

    assert say((0.02, 200.0)) == "every setting: every exposure tried (0.02-200× the clip level)"
    assert say((0.02, 1.2)) == "every setting: up to 1.2× the clip level (from the lowest tried, 0.02×)"
    assert say((20.0, 200.0)) == "every setting: 20× the clip level and up (to the highest tried, 200×)"
    assert validate.LEVELS[0] == ends[0] and validate.LEVELS[-1] == ends[1]  # the default ends are the grid's


def test_degrees_in_words_say_no_detection_for_an_empty_mean():
    assert validate._degrees(21.716) == "21.72°"
    assert validate._degrees(float(pd.Series([], dtype=float).mean())) == "no detection"  # no frame detected


def test_a_calibrations_nroy_set_is_a_prediction_set(tmp_path):
    """validate --calibration nroy.csv: each point's own dimmer per V1 side, the primary side's for V2, and
    the primary test's side from the point; an empty NROY set or a foreign file is one line."""
    from studies.catalog import calibration, prediction_set

    space = calibration.search_space(calibration.load_observations())
    path = tmp_path / "nroy.csv"
    pd.DataFrame(sample(space, 3, seed=2)).to_csv(path, index=False)
    chosen = prediction_set.load(path, limit=2)
    assert chosen.source == prediction_set.CALIBRATION and len(chosen.points) == 2
    p0, p1 = chosen.points
    v1 = chosen.apply({"scenario": {"beacon": "v1", "side": "green", "camera": "logitech-c270"}, "seed": 0}, 0)
    assert v1["scenario"]["led_current_mA"] == pytest.approx(p0["led_drive_v1_green"])
    v2 = chosen.apply({"scenario": {"beacon": "v2", "side": "blue", "camera": "canon-t6-18mm"}, "seed": 0}, 1)
    assert v2["scenario"]["led_current_mA"] == pytest.approx(p1["led_drive_v2_primary"])
    assert v2["camera_overrides"]["effects.focus_distance_m"] == pytest.approx(p1["focus_distance"])
    assert chosen.primary_side(1) == p1["primary_test_side"] and validate.default_points(path) == 20
    pd.DataFrame(columns=list(space)).to_csv(path, index=False)
    with pytest.raises(ValueError, match="NROY set is empty"):
        prediction_set.load(path)
    pd.DataFrame({"x": [1.0]}).to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"expected a calibration's nroy\.csv .* missing column"):
        prediction_set.load(path)


def test_validate_uses_the_studys_per_session_morphology_only_where_it_says_so():
    """The 10 mm lens's erosion turned down from 4 m (1-3 iterations: spread over the points) and its close
    off at 5 m (docs/source-study.md §5.3); every other condition keeps the printed 5 closes and 4 erosions."""

    def task(camera, range_m):
        return {"scenario": {"camera": camera, "range_m": range_m}, "nominal": {"range_m": range_m}, "seed": 0}

    assert validate.session_settings(task("canon-t6-10mm", 4.0), None)["thesis_morphology"] == {"erode_iterations": 2}
    spread = [validate.session_settings(task("canon-t6-10mm", 4.0), p)["thesis_morphology"] for p in range(6)]
    assert [m["erode_iterations"] for m in spread] == [1, 2, 3, 1, 2, 3]
    assert validate.session_settings(task("canon-t6-10mm", 5.0), 0)["thesis_morphology"] == {
        "erode_iterations": 1,
        "close_iterations": 0,
    }
    for camera, range_m in (("canon-t6-10mm", 3.0), ("canon-t6-18mm", 5.0), ("logitech-c270", 10.0)):
        assert "thesis_morphology" not in validate.session_settings(task(camera, range_m), 1)


def test_conclusions_name_the_side_a_calibrated_point_chose_for_the_primary_test():
    """The table shows a point-chosen primary side as "primary"; the verdicts must use the side
    the frames showed (regression: the colour-reach note was asked for a side called "primary")."""
    base = {
        "thresholds": "study", "beacon": "v2", "environment": "dark-room", "weights": "tuned",
        "rectification": "none", "side_blobs": 2, "core_saturated_fraction_mean": 0.5, "yaw_est_deg": np.nan,
        "yaw_err_deg": np.nan, "range_est_m": np.nan, "failure": "lost", "side_correct": False, "detected": False,
        "side_of_test": None, "nominal_yaw_deg": 0.0,
    }  # fmt: skip
    frames = pd.DataFrame(
        [
            {**base, "test": "primary", "camera": "canon-t6-18mm", "side": "green", "side_of_test": "primary",
             "nominal_range_m": r}
            for r in (1.0, 5.0)
        ]
        + [{**base, "test": "range", "camera": "logitech-c270", "side": "red", "nominal_range_m": 5.0}]
    )  # fmt: skip
    table = validate.validation_table(frames)
    assert set(table[table.test == "primary"].side) == {"primary"}
    verdicts = validate.conclusions(table, frames)
    detected = next(v for v in verdicts if v["conclusion"].startswith("The DSLR (18 mm) detected"))
    assert detected["simulation"] == "disagree"  # no primary frame detected
    assert "renders the green LED" in detected["reason"] and "primary LED" not in detected["reason"]
    # the overlap check tests the shown side too: boxes where green meets blue (and nothing meets red)
    boxes = {
        "red": [((0, 200, 200), (5, 255, 255))],
        "green": [((50, 100, 100), (90, 255, 255))],
        "blue": [((80, 100, 100), (120, 255, 255))],
    }
    colours = next(v for v in validate.conclusions(table, frames, hsv=boxes) if v["conclusion"].startswith("…and"))
    assert "blue/green" in colours["reason"]


def test_derived_thresholds_pool_the_captures_of_each_colour():
    """validate's thresholds come from the preliminary captures' core histograms summed per colour;
    a colour with a capture whose cores held no pixel gets no box, one never captured none either."""
    rng = np.random.default_rng(6)
    green = [np.zeros((3, 256), np.int64) for _ in range(2)]
    for counts in green:
        counts[0] += np.bincount(rng.integers(55, 66, 400), minlength=256)
        counts[1] += np.bincount(rng.integers(150, 256, 400), minlength=256)
        counts[2] += np.bincount(rng.integers(100, 256, 400), minlength=256)
    rows = [{"side": "green", "hsv_histogram": c.tolist()} for c in green]
    rows += [{"side": "red", "hsv_histogram": green[0].tolist()}, {"side": "red", "hsv_histogram": None}]
    derived = validate.derive_thresholds(rows)
    assert derived["green"] == [[list(lo), list(hi)] for lo, hi in hsv_ranges_from_histogram(green[0] + green[1])]
    assert derived["red"] == [] and derived["blue"] == [] and derived["yellow"] == []
