"""The calibration study: its observations file, the frame tasks a point becomes, and a history match
written, resumed and read back (the real frame path behind a planted simulator with a known answer)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.thesis_tracker import ThesisTrackerSettings, survivor_size
from scenes.sourced import DataFileError
from studies.catalog import calibration
from studies.engine.calibration import InputSpace, Settings
from studies.engine.frame_task import FrameTask


def test_the_observations_are_close_range_only_with_their_reasons():
    observed = calibration.load_observations()
    assert len(observed) == 36 and len({o.observation.name for o in observed}) == 36
    assert len({o.frame for o in observed}) == 12 and {o.output for o in observed} == set(calibration.OUTPUTS) - {
        "core_clipped"
    }
    # "found" bounds the near-miss measures: the closed regions at least as tall as the printed erosion needs
    heights = [o.observation for o in observed if o.output == "side_closed_height_px"]
    assert {(h.kind, h.z) for h in heights} == {("at_least", survivor_size(ThesisTrackerSettings())[1])}
    assert {o.side for o in observed if o.condition.startswith("t6-")} == {"primary"}
    ranges = {calibration.CONDITIONS[o.condition]["scenario"]["range_m"] for o in observed}
    assert ranges <= {0.15, 1.0}  # calibration data only: nothing at 2 m or beyond
    assert all(len(o.observation.obs_reason) > 10 and len(o.observation.disc_reason) > 10 for o in observed)
    assert {o.environment for o in observed if o.condition == "webcam-150mm"} == {"dark-room", "lit-room"}
    assert {o.yaw_deg for o in observed if o.condition.startswith("t6-")} == {0.0, 30.0}


FRAME = '[a]\ncondition = "webcam-150mm"\nside = "red"\nenvironment = "dark-room"\ndrive = "dimmed"\n'


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[a]\ncondition = "webcam-2m"\n', r"a\.side: missing|a\.condition"),
        ('[a]\ncolour = "red"\n', r"a\.colour: unknown key"),
        (
            '[a]\ncondition = "webcam-150mm"\nside = "red"\nenvironment = "dark-room"\ndrive = "dimmed"\n',
            r"a: no output",
        ),
        (
            FRAME + '[a.side_blobs]\nkind = "between"\nz = 5\nobs_sd = 1\ndisc_sd = 1\n'
            'obs_reason = "a reason of a sentence"\ndisc_reason = "a reason of a sentence"\n',
            r"a\.side_blobs\.kind: expected equal, at_least, at_most",
        ),
        (
            '[a]\ncondition = "webcam-150mm"\nside = "primary"\nenvironment = "dark-room"\ndrive = "dimmed"\n',
            r"a\.side",
        ),
    ],
)
def test_a_bad_observations_file_is_one_line(tmp_path, text, message):
    path = tmp_path / "obs.toml"
    path.write_text(text)
    with pytest.raises(DataFileError, match=message) as info:
        calibration.load_observations(path)
    assert "\n" not in str(info.value)


def test_a_point_becomes_frame_tasks_with_every_unknown_set():
    observed = calibration.load_observations()
    unknowns = calibration.search_space(observed)
    assert {"led_intensity_red", "raw_saturation_t6", "ssf_webcam", "focus_distance_10mm", "tuning_webcam"} <= set(
        unknowns
    )
    space = InputSpace.from_unknowns(unknowns)
    point = space.values(np.full((1, space.dim), 0.9))[0]
    tasks = calibration.tasks([point], observed, unknowns, seeds=2)
    assert len(tasks) == 2 * len({o.frame for o in observed})  # a frame's outputs share its frames
    webcam = [t for t in tasks if t["tags"]["observed"] == "webcam_150mm_green_lit"]
    assert len(webcam) == 2 and all(FrameTask.coerce(t).is_full_frame for t in webcam)
    sc = webcam[0]["scenario"]
    assert sc["camera"] == point["tuning_webcam"] and sc["environment"] == "lit-room" and sc["beacon"] == "v1"
    assert sc["led_current_mA"] == pytest.approx(point["led_drive_v1_green"])
    assert sc["data"]["leds.green.luminous_intensity_cd"] == pytest.approx(point["led_intensity_green"])
    assert sc["data"]["beacons.v1.lit_face_diameter_mm"] == pytest.approx(point["lit_face_diameter_v1"])
    t6 = next(t for t in tasks if t["tags"]["observed"] == "t6_10mm_1m_30deg")
    assert t6["scenario"]["side"] == point["primary_test_side"]  # the primary test's side is the point's
    assert t6["scenario"]["led_current_mA"] == pytest.approx(point["led_drive_v2_primary"])
    assert t6["scenario"]["yaw_deg"] == 30.0 and t6["exposure"]["iso"] == 6400
    assert t6["camera_overrides"]["effects.focus_distance_m"] == pytest.approx(point["focus_distance_10mm"])
    assert t6["camera_overrides"]["sensor.ssf_csv"] == point["ssf_t6"]


def test_a_history_match_is_written_resumed_and_recovers_a_planted_answer(tmp_path, monkeypatch):
    """A planted simulator behind the real space of the T6 + 18 mm's unknowns (22 dimensions): both
    observations see 2·(lit face − 10 mm), z = 5 with variance 0.09 + 1.0, so the lit face is not ruled
    out exactly where |2(l − 10) − 5| ≤ 3·√1.09: 10.93-14.07 mm, 63 % of its 10-15 mm range. The match
    finds that band among 21 inactive inputs, writes its record, and a second run resumes from it
    without simulating again."""
    wanted = ("t6_18mm_1m_0deg", "t6_18mm_1m_30deg")
    text = calibration.OBSERVATIONS_FILE.read_text()
    tables = text.split("\n[")
    kept = [t for t in tables[1:] if t.split("]")[0] in (*wanted, *(f"{w}.side_blobs" for w in wanted))]
    observations = tmp_path / "obs.toml"
    observations.write_text("".join("[" + t + "\n" for t in kept))
    assert [o.observation.name for o in calibration.load_observations(observations)] == [
        f"{w}.side_blobs" for w in wanted
    ]
    calls = []

    def planted(out, observed, unknowns, seeds, execution, render=None):
        def simulate(points):
            calls.append(len(points))
            return np.array([[2.0 * (p["lit_face_diameter"] - 10.0)] * len(observed) for p in points])

        return simulate

    monkeypatch.setattr(calibration, "simulator", planted)
    settings = Settings(n_per_wave=24, min_waves=3, max_waves=3, n_reference=512, n_restarts=1, seed=1)
    out = tmp_path / "match"
    result = calibration.run(out, settings=settings, seeds=1, observations=observations)
    assert len(result.waves) == 3 and sum(calls) >= 3 * 24 and result.space.dim > 20
    lit = np.array([v["lit_face_diameter"] for v in result.space.values(result.nroy_points)])
    half = 1.5 * np.sqrt(1.09)
    assert abs(lit.min() - (12.5 - half)) < 0.3 and abs(lit.max() - (12.5 + half)) < 0.3
    assert result.waves[-1].nroy_fraction == pytest.approx(2 * half / 5, abs=0.06)
    summary = json.loads((out / "summary.json").read_text(), parse_constant=pytest.fail)
    assert [w["wave"] for w in summary["waves"]] == [1, 2, 3] and summary["nroy_points"] == len(lit)
    assert (out / "nroy.csv").read_text().splitlines()[0].split(",") == list(result.space.names)
    table = calibration.input_table(result)
    assert table.input[0] == "lit_face_diameter"  # the one input the planted outputs depend on, ranked first
    assert float(table["share kept"][0]) == pytest.approx(2 * half / 5, abs=0.1)
    page = (out / "report.html").read_text()
    assert "Not ruled out (NROY)" in page and page.count("data:image/png") == 5
    before = len(calls)
    again = calibration.run(out, settings=settings, seeds=1, observations=observations)
    assert len(calls) == before and len(again.waves) == 3  # resumed: every wave was on record


def test_the_quick_form_renders_its_near_fields_with_fewer_samples():
    observed = calibration.load_observations()
    unknowns = calibration.search_space(observed)
    space = InputSpace.from_unknowns(unknowns)
    point = space.values(np.full((1, space.dim), 0.5))
    full = calibration.tasks(point, observed, unknowns, seeds=1)
    quick = calibration.tasks(point, observed, unknowns, seeds=1, render=calibration.QUICK_RENDER)
    assert {t["render"]["near_field_spp"] for t in full} == {1024}
    assert {t["render"]["near_field_spp"] for t in quick} == {256}
