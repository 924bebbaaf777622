"""A camera = geometry + lens + body (sensor, image processing, exposure), loaded from data.

``camera_models/data/<name>.toml`` holds the pixel grid (``[geometry]``, read by
:mod:`scenes.view`) and the lens (``[optics]``); its ``body`` names
``camera_models/data/bodies/<body>.toml`` with ``[sensor]``, ``[isp]`` and ``[exposure]``.
Every number carries a ``source`` or an ``assumed`` note (:func:`scenes.sourced.load_sourced`).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, fields, is_dataclass, replace
from functools import lru_cache
from pathlib import Path

import colour
import numpy as np
from numpy.typing import NDArray

from camera_models.glare import GlareSpread, OpticsEffects
from scenes import spectra
from scenes.hardware import HardwareFile, hardware_source
from scenes.sourced import DataFileError, Fields, loads_sourced
from scenes.view import CAMERA_DATA_DIR, CameraGeometry, geometry_from_fields

__all__ = [
    "BODY_DIR",
    "COLOUR_MATRICES",
    "DERIVED_OVERRIDES",
    "DISTORTION_TERMS",
    "HIGHLIGHT_MODES",
    "NOISE_REDUCTION_METHODS",
    "NR_KEYS",
    "OUTPUTS",
    "RELATIVE_ILLUMINATION_MODELS",
    "TONE_CURVES",
    "Camera",
    "ExposureModel",
    "ISPModel",
    "LensModel",
    "SensorModel",
    "VignettingEntry",
    "builtin_ssf_names",
    "camera_template",
    "camera_to_xyz_from_ssf",
    "load_camera",
    "load_ssf_qe",
    "ssf_qe",
    "with_overrides",
    "with_ssf",
]

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
    tone_curve: str  # "srgb", "picture-standard" or "linear" (gamma 1)
    jpeg_quality: int | None  # None when the camera saves no JPEG (output "bgr8")
    chroma_subsampling: str | None
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
    # (raw saturation − black) / (the level the ISP maps to white − black), in (0.5, 1]: 1, the ISP's
    # white point is where the raw clips; below 1 a clipped core stays under white until white
    # balance lifts some channels past it (dcraw(1): pink highlights when the saturation level is
    # set too high). Not a body setting: an unknown (studies/data/unknowns.toml)
    raw_saturation_ratio: float = 1.0
    # where camera_to_xyz comes from: "from-ssf" (fitted to the sensor's sensitivities, refitted when
    # they are swapped: with_ssf) or "published" (the body's own matrix, e.g. a DNG ColorMatrix: kept);
    # "none": no colour correction, the output is white-balanced camera RGB (camera_to_xyz unused)
    colour_matrix: str = "from-ssf"
    # what the camera hands over (OUTPUTS): "jpeg" (a JPEG file at jpeg_quality, chroma_subsampling)
    # or "bgr8" (the uncompressed 8-bit frame of a machine-vision pixel format BGR8, kept exactly:
    # a lossless PNG when written to a file)
    output: str = "jpeg"

    def white_level_DN(self, sensor: SensorModel) -> float:
        """The raw level this ISP maps to white, DN: the sensor's clip level over
        :attr:`raw_saturation_ratio` (above black)."""
        return sensor.black_level_DN + (sensor.white_level_DN - sensor.black_level_DN) / self.raw_saturation_ratio


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


def load_ssf_qe(csv_path: Path, peak_qe: float, energy_response: bool) -> NDArray[np.float64]:
    """Quantum efficiency per channel on :data:`spectra.WAVELENGTHS_NM`, electrons/photon,
    from a spectral-sensitivity CSV file (:func:`ssf_qe` of its text)."""
    return ssf_qe(Path(csv_path).read_text(encoding="utf-8"), peak_qe, energy_response)


def ssf_qe(csv_text: str, peak_qe: float, energy_response: bool) -> NDArray[np.float64]:
    """Quantum efficiency per channel on :data:`spectra.WAVELENGTHS_NM`, electrons/photon.

    ``csv_text`` has columns ``wavelength_nm, r, g, b``. The curves (relative response to
    spectral radiance, 10 nm steps) are interpolated to 1 nm; an energy response s(λ)
    becomes a photon response s(λ)/λ; the result is scaled so the green channel's peak
    equals ``peak_qe``.
    """
    rows = list(csv.DictReader(io.StringIO(csv_text)))
    if len(rows) < 2:
        raise ValueError(f"expected at least 2 rows of wavelengths, got {len(rows)}")
    lam = np.array([float(r["wavelength_nm"]) for r in rows])
    rgb = np.array([[float(r[c]) for r in rows] for c in "rgb"])
    if not np.isfinite(lam).all() or not (np.diff(lam) > 0).all():
        raise ValueError("wavelength_nm: expected finite wavelengths in increasing order, each once")
    if not np.isfinite(rgb).all() or (rgb < 0).any():
        raise ValueError("r, g, b: expected finite sensitivities >= 0")
    qe = np.stack([np.interp(spectra.WAVELENGTHS_NM, lam, ch, left=0.0, right=0.0) for ch in rgb])
    for channel, curve in zip("rgb", qe, strict=True):
        if not curve.max() > 0:
            lo, hi = spectra.WAVELENGTHS_NM[0], spectra.WAVELENGTHS_NM[-1]
            raise ValueError(f"{channel}: expected a sensitivity > 0 somewhere in {lo:.0f}-{hi:.0f} nm, got none")
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


def load_camera(name: str) -> Camera:
    """The camera called ``name`` (see ``camera_names()``); unknown names and bad files raise ValueError.

    The camera is made from the contents its file was read with (:func:`scenes.hardware.hardware_source`),
    never from a path: a run's workers compute with the contents its key covers."""
    return _camera_from_source(hardware_source("camera", name))


CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
HIGHLIGHT_MODES = ("clip", "unclip", "blend")
"""ISP highlight handling: dcraw ``-H 0``, ``-H 1``, ``-H 2`` (see :mod:`camera_models.isp`)."""
NOISE_REDUCTION_METHODS = ("none", "nlmeans")
TONE_CURVES = ("srgb", "picture-standard", "linear")
"""ISP tone curves: sRGB encoding, Canon's Picture Style Standard, or none (``linear``: gamma 1, the
8-bit code proportional to the linear signal, as a machine-vision camera with its gamma/LUT off)."""
CHROMA_SUBSAMPLINGS = ("4:4:4", "4:2:2", "4:2:0")
OUTPUTS = ("jpeg", "bgr8")
"""``[isp] output``: a JPEG file, or the uncompressed 8-bit BGR frame a machine-vision camera
delivers in its BGR8 pixel format (no compression; saved as a lossless PNG)."""
DISTORTION_TERMS = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "equidistant": ()}
"""Coefficients of each lens distortion model (lensfun conventions; see :mod:`camera_models.optics`)."""


@lru_cache(maxsize=16)
def _camera_from_source(source: HardwareFile) -> Camera:
    """Load and check a camera file's contents: every field is checked with a one-line error
    naming it, and a field no part of the model reads (a misspelt key) is an error naming the
    nearest field that exists."""
    values, _ = loads_sourced(source.text, source.label)
    top = Fields(values, f"camera file {source.label}")
    geometry = geometry_from_fields(top)
    if top.has("body"):  # a built-in body shared by several lenses
        bodies = sorted(p.stem for p in BODY_DIR.glob("*.toml"))
        body_name = top.text("body", choices=tuple(bodies))
        data = source.named_file("body", body_name)
        if data is None:
            raise DataFileError(f"{top.file}: body: cannot read the body file {body_name}.toml")
        label = f"body file {body_name}.toml"
        body = Fields(loads_sourced(data.decode("utf-8"), label)[0], label)
        body.text("name")
    else:  # sensor, image processing and exposure written in the camera file itself
        body = top
    lens = _lens(top.table("optics"))
    sensor = _sensor(body.table("sensor"), source)
    isp = _isp(body.table("isp"), sensor)
    exposure = _exposure(body.table("exposure"))
    top.check_known()
    if body is not top:
        body.check_known()
    return Camera(geometry.name, geometry, lens, sensor, isp, exposure)


def _lens(o: Fields) -> LensModel:
    dist = o.table("distortion")
    model = dist.text("model", choices=tuple(DISTORTION_TERMS))
    crop = o.number("crop_factor", positive=True, default=1.0)
    calibration_crop = dist.number("calibration_crop_factor", positive=True, default=crop)
    glare = o.table("glare") if o.has("glare") else None
    crosstalk = o.table("crosstalk", default={})
    return LensModel(
        f_number=o.number("f_number", minimum=0.5, maximum=64.0),
        transmittance=o.number("transmittance", positive=True, maximum=1.0),
        blur_sigma_um=o.number("blur_sigma_um", minimum=0.0, maximum=1000.0),
        distortion_model=model,
        distortion_terms=tuple(dist.number(t) for t in DISTORTION_TERMS[model]),
        distortion_scale=calibration_crop / crop,
        vignetting=_vignetting(o),
        lensfun_camera=o.text("lensfun_camera", default=None) if o.has("lensfun_camera") else None,
        lensfun_lens=o.text("lensfun_lens", default=None) if o.has("lensfun_lens") else None,
        glare=_glare(glare) if glare is not None else None,
        crosstalk_fraction=crosstalk.number("fraction", minimum=0.0, maximum=0.5, default=0.0),
        crosstalk_diagonal_share=crosstalk.number("diagonal_share", minimum=0.0, maximum=1.0, default=0.0),
    )


def _glare(g: Fields) -> GlareSpread:
    """``[optics.glare]``, with the bounds :class:`~camera_models.glare.GlareSpread` needs checked
    here, so an error names the file and the field."""
    fraction = g.number("fraction", minimum=0.0, maximum=1.0)
    if fraction >= 1.0:  # all the light in the tail leaves no image
        raise DataFileError(f"{g.file}: {g.prefix}fraction: expected a number >= 0 and < 1, got {fraction!r}")
    knee_um = g.number("knee_um", positive=True)
    exponent = g.number("exponent", positive=True)
    outer_radius_mm = g.number("outer_radius_mm", positive=True)
    if not outer_radius_mm * 1e3 > knee_um:
        raise DataFileError(
            f"{g.file}: {g.prefix}outer_radius_mm: expected a number > knee_um / 1000 = {knee_um / 1e3:g} "
            f"(the tail ends beyond its knee), got {outer_radius_mm!r}"
        )
    return GlareSpread(fraction=fraction, knee_um=knee_um, exponent=exponent, outer_radius_mm=outer_radius_mm)


RELATIVE_ILLUMINATION_MODELS = ("natural", "vignetting")
"""``[optics.relative_illumination] model``: the lens's natural fall-off (no vignetting data) or
the lensfun ``[[optics.vignetting]]`` entries (:func:`camera_models.optics.relative_illumination`)."""


def _vignetting(o: Fields) -> tuple[VignettingEntry, ...]:
    terms = ("f_number", "k1", "k2", "k3")
    out = (VignettingEntry(**{k: e.number(k, positive=k == "f_number") for k in terms}) for e in o.tables("vignetting"))
    entries = tuple(sorted(out, key=lambda e: e.f_number))
    if o.has("relative_illumination"):  # says which model applies; it must agree with the data
        ri = o.table("relative_illumination")
        model = ri.text("model", choices=RELATIVE_ILLUMINATION_MODELS)
        if (model == "vignetting") != bool(entries):
            expected = "vignetting (the file has [[optics.vignetting]] entries)" if entries else "natural"
            raise DataFileError(f"{ri.file}: {ri.prefix}model: expected {expected}, got {model!r}")
    return entries


def _ssf_text(s: Fields, source: HardwareFile) -> str:
    """The spectral-sensitivity CSV's text: a built-in one (``data/ssf``) or a file next to the
    camera file, as read with the camera file (:data:`scenes.hardware.REFERENCES`)."""
    name = s.text("ssf_csv")
    data = source.named_file("sensor.ssf_csv", name)
    if data is None:
        builtin = sorted(p.name for p in SSF_DIR.glob("*.csv"))
        raise DataFileError(
            f"{s.file}: {s.prefix}ssf_csv: expected one of {', '.join(builtin)} or a CSV next to the "
            f"camera file, got {name!r}"
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise DataFileError(f"{s.file}: {s.prefix}ssf_csv: expected a UTF-8 CSV file, got {name!r}") from None


def _sensor(s: Fields, source: HardwareFile) -> SensorModel:
    uses_iso = s.has("base_iso")
    bits = s.number("adc_bits", integer=True, minimum=8, maximum=16)
    black = s.number("black_level_DN", minimum=0.0)
    white = s.number("white_level_DN", positive=True, maximum=2**bits - 1)
    if white <= black:
        raise DataFileError(f"{s.file}: {s.prefix}white_level_DN: expected a number > black_level_DN, got {white!r}")
    ssf = _ssf_text(s, source)
    peak_qe, energy_response = s.number("peak_qe", positive=True, maximum=1.0), s.flag("ssf_is_energy_response")
    try:
        qe = ssf_qe(ssf, peak_qe, energy_response)
    except (KeyError, ValueError) as exc:
        raise DataFileError(
            f"{s.file}: {s.prefix}ssf_csv: expected a CSV with columns wavelength_nm, r, g, b ({exc})"
        ) from None
    if uses_iso:
        base = s.number("base_iso", positive=True)
        gains = {
            "base_iso": base,
            "min_iso": s.number("min_iso", positive=True),
            "max_iso": s.number("max_iso", positive=True),
            "gain_code_min": None,
            "gain_code_max": None,
            "analog_gain_at_max_code": None,
        }
        high_gain = s.number("read_noise_high_iso", positive=True) / base
    else:
        code_min = s.number("gain_code_min", integer=True, minimum=0)
        gains = {
            "base_iso": None,
            "min_iso": None,
            "max_iso": None,
            "gain_code_min": code_min,
            "gain_code_max": s.number("gain_code_max", integer=True, minimum=code_min + 1),
            "analog_gain_at_max_code": s.number("analog_gain_at_max_code", minimum=1.0),
        }
        high_gain = s.number("read_noise_high_gain", minimum=1.0)
    return SensorModel(
        cfa=s.text("cfa", choices=CFA_PATTERNS),
        qe_rgb=qe,
        adc_bits=bits,
        black_level_DN=black,
        white_level_DN=white,
        gain_K_DN_per_e_at_base=s.number("gain_K_DN_per_e_at_base", positive=True),
        read_noise_e_at_base=s.number("read_noise_e_at_base", minimum=0.0),
        read_noise_e_at_high_gain=s.number("read_noise_e_at_high_iso", minimum=0.0),
        high_gain=high_gain,
        row_noise_fraction=s.number("row_noise_fraction", minimum=0.0, maximum=1.0),
        full_well_e=s.number("full_well_e", positive=True),
        blooming_fraction=s.number("blooming_fraction", minimum=0.0, maximum=1.0),
        dark_current_e_per_s=s.number("dark_current_e_per_s", minimum=0.0),
        dsnu_dark_current_fraction=s.number("dsnu_dark_current_fraction", minimum=0.0),
        dsnu_offset_DN=s.number("dsnu_offset_DN", minimum=0.0),
        prnu_fraction=s.number("prnu_fraction", minimum=0.0, maximum=1.0),
        fixed_pattern_seed=s.number("fixed_pattern_seed", integer=True, minimum=0),
        **gains,
    )


COLOUR_MATRICES = ("from-ssf", "none")
"""``[isp] colour_matrix`` without ``xyz_to_camera``: the matrix fitted to the sensitivities, or
``none`` (no colour correction: the output is the white-balanced camera RGB, as a machine-vision
camera with its colour-correction matrix off delivers it)."""

NR_KEYS = ("nr_analog_gain", "nr_luma_h", "nr_chroma_h")
"""Noise-reduction strengths of a processing option: analog gains and the filter's h at each."""


def _isp(i: Fields, sensor: SensorModel) -> ISPModel:
    if i.has("xyz_to_camera"):  # DNG-style matrix for raw (unbalanced) camera RGB; make it act on balanced RGB
        rows = i.raw("xyz_to_camera")
        if not (isinstance(rows, list) and len(rows) == 3 and all(isinstance(r, list) and len(r) == 3 for r in rows)):
            raise DataFileError(f"{i.file}: {i.prefix}xyz_to_camera: expected a 3x3 matrix, got {rows!r}")
        if i.has("colour_matrix"):
            raise DataFileError(
                f"{i.file}: {i.prefix}colour_matrix: expected nothing beside xyz_to_camera (which sets the matrix), "
                f"got {i.raw('colour_matrix')!r}"
            )
        xyz_to_camera, matrix = _matrix(rows), "published"
        d65 = np.array([0.95047, 1.0, 1.08883])  # CIE D65 white, Y = 1 (CIE 15:2004)
        neutral = xyz_to_camera @ d65
        camera_to_xyz = np.linalg.inv(xyz_to_camera) @ np.diag(neutral / neutral[1])
    else:
        matrix = i.text("colour_matrix", choices=COLOUR_MATRICES, default="from-ssf")
        camera_to_xyz = camera_to_xyz_from_ssf(sensor.qe_rgb)
    profiles = i.table("processing_options", default={})
    processing = i.text("processing", choices=tuple(profiles.values) or ("legacy",), default="legacy")
    tone_curve = i.text("tone_curve", TONE_CURVES, "srgb")
    # every option is checked, the chosen one used
    options = {k: _processing_option(profiles.table(k), tone_curve) for k in profiles.values}
    chosen = options.get(processing) or _processing_option(Fields({}, i.file), tone_curve)
    # the noise-reduction strengths belong to the body: kept whichever option is chosen, so a run
    # can switch noise reduction on by itself (camera override "isp.noise_reduction")
    nr = next((o["nr"] for o in (chosen, *options.values()) if o["nr"]["nr_analog_gain"]), chosen["nr"])
    output = i.text("output", choices=OUTPUTS, default="jpeg")
    if output == "jpeg":
        jpeg_quality = i.number("jpeg_quality", integer=True, minimum=1, maximum=100)
        chroma = i.text("chroma_subsampling", choices=CHROMA_SUBSAMPLINGS)
    else:  # no JPEG: its settings would be read by nothing
        for key in ("jpeg_quality", "chroma_subsampling"):
            if i.has(key):
                raise DataFileError(
                    f"{i.file}: {i.prefix}{key}: expected nothing (output = {output!r} saves no JPEG), "
                    f"got {i.raw(key)!r}"
                )
        jpeg_quality = chroma = None
    return ISPModel(
        demosaic=i.text("demosaic", choices=("bilinear",)),
        white_balance=i.text("white_balance", choices=("daylight", "auto")),
        awb_max_gain_ratio=i.number("awb_max_gain_ratio", minimum=1.0, default=1.0),
        camera_to_xyz=camera_to_xyz,
        colour_matrix=matrix,
        tone_curve=chosen["tone_curve"],
        jpeg_quality=jpeg_quality,
        chroma_subsampling=chroma,
        output=output,
        processing=processing,
        highlight=chosen["highlight"],
        noise_reduction=chosen["noise_reduction"],
        **nr,
        tone_contrast=chosen["tone_contrast"],
        sharpening_amount=chosen["sharpening_amount"],
        sharpening_sigma_px=chosen["sharpening_sigma_px"],
    )


def _processing_option(pp: Fields, tone_curve: str) -> dict:
    """One ``[isp.processing_options.<name>]`` table, checked (its stages after white balance)."""
    nr = {k: pp.numbers(k, minimum=0.0) if pp.has(k) else () for k in NR_KEYS}
    if len({len(v) for v in nr.values()}) > 1:
        raise DataFileError(f"{pp.file}: {pp.prefix}nr_luma_h: expected as many strengths as nr_analog_gain")
    return {
        "tone_curve": pp.text("tone_curve", choices=TONE_CURVES, default=tone_curve),
        "highlight": pp.text("highlight", choices=HIGHLIGHT_MODES, default="clip"),
        "noise_reduction": pp.text("noise_reduction", choices=NOISE_REDUCTION_METHODS, default="none"),
        "nr": nr,
        "tone_contrast": pp.number("tone_contrast", minimum=0.0, maximum=1.0, default=0.0),
        "sharpening_amount": pp.number("sharpening_amount", minimum=0.0, maximum=5.0, default=0.0),
        "sharpening_sigma_px": pp.number("sharpening_sigma_px", positive=True, default=1.0),
    }


def _exposure(e: Fields) -> ExposureModel:
    mode = e.text("mode", choices=("manual", "auto"))
    manual = mode == "manual"
    return ExposureModel(
        mode=mode,
        exposure_s=e.number("exposure_s", positive=True) if manual or e.has("exposure_s") else None,
        iso=e.number("iso", positive=True) if e.has("iso") else None,
        min_exposure_s=e.number("min_exposure_s", positive=True),
        max_exposure_s=e.number("max_exposure_s", positive=True),
        target_mean=e.number("target_mean", positive=True, maximum=1.0) if not manual or e.has("target_mean") else None,
        ae_frames=e.number("ae_frames", integer=True, minimum=1) if not manual or e.has("ae_frames") else None,
        ae_damping=e.number("ae_damping", positive=True, maximum=1.0) if e.has("ae_damping") else None,
    )


def with_overrides(camera: Camera, overrides: dict[str, object]) -> Camera:
    """``camera`` with some fields of its parts replaced: ``{"lens.f_number": 5.6, "isp.jpeg_quality": 90}``.

    Each key is a dotted path of dataclass fields below the camera (``<part>.<field>``, in the
    part's own units, e.g. ``exposure.max_exposure_s`` in s). An empty mapping returns
    ``camera`` itself. A path that names no field raises ``ValueError`` (one line, naming it).
    """
    if not overrides:
        return camera
    for path, value in overrides.items():
        derived = DERIVED_OVERRIDES.get(str(path))
        camera = derived(camera, value) if derived else _replace_path(camera, str(path).split("."), value, str(path))
    return camera


def builtin_ssf_names() -> list[str]:
    """The spectral-sensitivity CSVs shipped in ``camera_models/data/ssf`` (file names)."""
    return sorted(p.name for p in SSF_DIR.glob("*.csv"))


def with_ssf(camera: Camera, name: object) -> Camera:
    """``camera`` with its sensor's spectral sensitivities replaced by a built-in curve (a file of
    ``camera_models/data/ssf``, all energy responses from pbrt-v4), scaled to the same peak QE.

    A colour matrix fitted to the sensitivities (``isp.colour_matrix = "from-ssf"``) is fitted
    again, as the body's firmware would be fitted to its own sensor; a published one (a DNG
    matrix) is the body's firmware and is kept. The camera override ``sensor.ssf_csv`` calls this.
    """
    names = builtin_ssf_names()
    if name not in names:
        raise ValueError(f"camera override 'sensor.ssf_csv': expected one of {', '.join(names)}, got {name!r}")
    qe = load_ssf_qe(SSF_DIR / str(name), float(camera.sensor.qe_rgb.max()), energy_response=True)
    sensor = replace(camera.sensor, qe_rgb=qe)
    isp = camera.isp
    if isp.colour_matrix != "published":  # "none" keeps the fitted matrix current too (it is unused)
        isp = replace(isp, camera_to_xyz=camera_to_xyz_from_ssf(qe))
    return replace(camera, sensor=sensor, isp=isp)


DERIVED_OVERRIDES = {"sensor.ssf_csv": with_ssf}
"""Camera overrides that are not one field: the value rebuilds the fields derived from it."""


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


def camera_template(like: str = "canon-t6-18mm") -> str:
    """A complete camera file to copy and edit: the camera ``like`` with its body written in.

    The result has the form of every camera file (``name``, ``description``, ``[geometry]``,
    ``[optics]``) with ``[sensor]``, ``[isp]`` and ``[exposure]`` in the file itself instead
    of a ``body = ...`` reference, named ``my-camera``; it loads as a camera identical to
    ``like`` apart from its name.
    """
    source = hardware_source("camera", like)
    lines = source.text.splitlines()
    body_name = loads_sourced(source.text, source.label)[0].get("body")
    header = [
        f"# A camera file for beacon-sim, made from '{like}' (beacon-sim cameras --template --like {like}).",
        "# Edit every value for your camera and lens; give each number a `source` (data sheet, measurement)",
        "# or an `assumed` note saying why the value is reasonable. Use it with --camera-file FILE.",
        "# Units are in the field names; [geometry] may give focal_length_mm or diagonal_fov_deg.",
    ]
    out = [*header]
    for line in lines:
        if line.startswith("name ="):
            out.append('name = "my-camera"')
        elif line.startswith("description ="):
            out.append(f'description = "my camera (from the template of {like})"')
        elif not line.startswith("body ="):
            out.append(line)
    if body_name is not None:
        body_lines = (source.named_file("body", body_name) or b"").decode("utf-8").splitlines()
        out += ["", f"# sensor, image processing and exposure (from the body '{body_name}')"]
        out += [line for line in body_lines if not line.startswith("name =")]
    return "\n".join(out) + "\n"
