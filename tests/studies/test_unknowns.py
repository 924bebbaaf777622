"""studies.engine.unknowns: the registry of inputs the source study did not give (studies/data/unknowns.toml),
its sampling, how a set of values becomes a frame task, camera overrides on the frame path, the CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import qmc

from camera_models.camera import load_camera, with_overrides
from pipeline.thesis_tracker import ThesisTrackerSettings
from scenes.scenario import RenderSettings, Scenario
from scenes.sourced import DataFileError
from studies.engine.frame import camera_with_overrides, capture_frame, frame_inputs
from studies.engine.unknowns import (
    KINDS,
    Unknown,
    apply,
    data_file_value,
    fixed,
    groups_of,
    load_unknowns,
    nominal,
    sample,
)

TINY = {"spp": 1, "oversampling": 1, "near_field_spp": 16, "crop": "target", "seed": 0}
REQUIRED = {
    "led_current_mA", "luminous_intensity_cd", "reduced_optical_depth", "sheet_transmittance",
    "lit_face_diameter_mm", "housing", "focus_distance_m", "f_number", "glare", "highlight", "noise_reduction",
    "max_exposure_s",
}  # fmt: skip


@pytest.fixture(scope="module")
def registry():
    return load_unknowns()


def test_every_entry_has_target_kind_nominal_and_a_reason(registry):
    assert len(registry) >= 12
    for name, u in registry.items():
        assert u.name == name and u.kind in KINDS
        assert u.target.split(".")[0] in ("scenario", "camera", "data", "tracker")
        assert u.provenance.startswith(("source: ", "assumed: ")) and len(u.provenance) > 40, name
        assert u.contains(u.nominal), name
        if u.kind in ("uniform", "loguniform"):
            assert u.low <= u.nominal <= u.high and u.low < u.high
        if u.kind == "choice":
            assert u.nominal in u.choices and len(u.choices) >= 2
    covered = {part for u in registry.values() for part in u.target.split(".")[-2:]}
    assert REQUIRED <= covered


def test_nominals_agree_with_the_data_files_and_the_camera_models(registry):
    """A data target's nominal is the data file's value; a camera target's nominal is each of its cameras'
    current value wherever the model has that field."""
    for u in registry.values():
        if u.namespace == "data":
            assert data_file_value(u.target) == pytest.approx(u.nominal), u.name
        if u.namespace == "camera":
            for cam in u.cameras or ("canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920"):
                obj = load_camera(cam)
                for key in u.path.split("."):
                    obj = getattr(obj, key, None)
                if obj is not None:
                    expected = pytest.approx(u.nominal) if isinstance(obj, float) else u.nominal
                    assert obj == expected, (u.name, cam)


@pytest.mark.parametrize("method", ["sobol", "lhs", "random"])
def test_samples_lie_within_bounds_and_repeat_per_seed(registry, method):
    a = sample(registry, 64, seed=7, method=method)
    assert a == sample(registry, 64, seed=7, method=method)
    assert a != sample(registry, 64, seed=8, method=method)
    assert len(a) == 64 and all(set(s) == set(registry) for s in a)
    for s in a:
        for name, value in s.items():
            assert registry[name].contains(value), (name, value)
    json.dumps(a)  # plain values: a task stays JSON-able
    for name, u in registry.items():
        if u.kind == "choice":
            assert {s[name] for s in a} == set(u.choices), name  # every choice is drawn


def test_sobol_mean_of_a_uniform_entry_is_its_midpoint(registry):
    uniform = [u for u in registry.values() if u.kind == "uniform"]
    assert uniform
    values = sample(registry, 256, seed=0)
    for u in uniform:
        mean = np.mean([s[u.name] for s in values])
        mid = (u.low + u.high) / 2
        assert abs(mean - mid) <= 0.02 * mid, u.name


def test_choices_apart_keeps_every_choice_split_its_own_and_each_column_a_sobol_column():
    """Sixteen points: with ``choices_apart`` no two of six two-choice unknowns move together (in a plain
    Sobol' design of 16 points they do: its halves split the points in only 8 ways), each choice still
    takes each share 8 times, and each number still has one point in each sixteenth of its range (a
    scrambled Sobol' column's stratification, which any of its dimensions keeps)."""
    choices = {f"c{i}": Unknown(f"c{i}", "scenario.housing", "choice", "a", choices=("a", "b")) for i in range(6)}
    numbers = {f"x{i}": Unknown(f"x{i}", "scenario.range_m", "uniform", 0.5, low=0.0, high=1.0) for i in range(4)}
    registry = {**numbers, **choices}
    apart = sample(registry, 16, seed=0, choices_apart=True)
    splits = [groups_of([p[name] for p in apart]) for name in choices]
    assert len(set(splits)) == len(splits)
    assert all(sorted(split).count(0) == 8 for split in splits)
    for name in numbers:
        assert sorted(int(p[name] * 16) for p in apart) == list(range(16)), name
    assert apart == sample(registry, 16, seed=0, choices_apart=True)
    with pytest.raises(ValueError, match=r"^choices_apart: works on the Sobol' sequence's dimensions"):
        sample(registry, 16, seed=0, method="lhs", choices_apart=True)
    plain = sample(numbers, 16, seed=3)  # without it: the sequence's first dimensions, as before
    q = qmc.Sobol(4, scramble=True, seed=3).random(16)
    assert np.allclose([[p[name] for name in numbers] for p in plain], q)
    wide = {f"c{i}": Unknown(f"c{i}", "scenario.housing", "choice", "a", choices=("a", "b")) for i in range(12)}
    crowded = sample(wide, 16, seed=0, choices_apart=True)
    assert len({groups_of([p[name] for p in crowded]) for name in wide}) == 8  # all the splits 16 points have


def test_fixed_and_nominal(registry):
    pinned = fixed(registry, led_drive=2.0, housing="white")
    assert pinned["led_drive"].kind == "fixed" and registry["led_drive"].kind == "loguniform"
    assert all(s["led_drive"] == 2.0 and s["housing"] == "white" for s in sample(pinned, 8, seed=1))
    assert nominal(pinned)["led_drive"] == 2.0 and nominal(registry)["led_drive"] == 20.0
    with pytest.raises(ValueError, match=r"led_drive=100 is outside 0.05-20 mA"):
        fixed(registry, led_drive=100)
    with pytest.raises(ValueError, match="no unknown 'nope'"):
        fixed(registry, nope=1)


def test_apply_sets_scenario_and_camera_fields_and_leaves_the_task_alone(registry):
    task = {"scenario": {"range_m": 2.0, "camera": "canon-t6-18mm"}, "render": dict(TINY), "seed": 0}
    before = json.dumps(task, sort_keys=True)
    values = {"led_drive": 1.5, "housing": "white", "f_number_18mm": 5.6, "f_number_10mm": 5.6,
              "webcam_max_exposure": 0.1, "highlight_mode": "blend", "lit_face_diameter": 12.0}  # fmt: skip
    out = apply(task, values, registry)
    assert json.dumps(task, sort_keys=True) == before
    assert out["scenario"] == {"range_m": 2.0, "camera": "canon-t6-18mm", "led_current_mA": 1.5, "housing": "white"}
    # 10 mm and webcam entries do not apply to the 18 mm camera; the data value at its nominal changes nothing
    assert out["camera_overrides"] == {"lens.f_number": 5.6, "isp.highlight": "blend"}
    assert out["render"] == task["render"] and out["seed"] == 0
    Scenario(**out["scenario"])  # still a valid scenario
    assert "camera_overrides" not in apply(task, {"led_drive": 1.0}, registry)
    # a data value off the file's goes into the scenario's data (a V1 entry does not touch a V2 task)
    data = apply(task, {"lit_face_diameter": 14.0, "lit_face_diameter_v1": 11.0, "led_intensity_red": 6.0}, registry)
    assert data["scenario"]["data"] == {"beacons.v2.lit_face_diameter_mm": 14.0, "leds.red.luminous_intensity_cd": 6.0}
    assert Scenario(**data["scenario"]).design.lit_face_diameter_m == pytest.approx(0.014)
    assert {u.acts for u in registry.values()} == {"gain", "render", "camera", "tracker"}
    assert registry["led_intensity_red"].acts == "gain" and registry["foam_optical_depth"].acts == "render"
    webcam = apply({"scenario": {"camera": "logitech-c270"}}, {"webcam_max_exposure": 0.1}, registry)
    assert webcam["camera_overrides"] == {"exposure.max_exposure_s": 0.1}


def test_a_tracker_setting_applies_only_to_its_lens_from_its_range(registry):
    """The study's per-session morphology (10 mm lens: erosion turned down from 4 m, close off at 5 m)
    reaches the task's tracker settings only on that lens at or beyond those nominal ranges."""
    values = {"erode_iterations_10mm_far": 1, "close_iterations_10mm_5m": 0}

    def morphology(camera: str, range_m: float):
        task = {"scenario": {"camera": camera, "range_m": range_m + 0.03}, "nominal": {"range_m": range_m}, "seed": 0}
        return apply(task, values, registry).get("thesis_morphology")

    assert morphology("canon-t6-10mm", 3.0) is None  # the jittered range does not decide, the nominal does
    assert morphology("canon-t6-10mm", 4.0) == {"erode_iterations": 1}
    assert morphology("canon-t6-10mm", 5.0) == {"erode_iterations": 1, "close_iterations": 0}
    assert morphology("canon-t6-18mm", 5.0) is None


def test_a_turned_down_erosion_keeps_markers_the_printed_one_deletes():
    """Discs 9 px tall vanish under the printed 4 erosions (13 px needed) and survive 2 (7 px needed):
    what a task's thesis_morphology does to the study's tracker on the same image."""
    import cv2

    from pipeline.angles import Intrinsics
    from pipeline.thesis_tracker import survivor_size, thesis_track
    from studies.engine.frame import _detectors
    from studies.engine.frame_task import FrameTask

    image = np.zeros((480, 640, 3), np.uint8)
    yy, xx = np.mgrid[0:480, 0:640]
    green = cv2.cvtColor(np.uint8([[(77, 100, 220)]]), cv2.COLOR_HSV2BGR)[0, 0]  # inside the study's green box
    for u in (200, 260, 320, 380, 440):
        image[(xx - u) ** 2 + (yy - 240) ** 2 <= 4.5**2] = green
    webcam = Intrinsics(600.0, 600.0, 319.5, 239.5, 640, 480)
    task = FrameTask(scenario={}, seed=0, trackers=["thesis"], thesis_morphology={"erode_iterations": 2})
    ((_, _, turned_down),) = list(_detectors(task))
    assert survivor_size(ThesisTrackerSettings())[1] == 13 and survivor_size(turned_down)[1] == 7
    count = [sum(b.colour == "green" for b in thesis_track(image, webcam, s).blobs) for s in (None, turned_down)]
    assert count == [0, 5]
    with pytest.raises(ValueError, match=r"task\.thesis_morphology\.min_area: expected one of"):
        FrameTask(scenario={}, seed=0, thesis_morphology={"min_area": 3})


def test_with_overrides_changes_exactly_the_named_field():
    camera = load_camera("canon-t6-18mm")
    changed = with_overrides(camera, {"lens.f_number": 5.6})
    assert camera.lens.f_number == 3.5 and changed.lens.f_number == 5.6
    assert changed.lens == type(camera.lens)(**{**camera.lens.__dict__, "f_number": 5.6})
    assert changed.sensor is camera.sensor and changed.isp is camera.isp and changed.exposure is camera.exposure
    assert with_overrides(camera, {}) is camera
    for path, message in [
        ("lens.no_such_field", r"'lens.no_such_field': LensModel has no field 'no_such_field'"),
        ("optics.f_number", r"'optics.f_number': Camera has no field 'optics'"),
        ("lens", r"'lens': names a part, not a field"),
        ("lens.f_number.x", r"float has no field 'x'"),
    ]:
        with pytest.raises(ValueError, match=message) as err:
            with_overrides(camera, {path: 1.0})
        assert "\n" not in str(err.value)


def test_bad_data_file_gives_one_line_naming_file_and_field(tmp_path):
    good = (
        'target = "scenario.housing"\nkind = "choice"\nchoices = ["black", "white"]\n'
        'assumed = "a reason long enough to count"\n'
    )
    cases = {
        '[a]\nnominal = "grey"\n' + good: r"bad\.toml: a\.nominal: 'grey' is outside black \| white",
        '[a]\nnominal = "black"\n' + good.replace("assumed", "note"): r"a\.note: unknown key",
        '[a]\nnominal = "black"\n' + good.replace("scenario.housing", "scenario.colour"): r"a\.target: 'colour' is not",
        '[a]\ntarget = "camera.lens.f_number"\nkind = "uniform"\nlow = 2\nhigh = 1\nnominal = 1.5\nsource = "x"\n': (
            r"a: needs exactly one of 'source' or 'assumed'"
        ),
        '[a]\ntarget = "camera.lens.f_number"\nkind = "loguniform"\nlow = 0\nhigh = 1\nnominal = 0.5\n'
        'source = "a reason long enough to count"\n': r"a\.low: a loguniform range needs low > 0",
        '[a]\ntarget = "data.leds.red.luminous_intensity_cd"\nkind = "fixed"\nnominal = 9.0\n'
        'source = "a reason long enough to count"\n': r"a\.nominal: 9\.0 differs from the data file's 5\.1",
        '[a]\ntarget = "data.beacons.v2.arm_length_mm"\nkind = "fixed"\nnominal = 70.0\n'
        'source = "a reason long enough to count"\n': r"a\.target: 'data\.beacons\.v2\.arm_length_mm' is not a value a "
        "scenario can replace",
        '[a]\ntarget = "tracker.thesis.min_area"\nkind = "fixed"\nnominal = 0\n'
        'source = "a reason long enough to count"\n': r"a\.target: expected tracker\.thesis\.<close_iterations\|",
        '[a]\ntarget = "tracker.thesis.erode_iterations"\nkind = "uniform"\nlow = 1\nhigh = 3\nnominal = 2\n'
        'source = "a reason long enough to count"\n': r"a: a tracker setting takes whole numbers >= 0",
        '[a]\ntarget = "tracker.thesis.erode_iterations"\nkind = "fixed"\nnominal = 2\nmin_range_m = -1\n'
        'source = "a reason long enough to count"\n': r"a\.min_range_m: expected a range in metres > 0, got -1",
    }
    for text, message in cases.items():
        path = tmp_path / "bad.toml"
        path.write_text(text)
        with pytest.raises(DataFileError, match=message) as err:
            load_unknowns(path)
        assert "\n" not in str(err.value)


def test_frame_path_applies_overrides_and_ignores_their_absence():
    task = {
        "scenario": {"range_m": 2.0, "yaw_deg": 10.0, "foam": True, "paper_sheets": 1, "paper_colour": "matched",
                     "led_current_mA": 2.0},
        "render": dict(TINY), "seed": 0, "exposure": {"iso": 6400, "exposure_s": 1 / 60},
    }  # fmt: skip
    assert frame_inputs(task)[1] is load_camera("canon-t6-18mm")  # no overrides: the very same camera
    assert frame_inputs({**task, "camera_overrides": {}})[1] is load_camera("canon-t6-18mm")
    darker = {**task, "camera_overrides": {"lens.f_number": 5.6}}
    assert frame_inputs(darker)[1].lens.f_number == 5.6
    black = load_camera("canon-t6-18mm").sensor.black_level_DN
    signal = [capture_frame(t).capture.raw.astype(float).sum() - black * capture_frame(t).capture.raw.size
              for t in (task, darker)]  # fmt: skip
    assert signal[1] < 0.6 * signal[0]  # (3.5 / 5.6)² = 0.39 of the light, plus vignetting change
    with pytest.raises(ValueError, match=r"'lens\.glare_fraction': LensModel has no field"):
        capture_frame({**task, "camera_overrides": {"lens.glare_fraction": 0.02}})
    with pytest.raises(ValueError, match=r"'geometry\.width_px': the geometry is fixed"):
        capture_frame({**task, "camera_overrides": {"geometry.width_px": 100}})


def test_cli_lists_the_unknowns():
    run = [sys.executable, "-m", "studies.cli", "unknowns"]
    listed = json.loads(subprocess.run([*run, "--json"], capture_output=True, text=True, check=True).stdout)
    assert [r["name"] for r in listed] == list(load_unknowns())
    assert {"target", "range", "nominal", "provenance", "acts"} <= set(listed[0])
    table = subprocess.run(run, capture_output=True, text=True, check=True).stdout.splitlines()
    assert table[0].split("\t")[:3] == ["name", "target", "range"] and len(table) == len(listed) + 1


def _other_value(u):
    """A value of ``u`` away from its nominal: another choice, or the bound farther from it."""
    if u.kind == "fixed":  # a setting the study states (e.g. its close off at 5 m): the nominal is the change
        return u.nominal
    if u.kind == "choice":
        return next(c for c in u.choices if c != u.nominal)
    return u.high if u.high - u.nominal >= u.nominal - u.low else u.low


def _walk(obj, path: str):
    for key in path.split("."):
        obj = getattr(obj, key)
    return obj


def test_every_unknown_is_settable_per_task_and_changes_what_it_acts_on(registry):
    """Each registry entry, set away from its nominal on a task of a camera (and beacon, and range) it
    applies to: a gain changes the scenario's light but not the scene a render is made of; a render
    entry changes the scene description (so the render key); a camera entry changes that field of the
    camera model; a tracker entry changes the study's tracker's settings and neither the scene nor
    the camera."""
    from scenes.assemble import scene_spec
    from studies.engine.frame import _detectors
    from studies.engine.frame_task import FrameTask

    seen = set()
    for u in registry.values():
        camera = u.cameras[0] if u.cameras else "canon-t6-18mm"
        beacon = u.path.split(".")[1] if u.path.startswith("beacons.") else "v2"
        housing = "white" if u.path.endswith("housing_transmittance.white") else "black"  # the finish it is of
        scenario = {
            "camera": camera,
            "beacon": beacon,
            "range_m": max(3.0, u.min_range_m or 0.0),
            "foam": True,
            "paper_sheets": 1,
            "housing": housing,
        }
        task = {"scenario": {**scenario, "paper_colour": "matched"}, "render": dict(TINY), "seed": 0}
        out = apply(task, {u.name: _other_value(u)}, registry)
        assert out != task, u.name
        before, after = (Scenario(**t["scenario"], render=RenderSettings(**TINY)) for t in (task, out))
        if u.acts == "camera" and u.path == "sensor.ssf_csv":  # a derived override: the curve it loads
            changed = camera_with_overrides(load_camera(camera), out["camera_overrides"])
            assert not np.array_equal(changed.sensor.qe_rgb, load_camera(camera).sensor.qe_rgb), u.name
        elif u.acts == "camera":
            changed = camera_with_overrides(load_camera(camera), out["camera_overrides"])
            assert _walk(changed, u.path) == _other_value(u) != _walk(load_camera(camera), u.path), u.name
        elif u.acts == "tracker":
            assert scene_spec(before) == scene_spec(after) and "camera_overrides" not in out, u.name
            (settings,) = [s for tracker, _, s in _detectors(FrameTask.coerce(out)) if tracker == "thesis"]
            field = u.path.split(".")[1]
            assert getattr(settings, field) == _other_value(u) != getattr(ThesisTrackerSettings(), field), u.name
        elif u.acts == "gain":
            assert before != after and before.without_gains() == after.without_gains(), u.name
            assert scene_spec(before) == scene_spec(after), u.name
        else:
            assert scene_spec(before) != scene_spec(after), u.name
        seen.add(u.acts if u.acts != "camera" else u.path.split(".")[0])
    assert {"gain", "render", "lens", "sensor", "isp", "effects", "tracker"} <= seen  # every kind
