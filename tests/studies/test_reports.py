"""Reports that answer and stay honest: a synthetic study with known outcomes, read back.

The three studies of the main job are given results tables with outcomes chosen by hand
(no rendering): a camera that works at every range tried, one that fails near the camera
on colour and whose fall-off is perfectly separated (every frame correct to 8 m, none from
10 m), cameras tied at the farthest range, a perfect colour separation and a known LED
recommendation. Their summary.json, report.html and the index are then read back and
their statements checked against what the outcomes imply.
"""

from __future__ import annotations

import html
import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import pytest

from scenes.led import led_for_side
from studies.catalog import brightness_diffuser, range_limit, webcam_vs_dslr
from studies.catalog.index import FIGURE_NAME, write_index
from studies.engine.report import PAGE_WIDTH_IN, Provenance, page_context
from studies.engine.tasks import StudyOptions

matplotlib.use("Agg")
import matplotlib.pyplot as plt

T6, T6_10, C270 = "canon-t6-18mm", "canon-t6-10mm", "logitech-c270"
CHROMA = {"red": (0.6, 0.3), "green": (0.2, 0.7)}


def _row(
    camera, side, range_m, outcome, *, yaw=0.0, current=2.0, tracker="best", seed=0, diffuser=(True, 1, "matched")
):
    """One frame × detector row. ``outcome``: "ok", "colour" (wrong side), "merged" (too few
    blobs), "faint" (nothing found) or "clipped" (cores saturated, nothing found)."""
    ok = outcome == "ok"
    detected = outcome in ("ok", "colour")
    other = "green" if side == "red" else "red"
    r, g = CHROMA[side]
    row = {
        "camera": camera,
        "beacon": "v2",
        "side": side,
        "environment": "dark",
        "led_current_mA": current,
        "nominal_yaw_deg": yaw,
        "yaw_deg": yaw,
        "nominal_range_m": range_m,
        "range_m": range_m,
        "seed": seed,
        "tracker": tracker,
        "estimator": "best",
        "foam": diffuser[0],
        "paper_sheets": diffuser[1],
        "paper_colour": diffuser[2],
        "detected": detected,
        "side_correct": ok,
        "numbering_correct": ok,
        "side_detected": side if ok else (other if outcome == "colour" else None),
        "range_err_m": 0.01 if ok else math.nan,
        "yaw_err_deg": 0.1 if ok else math.nan,
        "failure": "too-few-blobs" if outcome == "merged" else ("no-blobs" if outcome in ("faint", "clipped") else ""),
        "reason": outcome,
        "core_saturated_fraction_mean": 0.9 if outcome == "clipped" else 0.05,
        "marker_spacing_px": 40.0,
        "core_diameter_px": 5.0,
    }
    for i in range(1, 6):
        row[f"marker{i}_r_chroma"], row[f"marker{i}_g_chroma"] = r, g
        row[f"marker{i}_R"], row[f"marker{i}_G"], row[f"marker{i}_B"] = r, g, 1 - r - g
    return row


def _range_limit_frame() -> pd.DataFrame:
    rows = []
    for seed in range(3):
        for r in (2.0, 4.0, 6.0, 8.0, 10.0, 12.0):
            for yaw in (0.0, 30.0):
                rows.append(_row(T6, "red", r, "ok", yaw=yaw, seed=seed))
                c270 = "colour" if (r < 3 or yaw == 30.0) else ("ok" if r < 9 else "merged")
                rows.append(_row(C270, "red", r, c270, yaw=yaw, seed=seed))
                for cam in (T6, C270):
                    rows.append(_row(cam, "red", r, "faint", yaw=yaw, seed=seed, tracker="thesis"))
    return pd.DataFrame(rows)


def _webcam_frame() -> pd.DataFrame:
    rows = []
    rng = np.random.default_rng(0)
    for seed in range(2):
        for r in (2.0, 5.0, 7.0, 10.0):
            for side in ("red", "green"):
                for cam in (T6, T6_10):
                    for current in (2.0, 20.0):
                        for tracker in ("best", "thesis"):
                            outcome = "ok" if current == 2.0 and tracker == "best" else "clipped"
                            row = _row(cam, side, r, outcome, current=current, tracker=tracker, seed=seed)
                            if cam == T6_10:  # noisy colours: a finite separation
                                for i in range(1, 6):
                                    row[f"marker{i}_r_chroma"] += rng.normal(0, 0.05)
                                    row[f"marker{i}_g_chroma"] += rng.normal(0, 0.05)
                            rows.append(row)
    return pd.DataFrame(rows)


def _brightness_frame() -> pd.DataFrame:
    rows = []
    for seed in range(2):
        for cam in (T6, C270):
            for current in (2.0, 20.0):
                for diffuser in ((False, 0, "white"), (True, 3, "white")):
                    outcome = "ok" if current == 2.0 else "clipped"
                    row = _row(cam, "red", 5.0, outcome, current=current, seed=seed, diffuser=diffuser)
                    row["core_saturated_fraction_mean"] = 0.9 if (current == 20.0 or not diffuser[0]) else 0.05
                    rows.append(row)
    return pd.DataFrame(rows)


class _Tables(HTMLParser):
    """Every table of a page as header cells and body rows (cell text)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[dict] = []
        self._cell: list[str] | None = None
        self._row: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append({"header": [], "rows": []})
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append(("th:" if tag == "th" else "") + "".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            table = self.tables[-1]
            if all(c.startswith("th:") for c in self._row):
                table["header"] = [c[3:] for c in self._row]
            else:
                table["rows"].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _tables(path: Path) -> list[dict]:
    parser = _Tables()
    parser.feed(path.read_text())
    return parser.tables


def _text(path: Path) -> str:
    """A page's text, tags dropped, whitespace collapsed."""
    return html.unescape(re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", path.read_text())))


@pytest.fixture(scope="module")
def main_job(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("main-job")
    options = {
        range_limit: StudyOptions(cameras=(T6, C270), yaws_deg=(0.0, 30.0), ranges_m=(2.0, 4.0), currents_mA=(2.0,)),
        webcam_vs_dslr: StudyOptions(cameras=(T6, T6_10), sides=("red", "green"), currents_mA=(2.0, 20.0)),
        brightness_diffuser: StudyOptions(cameras=(T6, C270), currents_mA=(2.0, 20.0)),
    }
    frames = {
        range_limit: _range_limit_frame(),
        webcam_vs_dslr: _webcam_frame(),
        brightness_diffuser: _brightness_frame(),
    }
    with page_context(quick=True, index_href="../index.html", provenance=MADE_BY):
        for module, frame in frames.items():
            (out / module.NAME).mkdir()
            module.write_outputs(out / module.NAME, options[module], frame)
    write_index(out, elapsed_s=12.0, quick=True, made_by=MADE_BY)
    return out


MADE_BY = Provenance(version="9.8.7", commit="0123456789ab", date="2031-05-06")


def _summary(out: Path, name: str) -> dict:
    return json.loads((out / name / "summary.json").read_text())


def _record(summary: dict, camera: str, yaw: float) -> dict:
    return next(r for r in summary["max_range"] if r["camera"] == camera and r["yaw_deg"] == yaw)


def test_range_limit_states_the_working_interval_with_the_near_failures(main_job):
    summary = _summary(main_job, "range-limit")
    c270 = _record(summary, C270, 0.0)
    # colour failures at 2 m, correct 4-8 m, merged from 10 m: the likelihood is flat between the grid points, so
    # the limits are the middles of the gaps (3 m and 9 m)
    assert c270["near_limit_m"] == pytest.approx(3.0, abs=0.1) and c270["max_range_m"] == pytest.approx(9.0, abs=0.1)
    assert c270["working_range"] == "3 m to 9 m"
    assert (c270["near_failures"], c270["near_frames"], c270["near_cause"]) == (3, 3, "colour")
    assert c270["failures_nearer"] == "3 of 3 frames nearer than 4 m fail (colour)"
    assert c270["limiting_cause"] == "resolution / merging"
    # perfect separation with 3 frames a point: an interval, not a point; it cannot pass 10 m (0 of 3 correct there)
    assert c270["high_m"] - c270["low_m"] > 1.0 and c270["low_m"] < 8.0 and c270["high_m"] <= 10.0
    t6 = _record(summary, T6, 30.0)
    assert t6["at_least"] and t6["working_range"] == "≤ 2 m to ≥ 12 m" and t6["limiting_cause"] == "not reached by 12 m"
    assert t6["far_interval"] == "0 to > 12 m"  # 18 of 18 cannot show P ≥ 0.95
    assert _record(summary, C270, 30.0)["working_range"] == "none (0 of 18 frames correct)"
    text = _text(main_job / "range-limit" / "report.html")
    assert "at 0° it works 3 m to 9 m" in text and "3 of 3 frames nearer than 4 m fail (colour)" in text
    assert "≤ 2 m to ≥ 12 m" in text and "all frames correct" not in text
    assert "at 30° no frame is correct (failures: colour)" in text
    # the range points themselves, near failures included, are tabled with their cause
    points = next(t for t in _tables(main_job / "range-limit" / "report.html") if "range, m" in t["header"])
    i_range, i_fail = points["header"].index("range, m"), points["header"].index("failed (main cause: frames)")
    c270_2m = [r for r in points["rows"] if r[0] == C270 and r[i_range] == "2"]
    assert [r[i_fail] for r in c270_2m] == ["3 (colour: 3)", "3 (colour: 3)"]  # 0° and 30°


def test_webcam_vs_dslr_states_ties_and_a_perfect_separation(main_job):
    summary = _summary(main_job, "webcam-vs-dslr")
    ranking = {r["camera"]: r for r in summary["ranking"]}
    assert ranking[T6]["far_limit"] == ranking[T6_10]["far_limit"] == "≥ 10 m"
    assert ranking[T6]["tied_on_range"] == [T6_10] and ranking[T6]["rank"] == 1  # ranked by colour: perfect first
    sep = next(s for s in summary["colour_separability"] if s["camera"] == T6 and s["led_current_mA"] == 2.0)
    # standard JSON has no inf: the distance is null, and no_overlap says what it was
    assert sep["min_mahalanobis"] is None and sep["no_overlap"] and sep["pairs"][0]["bayes_error"] == 0.0
    assert webcam_vs_dslr.separability_text(sep).startswith("no overlap in any 1 pair among the sides run")
    noisy = next(s for s in summary["colour_separability"] if s["camera"] == T6_10 and s["led_current_mA"] == 2.0)
    # chromaticities 0.4 apart in r and g with σ = 0.05 each: d ≈ √(0.4² + 0.4²)/0.05 ≈ 11
    assert noisy["min_mahalanobis"] == pytest.approx(math.hypot(0.4, 0.4) / 0.05, rel=0.25)
    assert (sep["right_colour"], sep["detections"]) == (16, 16)
    text = _text(main_job / "webcam-vs-dslr" / "report.html")
    assert f"Tied on range: {T6}, {T6_10} all reach ≥ 10 m (the farthest range tried)" in text
    assert "at the datasheet current" not in text and "LED drive 2 and 20 mA" in text


def test_brightness_diffuser_recommends_the_known_setting_with_its_power(main_job):
    rec = {r["camera"]: r for r in _summary(main_job, "brightness-diffuser")["recommended"]}
    power = 1e3 * led_for_side("red").radiant_flux_W(2.0)
    for cam in (T6, C270):  # the bare LED clips its cores, 20 mA fails: foam + 3 sheets at 2 mA is the window
        assert (rec[cam]["led_current_mA"], rec[cam]["diffuser"]) == (2.0, "foam + 3 white sheets")
        assert rec[cam]["led_power_mW"] == pytest.approx(power)
        assert (rec[cam]["successes"], rec[cam]["frames"], rec[cam]["window"]) == (2, 2, "1 of 4 configurations")
    text = _text(main_job / "brightness-diffuser" / "report.html")
    assert f"2 mA behind foam + 3 white sheets: {power:.2g} mW per LED" in text


def test_index_answers_first(main_job):
    page = (main_job / "index.html").read_text()
    assert page.index('class="lead"') < page.index(FIGURE_NAME) < page.index("<table") < page.index("Reports</h2>")
    lead = _text(main_job / "index.html").split("Per camera")[0]
    # 18 of 18 correct cannot show P ≥ 0.95 (the T6's interval starts at 0 m), so it overlaps the C270's "none" at
    # 30°, and the C270's colours were not measured: the rule cannot choose, and says so
    assert (
        f"The evidence cannot choose between {T6} and {C270}: their far limits at 30° overlap "
        f"({T6} ≥ 12 m (95 %: 0 to > 12 m); {C270} none (95 %: < 2 m)) and colour separability does not break the "
        f"tie ({T6} perfect, {C270} not measured): run with more frames." in lead
    )
    assert "Rule: the camera with the largest far limit at the largest yaw tried (30°;" in lead
    answers = json.loads((main_job / "answers.json").read_text())
    assert answers["decision"]["status"] == "tie" and answers["decision"]["camera"] is None
    assert answers["decision"]["contenders"] == [T6, C270]
    c270 = next(c for c in answers["cameras"] if c["camera"] == C270)
    assert "3 of 3 frames nearer than 4 m fail (colour)" in c270["near_yaw"]
    assert c270["limit"] == "0°: resolution / merging beyond 9 m; colour nearer than 4 m; 30°: colour at every range"
    table = _tables(main_job / "index.html")[0]
    assert table["header"] == [
        "camera",
        "working range at 0° (range-limit)",
        "working range at 30° (range-limit)",
        "LED drive and diffuser (brightness-diffuser)",
        "colour separability (webcam-vs-dslr)",
        "what limits it (range-limit)",
    ]
    rows = {r[0]: r for r in table["rows"]}
    assert [r[0] for r in table["rows"]] == [T6, C270, T6_10]
    assert (
        "far limit 95 % interval: 0 to > 12 m" in rows[T6][1]
        and "range-limit: V2 red side, 2 mA, 18 frames" in rows[T6][1]
    )
    # one source per column: the T6 10 mm, which range-limit did not sweep, has no range from webcam-vs-dslr
    assert rows[T6_10][1] == rows[T6_10][2] == "not in range-limit"
    assert rows[T6][4].endswith("webcam-vs-dslr: green and red sides, 2 mA, 16 frames")
    assert rows[T6][3].endswith("brightness-diffuser: red side") and rows[C270][4] == "not in webcam-vs-dslr"
    links = re.findall(r"href='([^']+)'", page)
    assert links == ["range-limit/report.html", "brightness-diffuser/report.html", "webcam-vs-dslr/report.html"]


@pytest.mark.parametrize(
    "page", ["index.html", "range-limit/report.html", "webcam-vs-dslr/report.html", "brightness-diffuser/report.html"]
)
def test_every_page_says_what_made_it(main_job, page):
    text = _text(main_job / page)
    assert "quick form" in text and "beacon-sim 9.8.7, commit 0123456789ab, 2031-05-06" in text
    links = re.findall(r"href='([^']+)'", (main_job / page).read_text())
    assert ("../index.html" in links) == (page != "index.html")  # every report links back to the index


@pytest.mark.parametrize(
    "page", ["index.html", "range-limit/report.html", "webcam-vs-dslr/report.html", "brightness-diffuser/report.html"]
)
def test_every_table_row_and_column_is_labelled(main_job, page):
    tables = _tables(main_job / page)
    assert tables
    for table in tables:
        assert table["header"] and all(h and not h.startswith("Unnamed") for h in table["header"])
        for row in table["rows"]:
            assert len(row) == len(table["header"]) and row[0] not in ("", "–")


def test_no_interval_has_zero_width(main_job):
    for name in ("range-limit", "webcam-vs-dslr"):
        for rec in _summary(main_job, name)["max_range"]:
            if rec["max_range_m"] > 0:
                assert rec["high_open"] or rec["high_m"] > rec["low_m"], rec  # open above: null in JSON


def test_every_curve_has_its_own_style(main_job):
    frame = _webcam_frame()
    options = StudyOptions(cameras=(T6, T6_10), sides=("red", "green"), currents_mA=(2.0, 20.0))
    fig = webcam_vs_dslr._curves_figure(plt, frame, options)
    for ax in fig.axes:
        series = {c.get_label(): c.lines[0] for c in ax.containers if c.get_label().startswith("canon")}
        styles = {label: (line.get_marker(), line.get_linestyle(), line.get_color()) for label, line in series.items()}
        assert len(set(styles.values())) == len(styles) == 2
        # equal curves (both cameras correct everywhere) are offset sideways, so neither hides the other
        first, second = (tuple(line.get_xdata()) for line in series.values())
        assert first != second
    plt.close(fig)


def test_heat_map_numbers_are_legible(main_job):
    table = brightness_diffuser.configuration_table(_brightness_frame())
    g = table[(table.tracker == "best") & (table.camera == T6)]
    fig = brightness_diffuser._heat_maps(plt, g, set())
    width, _ = fig.get_size_inches()
    assert width <= PAGE_WIDTH_IN  # shown unscaled: 11 pt stays 11 pt (≈ 15 px)
    numbers = [t for ax in fig.axes for t in ax.texts]
    assert numbers and min(t.get_fontsize() for t in numbers) >= 10
    assert {t.get_text() for t in fig.axes[0].texts} == {"2/2", "0/2"}  # the frames behind each fraction
    plt.close(fig)


def test_answers_json_is_standard_json(main_job):
    """No bare NaN or Infinity (not JSON, RFC 8259): a limit not measured or open above is null."""

    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    answers = json.loads((main_job / "answers.json").read_text(), parse_constant=refuse)
    assert answers["cameras"]
