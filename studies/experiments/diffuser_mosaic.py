"""The diffuser mosaic: one marker at 150 mm with 0-5 sheets of paper, without and with
foam (the study photographed exactly this while choosing its diffusers).

Each tile is the two-stage render of a single marker (its near-field exit radiance on
the lit face) seen square-on from 150 mm by the camera's pinhole geometry, in the dark.
All tiles share one exposure on a logarithmic scale, so tiles can be compared: the
number under each is the marker's total exit flux relative to the bare LED.
"""

from __future__ import annotations

from pathlib import Path

import colour
import numpy as np

from scenes import spectra
from scenes.beacon import beacon_design
from scenes.diffusers import MAX_PAPER_SHEETS, DiffuserConfig
from scenes.led import led_for_side
from scenes.near_field import NearFieldSettings, marker_emission
from scenes.render_cache import RenderCache
from studies.experiments.two_stage_check import MarkerView, render_passes, two_stage_scene

__all__ = ["diffuser_mosaic"]


def diffuser_mosaic(
    out_png: Path,
    side: str = "red",
    paper_colour: str = "white",
    housing: str = "white",
    camera: str = "logitech-c270",
    range_m: float = 0.15,
) -> dict:
    """Render the mosaic to ``out_png``; return the relative fluxes by configuration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    led, design, cache = led_for_side(side), beacon_design("v2"), RenderCache()
    tiles, flux = {}, {}
    for foam in (False, True):
        for sheets in range(MAX_PAPER_SHEETS + 1):
            config = DiffuserConfig(foam, sheets, paper_colour)
            view = MarkerView(
                config=config,
                side=side,
                housing=housing,
                range_m=range_m,
                view_deg=0.0,
                camera=camera,
                half_px=70,
                oversampling=1,
            )
            tiles[(foam, sheets)] = render_passes(two_stage_scene(view, 64, _near(), cache), 1).images[0]
            emission = marker_emission(design, led, housing, config, side, cache, _near())
            factor = emission.spectral_factor
            flux[(foam, sheets)] = emission.exit_flux_per_W_sr() * spectra.integrate_nm(led.spectral_shape * factor)
    bare = flux[(False, 0)]
    peak = max(t.max() for t in tiles.values())
    xyz = spectra.integrate_nm(led.spectral_shape[:, None] * spectra.cie1931_cmfs().values, axis=0)
    rgb = np.clip(colour.XYZ_to_sRGB(xyz / xyz[1], apply_cctf_encoding=False), 0, None)
    rgb /= rgb.max()
    fig, axes = plt.subplots(2, MAX_PAPER_SHEETS + 1, figsize=(13, 5.2), constrained_layout=True)
    for (foam, sheets), img in tiles.items():
        ax = axes[int(foam), sheets]
        level = np.clip(np.log10(np.maximum(img / peak, 1e-3)) / 3 + 1, 0, 1)  # 3 decades → [0, 1]
        ax.imshow(colour.cctf_encoding(level[..., None] * rgb))
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_xlabel(f"flux {flux[(foam, sheets)] / bare:.3g} × bare", fontsize=9)
        if foam is False:
            ax.set_title(f"{sheets} sheet{'s' if sheets != 1 else ''}")
        if sheets == 0:
            ax.set_ylabel("with foam" if foam else "no foam", fontsize=11)
    fig.suptitle(
        f"{side} LED, {paper_colour} paper, {housing} housing, seen from {range_m * 1000:.0f} mm by "
        f"{camera} (common log exposure, 3 decades)"
    )
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return {f"foam={f},sheets={n}": v / bare for (f, n), v in flux.items()}


def _near():

    return NearFieldSettings()
