"""The index decides: the rule on synthetic far limits and summaries with known answers, the
picture written with the same bytes for the same input, and what made each page stated."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import pytest

from studies.catalog import index
from studies.catalog.index import (
    BY_RANGE,
    BY_SEPARABILITY,
    CHOSEN,
    FIGURE_NAME,
    NONE,
    TIE,
    FarLimit,
    answers,
    decide,
    decision_yaw,
    far_limit_png,
    write_index,
)
from studies.engine import report
from studies.engine.report import Provenance, Report, page_context

A, B, C = "cam-a", "cam-b", "cam-c"
MADE_BY = Provenance(version="1.2.3", commit="abcdef123456", date="2030-01-02")


def _limit(cam, est, low, high, *, yaw=30.0, open_above=False, decided=True) -> FarLimit:
    text = "none" if est <= 0 else (f"≥ {est:g} m" if open_above else f"{est:g} m")
    hi = "> 20" if math.isinf(high) else f"{high:g}"
    return FarLimit(cam, yaw, est, low, high, open_above, decided, text, f"{low:g} to {hi} m", 20.0)


def _refuse(name):
    raise ValueError(f"non-standard JSON constant {name}")


def test_a_clear_winner_is_chosen_on_range():
    d = decide([_limit(B, 13, 10.6, 14.4), _limit(A, 18.9, 15.2, 19.9), _limit(C, 0, 0, 1.9)], {})
    assert (d.status, d.camera, d.broken_by, d.contenders) == (CHOSEN, A, BY_RANGE, (A,))
    assert [x.camera for x in d.limits] == [A, B, C]  # largest first


def test_overlapping_intervals_that_nothing_separates_cannot_choose():
    limits = [_limit(A, 14, 11, 17), _limit(B, 13, 10, 16), _limit(C, 6, 4, 8)]
    for seps in ({A: 30.0}, {A: 30.0, B: 30.0}, {A: math.inf, B: math.inf}, {}):  # B unmeasured, or equal
        d = decide(limits, seps)
        assert (d.status, d.camera, d.contenders) == (TIE, None, (A, B)), seps


def test_an_open_above_limit_beats_a_closed_one_below_its_lower_bound():
    open_a = _limit(A, 20, 16.5, math.inf, open_above=True)
    d = decide([_limit(B, 14, 11, 15.8), open_a], {})
    assert (d.status, d.camera, d.broken_by) == (CHOSEN, A, BY_RANGE)
    # open above it reaches every range past its lower bound: a closed limit above 16.5 m overlaps it, even one
    # whose estimate is larger (tried farther)
    d = decide([_limit(B, 19, 17, 19.9), open_a], {})
    assert d.status == TIE and set(d.contenders) == {A, B}
    # a non-finite bound stored as null (standard JSON) still reads as open above
    rec = {"camera": A, "yaw_deg": 30.0, "max_range_m": 20.0, "low_m": 16.5, "high_m": None, "at_least": True}
    assert FarLimit.from_record(rec).open_above and FarLimit.from_record(rec).high_m == math.inf


def test_a_tie_is_broken_by_colour_separability():
    limits = [_limit(A, 14, 11, 17), _limit(B, 13, 10, 16)]
    d = decide(limits, {A: 9.0, B: 61.0})
    assert (d.status, d.camera, d.broken_by) == (CHOSEN, B, BY_SEPARABILITY)  # the smaller estimate, better colours
    d = decide(limits, {A: math.inf, B: 61.0})  # perfect separation beats any finite distance
    assert (d.camera, d.broken_by) == (A, BY_SEPARABILITY)


def test_no_camera_working_is_not_a_choice_and_moves_to_a_yaw_where_one_works():
    assert decide([_limit(A, 0, 0, 1.9), _limit(B, 0, 0, 3.9)], {A: 50.0}).status == NONE
    assert decide([], {}).status == NONE
    limits = [_limit(A, 0, 0, 1.9), _limit(A, 7, 5, 8, yaw=0.0), _limit(B, 0, 0, 1.9)]
    assert decision_yaw(limits) == 0.0
    assert decision_yaw([_limit(A, 0, 0, 1.9), _limit(A, 0, 0, 1.9, yaw=0.0)]) == 30.0


def _range_record(cam, yaw, est, low, high, *, at_least=False, frames=60):
    hi = "> 20" if high is None else f"{high:g}"
    far = "none" if est <= 0 else (f"≥ {est:g} m" if at_least else f"{est:g} m")
    return {
        "camera": cam,
        "beacon": "v2",
        "side": "red",
        "led_current_mA": 2.0,
        "yaw_deg": yaw,
        "tracker": "best",
        "max_range_m": est,
        "low_m": low,
        "high_m": high,  # None: infinite, as standard JSON writes it
        "at_least": at_least,
        "limiting_cause": "signal-to-noise" if est > 0 else "colour",
        "frames": frames,
        "successes": frames - 3,
        "fitted_from_m": 2.0,
        "near_at_most": True,
        "near_limit_m": 2.0,
        "near_failures": 0,
        "nearest_tested_m": 2.0,
        "farthest_tested_m": 20.0,
        "working_range": f"≤ 2 m to {far}" if est > 0 else "none (0 of 18 frames correct)",
        "far_limit": far,
        "far_interval": f"{low:g} to {hi} m",
        "decision": f"{frames} frames: decided (interval within ±20 % of the limit)",
        "far_decided": True,
    }


def _separation(cam, d):
    return {
        "camera": cam,
        "led_current_mA": 2.0,
        "pairs": [{"pair": "green-red", "mahalanobis": d, "bayes_error": 1e-9, "delta_e_2000": 50.0}],
        "min_mahalanobis": d,
        "frames": 16,
        "detections": 16,
        "right_colour": 15,
    }


def _summaries(b_30=(13.0, 10.6, 14.4), seps=(61.0, 113.0)) -> dict:
    rl = {
        "study": "range-limit",
        "max_range": [
            _range_record(A, 0.0, 18.0, 15.0, 19.0),
            _range_record(A, 30.0, 16.0, 14.6, 18.0),
            _range_record(B, 0.0, 19.5, 17.2, None, at_least=False),
            _range_record(B, 30.0, *b_30),
            _range_record(C, 0.0, 7.0, 5.8, 7.5),
            _range_record(C, 30.0, 0.0, 0.0, 1.97),
        ],
    }
    wv = {
        "study": "webcam-vs-dslr",
        "colour_separability": [_separation(A, seps[0]), _separation(B, seps[1])],
        "ranking": [{"camera": B, "at_led_current_mA": 2.0, "far_limit": "≥ 10 m", "tied_on_range": [A]}],
        "yaws_deg": [0.0],
        "max_range": [{"camera": A, "farthest_tested_m": 10.0, "frames": 16}],
    }
    bd = {
        "study": "brightness-diffuser",
        "recommended": [
            {
                "camera": A,
                "side": "red",
                "window": "3 of 8 configurations",
                "led_current_mA": 2.0,
                "diffuser": "foam + 3 white sheets",
                "led_power_mW": 0.77,
                "side_power_mW": 3.9,
                "successes": 2,
                "frames": 2,
                "p_low": 0.34,
                "core_saturation": 0.0,
            }
        ],
        "configurations": [{"frames": 2}],
    }
    return {"range-limit": rl, "webcam-vs-dslr": wv, "brightness-diffuser": bd}


def test_the_first_line_names_the_camera_its_range_and_setting():
    result = answers(_summaries(), {A: "foam + 1 matched sheet", B: "foam + 1 matched sheet"})
    assert result["headline"] == (
        f"Use {A}: it works from ≤ 2 m to 18 m at 0° (95 %: 15 to 19 m) and to 16 m at 30° (95 %: 14.6 to 18 m), "
        "with the LED at 2 mA behind foam + 1 matched sheet on the red side; brightness-diffuser's window for it "
        "is 2 mA behind foam + 3 white sheets (0.77 mW per LED)."
    )
    assert result["verdict"][0] == result["headline"]
    assert [c["camera"] for c in result["cameras"]] == [A, B, C]  # the decision's order
    decision = json.loads(json.dumps(index.strict_json(result), allow_nan=False), parse_constant=_refuse)["decision"]
    assert (decision["status"], decision["camera"], decision["broken_by"], decision["tie"]) == (
        "chosen",
        A,
        "far limit",
        False,
    )
    assert decision["yaw_deg"] == 30.0 and decision["rule"].startswith("Rule: the camera with the largest far limit")
    assert decision["headline"] == result["headline"]
    # webcam-vs-dslr ranks B first on its own sweep: the page says why the decision differs
    assert result["agreement"].startswith(f"webcam-vs-dslr ranks {B} first on its own sweep (0° only, to 10 m;")


def test_overlapping_summaries_break_on_separability_or_say_they_cannot_choose():
    result = answers(_summaries(b_30=(15.0, 13.0, 17.0)))  # B's 30° interval overlaps A's; B separates better
    d = result["decision"]
    assert (d["status"], d["camera"], d["broken_by"], d["contenders"]) == ("chosen", B, "colour separability", [A, B])
    assert result["headline"].startswith(f"Use {B}: it works from ≤ 2 m to 19.5 m at 0°")
    assert "Chosen on colour" in result["headline"]
    result = answers(_summaries(b_30=(15.0, 13.0, 17.0), seps=(61.0, 61.0)))
    assert result["decision"]["status"] == "tie" and result["decision"]["camera"] is None
    assert result["headline"].startswith(f"The evidence cannot choose between {A} and {B}: their far limits at 30°")
    assert result["headline"].endswith("run with more frames.")


def _write(tmp_path: Path, summaries: dict) -> Path:
    for name, summary in summaries.items():
        (tmp_path / name).mkdir(parents=True, exist_ok=True)
        (tmp_path / name / "summary.json").write_text(json.dumps(summary))
    return tmp_path


def test_the_picture_is_written_beside_the_page_with_the_same_bytes(tmp_path):
    out = _write(tmp_path, _summaries())
    write_index(out, quick=True, made_by=MADE_BY)
    first = (out / FIGURE_NAME).read_bytes()
    assert first.startswith(b"\x89PNG") and b"Software" not in first and b"matplotlib" not in first
    assert f"src='{FIGURE_NAME}'" in (out / "index.html").read_text()
    write_index(out, quick=True, made_by=MADE_BY)
    assert (out / FIGURE_NAME).read_bytes() == first
    limits = [_limit(A, 16, 14, 18), _limit(B, 20, 16, math.inf, open_above=True), _limit(A, 18, 15, 19, yaw=0.0)]
    assert far_limit_png(limits, [A, B], B) == far_limit_png(limits, [A, B], B)
    assert far_limit_png(limits, [A, B], B) != far_limit_png(limits, [A, B], A)  # the chosen camera is marked


def test_the_page_and_answers_say_what_made_them(tmp_path):
    out = _write(tmp_path, _summaries())
    result = write_index(out, quick=True, made_by=MADE_BY)
    page = (out / "index.html").read_text()
    assert "quick form" in page and "beacon-sim 1.2.3, commit abcdef123456, 2030-01-02" in page
    assert page.index(f"Use {A}:") < page.index("Rule: ") < page.index(FIGURE_NAME)
    stored = json.loads((out / "answers.json").read_text(), parse_constant=_refuse)
    assert stored["provenance"] == MADE_BY.to_dict() == result["provenance"]
    assert stored["quick_form"] is True and stored["decision"]["camera"] == A
    # not a quick run: not said
    write_index(out, made_by=MADE_BY)
    assert "quick form" not in (out / "index.html").read_text()


def test_provenance_without_git_is_stated_without_error(monkeypatch):
    def no_git(*args, **kwargs):
        raise FileNotFoundError("git")

    report._commit.cache_clear()
    monkeypatch.setattr(subprocess, "run", no_git)
    try:
        made = report.provenance()
        assert made.commit is None and "commit unknown" in made.text() and made.version
    finally:
        report._commit.cache_clear()


def test_a_report_links_back_to_the_index_only_inside_a_main_job(tmp_path):
    rep = Report("a study")
    with page_context(quick=True, index_href="../index.html", provenance=MADE_BY):
        inside = rep.write(tmp_path / "in.html").read_text()
    outside = rep.write(tmp_path / "out.html").read_text()
    assert "href='../index.html'" in inside and "quick form" in inside
    assert "href=" not in outside and "quick form" not in outside and "beacon-sim" in outside


@pytest.mark.parametrize("missing", ["range-limit", "webcam-vs-dslr", "brightness-diffuser"])
def test_a_missing_study_still_gives_a_page(tmp_path, missing):
    summaries = {k: v for k, v in _summaries().items() if k != missing}
    result = write_index(_write(tmp_path, summaries), made_by=MADE_BY)
    if missing == "range-limit":
        assert result["headline"] == "No range-limit results: the index cannot say which camera to use."
        assert not (tmp_path / FIGURE_NAME).exists()
    else:
        assert result["decision"]["camera"] == A


def test_noise_plus_physics_intervals_reach_the_answers_and_the_first_line():
    """With --uncertainty, range-limit's records carry a noise + physics interval: answers.json keeps it
    beside the noise one, and the first line states both."""
    summaries = _summaries()
    physics = {"low": 9.1, "high": None, "rate": 1 - 2 / 17, "points": 16, "order": 1}
    for rec in summaries["range-limit"]["max_range"]:
        rec.update(far_physics=physics, far_interval_physics="9.1 m to ≥ the farthest tried (88 %, 16 points)")
    result = answers(summaries, {A: "foam + 1 matched sheet", B: "foam + 1 matched sheet"})
    assert "(95 %: 15 to 19 m; noise + physics: 9.1 m to ≥ the farthest tried (88 %, 16 points))" in result["headline"]
    chosen = next(c for c in result["decision"]["limits"] if c["camera"] == A)
    assert chosen["far_physics"] == physics and chosen["far_interval"] == "14.6 to 18 m"
    plain = answers(_summaries(), {A: "foam + 1 matched sheet", B: "foam + 1 matched sheet"})
    assert "noise + physics" not in plain["headline"] and "far_physics" not in plain["decision"]["limits"][0]


@pytest.mark.parametrize("suffix", ["parquet", "csv"])
def test_the_diffuser_named_is_the_nominal_runs_not_the_points_paper(tmp_path, suffix):
    """At points of the unknowns the paper's colour is an unknown (white here): the setting the
    first line names is the one the study ran, matched paper; without points every row counts."""
    import pandas as pd

    rows = {"camera": ["cam-a"] * 3, "foam": [True] * 3, "paper_sheets": [1] * 3}
    with_points = pd.DataFrame({**rows, "paper_colour": ["matched", "white", "white"], "point": [None, 0.0, 1.0]})
    plain = pd.DataFrame({**rows, "paper_colour": ["matched", "white", "white"]})
    both = "foam + 1 matched sheet or foam + 1 white sheet"
    for frame, expected in ((with_points, "foam + 1 matched sheet"), (plain, both)):
        path = tmp_path / f"results.{suffix}"
        frame.to_parquet(path) if suffix == "parquet" else frame.to_csv(path, index=False)
        assert index.range_limit_diffusers(tmp_path) == {"cam-a": expected}


def test_the_picture_draws_the_noise_plus_physics_interval_behind_the_noise_one():
    """A band from the points' k-th smallest to k-th largest far limit (to the arrow when open
    above), a dot at 0 for "none" at both ends, and the same in words beside each row."""
    from dataclasses import replace

    from matplotlib.text import Text

    physics = {"rate": 1 - 2 / 17, "points": 16, "order": 1}
    open_band = replace(_limit(A, 16, 14, 18), physics={**physics, "low": 4.5, "high": None})
    closed = replace(_limit(B, 20, 16, math.inf, open_above=True), physics={**physics, "low": 0.0, "high": 11.7})
    none = replace(_limit(C, 0, 0, 4), physics={**physics, "low": 0.0, "high": 0.0})
    fig = index.far_limit_figure([open_band, closed, none], [A, B, C], A)
    ax = fig.axes[0]
    bands = [line.get_xdata().tolist() for line in ax.get_lines() if line.get_linewidth() == 9]
    assert bands == [[4.5, 20 * 1.05], [0.0, 11.7]]
    dots = [line for line in ax.get_lines() if line.get_marker() == "o" and line.get_alpha() is not None]
    assert len(dots) == 1 and dots[0].get_xdata().tolist() == [0.0]
    words = [t.get_text() for t in ax.findobj(Text)]
    for text in ("with the unknowns 4.5 to ≥ 20 m", "with the unknowns none to 11.7 m", "with the unknowns none"):
        assert any(w.endswith(text) for w in words), text
    plain = index.far_limit_figure([_limit(A, 16, 14, 18)], [A], A)
    assert not [line for line in plain.axes[0].get_lines() if line.get_linewidth() == 9]


def test_the_run_time_says_when_it_includes_resumed_parts(tmp_path):
    out = _write(tmp_path, _summaries())
    text = lambda: (out / "index.html").read_text()  # noqa: E731
    write_index(out, elapsed_s=1234.4, made_by=MADE_BY)
    assert "Finished in 1234 s (a finished job" in text() and "resumed" not in text()
    write_index(out, elapsed_s=11452.0, made_by=MADE_BY, resumed=True)
    assert "Finished in 11452 s, with the interrupted parts this run resumed" in text()
    assert json.loads((out / "answers.json").read_text())["elapsed_s"] == 11452.0
