"""beacon-sim sensitivity on fake frames of a planted truth: the unknown that moves the far limit is
ranked first, the run says how it got there, and the command refuses bad input in one line."""

from __future__ import annotations

import json

import pytest

from studies.catalog import prediction_set, sensitivity
from studies.engine import sequential
from studies.engine.sensitivity import aliased_inputs
from tests.helpers.planted_frames import planted_rows, red_bin


def test_the_planted_unknown_is_the_one_to_measure_first(monkeypatch, tmp_path):
    """The far limit moves 3 m per candela of the red LEDs' bin and with nothing else."""
    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda t: 8.0 + 3.0 * (red_bin(t) - 5.1)))
    setting = sensitivity.Setting(camera="canon-t6-18mm", side="red")
    summary = sensitivity.run(tmp_path, setting, points=24, calibration=None, quick=True)
    far = summary["analyses"]["far_limit_m"]
    st = dict(zip(far["sobol"]["inputs"], far["sobol"]["st"], strict=True))
    assert (
        max(st, key=st.get) == "led_intensity_red"
        and st["led_intensity_red"] > 0.8
        and all(v < 0.1 for k, v in st.items() if k != "led_intensity_red")
    )
    assert far["sentences"][0].startswith("measure led_intensity_red")
    assert "on an emulator of 24 runs" in far["emulator"]
    record = json.loads((tmp_path / "sensitivity.json").read_text())
    assert record["points"] == 24 and len(record["outputs"]) == 24
    assert (tmp_path / "range-limit" / "results.parquet").is_file()
    design = json.loads((tmp_path / "range-limit" / "summary.json").read_text())["design"]
    cap = sensitivity.UNIT_BUDGET_GRIDS * 4 * 2  # the quick grid: 4 ranges × 2 seeds
    assert design["design"]["unit_budget_frames"] == cap and max(u["frames"] for u in design["units"]) <= cap
    page = (tmp_path / "report.html").read_text()
    figures = sum("sobol" in a for a in summary["analyses"].values())  # one chart per ranked output
    assert page.count("data:image/png;base64,") == figures >= 1 and "Share of the variance of the far limit" in page


def test_only_unknowns_that_act_on_the_camera_and_beacon_are_ranked():
    space, acting = sensitivity.acting_space(
        sensitivity.Setting(camera="logitech-c270", beacon="v1"),
        ["f_number_18mm", "webcam_max_exposure", "lit_face_diameter", "lit_face_diameter_v1", "led_intensity_red"],
    )
    assert set(space.names) == {"webcam_max_exposure", "lit_face_diameter_v1", "led_intensity_red"}
    assert set(acting) == set(space.names)


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--camera", "no-such-camera"], "camera"),
        (["--camera", "logitech-c270", "--points", "3"], "points"),
        (["--camera", "logitech-c270", "--yaw-deg", "120"], "yaw-deg"),
    ],
)
def test_bad_input_is_refused_in_one_line_before_any_work(monkeypatch, tmp_path, args, field):
    from tests.helpers.cli import assert_one_line_error, invoke, patch_work

    patch_work(monkeypatch)
    code, _, err = invoke(["sensitivity", "--out", str(tmp_path / "o"), *args])
    assert_one_line_error(code, err, field)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("camera", ["canon-t6-18mm", "logitech-c270"])
def test_the_points_keep_the_cameras_choices_apart(camera):
    """16 registry points: no two choices acting on the camera and beacon move together (the plain Sobol'
    design of the 2026-12 runs aliased housing and paper colour for both cameras)."""
    for apart, expected in ((False, (("paper_colour", "housing"),)), (True, ())):
        physics, _ = prediction_set.physics_points(16, seed=0, calibration=None, choices_apart=apart)
        space, _ = sensitivity.acting_space(sensitivity.Setting(camera=camera), list(physics[0]))
        q = space.to_unit([{name: p[name] for name in space.names} for p in physics])
        assert aliased_inputs(space, q) == expected
