"""Which colours a camera can give an LED's light at all: the study's HSV boxes against every exposure.

A marker's image runs from its dim rim to its (often clipped) core, so its pixels take the
colour a camera renders for that light at every exposure from zero to the core's. That set
of colours is a curve: the colour of a *uniform patch* of the light as its exposure grows
(:func:`patch_colours`). A colour box of the study's tracker can only ever pass a marker if
the curve enters the box; if it never does, no drive, diffuser, distance or morphology can
make the tracker see that colour (what mixes pixels after the ISP — demosaicing at sharp
edges, JPEG chroma subsampling, the 50 % resize — mixes neighbouring colours of the curve,
which for a blurred marker lie close together on it).

The patch is noise-free and has no optics: the light's raw camera response (the sensor's
quantum efficiency × the light's spectrum) scaled so its largest channel is ``k`` times the
clip level, pixel crosstalk if asked, the raw clip, then the camera's own ISP
(:func:`camera_models.isp.process`: demosaic, white balance, highlight mode, colour matrix,
tone curve). The spectral unknowns (the LED's dominant-wavelength bin, the paper) and the ISP
unknowns (highlight mode, white balance, crosstalk) are swept here at no rendering cost.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from camera_models.camera import Camera, with_overrides
from camera_models.glare import crosstalk_kernel
from camera_models.isp import process
from camera_models.sensor import mosaic
from pipeline.thesis_tracker import STUDY_HSV_RANGES, HsvBox
from scenes import spectra
from scenes.diffusers import paper
from scenes.led import led_for_side

__all__ = [
    "DOMINANT_SHIFTS_NM",
    "HIGHLIGHTS",
    "LEVELS",
    "WHITE_BALANCES",
    "Reach",
    "in_boxes",
    "light_spectrum",
    "patch_colours",
    "raw_response",
    "reach",
    "reach_table",
    "trajectory_figure",
]

LEVELS = np.geomspace(0.02, 200.0, 121)
"""Exposures tried: the largest raw channel from 2 % of the clip level to 200 times it."""
PATCH_PX = 16


def light_spectrum(side: str, *, dominant_shift_nm: float = 0.0, paper_colour: str = "matched") -> NDArray:
    """Relative spectral radiance of one side's LED seen through one sheet of its paper (project grid).

    ``dominant_shift_nm`` moves the LED's dominant wavelength (its bin); ``paper_colour``
    ``matched`` (the side's colour), ``white`` or ``none``.
    """
    led = led_for_side(side)
    peak = spectra.peak_for_dominant_nm(led.dominant_wavelength_nm + dominant_shift_nm, led.fwhm_nm)
    shape = spectra.led_shape(peak, led.fwhm_nm)
    if paper_colour != "none":
        shape = shape * paper(side if paper_colour == "matched" else paper_colour).transmittance
    return shape


def raw_response(camera: Camera, spectrum: NDArray) -> NDArray[np.float64]:
    """(3,) raw R, G, B electrons of a light of relative spectral radiance ``spectrum`` (energy units),
    relative (largest = 1): quantum efficiency × photons, photons ∝ energy × λ."""
    e = spectra.integrate_nm(camera.sensor.qe_rgb * (spectrum * spectra.WAVELENGTHS_NM)[None, :])
    return e / e.max()


def patch_colours(
    camera: Camera, response: NDArray, levels: NDArray = LEVELS, *, crosstalk: float = 0.0
) -> NDArray[np.uint8]:
    """(len(levels), 3) OpenCV HSV (H 0-180) the camera saves for a uniform patch of a light.

    Parameters
    ----------
    camera
        The camera (its ISP options as set; see :func:`camera_models.camera.with_overrides`).
    response
        (3,) raw channel response of the light (:func:`raw_response`).
    levels
        Exposure of each patch: its largest raw channel over the clip level (1 = just clipped).
    crosstalk
        Fraction of a pixel's charge its 8 neighbours collect (``camera.lens.crosstalk_diagonal_share``
        sets the diagonal part); 0 = none.
    """
    s = camera.sensor
    kernel = crosstalk_kernel(crosstalk, diagonal_share=camera.lens.crosstalk_diagonal_share) if crosstalk else None
    out = np.empty((len(levels), 3), dtype=np.uint8)
    for i, k in enumerate(levels):
        rgb = np.broadcast_to(np.asarray(response, dtype=np.float64) * k, (PATCH_PX, PATCH_PX, 3))
        m = mosaic(np.ascontiguousarray(rgb), s.cfa)
        if kernel is not None:  # charge moves before the clip; reflecting about the edge pixel keeps the CFA phase
            m = cv2.filter2D(m, -1, kernel, borderType=cv2.BORDER_REFLECT_101)
        dn = s.black_level_DN + np.clip(m, 0.0, 1.0) * (s.white_level_DN - s.black_level_DN)
        rgb8 = process(np.rint(dn).astype(np.uint16), camera, analog_gain=1.0).rgb8
        centre = rgb8[PATCH_PX // 2 : PATCH_PX // 2 + 1, PATCH_PX // 2 : PATCH_PX // 2 + 1]
        out[i] = cv2.cvtColor(np.ascontiguousarray(centre), cv2.COLOR_RGB2HSV)[0, 0]
    return out


def in_boxes(hsv: NDArray[np.uint8], boxes: list[HsvBox]) -> NDArray[np.bool_]:
    """Whether each HSV colour lies in any of the boxes (inclusive, as ``cv2.inRange``)."""
    hsv = np.asarray(hsv, dtype=np.int32)
    hit = np.zeros(len(hsv), dtype=bool)
    for lo, hi in boxes:
        hit |= np.all((hsv >= np.array(lo)) & (hsv <= np.array(hi)), axis=1)
    return hit


@dataclass(frozen=True)
class Reach:
    """Where a light's colour curve meets the study's boxes.

    Attributes
    ----------
    levels
        Exposures tried (largest raw channel over the clip level).
    hsv
        (n, 3) OpenCV HSV at each level.
    boxes
        Colour name → exposures (of ``levels``) whose colour that box passes.
    """

    levels: NDArray
    hsv: NDArray
    boxes: dict[str, NDArray]

    def span(self, colour: str) -> tuple[float, float] | None:
        """Lowest and highest exposure whose colour the box of ``colour`` passes (None: never)."""
        k = self.boxes[colour]
        return (float(k.min()), float(k.max())) if len(k) else None


def reach(
    camera: Camera,
    side: str,
    *,
    dominant_shift_nm: float = 0.0,
    paper_colour: str = "matched",
    crosstalk: float = 0.0,
    overrides: dict | None = None,
    ranges: dict[str, list[HsvBox]] = STUDY_HSV_RANGES,
    levels: NDArray = LEVELS,
) -> Reach:
    """The colour curve of one side's light through ``camera`` (with ``overrides``) against the boxes."""
    cam = with_overrides(camera, overrides or {})
    hsv = patch_colours(
        cam,
        raw_response(cam, light_spectrum(side, dominant_shift_nm=dominant_shift_nm, paper_colour=paper_colour)),
        levels,
        crosstalk=crosstalk,
    )
    return Reach(levels, hsv, {c: levels[in_boxes(hsv, b)] for c, b in ranges.items()})


DOMINANT_SHIFTS_NM = {
    "red": (-6.0, 0.0, 6.0),
    "green": (-8.0, 0.0, 8.0),
    "blue": (-5.0, 0.0, 5.0),
    "yellow": (-5.0, 0.0, 5.0),
}
"""Dominant-wavelength bin of each LED about its nominal (scenes/data/leds.toml): red 618-630 nm
(source: Cree CLD-CT011.000), blue 465-475 nm (Cree CLD-CT063.000), yellow 585-595 nm (OptoSupply
OSY5RS3131A); green ±8 nm assumed (the family sheet CLD-CT939.000 gives only 527 nm typical;
InGaN green bins span 515-535 nm)."""
HIGHLIGHTS = ("clip", "blend", "unclip")
WHITE_BALANCES = ("daylight", "auto")
"""``auto`` on a uniform patch is grey world on the light itself (limited by the ISP's AWB range):
the extreme of a frame whose only light is the marker."""


def reach_table(cameras: dict[str, Camera], sides=tuple(DOMINANT_SHIFTS_NM)) -> list[dict]:
    """Every camera × side × highlight mode × white balance × crosstalk (none, the camera's) ×
    paper (matched, white) × dominant wavelength: the exposures at which the study's box of
    the side's colour passes the light's colour, and which other boxes it enters."""
    rows = []
    for (name, cam), side in itertools.product(cameras.items(), sides):
        crosstalks = sorted({0.0, cam.lens.crosstalk_fraction})
        for hl, wb, xt, paper_colour, shift in itertools.product(
            HIGHLIGHTS, WHITE_BALANCES, crosstalks, ("matched", "white"), DOMINANT_SHIFTS_NM[side]
        ):
            r = reach(
                cam, side, dominant_shift_nm=shift, paper_colour=paper_colour, crosstalk=xt,
                overrides={"isp.highlight": hl, "isp.white_balance": wb},
            )  # fmt: skip
            own = r.span(side)
            rows.append(
                {
                    "camera": name, "side": side, "highlight": hl, "white_balance": wb, "crosstalk": xt,
                    "paper_colour": paper_colour, "dominant_shift_nm": shift,
                    "own_box": own is not None,
                    "own_low": own[0] if own else np.nan, "own_high": own[1] if own else np.nan,
                    "other_boxes": ",".join(c for c in r.boxes if c != side and len(r.boxes[c])),
                }
            )  # fmt: skip
    return rows


def trajectory_figure(cameras: dict[str, Camera], path) -> None:
    """Hue and saturation against exposure for each camera and side at nominal settings, the
    study's boxes shaded: where a curve is in its own box the tracker can see that colour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sides = tuple(DOMINANT_SHIFTS_NM)
    fig, axes = plt.subplots(len(cameras), len(sides), figsize=(3.6 * len(sides), 2.9 * len(cameras)), squeeze=False)
    for (name, cam), row in zip(cameras.items(), axes, strict=True):
        for side, ax in zip(sides, row, strict=True):
            for hl, style in (("clip", "-"), ("blend", "--")):
                r = reach(cam, side, overrides={"isp.highlight": hl})
                ax.plot(r.levels, r.hsv[:, 0], style, color="tab:blue", label=f"hue ({hl})")
                ax.plot(r.levels, r.hsv[:, 1] * (180 / 255), style, color="tab:orange", label=f"saturation ({hl})")
                hit = r.boxes[side]
                if len(hit):
                    ax.axvspan(hit.min(), hit.max(), color="tab:green", alpha=0.2 if hl == "clip" else 0.12)
            for lo, hi in STUDY_HSV_RANGES[side]:
                ax.axhspan(lo[0], hi[0], color="tab:blue", alpha=0.08)
                ax.axhspan(lo[1] * 180 / 255, hi[1] * 180 / 255, color="tab:orange", alpha=0.08)
            ax.set_xscale("log")
            ax.set_ylim(0, 180)
            ax.set_title(f"{name}: {side} LED", fontsize=9)
            ax.set_xlabel("exposure (largest raw channel / clip)", fontsize=8)
    axes[0, 0].set_ylabel("H (0-180), S (scaled to 0-180)", fontsize=8)
    axes[0, 0].legend(fontsize=6)
    fig.suptitle(
        "Colour of a uniform patch of each LED's light (matched paper) against exposure; shaded bands: the "
        "study's box for that colour (blue: its H range, orange: its S range); green span: exposures it passes",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
