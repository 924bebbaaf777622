"""Near-field marker model: energy conservation, bare-LED limit, caching."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from scenes.beacon import beacon_design
from scenes.diffusers import DiffuserConfig
from scenes.led import led_for_side
from scenes.near_field import STATS, NearFieldSettings, marker_emission
from scenes.render_cache import RenderCache

pytestmark = pytest.mark.usefixtures("mitsuba_variant")

FAST = NearFieldSettings(spp=128, film_px=32, radial_bins=8)
V2, RED = beacon_design("v2"), led_for_side("red")


def _led_flux_per_W_sr() -> float:
    return 2 * math.pi / (RED.cos_exponent + 1)


@pytest.mark.parametrize(
    "config",
    [
        DiffuserConfig(False, 1, "white"),
        DiffuserConfig(True, 0, "white"),
        DiffuserConfig(True, 1, "white"),
        DiffuserConfig(False, 3, "white"),
        DiffuserConfig(True, 5, "red"),
    ],
    ids=lambda c: f"foam{int(c.foam)}-{c.paper_sheets}{c.paper_colour}",
)
@pytest.mark.parametrize("housing", ["white", "black"])
def test_marker_never_emits_more_than_its_led(config, housing, tmp_path):
    e = marker_emission(V2, RED, housing, config, "red", RenderCache(tmp_path), FAST)
    assert 0.0 < e.exit_flux_per_W_sr() < _led_flux_per_W_sr()


def test_more_paper_means_less_light(tmp_path):
    cache = RenderCache(tmp_path)
    flux = [
        marker_emission(V2, RED, "white", DiffuserConfig(True, n, "white"), "red", cache, FAST).exit_flux_per_W_sr()
        for n in (0, 1, 3, 5)
    ]
    assert all(a > b for a, b in itertools.pairwise(flux))


def test_without_diffusers_the_marker_is_the_bare_led(tmp_path):
    """Near-field render of an open housing: on-axis intensity I₀ and the cos^m fall-off."""
    e = marker_emission(
        V2,
        RED,
        "black",
        DiffuserConfig(),
        "red",
        RenderCache(tmp_path),
        NearFieldSettings(spp=256, film_px=48, radial_bins=12),
    )
    for theta in (0.0, 8.0, 16.0):
        expected = float(RED.relative_intensity(math.radians(theta)))
        assert e.intensity_per_W_sr(theta) == pytest.approx(expected, rel=0.05)
    # a black housing only absorbs the beam's far wings (beyond ~27°): ≥ 95 % escapes
    assert 0.95 * _led_flux_per_W_sr() < e.exit_flux_per_W_sr() <= 1.01 * _led_flux_per_W_sr()


def test_second_sweep_over_drive_and_paper_renders_no_near_field(tmp_path, monkeypatch):
    from scenes.marker_photometry import marker_figures
    from scenes.scenario import RenderSettings, Scenario

    # a cache of its own: another test of this worker may have made one of these near fields already
    monkeypatch.setenv("BEACON_SIM_CACHE", str(tmp_path / "render-cache"))

    settings = RenderSettings(near_field_spp=64)

    def sweep():
        for current in (5.0, 10.0, 20.0):
            for sheets in (0, 1, 2):
                s = Scenario(side="red", foam=True, paper_sheets=sheets, led_current_mA=current, render=settings)
                marker_figures(s)

    before = STATS.renders
    sweep()
    first = STATS.renders - before
    sweep()
    assert first == 3 and STATS.renders - before == first


def test_light_field_table_is_lambertian_with_paper(tmp_path):
    e = marker_emission(V2, RED, "white", DiffuserConfig(True, 1, "white"), "red", RenderCache(tmp_path), FAST)
    assert e.profile_per_m2.shape[0] == 1  # one row: the same radiance at every angle
    i0, i60 = e.intensity_per_W_sr(0.0), e.intensity_per_W_sr(60.0)
    assert i60 == pytest.approx(0.5 * i0, rel=1e-9)
    assert np.all(e.profile_per_m2 >= 0)
