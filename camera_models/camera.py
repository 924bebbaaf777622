"""A camera = geometry + lens + body (sensor, image processing, exposure), loaded from data.

``camera_models/data/<name>.toml`` holds the pixel grid (``[geometry]``, read by
:mod:`scenes.view`) and the lens (``[optics]``); its ``body`` names
``camera_models/data/bodies/<body>.toml`` with ``[sensor]``, ``[isp]`` and ``[exposure]``.
Every number carries a ``source`` or an ``assumed`` note (:func:`scenes.sourced.load_sourced`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, fields, is_dataclass, replace
from functools import lru_cache

import colour
import numpy as np
from numpy.typing import NDArray

from camera_models.glare import GlareSpread, OpticsEffects
from scenes import spectra
from scenes.sourced import load_sourced
from scenes.view import CAMERA_DATA_DIR, CameraGeometry, camera_geometry, camera_names

BODY_DIR = CAMERA_DATA_DIR / "bodies"
SSF_DIR = CAMERA_DATA_DIR / "ssf"


@dataclass(frozen=True)
class VignettingEntry:
    """lensfun 'pa' vignetting at one f-number: V(r) = 1 + k1 r² + k2 r⁴ + k3 r⁶."""

    f_number: float
    k1: float
    k2: float
    k3: float


@dataclass(frozen=True)
class LensModel:
    """The lens: aperture, transmission, blur, distortion, relative illumination.

    Attributes
    ----------
    f_number
        Default working f-number N.
    transmittance
        Lens transmittance T (visible), dimensionless.
    blur_sigma_um
        RMS radius per axis of the Gaussian aberration/defocus/low-pass-filter blur, µm.
    distortion_model
        ``ptlens``, ``poly3`` (lensfun conventions, radius normalised to half the short
        image side) or ``equidistant`` (fisheye r = f·θ).
    distortion_terms
        Model coefficients (a, b, c) or (k1,).
    distortion_scale
        lensfun's crop-factor rescaling: lens calibration crop factor / camera crop factor.
    vignetting
        lensfun vignetting entries by f-number; empty means natural relative illumination.
    glare
        Veiling-glare tail (``[optics.glare]``, see :mod:`camera_models.glare`); None: no data.
    crosstalk_fraction, crosstalk_diagonal_share
        Pixel crosstalk (``[optics.crosstalk]``): fraction of a pixel's charge collected by
        its 8 neighbours, and the diagonal neighbours' share of it; 0 without data.
    """

    f_number: float
    transmittance: float
    blur_sigma_um: float
    distortion_model: str
    distortion_terms: tuple[float, ...]
    distortion_scale: float
    vignetting: tuple[VignettingEntry, ...]
    lensfun_camera: str | None
    lensfun_lens: str | None
    glare: GlareSpread | None = None
    crosstalk_fraction: float = 0.0
    crosstalk_diagonal_share: float = 0.0


@dataclass(frozen=True)
class SensorModel:
    """EMVA 1288 linear sensor parameters (see :mod:`camera_models.sensor`)."""

    cfa: str
    qe_rgb: NDArray[np.float64]  # (3, n_wavelengths) on spectra.WAVELENGTHS_NM, electrons per photon
    adc_bits: int
    black_level_DN: float
    white_level_DN: float
    gain_K_DN_per_e_at_base: float
    read_noise_e_at_base: float
    read_noise_e_at_high_gain: float
    high_gain: float  # analog gain (relative to base) of the high-gain read-noise figure
    row_noise_fraction: float
    full_well_e: float
    blooming_fraction: float
    dark_current_e_per_s: float
    dsnu_dark_current_fraction: float
    dsnu_offset_DN: float
    prnu_fraction: float
    fixed_pattern_seed: int
    # gain settings: ISO for DSLRs, UVC gain code for webcams
    base_iso: float | None
    min_iso: float | None
    max_iso: float | None
    gain_code_min: int | None
    gain_code_max: int | None
    analog_gain_at_max_code: float | None

    @property
    def uses_iso(self) -> bool:
        """Whether gain is set as an ISO (DSLR) rather than a UVC gain code (webcam)."""
        return self.base_iso is not None

    def analog_gain(self, iso: float | None = None, gain_code: float | None = None) -> float:
        """Analog gain relative to base, from an ISO or a gain code; validates the range."""
        if self.uses_iso:
            if gain_code is not None:
                raise ValueError("gain: this camera sets its gain as an ISO; use iso")
            iso = self.base_iso if iso is None else iso
            if not _finite(iso) or not self.min_iso <= iso <= self.max_iso:
                raise ValueError(f"iso: expected {self.min_iso:g}-{self.max_iso:g} for this camera, got {iso!r}")
            return float(iso) / self.base_iso
        if iso is not None:
            raise ValueError("iso: this camera has no ISO setting; use the gain code")
        gain_code = self.gain_code_min if gain_code is None else gain_code
        if not _finite(gain_code) or not self.gain_code_min <= gain_code <= self.gain_code_max:
            raise ValueError(f"gain: expected a gain code {self.gain_code_min}-{self.gain_code_max}, got {gain_code!r}")
        span = self.gain_code_max - self.gain_code_min
        return 1.0 + (self.analog_gain_at_max_code - 1.0) * (gain_code - self.gain_code_min) / span

    def K_DN_per_e(self, analog_gain: float) -> float:
        """Overall system gain K at an analog gain, DN per electron."""
        return self.gain_K_DN_per_e_at_base * analog_gain

    def read_noise_split(self) -> tuple[float, float]:
        """(σ_pre in e⁻, σ_post in DN): the two-stage read-noise model.

        σ_read(G)² = σ_pre² + (σ_post / K(G))² in electrons, fitted through the two
        published (or assumed) figures at base gain and at ``high_gain``.
        """
        k0, k1 = self.K_DN_per_e(1.0), self.K_DN_per_e(self.high_gain)
        s0, s1 = self.read_noise_e_at_base, self.read_noise_e_at_high_gain
        post2 = (s0**2 - s1**2) / (1.0 / k0**2 - 1.0 / k1**2)
        pre2 = s1**2 - post2 / k1**2
        if post2 < 0 or pre2 < 0:
            raise ValueError("read noise: the two figures do not fit a two-stage model")
        return math.sqrt(pre2), math.sqrt(post2)

    def read_noise_e(self, analog_gain: float) -> float:
        """Total temporal dark noise at zero exposure, input-referred, e⁻ (EMVA σ_d)."""
        pre, post = self.read_noise_split()
        return math.sqrt(pre**2 + (post / self.K_DN_per_e(analog_gain)) ** 2)

    def saturation_e(self, analog_gain: float) -> float:
        """Electrons at which the output clips: min(ADC clip, full well), e⁻."""
        adc = (self.white_level_DN - self.black_level_DN) / self.K_DN_per_e(analog_gain)
        return min(adc, self.full_well_e)


@dataclass(frozen=True)
class ISPModel:
    """In-camera image processing (see :mod:`camera_models.isp`)."""

    demosaic: str
    white_balance: str  # "daylight" or "auto"
    awb_max_gain_ratio: float
    camera_to_xyz: NDArray[np.float64]  # 3×3, white-balanced camera RGB -> XYZ (D65 white)
    tone_curve: str  # "srgb" or "picture-standard"
    jpeg_quality: int
    chroma_subsampling: str
    # stages after white balance, from the body's [isp.processing_options.<processing>] table; defaults = "legacy"
    processing: str = "legacy"
    highlight: str = "clip"  # "clip" (dcraw -H 0), "unclip" (-H 1) or "blend" (-H 2)
    noise_reduction: str = "none"  # "none" or "nlmeans"
    nr_analog_gain: tuple[float, ...] = ()  # analog gain (relative to base) of each strength point
    nr_luma_h: tuple[float, ...] = ()  # non-local means h on L, 8-bit code units, per point
    nr_chroma_h: tuple[float, ...] = ()  # non-local means hColor on a, b, 8-bit code units, per point
    tone_contrast: float = 0.0  # S-curve weight of "picture-standard", 0-1
    sharpening_amount: float = 0.0  # unsharp-mask amount on luma (0 = off)
    sharpening_sigma_px: float = 1.0  # unsharp-mask Gaussian sigma, px


@dataclass(frozen=True)
class ExposureModel:
    """Exposure control (see :mod:`camera_models.exposure`)."""

    mode: str  # "manual" or "auto"
    exposure_s: float | None
    iso: float | None
    min_exposure_s: float
    max_exposure_s: float
    target_mean: float | None
    ae_frames: int | None
    ae_damping: float | None


@dataclass(frozen=True)
class Camera:
    """Everything a camera does to light."""

    name: str
    geometry: CameraGeometry
    lens: LensModel
    sensor: SensorModel
    isp: ISPModel
    exposure: ExposureModel
    effects: OpticsEffects = OpticsEffects()
    """Optional optical effects (defocus, veiling glare, crosstalk); default none, the plain
    path. The unknowns registry switches them per task (``camera_overrides``)."""

    @property
    def pixel_area_m2(self) -> float:
        """Pixel area, m²."""
        return (self.geometry.pixel_pitch_um * 1e-6) ** 2


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def load_ssf_qe(csv_name: str, peak_qe: float, energy_response: bool) -> NDArray[np.float64]:
    """Quantum efficiency per channel on :data:`spectra.WAVELENGTHS_NM`, electrons/photon.

    The curves (relative response to spectral radiance, 10 nm steps) are interpolated
    to 1 nm; an energy response s(λ) becomes a photon response s(λ)/λ; the result is
    scaled so the green channel's peak equals ``peak_qe``.
    """
    with open(SSF_DIR / csv_name, encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    lam = np.array([float(r["wavelength_nm"]) for r in rows])
    rgb = np.array([[float(r[c]) for r in rows] for c in "rgb"])
    qe = np.stack([np.interp(spectra.WAVELENGTHS_NM, lam, ch, left=0.0, right=0.0) for ch in rgb])
    qe = np.clip(qe, 0.0, None)
    if energy_response:
        qe = qe / spectra.WAVELENGTHS_NM
    return qe * (peak_qe / qe[1].max())


def _matrix(rows) -> NDArray[np.float64]:
    return np.array([[float(v) for v in row] for row in rows], dtype=np.float64)


def camera_to_xyz_from_ssf(qe_rgb: NDArray[np.float64]) -> NDArray[np.float64]:
    """Camera RGB → XYZ matrix fitted to a sensitivity set with colour-science.

    ``colour.matrix_idt`` fits camera RGB (white-balanced under D65) to ACES2065-1 over
    its training reflectances; ACES2065-1 → XYZ then gives camera → XYZ.
    """

    shape = colour.SpectralShape(380, 720, 1)
    msds = colour.MultiSpectralDistributions(
        dict(zip(spectra.WAVELENGTHS_NM, (qe_rgb * spectra.WAVELENGTHS_NM).T, strict=True)),
        labels=("red", "green", "blue"),
    )
    illuminant = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    with colour.utilities.suppress_warnings(colour_usage_warnings=True, colour_runtime_warnings=True):
        idt, _ = colour.matrix_idt(msds, illuminant)
    aces = colour.RGB_COLOURSPACES["ACES2065-1"]
    return aces.matrix_RGB_to_XYZ @ np.asarray(idt)


@lru_cache(maxsize=16)
def load_camera(name: str) -> Camera:
    """The camera called ``name`` (see ``camera_names()``); unknown names raise ValueError."""
    if name not in camera_names():
        raise ValueError(f"camera: expected one of {', '.join(camera_names())}, got {name!r}")
    geometry = camera_geometry(name)
    values, _ = load_sourced(CAMERA_DATA_DIR / f"{name}.toml")
    body, _ = load_sourced(BODY_DIR / f"{values['body']}.toml")
    o = values["optics"]
    dist = o["distortion"]
    model = dist["model"]
    terms = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "equidistant": ()}[model]
    lens = LensModel(
        f_number=float(o["f_number"]),
        transmittance=float(o["transmittance"]),
        blur_sigma_um=float(o["blur_sigma_um"]),
        distortion_model=model,
        distortion_terms=tuple(float(dist[t]) for t in terms),
        distortion_scale=float(dist.get("calibration_crop_factor", 1.0)) / float(o.get("crop_factor", 1.0))
        if "calibration_crop_factor" in dist and "crop_factor" in o
        else 1.0,
        vignetting=tuple(
            sorted(
                (VignettingEntry(**{k: float(v) for k, v in e.items()}) for e in o.get("vignetting", [])),
                key=lambda e: e.f_number,
            )
        ),
        lensfun_camera=o.get("lensfun_camera"),
        lensfun_lens=o.get("lensfun_lens"),
        glare=GlareSpread(
            fraction=float(o["glare"]["fraction"]),
            knee_um=float(o["glare"]["knee_um"]),
            exponent=float(o["glare"]["exponent"]),
            outer_radius_mm=float(o["glare"]["outer_radius_mm"]),
        )
        if "glare" in o
        else None,
        crosstalk_fraction=float(o.get("crosstalk", {}).get("fraction", 0.0)),
        crosstalk_diagonal_share=float(o.get("crosstalk", {}).get("diagonal_share", 0.0)),
    )
    s = body["sensor"]
    qe = load_ssf_qe(s["ssf_csv"], float(s["peak_qe"]), bool(s["ssf_is_energy_response"]))
    uses_iso = "base_iso" in s
    sensor = SensorModel(
        cfa=s["cfa"],
        qe_rgb=qe,
        adc_bits=int(s["adc_bits"]),
        black_level_DN=float(s["black_level_DN"]),
        white_level_DN=float(s["white_level_DN"]),
        gain_K_DN_per_e_at_base=float(s["gain_K_DN_per_e_at_base"]),
        read_noise_e_at_base=float(s["read_noise_e_at_base"]),
        read_noise_e_at_high_gain=float(s["read_noise_e_at_high_iso"]),
        high_gain=float(s["read_noise_high_iso"]) / float(s["base_iso"])
        if uses_iso
        else float(s["read_noise_high_gain"]),
        row_noise_fraction=float(s["row_noise_fraction"]),
        full_well_e=float(s["full_well_e"]),
        blooming_fraction=float(s["blooming_fraction"]),
        dark_current_e_per_s=float(s["dark_current_e_per_s"]),
        dsnu_dark_current_fraction=float(s["dsnu_dark_current_fraction"]),
        dsnu_offset_DN=float(s["dsnu_offset_DN"]),
        prnu_fraction=float(s["prnu_fraction"]),
        fixed_pattern_seed=int(s["fixed_pattern_seed"]),
        base_iso=float(s["base_iso"]) if uses_iso else None,
        min_iso=float(s["min_iso"]) if uses_iso else None,
        max_iso=float(s["max_iso"]) if uses_iso else None,
        gain_code_min=None if uses_iso else int(s["gain_code_min"]),
        gain_code_max=None if uses_iso else int(s["gain_code_max"]),
        analog_gain_at_max_code=None if uses_iso else float(s["analog_gain_at_max_code"]),
    )
    i = body["isp"]
    if "xyz_to_camera" in i:  # DNG-style matrix for raw (unbalanced) camera RGB; make it act on balanced RGB
        xyz_to_camera = _matrix(i["xyz_to_camera"])
        d65 = np.array([0.95047, 1.0, 1.08883])  # CIE D65 white, Y = 1 (CIE 15:2004)
        neutral = xyz_to_camera @ d65
        camera_to_xyz = np.linalg.inv(xyz_to_camera) @ np.diag(neutral / neutral[1])
    else:
        camera_to_xyz = camera_to_xyz_from_ssf(qe)
    processing = i.get("processing", "legacy")
    profiles = i.get("processing_options", {})
    if processing not in profiles and processing != "legacy":
        raise ValueError(f"isp.processing: expected one of {', '.join(profiles) or 'legacy'}, got {processing!r}")
    pp = profiles.get(processing, {})
    # the noise-reduction strengths belong to the body: kept whichever option is chosen, so a run
    # can switch noise reduction on by itself (camera override "isp.noise_reduction")
    nr = next((p for p in (pp, *profiles.values()) if "nr_analog_gain" in p), {})
    isp = ISPModel(
        demosaic=i["demosaic"],
        white_balance=i["white_balance"],
        awb_max_gain_ratio=float(i.get("awb_max_gain_ratio", 1.0)),
        camera_to_xyz=camera_to_xyz,
        tone_curve=pp.get("tone_curve", i.get("tone_curve", "srgb")),
        jpeg_quality=int(i["jpeg_quality"]),
        chroma_subsampling=i["chroma_subsampling"],
        processing=processing,
        highlight=pp.get("highlight", "clip"),
        noise_reduction=pp.get("noise_reduction", "none"),
        nr_analog_gain=tuple(float(v) for v in nr.get("nr_analog_gain", ())),
        nr_luma_h=tuple(float(v) for v in nr.get("nr_luma_h", ())),
        nr_chroma_h=tuple(float(v) for v in nr.get("nr_chroma_h", ())),
        tone_contrast=float(pp.get("tone_contrast", 0.0)),
        sharpening_amount=float(pp.get("sharpening_amount", 0.0)),
        sharpening_sigma_px=float(pp.get("sharpening_sigma_px", 1.0)),
    )
    e = body["exposure"]
    exposure = ExposureModel(
        mode=e["mode"],
        exposure_s=float(e["exposure_s"]) if "exposure_s" in e else None,
        iso=float(e["iso"]) if "iso" in e else None,
        min_exposure_s=float(e["min_exposure_s"]),
        max_exposure_s=float(e["max_exposure_s"]),
        target_mean=float(e["target_mean"]) if "target_mean" in e else None,
        ae_frames=int(e["ae_frames"]) if "ae_frames" in e else None,
        ae_damping=float(e["ae_damping"]) if "ae_damping" in e else None,
    )
    return Camera(name, geometry, lens, sensor, isp, exposure)


def with_overrides(camera: Camera, overrides: dict[str, object]) -> Camera:
    """``camera`` with some fields of its parts replaced: ``{"lens.f_number": 5.6, "isp.jpeg_quality": 90}``.

    Each key is a dotted path of dataclass fields below the camera (``<part>.<field>``, in the
    part's own units, e.g. ``exposure.max_exposure_s`` in s). An empty mapping returns
    ``camera`` itself. A path that names no field raises ``ValueError`` (one line, naming it).
    """
    if not overrides:
        return camera
    for path, value in overrides.items():
        camera = _replace_path(camera, str(path).split("."), value, str(path))
    return camera


def _replace_path(obj, keys: list[str], value: object, path: str):
    name = keys[0]
    if obj is None:
        raise ValueError(f"camera override {path!r}: this camera has no data for the part holding {name!r} (None)")
    names = [f.name for f in fields(obj)] if is_dataclass(obj) and not isinstance(obj, type) else []
    if name not in names:
        where = type(obj).__name__
        expected = f"one of {', '.join(names)}" if names else "no further fields"
        raise ValueError(f"camera override {path!r}: {where} has no field {name!r} (expected {expected})")
    current = getattr(obj, name)
    if len(keys) > 1:
        value = _replace_path(current, keys[1:], value, path)
    elif is_dataclass(current):
        raise ValueError(f"camera override {path!r}: names a part, not a field (override one of its fields)")
    elif isinstance(current, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    return replace(obj, **{name: value})
