"""Diffuser optics: paper stacks against Kubelka–Munk, dyed paper, foam estimate."""

from __future__ import annotations

import pytest

from scenes import spectra
from scenes.diffusers import (
    adding,
    foam_optical_depth_from_transmittance,
    foam_transmittance_diffusion,
    km_invert,
    km_layer,
    paper,
)
from scenes.led import led_for_side
from tests.helpers.diffuse_sky import transmitted_radiance


def test_km_inversion_round_trips():
    r, t = km_layer(3.0, 0.05)
    sx, kx = km_invert(r, t)
    assert sx == pytest.approx(3.0, rel=1e-10) and kx == pytest.approx(0.05, rel=1e-8)


@pytest.mark.usefixtures("mitsuba_variant")
@pytest.mark.parametrize("n_sheets", [1, 2, 3, 4, 5])
def test_rendered_paper_stack_transmittance_matches_kubelka_munk(n_sheets):
    """N sheets (Mitsuba, diffuse_sheet BSDF, all inter-reflections traced) under uniform
    diffuse light transmit T_N of the KM layer of N-fold thickness, within 10 %."""
    from scenes.mitsuba_variant import select_variant

    select_variant("mono")
    white = paper("white")
    r1, t1 = white.at(550.0)
    sheet = {"type": "diffuse_sheet", "reflectance": r1, "transmittance": t1}
    transmitted = transmitted_radiance([sheet] * n_sheets, spp=512, max_depth=400, seed=n_sheets)
    sx, kx = km_invert(r1, t1)
    expected = km_layer(n_sheets * sx, n_sheets * kx)[1]
    assert transmitted == pytest.approx(expected, rel=0.10)
    # the adding method and KM agree to rounding (independent formulas)
    r, t = 0.0, 1.0
    for _ in range(n_sheets):
        r, t = adding(r, t, r1, t1)
    assert t == pytest.approx(expected, rel=1e-9)


# subtractive colours: yellow paper removes blue only, and passes red light as well
BLOCKED = {
    "red": ("green", "blue", "yellow"),
    "green": ("red", "blue", "yellow"),
    "blue": ("red", "green", "yellow"),
    "yellow": ("blue",),
}


@pytest.mark.parametrize("colour", ["red", "green", "blue", "yellow"])
def test_dyed_paper_passes_its_own_led_and_blocks_the_others(colour):
    sheet = paper(colour)
    t = sheet.transmittance
    own = spectra.integrate_nm(t * led_for_side(colour).spectral_shape)
    others = [spectra.integrate_nm(t * led_for_side(c).spectral_shape) for c in BLOCKED[colour]]
    assert own > 5 * max(others)
    assert own <= paper("white").transmittance[0] + 1e-12  # a dye only absorbs


def test_red_led_behind_green_paper_is_dimmer_by_the_dyes_ratio():
    red = led_for_side("red").spectral_shape
    through_red = spectra.integrate_nm(red * paper("red").transmittance)
    through_green = spectra.integrate_nm(red * paper("green").transmittance)
    assert through_green < 0.05 * through_red


def test_foam_depth_inverts_measured_transmittance():
    t = foam_transmittance_diffusion(3.3, 0.999)
    assert foam_optical_depth_from_transmittance(t, 0.999) == pytest.approx(3.3, rel=1e-6)
    # conservative diffusion slab: T = 1 / (1 + 3τ'/4)
    assert foam_transmittance_diffusion(4.0, 1.0) == pytest.approx(1 / (1 + 3.0), rel=1e-6)
