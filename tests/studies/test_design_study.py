"""beacon-sim design on fake frames of a planted truth: longer arms and more drive reach farther, so
under a power budget the search finds long arms at the budget's drive, beside V2 at that budget;
the command refuses bad budgets in one line before any work."""

from __future__ import annotations

import json
import math

import pytest

from scenes.beacon import beacon_design
from scenes.hardware import clear_user_hardware
from studies.catalog import design
from studies.engine import sequential
from tests.helpers.planted_frames import FALL_OFF_M, planted_rows


def _r50(task) -> float:
    """Far limit's midpoint, m: grows with the arm (the study's resolution argument) and the drive."""
    sc = task["scenario"]
    arm_mm = beacon_design(sc["beacon"]).arm_length_m * 1e3
    return 2.0 + 0.06 * arm_mm + 1.5 * math.log(sc["led_current_mA"])


@pytest.fixture
def planted(monkeypatch):
    monkeypatch.setattr(sequential, "run_frames", planted_rows(_r50))
    yield
    clear_user_hardware()


def test_the_search_finds_long_arms_at_the_budgets_drive_and_compares_v2(planted, tmp_path):
    target = design.Target(camera="logitech-c270", side="red", yaws_deg=(30.0,), quick=True)
    budget = design.Budget(side_power_mW=10.0)
    summary = design.run(tmp_path, target, budget, trials=24, seed=0)
    assert summary["evaluations"] == 24 and summary["feasible"] > 0
    assert all(p["metrics"]["side_power_mW"] <= 10.0 for p in summary["front"])
    best = max(summary["front"], key=lambda p: p["metrics"]["far_limit_m"])
    # the planted optimum: the longest arm (150 mm) at the budget's drive; far limit r50 - s ln 19
    top_mA = 10.0 / design.side_power_mW("red", 1.0)
    optimum = 2.0 + 0.06 * 150 + 1.5 * math.log(top_mA) - FALL_OFF_M * math.log(19)
    assert best["design"]["arm_length_mm"] > 100 and best["design"]["led_current_mA"] > 3.0
    assert best["metrics"]["far_limit_m"] > 0.8 * optimum  # 24 evaluations, each limit fitted to ±20 %
    v2 = summary["v2_at_budget"]
    assert v2["design"]["led_current_mA"] == pytest.approx(10.0 / design.side_power_mW("red", 1.0), rel=1e-6)  # γ = 1
    assert v2["design"]["arm_length_mm"] == 70.0 and v2["metrics"]["side_power_mW"] == pytest.approx(10.0)
    assert best["metrics"]["far_limit_m"] > v2["metrics"]["far_limit_m"]  # 140+ mm arms beat V2's 70 at equal power
    stored = json.loads((tmp_path / "design.json").read_text())
    assert stored["front"] == summary["front"] and (tmp_path / "report.html").is_file()
    assert (tmp_path / "front.csv").is_file() and (tmp_path / "search.journal").is_file()
    # resumed to more trials: the first 24 evaluations are kept, not redone
    more = design.run(tmp_path, target, budget, trials=28, seed=0, resume=True)
    assert more["evaluations"] == 28


def test_v2_and_v1_are_instances_of_the_parametric_beacon(tmp_path):
    import numpy as np

    from scenes.parametric_beacon import BeaconParameters

    try:
        for name in ("v1", "v2"):
            copy = beacon_design(BeaconParameters.of(name).register(tmp_path))
            for a, b in zip(copy.markers, beacon_design(name).markers, strict=True):
                assert np.allclose(a.position_m, b.position_m) and np.allclose(a.normal, b.normal)
        assert BeaconParameters.of("v2").span_mm == 2 * 70 + 12
        with pytest.raises(ValueError, match=r"arm_length_mm: expected a size > 0 mm, got -5"):
            BeaconParameters(arm_length_mm=-5, out_of_plane_mm=40, lit_face_diameter_mm=12)
        with pytest.raises(ValueError, match=r"in_plane_leds_face: expected one of viewer, outward"):
            BeaconParameters(70, 40, 12, in_plane_leds_face="up")
    finally:
        clear_user_hardware()


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--camera", "logitech-c270", "--max-side-power-mw", "-1"], "max-side-power-mw"),
        (["--camera", "logitech-c270", "--max-side-power-mw", "0.0001"], "max-side-power-mw"),
        (["--camera", "logitech-c270", "--max-span-mm", "20"], "max-span-mm"),
        (["--camera", "nope"], "camera"),
        (["--camera", "logitech-c270", "--trials", "0"], "trials"),
        (["--camera", "logitech-c270", "--focal-length-mm", "4,12"], "focal-length-mm"),
        (["--camera", "raspberry-pi-hq-6mm", "--focal-length-mm", "12,4"], "focal-length-mm"),
        (["--camera", "logitech-c270", "--yaw-deg", "0,95"], "yaw-deg"),
        (["--camera", "logitech-c270", "--at", "low"], "at"),
        (["--camera", "logitech-c270", "--at", "best", "--uncertainty", "3"], "at"),
        (["--camera", "logitech-c270", "--uncertainty", "0"], "uncertainty"),
        (["--camera", "logitech-c270", "--p-working", "1"], "p-working"),
    ],
)
def test_bad_budgets_are_refused_in_one_line_before_any_work(monkeypatch, tmp_path, args, field):
    from tests.helpers.cli import assert_one_line_error, invoke, patch_work

    patch_work(monkeypatch)
    code, _, err = invoke(["design", "--out", str(tmp_path / "o"), *args])
    assert_one_line_error(code, err, field)
    assert not (tmp_path / "o").exists()


def test_a_lens_variant_keeps_the_body_and_changes_only_the_focal_length(tmp_path):
    from camera_models.camera import load_camera
    from camera_models.lens_variant import lens_variant_text, register_lens_variant

    try:
        name = register_lens_variant("raspberry-pi-hq-6mm", 25.0, tmp_path)
        variant, base = load_camera(name), load_camera("raspberry-pi-hq-6mm")
        assert variant.geometry.focal_length_mm == 25.0 and base.geometry.focal_length_mm == 6.0
        assert variant.geometry.width_px == base.geometry.width_px and variant.lens.f_number == base.lens.f_number
        assert variant.sensor.full_well_e == base.sensor.full_well_e
        with pytest.raises(ValueError, match=r"camera: logitech-c270 has a fixed lens"):
            lens_variant_text("logitech-c270", 8.0)
        with pytest.raises(ValueError, match=r"focal_length_mm: expected a focal length in \(0, 2000\] mm"):
            lens_variant_text("raspberry-pi-hq-6mm", -3.0)
        space = design.space_for(design.Target(camera="raspberry-pi-hq-6mm", focal_lengths_mm=(4.0, 35.0)))
        assert space.names[-1] == "focal_length_mm" and design.space_for(design.Target(camera="x")) is design.SPACE
    finally:
        clear_user_hardware()


def _r50_toward_camera(task) -> float:
    """Far limit's midpoint, m, from the radiant intensity the side's LED part sends toward the camera
    at the task's yaw (its beam pattern, :meth:`scenes.led.LED.relative_intensity`) and the arm."""
    sc = task["scenario"]
    d = beacon_design(sc["beacon"])
    led = d.led(sc["side"])
    toward = led.radiant_intensity_W_sr(sc["led_current_mA"]) * float(
        led.relative_intensity(math.radians(sc["yaw_deg"]))
    )
    return 4.0 + 0.03 * d.arm_length_m * 1e3 + 1.5 * math.log(toward / 1e-3)


def test_the_led_part_whose_beam_reaches_the_camera_reaches_farther(monkeypatch, tmp_path):
    """Green has two parts: at equal power the 15° lamp sends ~3.7x the 30° lamp's intensity on axis but
    ~1/11 of it 20° off axis (cos^m lobes with m 81 and 20): on the planted truth the narrow part
    reaches farther facing the camera and the wide one at 20°; the search at 20° picks the wide one, its
    designs name their part and their power is that part's."""
    monkeypatch.setattr(sequential, "run_frames", planted_rows(_r50_toward_camera))
    d = {"arm_length_mm": 100.0, "out_of_plane_mm": 40.0, "lit_face_diameter_mm": 12.0, "foam": False,
         "paper_sheets": 0}  # fmt: skip
    try:
        far = {}
        for yaw in (0.0, 20.0):
            target = design.Target(camera="logitech-c270", side="green", yaws_deg=(yaw,), quick=True)
            for part in ("green", "cree-c503t-gan"):
                current = design.current_for_side_power("green", 6.0, part)  # 6 mW per side either way
                metrics = design.evaluate_design({**d, "led": part, "led_current_mA": current}, target, tmp_path)
                assert metrics["side_power_mW"] == pytest.approx(6.0, rel=1e-5)
                far[yaw, part] = metrics["far_limit_m"]
        assert far[0.0, "cree-c503t-gan"] > far[0.0, "green"] and far[20.0, "green"] > far[20.0, "cree-c503t-gan"]
        target = design.Target(camera="logitech-c270", side="green", yaws_deg=(20.0,), quick=True)
        summary = design.run(tmp_path / "search", target, design.Budget(side_power_mW=10.0), trials=20, seed=1)
        best = max(summary["front"], key=lambda p: p["metrics"]["far_limit_m"])
        assert best["design"]["led"] == "green"
        power = design.side_power_mW("green", best["design"]["led_current_mA"], best["design"]["led"])
        assert best["metrics"]["side_power_mW"] == pytest.approx(power)
        assert "LED part" in (tmp_path / "search" / "report.html").read_text()
    finally:
        clear_user_hardware()


def test_a_parametric_beacon_names_its_parts_in_its_file(tmp_path):
    from scenes.parametric_beacon import BeaconParameters

    try:
        p = BeaconParameters(80, 40, 12, leds=(("blue", "cree-c503t-ban"), ("green", "cree-c503t-gan")))
        d = beacon_design(p.register(tmp_path))
        assert d.led_parts == p.leds and BeaconParameters.of(d.name).leds == p.leds
        assert BeaconParameters(80, 40, 12).name != p.name
        with pytest.raises(ValueError, match=r"leds\.red: expected a red part for the red side \(red\)"):
            BeaconParameters(80, 40, 12, leds=(("red", "cree-c503t-gan"),))
    finally:
        clear_user_hardware()


def test_a_design_scored_over_the_points_of_the_unknowns_and_a_yaw_range(monkeypatch, tmp_path):
    """At points of a planted unknown (the red bin moves the fall-off) a design's far limit at
    ``--at low`` is the noise + physics interval's lower end and at ``median`` the points' median, of
    its worst yaw; planted: r50 falls 0.1 m per degree of yaw, so 30° decides."""
    from tests.helpers.planted_frames import red_bin

    def r50(task) -> float:
        return 7.0 + 1.5 * (red_bin(task) - 5.1) - 0.1 * task["scenario"]["yaw_deg"]

    monkeypatch.setattr(sequential, "run_frames", planted_rows(r50))
    points = tuple({"led_intensity_red": v} for v in (3.4, 6.5, 4.6))
    d = {"arm_length_mm": 70.0, "out_of_plane_mm": 46.0, "lit_face_diameter_mm": 12.0, "led_current_mA": 2.0,
         "foam": True, "paper_sheets": 1}  # fmt: skip
    try:
        far = {}
        for at in ("nominal", "low", "median"):
            target = design.Target(camera="logitech-c270", yaws_deg=(0.0, 30.0), quick=True, physics=points, at=at)
            far[at] = design.evaluate_design(d, target, tmp_path)["far_limit_m"]  # median: low's frames, resumed
        truth = sorted(7.0 + 1.5 * (p["led_intensity_red"] - 5.1) - 3.0 - FALL_OFF_M * math.log(19) for p in points)
        assert far["nominal"] == pytest.approx(7.0 - 3.0 - FALL_OFF_M * math.log(19), abs=0.6)
        assert far["low"] == pytest.approx(truth[0], abs=0.6) and far["median"] == pytest.approx(truth[1], abs=0.6)
        with pytest.raises(ValueError, match=r"at: 'low' needs points of the unknowns"):
            design.Target(camera="logitech-c270", at="low")
    finally:
        clear_user_hardware()


def test_a_design_is_scored_at_the_working_level_the_target_asks_for(monkeypatch, tmp_path):
    """Planted fall-off with its midpoint at 7 m: at level p the far limit is 7 − s·ln(p/(1 − p))
    (0.8: 6.3 m, 0.99: 4.7 m for s = 0.5 m); a level outside (0.5, 1) is refused in one line."""
    monkeypatch.setattr(sequential, "run_frames", planted_rows(lambda task: 7.0))
    d = {"arm_length_mm": 70.0, "out_of_plane_mm": 46.0, "lit_face_diameter_mm": 12.0, "led_current_mA": 2.0,
         "foam": True, "paper_sheets": 1}  # fmt: skip
    try:
        for p in (0.8, 0.99):
            target = design.Target(camera="logitech-c270", yaws_deg=(0.0,), quick=True, p_working=p)
            far = design.evaluate_design(d, target, tmp_path)["far_limit_m"]  # one beacon, its frames shared
            assert far == pytest.approx(7.0 - FALL_OFF_M * math.log(p / (1 - p)), abs=0.5)
        with pytest.raises(ValueError, match=r"^p_working: expected a probability between 0.5 and 1"):
            design.Target(camera="logitech-c270", p_working=0.3)
    finally:
        clear_user_hardware()


def _r50_by_hue(task) -> float:
    """Far limit's midpoint, m: the planted truth peaks where the green side's LED is at 512 nm."""
    sc = task["scenario"]
    nm = beacon_design(sc["beacon"]).led(sc["side"]).dominant_wavelength_nm
    return 9.0 - 0.15 * abs(nm - 512.0) + 0.02 * beacon_design(sc["beacon"]).arm_length_m * 1e3


def test_the_search_finds_the_side_colour_of_a_planted_optimum(monkeypatch, tmp_path):
    """With --side-colour the green side's dominant wavelength is a design parameter over its band
    (500-540 nm): on a planted truth that peaks at 512 nm the farthest design's LED is near it, its
    beacon file gives the side that colour, and its power is that of the part at that colour (the
    luminous intensity kept: the radiant flux follows the efficacy of the shifted spectrum)."""
    monkeypatch.setattr(sequential, "run_frames", planted_rows(_r50_by_hue))
    target = design.Target(camera="logitech-c270", side="green", yaws_deg=(0.0,), quick=True, side_colour=True)
    param = {p.name: p for p in design.space_for(target).params}["dominant_wavelength_nm"]
    assert (param.low, param.high) == (500.0, 540.0)
    try:
        summary = design.run(tmp_path, target, design.Budget(side_power_mW=10.0), trials=24, seed=2)
        best = max(summary["front"], key=lambda p: p["metrics"]["far_limit_m"])
        nm = best["design"]["dominant_wavelength_nm"]
        assert abs(nm - 512.0) < 8.0, nm  # the band is 40 nm wide; 24 designs
        files = list((tmp_path / "beacons").glob("*.toml"))
        led = [beacon_design(f.stem).led("green") for f in files if f"value = {round(nm, 1)!r}" in f.read_text()]
        assert led and led[0].dominant_wavelength_nm == round(nm, 1)
        assert led[0].luminous_intensity_cd == design.led_for_side("green").luminous_intensity_cd
        from scenes import spectra

        k = spectra.K_M_LM_PER_W * spectra.integrate_nm(spectra.photopic_luminosity() * led[0].spectral_shape)
        flux = led[0].luminous_intensity_cd / k * led[0].flux_per_intensity_sr  # at 20 mA, the reference drive
        current = best["design"]["led_current_mA"]
        scale = (current / led[0].reference_current_mA) ** led[0].current_exponent
        assert best["metrics"]["side_power_mW"] == pytest.approx(5e3 * flux * scale, rel=1e-9)
        assert "λD, nm" in (tmp_path / "report.html").read_text()
        assert "dominant_wavelength_nm" not in {p.name for p in design.space_for(design.Target("logitech-c270")).params}
    finally:
        clear_user_hardware()


def test_a_side_colour_is_searched_only_as_far_as_it_stays_apart_from_the_others():
    """The better tracker names sides by their ideal-sRGB chromaticity; the study's closest pair is red
    and yellow. Recomputed here with colour-science (spectrum → XYZ → linear sRGB, clipped): yellow at
    its datasheet 590 nm is exactly that far from red and closer at 591 nm (towards amber), so the
    search keeps yellow in 583-590 nm; red, blue and green keep their whole bands."""
    import dataclasses

    import colour as colour_science
    import numpy as np

    from scenes import spectra
    from scenes.led import HUE_BANDS_NM, SIDE_COLOURS, led_for_side

    def chroma(side, nm=None):
        led = led_for_side(side)
        led = led if nm is None else dataclasses.replace(led, dominant_wavelength_nm=nm)
        xyz = spectra.integrate_nm(led.spectral_shape[None, :] * spectra.cie1931_cmfs().values.T)
        rgb = np.clip(colour_science.XYZ_to_RGB(xyz, colour_science.RGB_COLOURSPACES["sRGB"]), 0, None)
        return np.round(rgb[:2] / rgb.sum(), 4)

    pairs = {(a, b): np.hypot(*(chroma(a) - chroma(b))) for a in SIDE_COLOURS for b in SIDE_COLOURS if a < b}
    assert min(pairs, key=pairs.get) == ("red", "yellow")
    closest = pairs["red", "yellow"]
    assert np.hypot(*(chroma("yellow", 591.0) - chroma("red"))) < closest
    assert design.hue_range("yellow") == (HUE_BANDS_NM["yellow"][0], 590.0)
    for side in ("red", "green", "blue"):
        assert design.hue_range(side) == HUE_BANDS_NM[side]


def test_a_parametric_beacon_gives_its_sides_colours_in_its_file(tmp_path):
    from scenes import spectra
    from scenes.parametric_beacon import BeaconParameters

    try:
        p = BeaconParameters(80, 40, 12, hues_nm=(("green", 505.0), ("yellow", 585.0)))
        d = beacon_design(p.register(tmp_path))
        assert d.led("green").dominant_wavelength_nm == 505.0 and BeaconParameters.of(d.name).hues_nm == p.hues_nm
        # the model spectrum of the shifted part has that dominant wavelength (colour-science's, 1 nm)
        assert spectra.dominant_wavelength_nm(d.led("green").spectral_shape) == 505.0
        assert d.led("red") == beacon_design("v2").led("red")
        assert BeaconParameters(80, 40, 12).name != p.name
        with pytest.raises(ValueError, match=r"dominant_wavelength_nm\.yellow: expected a yellow dominant wavelength "
                           r"of 583-600 nm, got 620"):  # fmt: skip
            BeaconParameters(80, 40, 12, hues_nm=(("yellow", 620.0),))
    finally:
        clear_user_hardware()
