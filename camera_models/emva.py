"""EMVA 1288 photon-transfer data sets from the sensor model.

Simulates the standard's measurement: a sensor under uniform monochromatic light, an
exposure-time series at constant irradiance with a pair of bright and a pair of dark
frames at each exposure (temporal data), plus a stack of bright and dark frames at one
exposure (spatial data). Frames are the green pixels of the first green row of the
Bayer mosaic (one colour channel, as EMVA 1288 measures colour sensors channel by
channel), written as 16-bit PNG with a descriptor file in the format read by the
reference implementation (PyPI ``emva1288``):

    v 3.0
    n <bits> <width> <height>
    b <exposure ns> <photons per pixel>     followed by "i <file>" lines (bright)
    d <exposure ns>                         followed by "i <file>" lines (dark)

:func:`true_parameters` gives the model's own values of what EMVA 1288 measures.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from camera_models.camera import Camera
from camera_models.optics import photons_per_joule
from camera_models.sensor import SensorSettings, cfa_channels, emva_saturation_e, mosaic
from camera_models.sensor_paths import expose
from scenes import spectra

__all__ = ["EmvaSetup", "exposure_fractions", "green_qe", "true_parameters", "write_dataset"]


@dataclass(frozen=True)
class EmvaSetup:
    """What the photon-transfer measurement uses.

    Attributes
    ----------
    wavelength_nm
        Wavelength of the monochromatic light, nm (on the 1 nm grid).
    size_px
        Frames are ``size_px`` × ``size_px`` green pixels.
    t_max_s
        Longest exposure of the series, s.
    spatial_frames
        Frames per stack of the spatial (non-uniformity) measurement.
    """

    wavelength_nm: float = 530.0
    size_px: int = 128
    t_max_s: float = 0.02
    spatial_frames: int = 8


def green_qe(camera: Camera, wavelength_nm: float) -> float:
    """Quantum efficiency of the green channel at ``wavelength_nm``, electrons per photon."""
    if not spectra.WAVELENGTHS_NM[0] <= wavelength_nm <= spectra.WAVELENGTHS_NM[-1]:
        raise ValueError(f"wavelength_nm: expected 380-720 nm, got {wavelength_nm!r}")
    return float(np.interp(wavelength_nm, spectra.WAVELENGTHS_NM, camera.sensor.qe_rgb[1]))


def true_parameters(camera: Camera, analog_gain: float, setup: EmvaSetup = EmvaSetup()) -> dict:
    """The model's values of the EMVA 1288 quantities (green channel)."""
    s = camera.sensor
    return {
        "camera": camera.name,
        "analog_gain": analog_gain,
        "wavelength_nm": setup.wavelength_nm,
        "qe": green_qe(camera, setup.wavelength_nm),
        "K_DN_per_e": s.K_DN_per_e(analog_gain),
        "dark_noise_e": s.read_noise_e(analog_gain),
        "saturation_e": emva_saturation_e(s, analog_gain),
        "clip_e": s.saturation_e(analog_gain),
        "pixel_area_um2": camera.geometry.pixel_pitch_um**2,
        "bits": s.adc_bits,
    }


def exposure_fractions() -> np.ndarray:
    """Exposure times as fractions of the time to reach the clip level: coarse, then fine near saturation."""
    return np.concatenate([np.linspace(0.02, 0.86, 36), np.linspace(0.87, 1.12, 51)])


def write_dataset(camera: Camera, analog_gain: float, out: Path, seed: int = 0, setup: EmvaSetup = EmvaSetup()) -> dict:
    """Simulate the photon-transfer measurement and write frames + ``descriptor.txt`` to ``out``.

    Returns :func:`true_parameters` (also written to ``truth.json``).
    """
    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    truth = true_parameters(camera, analog_gain, setup)
    s = camera.sensor
    qe_rgb = np.array([np.interp(setup.wavelength_nm, spectra.WAVELENGTHS_NM, q) for q in s.qe_rgb])
    # photon rate so the clip level is reached at 0.9 t_max
    photons_per_s = truth["clip_e"] / truth["qe"] / (0.9 * setup.t_max_s)
    n = setup.size_px
    ch = cfa_channels(s.cfa, 0, 0, 2, 2)
    gy, gx = np.argwhere(ch == 1)[0]
    counter = [0]

    def frame(mu_photons: float, t_s: float) -> str:
        mean_rgb = np.broadcast_to(qe_rgb * mu_photons, (2 * n, 2 * n, 3))

        raw = expose(
            mosaic(np.asarray(mean_rgb), s.cfa), s, SensorSettings(t_s, analog_gain), seed * 100003 + counter[0]
        )
        counter[0] += 1
        name = f"images/f{counter[0]:05d}.png"
        cv2.imwrite(str(out / name), np.ascontiguousarray(raw[gy::2, gx::2]))
        return name

    lines = ["v 3.0", f"n {s.adc_bits} {n} {n}"]
    for frac in exposure_fractions() * 0.9:
        t = frac * setup.t_max_s
        mu_p = photons_per_s * t
        lines.append(f"b {t * 1e9:.3f} {mu_p:.6f}")
        lines += [f"i {frame(mu_p, t)}" for _ in range(2)]
        lines.append(f"d {t * 1e9:.3f}")
        lines += [f"i {frame(0.0, t)}" for _ in range(2)]
    t = 0.45 * setup.t_max_s  # spatial: 50 % of saturation
    mu_p = photons_per_s * t
    lines.append(f"b {t * 1e9 + 0.5:.3f} {mu_p:.6f}")
    lines += [f"i {frame(mu_p, t)}" for _ in range(setup.spatial_frames)]
    lines.append(f"d {t * 1e9 + 0.5:.3f}")
    lines += [f"i {frame(0.0, t)}" for _ in range(setup.spatial_frames)]
    (out / "descriptor.txt").write_text("\n".join(lines) + "\n", encoding="utf-8")
    truth["photons_per_s"] = photons_per_s
    truth["irradiance_W_m2"] = (
        photons_per_s / photons_per_joule(setup.wavelength_nm) / (camera.geometry.pixel_pitch_um * 1e-6) ** 2
    )
    (out / "truth.json").write_text(json.dumps(truth, indent=2, allow_nan=False), encoding="utf-8")  # RFC 8259
    return truth
