"""Save renders: multi-channel OpenEXR with the scenario in its header, and a PNG preview.

``radiance.exr`` holds one channel per component, ``<component>.Y`` (``led_red.Y``,
``ambient.Y``): radiance integrated over wavelength, W·m⁻²·sr⁻¹, float32, at the render's
oversampled resolution. Header attributes (all prefixed ``beaconsim``) give the
scenario and pixel grid as JSON, the wavelength grid (nm) and each component's
normalised spectral shape (nm⁻¹), so the full spectral radiance is
``channel × shape``. :func:`write_band_cube_exr` writes that product over 10 nm bands in
the spectral OpenEXR layout of Fichet et al. (2021), channels ``S0.<λ>nm``.
"""

from __future__ import annotations

import json
from pathlib import Path

import colour
import cv2
import numpy as np
import OpenEXR

from scenes import spectra
from scenes.radiance import PixelGrid, RadianceComponent, SpectralRadiance

__all__ = ["read_radiance_exr", "srgb_preview", "write_band_cube_exr", "write_preview_png", "write_radiance_exr"]


def _channel(name: str) -> str:
    return name.replace(":", "_")


def write_radiance_exr(path: str | Path, radiance: SpectralRadiance) -> Path:
    """Write the components and metadata of ``radiance`` to an OpenEXR file."""
    path = Path(path)
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "beaconsimScenario": json.dumps(radiance.scenario, sort_keys=True),
        "beaconsimGrid": json.dumps(radiance.grid.to_dict(), sort_keys=True),
        "beaconsimVariant": radiance.variant,
        "beaconsimUnits": "channels: radiance integrated over wavelength, W m^-2 sr^-1; "
        "shapes: nm^-1 on beaconsimWavelengthsNm",
        "beaconsimWavelengthsNm": spectra.WAVELENGTHS_NM.astype(np.float32),
        "beaconsimComponents": ",".join(_channel(c.name) for c in radiance.components),
    }
    channels = {}
    for c in radiance.components:
        channels[f"{_channel(c.name)}.Y"] = np.ascontiguousarray(c.image_W_m2_sr, dtype=np.float32)
        header[f"beaconsimShape_{_channel(c.name)}"] = c.spectral_shape_per_nm.astype(np.float32)
    OpenEXR.File(header, channels).write(str(path))
    return path


def read_radiance_exr(path: str | Path) -> SpectralRadiance:
    """Read a file written by :func:`write_radiance_exr`."""
    f = OpenEXR.File(str(path))
    h = f.header()
    try:
        names = h["beaconsimComponents"].split(",")
        grid = PixelGrid(
            **{k: (tuple(v) if isinstance(v, list) else v) for k, v in json.loads(h["beaconsimGrid"]).items()}
        )
        channels = f.channels()
        comps = tuple(
            RadianceComponent(
                name.replace("_", ":", 1) if name.startswith("led_") else name,
                np.asarray(channels[f"{name}.Y"].pixels, dtype=np.float32),
                np.asarray(h[f"beaconsimShape_{name}"], dtype=np.float64),
            )
            for name in names
        )
        scenario = json.loads(h["beaconsimScenario"])
    except KeyError as exc:
        raise ValueError(f"{path}: not a beacon-sim radiance file (missing {exc})") from None
    return SpectralRadiance(grid, comps, scenario, h.get("beaconsimVariant", ""))


def write_band_cube_exr(path: str | Path, radiance: SpectralRadiance) -> Path:
    """Write spectral radiance over 10 nm bands, W·m⁻²·sr⁻¹·nm⁻¹, spectral-EXR layout."""
    path = Path(path)
    cube = radiance.band_cube_W_m2_sr_nm()
    channels = {
        f"S0.{lam:.0f},000000nm": np.ascontiguousarray(cube[..., i]) for i, lam in enumerate(spectra.BAND_CENTRES_NM)
    }
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "spectralLayoutVersion": "1.0",
        "emissiveUnits": "W.m^-2.sr^-1.nm^-1",
        "beaconsimScenario": json.dumps(radiance.scenario, sort_keys=True),
        "beaconsimGrid": json.dumps(radiance.grid.to_dict(), sort_keys=True),
    }
    OpenEXR.File(header, channels).write(str(path))
    return path


def srgb_preview(radiance: SpectralRadiance, percentile: float = 99.5) -> np.ndarray:
    """An 8-bit sRGB picture of the render for people to look at (not a camera model).

    Each component's CIE XYZ per unit radiance comes from its spectral shape; the sum is
    exposed so that the given percentile of luminance maps to white, tone-mapped
    with log compression so that both the LEDs and the dim surroundings show.
    """
    cmfs = spectra.cie1931_cmfs()
    xyz = np.zeros((*radiance.grid.shape, 3))
    for c in radiance.components:
        per_unit = spectra.integrate_nm(c.spectral_shape_per_nm[:, None] * cmfs.values, axis=0)
        xyz += c.image_W_m2_sr[..., None] * per_unit
    y = xyz[..., 1]
    positive = y[y > 0]
    if positive.size == 0:
        return np.zeros((*radiance.grid.shape, 3), dtype=np.uint8)
    white = np.percentile(positive, percentile)
    floor = max(white * 1e-3, positive.min())
    # log tone map of luminance, chromaticity kept
    mapped = np.clip(np.log(np.maximum(y, floor) / floor) / np.log(white / floor), 0.0, 1.0)
    scale = np.where(y > 0, mapped / np.maximum(y, 1e-30), 0.0)
    rgb = colour.XYZ_to_sRGB(xyz * scale[..., None], apply_cctf_encoding=False)
    rgb = np.clip(rgb / max(1.0, float(np.percentile(rgb, 99.9))), 0.0, 1.0)
    return (colour.cctf_encoding(rgb, function="sRGB") * 255 + 0.5).astype(np.uint8)


def write_preview_png(path: str | Path, radiance: SpectralRadiance) -> Path:
    """Write :func:`srgb_preview` as a PNG."""

    path = Path(path)
    rgb = srgb_preview(radiance)
    if not cv2.imwrite(str(path), rgb[..., ::-1]):
        raise OSError(f"out: cannot write {path}")
    return path
