"""A scenario's data-file overrides (the LEDs' intensity bin, foam, paper, lit face) act as they should:
a gain rescales the same render exactly, a render-type value changes the scene and its key, and
bad values are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.assemble import bare_face_emitter, scene_spec
from scenes.diffusers import DiffuserConfig, km_invert, km_layer
from scenes.led import led_for_side
from scenes.near_field import NearFieldSettings, marker_emission
from scenes.render import render, render_key, with_emission
from scenes.render_cache import RenderCache
from scenes.scenario import RenderSettings, Scenario, ScenarioError

TINY = RenderSettings(spp=2, oversampling=1, crop="target", near_field_spp=64)
FAST = NearFieldSettings(spp=128, film_px=32, radial_bins=8)
RED_CD = led_for_side("red").luminous_intensity_cd


def _scenario(**data) -> Scenario:
    return Scenario(camera="logitech-c270", range_m=3.0, render=TINY, data=data)


def test_an_intensity_bin_rescales_the_same_render_exactly(tmp_path, mitsuba_variant):
    """Light transport is linear: twice the LED's luminous intensity doubles its radiance, from the
    same cached render (the gain is not part of the render key)."""
    cache = RenderCache(tmp_path)
    nominal = render(_scenario(), cache)
    brighter = render(_scenario(**{"leds.red.luminous_intensity_cd": 2 * RED_CD}), cache)
    assert brighter.from_cache and not nominal.from_cache
    a, b = (next(c for c in r.components if c.name == "led:red") for r in (nominal, brighter))
    lit = a.image_W_m2_sr > 0
    assert lit.any()
    np.testing.assert_allclose(b.image_W_m2_sr[lit] / a.image_W_m2_sr[lit], 2.0, rtol=1e-6)
    # the same from a held render: with_emission applies the bin without rendering
    again = with_emission(nominal, _scenario(**{"leds.red.luminous_intensity_cd": 2 * RED_CD}))
    held = next(c for c in again.components if c.name == "led:red")
    np.testing.assert_array_equal(held.image_W_m2_sr, b.image_W_m2_sr)
    with pytest.raises(ValueError, match="more than the LEDs' drive"):
        with_emission(nominal, _scenario(**{"beacons.v2.lit_face_diameter_mm": 14.0}))


def test_the_lit_face_spreads_the_same_flux_over_its_area_and_changes_the_render_key(mitsuba_variant):
    small, large = _scenario(), _scenario(**{"beacons.v2.lit_face_diameter_mm": 14.0})
    ratio = bare_face_emitter(large.design, "red")["radiance"] / bare_face_emitter(small.design, "red")["radiance"]
    assert ratio == pytest.approx((12.0 / 14.0) ** 2, rel=1e-12)  # radiance × area = the LED's flux
    keys = {render_key(s, mitsuba_variant.variant, ["led:red"], scene_spec(s)) for s in (small, large)}
    assert len(keys) == 2
    # the gain-only change keeps the key
    bright = _scenario(**{"leds.red.luminous_intensity_cd": 6.0})
    assert render_key(bright, mitsuba_variant.variant, ["led:red"], scene_spec(bright)) == render_key(
        small, mitsuba_variant.variant, ["led:red"], scene_spec(small)
    )


def test_a_sheet_transmittance_is_the_white_sheet_kubelka_munk_inverts_to(tmp_path, mitsuba_variant):
    """The sheet optics with T₁ = 0.15: white paper transmits 0.15 at every wavelength (KM inversion and
    layer give back what went in), and one sheet in the housing passes 0.15/0.19 of the light, as the
    cavity behind it (same reflectances) recycles the same fraction in both."""
    sheet = DiffuserConfig(False, 1, "white", sheet_transmittance=0.15).sheet("red")
    np.testing.assert_allclose(sheet.transmittance, 0.15, rtol=1e-9)
    sx, kx = km_invert(0.77, 0.15)
    assert km_layer(sx, kx)[1] == pytest.approx(0.15, rel=1e-9)
    led, cache = led_for_side("red"), RenderCache(tmp_path)
    design = _scenario().design
    flux = [
        marker_emission(design, led, "black", c, "red", cache, FAST).exit_flux_per_W_sr()
        for c in (DiffuserConfig(False, 1, "white"), DiffuserConfig(False, 1, "white", sheet_transmittance=0.15))
    ]
    assert flux[1] / flux[0] == pytest.approx(0.15 / 0.19, rel=0.03)


def test_a_denser_foam_passes_less_light(tmp_path, mitsuba_variant):
    led, cache, design = led_for_side("red"), RenderCache(tmp_path), _scenario().design
    flux = [
        marker_emission(
            design, led, "black", DiffuserConfig(True, 0, "white", foam_reduced_optical_depth=tau), "red", cache, FAST
        ).exit_flux_per_W_sr()
        for tau in (2.0, 4.0, 8.0)
    ]
    assert flux[0] > flux[1] > flux[2] > 0


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"leds.red.luminous_intensity": 6.0}, "data: 'leds.red.luminous_intensity' is not a settable"),
        ({"leds.red.luminous_intensity_cd": -1.0}, "data.leds.red.luminous_intensity_cd: expected 0 < value"),
        ({"leds.red.luminous_intensity_cd": "bright"}, "expected a finite number, got 'bright'"),
        ({"beacons.v1.lit_face_diameter_mm": 14.0}, "names beacon 'v1', but the scenario's beacon is 'v2'"),
        ({"beacons.v2.lit_face_diameter_mm": 3.0}, "lit_face_diameter_mm: expected 5 < value <= 30 mm"),
        ({"diffusers.foam.thickness_mm": 8.0}, "thickness_mm: expected 0 < value <= 5.5 mm"),
        ({"diffusers.paper.sheet_transmittance": 0.3}, r"sheet_transmittance: expected 0 < T < 1 - R = 0.23"),
    ],
)
def test_a_bad_override_is_one_line_naming_it(data, message):
    with pytest.raises(ScenarioError, match=message) as info:
        _scenario(**data)
    assert "\n" not in str(info.value)


def test_overrides_round_trip_and_stay_out_of_a_nominal_scenario_dict():
    s = _scenario(**{"leds.red.luminous_intensity_cd": 6.0, "diffusers.foam.thickness_mm": 4.0})
    assert s.data == (("diffusers.foam.thickness_mm", 4.0), ("leds.red.luminous_intensity_cd", 6.0))
    assert Scenario.from_dict(s.to_dict()) == s and "data" not in _scenario().to_dict()
    assert s.led.luminous_intensity_cd == 6.0 and s.diffuser.foam_optics().thickness_m == pytest.approx(4e-3)
    assert s.without_gains().data == (("diffusers.foam.thickness_mm", 4.0),)


def test_dust_attenuates_the_same_render_by_beer_lambert(tmp_path, mitsuba_variant):
    """Dust of extinction σ over the range r passes exp(−σ r) of every LED's light (Beer–Lambert),
    from the same cached render; 10 m Koschmieder visibility (σ = 3.912 / 10 m⁻¹) over 3 m leaves
    0.309. Dust beside room light is refused in one line, and clear air keeps the scenario's keys."""
    cache = RenderCache(tmp_path)
    clear = render(_scenario(), cache)
    dusty_scenario = Scenario(camera="logitech-c270", range_m=3.0, render=TINY, dust_extinction_per_m=0.3912)
    dusty = render(dusty_scenario, cache)
    assert dusty.from_cache
    assert dusty_scenario.dust_transmittance == pytest.approx(np.exp(-0.3912 * 3.0), rel=1e-12)
    for name in ("led:red", "led:green"):
        a, b = (next(c for c in r.components if c.name == name) for r in (clear, dusty))
        lit = a.image_W_m2_sr > 0
        np.testing.assert_allclose(b.image_W_m2_sr[lit] / a.image_W_m2_sr[lit], 0.30925, rtol=1e-5)
    held = next(c for c in with_emission(clear, dusty_scenario).components if c.name == "led:red")
    np.testing.assert_array_equal(
        held.image_W_m2_sr, next(c for c in dusty.components if c.name == "led:red").image_W_m2_sr
    )
    assert "dust_extinction_per_m" not in _scenario().to_dict()
    with pytest.raises(ScenarioError, match=r"^dust_extinction_per_m: dust only in an environment without ambient"):
        Scenario(environment="lit-room", dust_extinction_per_m=0.1)
    with pytest.raises(ScenarioError, match=r"^dust_extinction_per_m: expected an extinction coefficient >= 0"):
        Scenario(dust_extinction_per_m=-0.1)
