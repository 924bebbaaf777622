"""Dust as a gain (scenes/dust.py) against Mitsuba's own participating medium.

A lit disc 2.5 m from a camera inside a homogeneous dusty medium (single-scattering albedo 0.9 and
Henyey–Greenstein g = 0.7, typical of mineral dust in the visible: assumed, Dubovik et al. 2002
report 0.9-0.97 and 0.65-0.75) rendered with ``volpath``: the light in the disc's own pixels is the
clear render's times exp(−σ d) (what the gain applies), and the light the dust scatters into the view
around it (and over it), which the gain leaves out, is a faint wide veil: under 1 % of the disc's
radiance beyond 5 pixels (0.03° each) at 5 and 10 m visibility.
"""

from __future__ import annotations

import doctest
import math

import numpy as np
import pytest

from scenes import dust

D_M, R_M, N_PX = 2.5, 0.006, 64


def _render(extinction: float, spp: int, seed: int) -> np.ndarray:
    import mitsuba as mi

    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 64},
        "sensor": {
            "type": "perspective",
            "fov": 2.0,
            "to_world": mi.ScalarTransform4f().look_at([0, 0, D_M], [0, 0, 0], [0, 1, 0]),
            "film": {
                "type": "hdrfilm",
                "width": N_PX,
                "height": N_PX,
                "pixel_format": "luminance",
                "rfilter": {"type": "box"},
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "disc": {
            "type": "disk",
            "to_world": mi.ScalarTransform4f().scale([R_M, R_M, 1.0]),
            "emitter": {"type": "area", "radiance": 1.0},
            "bsdf": {"type": "null"},
        },
    }
    if extinction > 0:
        scene["dust"] = {
            "type": "homogeneous",
            "id": "dust",
            "sigma_t": extinction,
            "albedo": 0.9,
            "phase": {"type": "hg", "g": 0.7},
        }
        scene["sensor"]["medium"] = {"type": "ref", "id": "dust"}
        scene["disc"]["exterior"] = {"type": "ref", "id": "dust"}
        scene["air"] = {
            "type": "sphere",
            "radius": 20.0,
            "bsdf": {"type": "null"},
            "interior": {"type": "ref", "id": "dust"},
        }
    return np.asarray(mi.render(mi.load_dict(scene), seed=seed), dtype=np.float64)[..., 0]


@pytest.mark.parametrize("visibility_m", [10.0, 5.0])
def test_the_direct_view_through_dust_is_beer_lambert_and_the_veil_is_faint(mitsuba_variant, visibility_m):
    sigma = dust.extinction_per_m(visibility_m)
    t = dust.transmittance(sigma, D_M)
    clear = _render(0.0, 64, 0)
    dusty = _render(sigma, 1024, 1)
    disc = clear > 0.5 * clear.max()
    yy, xx = np.mgrid[:N_PX, :N_PX]
    radius_px = np.hypot(xx - (N_PX - 1) / 2, yy - (N_PX - 1) / 2)
    veil = dusty - t * clear
    near = veil[(radius_px < 8) & (clear == 0)].mean()  # the veil beside the disc, smooth across it
    assert (dusty[disc].sum() - near * disc.sum()) / clear[disc].sum() == pytest.approx(t, rel=0.01)
    core = t * clear[clear > 0.99 * clear.max()].mean()
    assert 0 < veil[(radius_px >= 5) & (clear == 0)].mean() < 0.01 * core


def test_the_module_example_holds():
    assert doctest.testmod(dust).failed == 0
    assert dust.visual_range_m(dust.extinction_per_m(7.0)) == pytest.approx(7.0)
    assert math.isinf(dust.visual_range_m(0.0))
    with pytest.raises(ValueError, match=r"^visual_range_m: expected a distance > 0 m"):
        dust.extinction_per_m(0.0)
