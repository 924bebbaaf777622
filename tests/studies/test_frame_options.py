"""Frame-task options of the study's weight and rectification experiments reach the detector."""

from __future__ import annotations

import numpy as np
import pytest

from camera_models.camera import load_camera
from pipeline.angles import Intrinsics
from pipeline.detect import detect
from pipeline.thesis_pose import EQUAL_WEIGHTS, STUDY_WEIGHTS
from scenes.scenario import Scenario
from scenes.view import camera_geometry, project
from studies.engine.frame import detect_options, noise_seed
from studies.engine.frame_task import FrameTask
from tests.helpers.synthetic import draw_markers


def test_task_options_become_detector_options():
    camera = load_camera("canon-t6-18mm")

    def options(**fields):
        return detect_options(FrameTask(scenario={}, seed=0, **fields), camera)

    assert options() == {}
    assert options(quest_weights="equal")["quest_weights"] == EQUAL_WEIGHTS
    rect = options(rectification={"alpha": 1})
    assert rect["alpha"] == 1.0 and rect["calibration"].width_px == 5184
    with pytest.raises(ValueError, match=r"^quest_weights: expected one of tuned, equal"):
        options(quest_weights="heavy")


def test_a_frame_task_round_trips_its_plain_form_and_names_a_misspelt_field():
    plain = {"scenario": {"range_m": 4.0}, "render": {"spp": 2}, "seed": 3, "full_frame": False, "trackers": ["best"]}
    task = FrameTask.coerce(plain)
    assert task.to_dict() == plain and not task.is_full_frame and task.with_noise
    assert noise_seed(task) == noise_seed(plain)  # the same noise from either form
    with pytest.raises(ValueError, match=r"^task\.full_fram: not a frame-task field \(did you mean 'full_frame'\?\)$"):
        FrameTask.coerce({**plain, "full_fram": True})
    with pytest.raises(ValueError, match=r"^task\.seed: expected an integer >= 0, got -1$"):
        FrameTask.coerce({**plain, "seed": -1})
    with pytest.raises(ValueError, match=r"^task\.trackers: expected a list of names, got 'best'$"):
        FrameTask.coerce({**plain, "trackers": "best"})


def test_equal_and_tuned_weights_give_different_study_attitudes_on_the_same_markers():
    """Same five marker pixels, the study's chain: the weights change only QUEST's answer."""
    sc = Scenario(camera="logitech-c270", range_m=1.5, yaw_deg=20.0)
    g = camera_geometry(sc.camera)
    uv = project(g, sc.camera_pose(), sc.marker_positions_world_m())
    image = draw_markers((g.height_px, g.width_px), uv, (1.0, 1.0, 1.0), 2.0, peak=1.0)
    intr = Intrinsics.from_geometry(g)
    tuned = detect(image, intr, tracker="best", estimator="thesis", quest_weights=STUDY_WEIGHTS)
    equal = detect(image, intr, tracker="best", estimator="thesis", quest_weights=EQUAL_WEIGHTS)
    assert tuned.pose is not None and equal.pose is not None
    assert tuned.pose.range_m == pytest.approx(equal.pose.range_m)  # inverse perspective: no weights
    assert not np.allclose(tuned.pose.quaternion_wxyz(), equal.pose.quaternion_wxyz())


def test_defocus_and_glare_switches_reach_the_capture(mitsuba_variant):
    """T6 + 18 mm, V2 red at 5 m: focused at 1 m the markers' over-exposed images grow (blur circle
    f²/(N(s−f))·|d−s|/d ≈ 17.6 px), and the glare tail lights pixels between them; without
    overrides the frame is the plain path's."""
    from studies.engine.frame import capture_frame

    task = {
        "scenario": {"beacon": "v2", "side": "red", "range_m": 5.0, "yaw_deg": 0.0, "camera": "canon-t6-18mm",
                     "environment": "dark", "led_current_mA": 20.0},
        "render": {"spp": 1, "oversampling": 1, "crop": "target", "near_field_spp": 16},
        "seed": 0,
    }  # fmt: skip

    def bright_pixels(overrides: dict) -> int:
        image = capture_frame({**task, "camera_overrides": overrides} if overrides else task).image_bgr
        return int((image.max(axis=2) >= 96).sum())

    plain = bright_pixels({})
    assert bright_pixels({"effects.focus_distance_m": 1.0}) > 2 * plain
    assert bright_pixels({"effects.glare": True}) > 2 * plain


def test_noise_seed_is_one_per_frame_and_shared_by_what_only_scores_it():
    """Frames that differ in what the camera sees draw independent noise; the detectors run,
    the tags and the camera path (reference or fast) do not change a frame's noise seed."""
    from studies.engine.frame import noise_seed

    base = {"scenario": {"range_m": 4.0, "yaw_deg": 0.0, "camera": "logitech-c270"}, "seed": 0, "full_frame": True}
    seeds = {
        noise_seed(base),
        noise_seed({**base, "seed": 1}),
        noise_seed({**base, "scenario": {**base["scenario"], "range_m": 5.0}}),
        noise_seed({**base, "exposure": {"iso": 800}}),
        noise_seed({**base, "camera_overrides": {"lens.f_number": 5.6}}),
        noise_seed({**base, "full_frame": False}),
    }
    assert len(seeds) == 6 and all(0 <= s < 2**63 for s in seeds)
    same = {"trackers": ["thesis"], "estimators": ["best"], "tags": {"test": "x"}, "reference_camera": True}
    assert noise_seed({**base, **same}) == noise_seed(base)


def test_a_tag_that_would_shadow_a_row_field_is_refused_before_any_work(monkeypatch):
    """A tag named like a row field (``frame``: full or crop) would silently replace it, or be replaced."""
    from studies.engine import frame

    monkeypatch.setattr(frame, "capture_frame", lambda task: pytest.fail("rendered before the check"))
    with pytest.raises(ValueError, match=r"tags\.frame: a row field"):
        frame.simulate_frame({"scenario": {"range_m": 2.0}, "seed": 0, "tags": {"frame": "webcam_150mm_red_dark"}})


def _two_beacons(**others_fields):
    base = {"beacon": "v2", "side": "red", "camera": "canon-t6-18mm", "environment": "dark", "led_current_mA": 2.0}
    a = {**base, "range_m": 5.0, "pan_deg": 4.0}  # appears left of centre
    b = {**base, "side": "green", "range_m": 7.0, "yaw_deg": 20.0, "pan_deg": -3.0, **others_fields}  # right
    plain = {"render": {"spp": 1, "oversampling": 1, "near_field_spp": 64}, "seed": 0, "full_frame": True,
             "noise": False, "exposure": {"iso": 400, "exposure_s": 1 / 60}, "trackers": ["best"]}  # fmt: skip
    return a, b, plain


def test_a_frame_with_two_beacons_is_the_sum_of_each_alone():
    """Light is linear: a noise-free whole frame holding beacons A and B has, on top of the black
    level, the electrons of A's frame plus B's (raw DN within 1 of the sum, rounding), and B's light
    falls where B's own frame puts it."""
    from studies.engine.frame import capture_frame

    a, b, plain = _two_beacons()
    both = capture_frame({**plain, "scenario": a, "others": [b]}).capture.raw.astype(np.int64)
    only_a = capture_frame({**plain, "scenario": a}).capture.raw.astype(np.int64)
    only_b = capture_frame({**plain, "scenario": b}).capture.raw.astype(np.int64)
    black = int(load_camera("canon-t6-18mm").sensor.black_level_DN)
    assert np.abs(both - (only_a + only_b - black)).max() <= 1
    lit_b = only_b - black > 50
    assert lit_b.sum() > 20 and not (only_a - black > 50)[lit_b].any()  # B's markers, away from A's
    assert (both - only_a)[lit_b].min() > 40


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"full_frame": False}, r"^task\.others: further beacons need a whole frame"),
        ({"others_env": "lit-room"}, r"^task\.others: further beacons only where the LEDs alone light the room"),
        ({"others_camera": "logitech-c270"}, r"^task\.others\[0\]\.camera: expected the frame's own"),
        ({"others_bad": True}, r"^task\.others: expected a list of tables of Scenario fields"),
    ],
)
def test_further_beacons_are_refused_in_one_line_where_they_cannot_be_added(change, message):
    from studies.engine.frame import capture_frame

    a, b, plain = _two_beacons()
    task = {**plain, "scenario": a, "others": [b]}
    if "full_frame" in change:
        task["full_frame"] = False
    if "others_env" in change:
        task["scenario"] = {**a, "environment": "lit-room"}
        task["others"] = [{**b, "environment": "lit-room"}]
    if "others_camera" in change:
        task["others"] = [{**b, "camera": "logitech-c270"}]
    if "others_bad" in change:
        task["others"] = b
    with pytest.raises(ValueError, match=message):
        capture_frame(task)


def test_further_beacons_draw_their_own_noise_and_leave_every_other_seed_as_it_was():
    """The noise seed of a task without ``others`` is the SHA-256 of its seed and its six mean-image
    fields, as before further beacons existed (stored frames and reruns agree); a task with them
    draws other noise."""
    import hashlib
    import json

    from studies.engine.frame import NOISE_SEED_FIELDS

    a, b, plain = _two_beacons()
    task = {**plain, "scenario": a}
    what = [
        0,
        {k: task.get(k) for k in ("scenario", "render", "exposure", "full_frame", "align_px", "camera_overrides")},
    ]
    before = int.from_bytes(hashlib.sha256(json.dumps(what, sort_keys=True).encode()).digest()[:8], "little") >> 1
    assert "others" not in NOISE_SEED_FIELDS and noise_seed(task) == before
    assert noise_seed({**task, "others": [b]}) != before


def test_scoring_variants_of_one_frame_share_its_capture_and_give_the_same_rows(monkeypatch, mitsuba_variant):
    """The weight experiment's detector variants of one frame (weights × rectification) follow one
    another in a worker: they are captured once and give the rows each gives alone."""
    from studies.engine import frame

    task = {
        "scenario": {"beacon": "v2", "side": "red", "range_m": 1.0, "yaw_deg": 10.0, "camera": "canon-t6-18mm",
                     "environment": "dark", "led_current_mA": 2.0},
        "render": {"spp": 1, "oversampling": 1, "crop": "target", "near_field_spp": 16},
        "seed": 0, "trackers": ["thesis"], "estimators": ["thesis"],
    }  # fmt: skip
    variants = [
        {**task, "quest_weights": w, "tags": {"weights": w}, **({"rectification": r} if r else {})}
        for w in ("tuned", "equal")
        for r in (None, {"alpha": 1.0})
    ]
    captures = []
    captured = frame.capture_frame
    monkeypatch.setattr(frame, "capture_frame", lambda t: captures.append(t) or captured(t))

    def rows(t: dict) -> list[dict]:
        return [
            {k: v for k, v in r.items() if k not in ("frame_s", "worker_peak_rss_MiB")} for r in frame.simulate_frame(t)
        ]

    frame._last_frame.clear()
    shared = [rows(t) for t in variants]
    assert len(captures) == 1
    alone = []
    for t in variants:
        frame._last_frame.clear()
        alone.append(rows(t))
    assert len(captures) == 1 + len(variants)
    assert shared == alone
    (tuned, tuned_rectified, equal, _) = (r[0] for r in shared)
    assert tuned["detected"] and tuned["yaw_est_deg"] != equal["yaw_est_deg"]  # the weights change QUEST's answer
    assert tuned_rectified["reason"] != tuned["reason"]  # the rectified image is tracked on its own
    rows({**task, "seed": 1})  # another frame: captured anew
    assert len(captures) == 2 + len(variants)
