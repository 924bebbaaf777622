"""Two-stage marker rendering against brute-force volumetric rendering (V2 marker,
foam + 1 sheet, 5 m): flux and radial profile agree within the Monte-Carlo error."""

from __future__ import annotations

import pytest
from scipy import stats

from scenes.near_field import NearFieldSettings
from scenes.render_cache import RenderCache
from studies.experiments.two_stage_check import MarkerView, compare

pytestmark = pytest.mark.usefixtures("mitsuba_variant")


def _check(c):
    assert abs(c.flux_z) < 3.0, c.to_dict()
    assert c.dof >= 8
    assert stats.chi2.sf(c.chi2, c.dof) > 1e-3, c.to_dict()  # profile consistent with pure noise


def test_two_stage_matches_brute_force(tmp_path):
    _check(
        compare(
            MarkerView(), brute_spp=1024, brute_passes=32, near=NearFieldSettings(spp=256), cache=RenderCache(tmp_path)
        )
    )


@pytest.mark.slow
@pytest.mark.parametrize("view_deg", [0.0, 30.0])
def test_two_stage_matches_brute_force_tightly(tmp_path, view_deg):
    c = compare(
        MarkerView(view_deg=view_deg),
        brute_spp=4096,
        brute_passes=256,
        near=NearFieldSettings(spp=1024),
        cache=RenderCache(tmp_path),
    )
    assert c.flux_brute_force_se < 0.05 * c.flux_brute_force  # enough power to see a 15 % disagreement
    _check(c)
