"""In-camera image processing: raw mosaic → the 8-bit image the camera saves (a JPEG, or an
uncompressed frame).

black level → normalise to the white level → demosaic (OpenCV, bilinear) → white
balance (daylight gains from the sensor's own sensitivities under D65, or grey-world
auto white balance limited around them) → highlight handling → camera RGB → CIE XYZ
(D65) → linear sRGB (colour-science) → tone curve → 8 bit → noise reduction →
sharpening → JPEG at the camera's quality and chroma subsampling (OpenCV/libjpeg).

A machine-vision camera hands over its frame in an 8-bit pixel format instead of a JPEG:
``[isp] output = "bgr8"`` keeps the 8-bit BGR frame exactly (:attr:`ProcessedImage.encoded` is
then a lossless PNG of it); with ``colour_matrix = "none"`` (no colour correction: camera RGB
after white balance) and the ``linear`` tone curve (gamma 1: code = round(255 · linear)) the
frame is the linear sensor signal above black, scaled to 8 bits, as such a camera's BGR8 format
delivers it with its colour-correction matrix and gamma/LUT off.

The stages after white balance are options of :class:`camera_models.camera.ISPModel`,
chosen per body by ``[isp] processing`` (a ``[isp.processing_options.<name>]`` table):

highlight
    ``clip``: clip every channel at the white level after white balance, as dcraw's
    default ``-H 0`` ("clip all highlights to solid white"); a pixel clipped in R and G
    but not B stays yellow. ``unclip``: keep values above the clip through white balance
    and the colour matrix, clip only the output (dcraw ``-H 1``, "leave highlights
    unclipped in various shades of pink"). ``blend``: dcraw ``-H 2`` ("blend clipped and
    unclipped values together for a gradual fade to white"), ``blend_highlights()`` of
    dcraw.c / LibRaw: lightness and hue of the unclipped pixel, chroma of the clipped one.
    Sources: dcraw(1) man page (https://linux.die.net/man/1/dcraw); LibRaw
    ``output_params.highlight`` "0-9: Highlight mode (0=clip, 1=unclip, 2=blend,
    3+=rebuild)" (https://www.libraw.org/docs/API-datastruct-eng.html); dcraw.c
    ``blend_highlights()``.
noise reduction
    ``none`` or ``nlmeans``: OpenCV's non-local means on CIELAB
    (``cv2.fastNlMeansDenoisingColored``; ``h`` acts on L, ``hColor`` on a, b), with luma
    and chroma strengths interpolated in log(analog gain) from the body's table. Canon
    EOS JPEGs get "High ISO speed noise reduction", default "Standard", applied at all
    ISOs and stronger at higher ISOs, reducing both chroma and luminance noise (DPReview,
    Canon EOS-1D Mark IV review p. 18; Imaging Resource, Canon 60D / T4i high-ISO NR pages).
tone curve
    ``srgb`` (IEC 61966-2-1, colour-science), ``linear`` (none: the code is proportional to
    the linear value) or ``picture-standard``: Canon Picture Style
    "Standard" uses a contrastier tone curve than the flat styles (DPReview, EOS 400D /
    50D reviews: "Type 1 (more contrast)"); Canon does not publish it, so it is modelled
    as an S-curve on the sRGB-encoded value, y = (1 − c)·v + c·(3v² − 2v³), 0 ≤ c ≤ 1.
sharpening
    Unsharp mask on luma (Y of YCbCr): Y + a·(Y − Gσ * Y); a = 0 is off. Picture Style
    sharpness is a 0-7 setting applied to JPEGs (DPReview EOS 400D / 50D reviews).

The ``legacy`` processing (clip, no noise reduction, sRGB, no sharpening) is the order
and arithmetic of the earlier ISP, byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import colour
import cv2
import numpy as np
from numpy.typing import NDArray

from camera_models.camera import HIGHLIGHT_MODES, NOISE_REDUCTION_METHODS, OUTPUTS, TONE_CURVES, Camera
from camera_models.sensor import cfa_channels
from scenes import spectra

__all__ = [
    "FILE_SUFFIXES",
    "NLMEANS_SEARCH_PX",
    "NLMEANS_TEMPLATE_PX",
    "PNG_COMPRESSION",
    "ProcessedImage",
    "auto_white_balance_gains",
    "blend_highlights",
    "camera_to_srgb_matrix",
    "check_isp_options",
    "daylight_gains",
    "demosaic",
    "encode_8bit",
    "encode_jpeg",
    "encode_jpeg_bgr",
    "encode_png_bgr",
    "noise_reduction_strength",
    "process",
    "reduce_noise",
    "saved_image",
    "srgb_encode_8bit",
    "tone_curve",
    "unsharp_mask",
    "white_balance_gains",
]

SUBSAMPLING_FLAGS = {
    "4:4:4": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444,
    "4:2:2": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
    "4:2:0": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
}
_PATTERN_NAMES = {(0, 1, 1, 2): "RGGB", (2, 1, 1, 0): "BGGR", (1, 0, 2, 1): "GRBG", (1, 2, 0, 1): "GBRG"}


def demosaic(linear: NDArray[np.float64], cfa: str, x0: int = 0, y0: int = 0) -> NDArray[np.float64]:
    """Bilinear demosaic of a normalised mosaic with OpenCV; returns (rows, columns, 3) RGB in [0, 1]."""
    as16 = np.rint(np.clip(linear, 0.0, 1.0) * 65535.0).astype(np.uint16)
    rgb = _demosaic_bgr16(as16, cfa, x0, y0)[..., ::-1].astype(np.float32)
    rgb *= np.float32(1.0 / 65535.0)
    return rgb


def _demosaic_bgr16(as16: NDArray[np.uint16], cfa: str, x0: int, y0: int) -> NDArray[np.uint16]:
    """OpenCV's bilinear demosaic of a 16-bit mosaic (full scale 65535) to BGR."""
    tile = tuple(int(c) for c in cfa_channels(cfa, x0, y0, 2, 2).ravel())
    return cv2.cvtColor(as16, getattr(cv2, f"COLOR_Bayer{_PATTERN_NAMES[tile]}2BGR"))


def _look_up(table: NDArray, codes: NDArray[np.uint16]) -> NDArray:
    """``table[codes]`` for a table with an entry for every 16-bit code: ``np.take`` without its
    bounds check (no code can be out of range), ~3x faster than indexing on an 18-Mpx frame."""
    if len(table) != 1 << 16 or codes.dtype != np.uint16:
        raise ValueError(f"table: expected 65536 entries looked up by uint16 codes, got {len(table)} by {codes.dtype}")
    return np.take(table, codes, mode="clip")


@lru_cache(maxsize=8)
def _raw_to_16bit(black_DN: float, white_DN: float) -> NDArray[np.uint16]:
    """Table from raw DN (0…65535) to the demosaic's 16-bit input: the float32 steps of
    :func:`process` and :func:`demosaic` (subtract black, scale, clip to [0, 1], × 65535,
    round) done once per code instead of once per pixel."""
    linear = np.arange(1 << 16, dtype=np.uint16).astype(np.float32)
    linear -= np.float32(black_DN)
    linear *= np.float32(1.0 / (white_DN - black_DN))
    return np.rint(np.clip(linear, 0.0, 1.0) * 65535.0).astype(np.uint16)


def daylight_gains(camera: Camera) -> NDArray[np.float64]:
    """White-balance gains (R, G, B; G = 1) that make a D65-lit white surface neutral."""
    d65 = spectra.illuminant_shape("D65")
    response = spectra.integrate_nm(camera.sensor.qe_rgb * (d65 * spectra.WAVELENGTHS_NM)[None, :])
    return response[1] / response


def auto_white_balance_gains(rgb_means: NDArray[np.float64], camera: Camera) -> NDArray[np.float64]:
    """Grey-world gains from the frame's mean raw RGB, limited to the ISP's range around daylight."""
    day = daylight_gains(camera)
    means = np.asarray(rgb_means, dtype=np.float64)
    if np.any(~np.isfinite(means)) or np.any(means <= 1e-6):
        return day
    grey = means[1] / means
    ratio = camera.isp.awb_max_gain_ratio
    return np.clip(grey, day / ratio, day * ratio)


def camera_to_srgb_matrix(camera: Camera) -> NDArray[np.float64]:
    """3×3 matrix from white-balanced camera RGB to linear sRGB (D65); white maps to white.

    The identity for a camera without colour correction (``isp.colour_matrix = "none"``): its
    output is the white-balanced camera RGB itself.
    """
    if camera.isp.colour_matrix == "none":
        return np.eye(3)
    xyz_from_balanced = camera.isp.camera_to_xyz
    white = xyz_from_balanced @ np.ones(3)
    d65 = colour.xy_to_XYZ(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"])
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(white / white[1], d65, transform="CAT02")
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    m = srgb.matrix_XYZ_to_RGB @ cat @ xyz_from_balanced
    return m / (m @ np.ones(3))[:, None]


FILE_SUFFIXES = {"jpeg": ".jpg", "png": ".png"}
"""File name suffix of each format the saved image can take (:attr:`ProcessedImage.file_format`)."""


@dataclass(frozen=True)
class ProcessedImage:
    """What the ISP makes of a raw frame.

    Attributes
    ----------
    bgr8
        (rows, columns, 3) uint8 image (sRGB, or what the camera's tone curve and colour
        matrix make), BGR order (OpenCV's, which the encoders take).
    encoded
        The saved file's bytes: a JPEG, or (``isp.output = "bgr8"``) a lossless PNG of ``bgr8``.
    wb_gains
        White-balance gains used (R, G, B).
    file_format
        ``jpeg`` or ``png`` (:data:`FILE_SUFFIXES`).
    """

    bgr8: NDArray[np.uint8]
    encoded: bytes
    wb_gains: NDArray[np.float64]
    file_format: str = "jpeg"

    @property
    def rgb8(self) -> NDArray[np.uint8]:
        """The same image in RGB order (a view)."""
        return self.bgr8[..., ::-1]

    @property
    def suffix(self) -> str:
        """The saved file's name suffix (``.jpg``, ``.png``)."""
        return FILE_SUFFIXES[self.file_format]

    @property
    def jpeg(self) -> bytes:
        """The saved JPEG's bytes; ValueError when the camera saves none (see :attr:`encoded`)."""
        if self.file_format != "jpeg":
            raise ValueError(f"image: this camera saves no JPEG (a {self.file_format} file); use encoded")
        return self.encoded


NLMEANS_TEMPLATE_PX = 7
"""Non-local means patch size, px (OpenCV documentation: "templateWindowSize ... recommended value 7")."""
NLMEANS_SEARCH_PX = 21
"""Non-local means search window, px (OpenCV documentation: "searchWindowSize ... recommended value 21")."""
_SQRT3 = float(np.sqrt(3.0))
# dcraw.c blend_highlights(), 3 colours: camera RGB -> (lightness, two opponent chroma axes) and back (× 3)
_BLEND_TRANS = np.array([[1.0, 1.0, 1.0], [_SQRT3, -_SQRT3, 0.0], [-1.0, -1.0, 2.0]])
_BLEND_ITRANS = np.array([[1.0, _SQRT3 / 2, -0.5], [1.0, -_SQRT3 / 2, -0.5], [1.0, 0.0, 1.0]])


def check_isp_options(camera: Camera) -> None:
    """Raise ValueError naming the ISP field whose option is unknown or out of range."""
    isp = camera.isp
    if isp.highlight not in HIGHLIGHT_MODES:
        raise ValueError(f"isp.highlight: expected one of {', '.join(HIGHLIGHT_MODES)}, got {isp.highlight!r}")
    if isp.noise_reduction not in NOISE_REDUCTION_METHODS:
        raise ValueError(
            f"isp.noise_reduction: expected one of {', '.join(NOISE_REDUCTION_METHODS)}, got {isp.noise_reduction!r}"
        )
    if isp.noise_reduction != "none":
        n = len(isp.nr_analog_gain)
        if n == 0 or len(isp.nr_luma_h) != n or len(isp.nr_chroma_h) != n or any(np.diff(isp.nr_analog_gain) <= 0):
            raise ValueError("isp.nr_analog_gain: expected increasing gains, one luma and one chroma strength each")
    if isp.tone_curve not in TONE_CURVES:
        raise ValueError(f"isp.tone_curve: expected one of {', '.join(TONE_CURVES)}, got {isp.tone_curve!r}")
    if not 0.0 <= isp.tone_contrast <= 1.0:
        raise ValueError(f"isp.tone_contrast: expected 0-1 (a monotonic curve), got {isp.tone_contrast!r}")
    if isp.sharpening_amount < 0.0 or isp.sharpening_sigma_px <= 0.0:
        raise ValueError("isp.sharpening_amount: expected amount >= 0 and sigma > 0")
    if not 0.5 < isp.raw_saturation_ratio <= 1.0:
        raise ValueError(f"isp.raw_saturation_ratio: expected 0.5 < ratio <= 1, got {isp.raw_saturation_ratio!r}")
    if isp.output not in OUTPUTS:
        raise ValueError(f"isp.output: expected one of {', '.join(OUTPUTS)}, got {isp.output!r}")
    if isp.output == "jpeg" and isp.jpeg_quality is None:  # a bgr8 body switched to JPEG by an override
        raise ValueError("isp.jpeg_quality: expected a quality 1-100 for a JPEG output, got None")


def process(
    raw: NDArray[np.uint16], camera: Camera, x0: int = 0, y0: int = 0, *, analog_gain: float | None = None
) -> ProcessedImage:
    """Run the camera's ISP on a raw mosaic whose top-left pixel sits at (x0, y0) in the frame.

    Parameters
    ----------
    raw
        Raw mosaic, DN.
    camera
        The camera; ``camera.isp`` chooses the stages (see the module docstring).
    x0, y0
        Frame position of ``raw``'s top-left pixel, px (sets the CFA phase).
    analog_gain
        Analog gain relative to base the frame was taken at (ISO / base ISO on a DSLR);
        needed only when the ISP's noise reduction is on, whose strength follows it.

    Notes
    -----
    Every stage works on 16-bit BGR values with OpenCV (multi-threaded, saturating) and
    tables, without float copies of the frame: raw → 16-bit linear by a table, bilinear
    demosaic, white balance and the colour matrix as one ``cv2.transform`` (output clipped to
    [0, 1]), the tone curve by one 65 536-entry table of 8-bit codes. A 16-bit output value
    within half a step of one of the curve's code steps cannot say on which side the pixel
    lay, so those values (flagged by the table; a few per cent of a dark frame) are encoded
    again from the pixel's exact linear value, and so are the pixels white balance takes past
    the white level (highlight mode). The codes are then those of the float path it replaced
    (:mod:`camera_models.isp_reference`) but for float32 rounding: rounding to 16 bits alone
    had moved 0.6 % of a dark webcam frame's bytes, more of them up than down, and raised its
    false blobs by 1.6 % (tests/camera_models/test_isp_options.py).
    """
    s, isp = camera.sensor, camera.isp
    check_isp_options(camera)
    if isp.noise_reduction != "none" and (analog_gain is None or not np.isfinite(analog_gain) or analog_gain <= 0):
        raise ValueError(f"analog_gain: noise reduction needs the frame's analog gain (> 0), got {analog_gain!r}")
    bgr16 = _demosaic_bgr16(_look_up(_raw_to_16bit(s.black_level_DN, isp.white_level_DN(s)), raw), s.cfa, x0, y0)
    gains = white_balance_gains(raw, camera, x0, y0)
    matrix = camera_to_srgb_matrix(camera)
    # white balance and colour matrix as one transform; the few pixels that white balance takes
    # past the white level are re-made after it by the highlight mode (clip or blend)
    to_bgr = np.eye(3)[::-1]  # RGB <-> BGR
    transform = to_bgr @ matrix @ np.diag(gains) @ to_bgr
    codes = _look_up(_encode_lut(isp.tone_curve, float(isp.tone_contrast)), cv2.transform(bgr16, transform))
    bgr8 = codes.astype(np.uint8)  # the low byte: the code; the high byte flags values next to a code step
    _encode_near_steps(bgr8, codes, bgr16, transform, isp.tone_curve, float(isp.tone_contrast))
    del codes
    if isp.highlight != "unclip":  # unclip: values above 1 go through the matrix; the output is clipped
        _redo_highlights(bgr8, bgr16, gains, matrix, isp)
    del bgr16
    if isp.noise_reduction != "none":
        luma_h, chroma_h = noise_reduction_strength(camera, analog_gain)
        bgr8 = _reduce_noise_bgr(bgr8, luma_h, chroma_h)
    if isp.sharpening_amount > 0.0:
        bgr8 = _unsharp_mask_bgr(bgr8, isp.sharpening_amount, isp.sharpening_sigma_px)
    return saved_image(bgr8, camera, gains)


def saved_image(bgr8: NDArray[np.uint8], camera: Camera, gains: NDArray[np.float64]) -> ProcessedImage:
    """The :class:`ProcessedImage` of an 8-bit BGR frame: encoded as the camera saves it, a JPEG
    (``isp.output = "jpeg"``) or, for an uncompressed output (``bgr8``), a lossless PNG."""
    if camera.isp.output == "jpeg":
        return ProcessedImage(bgr8, encode_jpeg_bgr(bgr8, camera), gains, "jpeg")
    if camera.isp.output == "bgr8":
        return ProcessedImage(bgr8, encode_png_bgr(bgr8), gains, "png")
    raise ValueError(f"isp.output: expected one of {', '.join(OUTPUTS)}, got {camera.isp.output!r}")


def white_balance_gains(raw: NDArray[np.uint16], camera: Camera, x0: int = 0, y0: int = 0) -> NDArray[np.float64]:
    """The ISP's white-balance gains (R, G, B) for a raw mosaic: the body's daylight gains, or
    grey-world gains from the mosaic's mean linear value per colour filter (``auto``)."""
    s, isp = camera.sensor, camera.isp
    if isp.white_balance == "daylight":
        return daylight_gains(camera)
    if isp.white_balance != "auto":
        raise ValueError(f"isp.white_balance: expected daylight or auto, got {isp.white_balance!r}")
    ch = cfa_channels(s.cfa, x0, y0, 2, 2)
    sums, counts = np.zeros(3), np.zeros(3)
    for dy in range(2):
        for dx in range(2):
            site = raw[dy::2, dx::2]
            sums[ch[dy, dx]] += float(site.sum(dtype=np.float64))
            counts[ch[dy, dx]] += site.size
    means = (sums / np.maximum(counts, 1) - s.black_level_DN) / (isp.white_level_DN(s) - s.black_level_DN)
    return auto_white_balance_gains(means, camera)


def _encode_near_steps(
    bgr8: NDArray[np.uint8], codes: NDArray[np.uint16], bgr16: NDArray[np.uint16], transform, tone: str, contrast: float
) -> None:
    """Re-encode, in place, the channel values the table flagged (high byte set: a code step
    lies within half a 16-bit step) from their exact linear value, ``transform`` · pixel / 65535."""
    near = np.flatnonzero(codes.reshape(-1) > 255)
    if not near.size:
        return
    px, ch = np.divmod(near, 3)
    linear = np.einsum("ij,ij->i", bgr16.reshape(-1, 3)[px].astype(np.float64), transform[ch]) / 65535.0
    bgr8.reshape(-1)[near] = encode_8bit(linear, tone, contrast)


def _redo_highlights(bgr8: NDArray[np.uint8], bgr16: NDArray[np.uint16], gains, matrix, isp) -> None:
    """Re-make, in place, the codes (BGR) of the pixels with a channel that white balance takes
    past the white level: clipped per channel (``clip``) or blended (``blend``,
    :func:`blend_highlights`) before the matrix, then encoded. Other pixels need neither."""
    limits = tuple(min(65535.0 / float(g), 65535.0) for g in gains[::-1])
    below = cv2.inRange(bgr16, (0.0, 0.0, 0.0), limits)  # 255 where no channel passes the white level
    hot = np.flatnonzero(below.ravel() == 0)
    if not hot.size:
        return
    rgb = bgr16.reshape(-1, 3)[hot][:, ::-1].astype(np.float64) * (gains / 65535.0)
    if isp.highlight == "clip":
        np.clip(rgb, 0.0, 1.0, out=rgb)
    else:
        rgb = blend_highlights(rgb.astype(np.float32), 1.0).astype(np.float64)
    linear = rgb @ matrix.T
    bgr8.reshape(-1, 3)[hot] = encode_8bit(linear[:, ::-1], isp.tone_curve, float(isp.tone_contrast))


_STEP_MARGIN = 0.01
"""Widening of the half-step window in which :func:`_encode_lut` flags a code step, in 16-bit
steps: it covers cv2.transform's float32 rounding of the output value (~10⁻⁷ relative)."""


@lru_cache(maxsize=8)
def _encode_lut(name: str, contrast: float) -> NDArray[np.uint16]:
    """Per 16-bit linear value k / 65535: its 8-bit code under the named tone curve, + 256
    where a code step lies within half a step of k (65 536 entries)."""
    k = np.arange(1 << 16, dtype=np.float64)
    table = encode_8bit(k / 65535.0, name, contrast).astype(np.uint16)
    half = 0.5 + _STEP_MARGIN
    below, above = (encode_8bit((k + d) / 65535.0, name, contrast) for d in (-half, half))
    table[below != above] += 256
    return table


def encode_8bit(linear: NDArray[np.floating], name: str = "srgb", contrast: float = 0.0) -> NDArray[np.uint8]:
    """8-bit codes round(255 · curve(clip(linear, 0, 1))) under the named tone curve
    (:func:`tone_curve`); ``srgb`` exactly by :func:`srgb_encode_8bit`.

    >>> encode_8bit(np.array([0.0, 0.0031308, 1.0])).tolist()
    [0, 10, 255]
    """
    if name == "srgb":
        return srgb_encode_8bit(np.array(linear, copy=True))
    return np.rint(tone_curve(linear, name, contrast) * 255.0).astype(np.uint8)


def blend_highlights(rgb: NDArray[np.float32], clip: float = 1.0) -> NDArray[np.float32]:
    """dcraw ``-H 2`` highlight blending, in place on white-balanced camera RGB (..., 3).

    For each pixel with a channel above ``clip`` (relative units, 1 = the white level of a
    channel of gain 1): opponent coordinates (L = R+G+B and two chroma axes) of the
    unclipped value and of the value clipped at ``clip``; the unclipped chroma is scaled
    to the clipped chroma's length and the pixel converted back (dcraw.c
    ``blend_highlights``). Pixels with no channel above ``clip`` are untouched. Clipped
    channels pull the pixel toward neutral at the unclipped lightness, so cores clipped
    in two channels fade toward white; the output may exceed ``clip`` (clipped later).
    """
    flat = rgb.reshape(-1, 3)
    hot = np.any(flat > clip, axis=1)
    if not hot.any():
        return rgb
    cam0 = flat[hot].astype(np.float64)
    lab0 = cam0 @ _BLEND_TRANS.T
    lab1 = np.minimum(cam0, clip) @ _BLEND_TRANS.T
    sum0 = np.sum(lab0[:, 1:] ** 2, axis=1)
    sum1 = np.sum(lab1[:, 1:] ** 2, axis=1)
    ratio = np.sqrt(np.divide(sum1, sum0, out=np.ones_like(sum0), where=sum0 > 0))
    lab0[:, 1:] *= ratio[:, None]
    flat[hot] = (lab0 @ _BLEND_ITRANS.T) / 3.0
    return rgb


def tone_curve(linear: NDArray[np.float64], name: str = "srgb", contrast: float = 0.0) -> NDArray[np.float64]:
    """Encoded value in [0, 1] of linear values (clipped to [0, 1]) under the named tone curve.

    ``srgb``: the sRGB encoding (IEC 61966-2-1, colour-science). ``linear``: none (gamma 1, the
    clipped linear value itself). ``picture-standard``:
    y = (1 − c)·v + c·(3v² − 2v³) with v the sRGB value and c = ``contrast`` in [0, 1]:
    0 → 0, 1 → 1, monotonic, mid-tone slope 1 + c/2, shadows and highlights compressed.
    """
    if name == "linear":
        return np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    v = np.asarray(colour.cctf_encoding(np.clip(linear, 0.0, 1.0), function="sRGB"), dtype=np.float64)
    if name == "srgb":
        return v
    if name == "picture-standard":
        return (1.0 - contrast) * v + contrast * v * v * (3.0 - 2.0 * v)
    raise ValueError(f"isp.tone_curve: expected one of {', '.join(TONE_CURVES)}, got {name!r}")


def noise_reduction_strength(camera: Camera, analog_gain: float) -> tuple[float, float]:
    """(luma h, chroma hColor) of the non-local means filter at an analog gain, 8-bit code units.

    Linear in log(gain) between the body's table points, held constant beyond its ends.
    """
    isp = camera.isp
    lg = np.log(np.asarray(isp.nr_analog_gain, dtype=np.float64))
    x = float(np.log(analog_gain))
    return float(np.interp(x, lg, isp.nr_luma_h)), float(np.interp(x, lg, isp.nr_chroma_h))


def reduce_noise(rgb8: NDArray[np.uint8], luma_h: float, chroma_h: float) -> NDArray[np.uint8]:
    """Luma and chroma noise reduction of an RGB uint8 image by OpenCV's coloured non-local means.

    ``cv2.fastNlMeansDenoisingColored`` converts to CIELAB and filters L with ``h`` =
    ``luma_h`` and a, b with ``hColor`` = ``chroma_h`` (8-bit code units; larger removes
    more noise and more detail), patch 7 px, search window 21 px.
    """
    return np.ascontiguousarray(_reduce_noise_bgr(np.ascontiguousarray(rgb8[..., ::-1]), luma_h, chroma_h)[..., ::-1])


def _reduce_noise_bgr(bgr8: NDArray[np.uint8], luma_h: float, chroma_h: float) -> NDArray[np.uint8]:
    return cv2.fastNlMeansDenoisingColored(
        bgr8, None, float(luma_h), float(chroma_h), NLMEANS_TEMPLATE_PX, NLMEANS_SEARCH_PX
    )


def unsharp_mask(rgb8: NDArray[np.uint8], amount: float, sigma_px: float) -> NDArray[np.uint8]:
    """Unsharp mask on luma: Y + amount·(Y − Gaussian(Y, sigma_px)) in YCbCr, chroma untouched (uint8 RGB)."""
    return np.ascontiguousarray(_unsharp_mask_bgr(np.ascontiguousarray(rgb8[..., ::-1]), amount, sigma_px)[..., ::-1])


def _unsharp_mask_bgr(bgr8: NDArray[np.uint8], amount: float, sigma_px: float) -> NDArray[np.uint8]:
    ycc = cv2.cvtColor(bgr8, cv2.COLOR_BGR2YCrCb)
    y = np.ascontiguousarray(ycc[..., 0])
    blurred = cv2.GaussianBlur(y, (0, 0), float(sigma_px))
    ycc[..., 0] = cv2.addWeighted(y, 1.0 + float(amount), blurred, -float(amount), 0.0)
    return cv2.cvtColor(ycc, cv2.COLOR_YCrCb2BGR)


_LUT_BITS = 16


@lru_cache(maxsize=1)
def _srgb_8bit_tables() -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.float32]]:
    """Bin tables for :func:`srgb_encode_8bit`: code at each bin's start, and the code step inside the bin.

    The 8-bit sRGB code steps up at t_k = decode((k + ½)/255), k = 0…254 (colour-science's
    curve). [0, 1] is cut into 2¹⁶ bins, narrower than the closest two steps (3 × 10⁻⁴),
    so a bin holds at most one step: ``base[i]`` counts the steps ≤ i/2¹⁶ and ``step[i]``
    is the step inside bin i (∞ if none). ``step32[i]`` is the smallest float32 ≥ ``step[i]``:
    for a float32 x, x ≥ step[i] exactly when x ≥ step32[i], so float32 input is compared
    without widening it to float64.
    """
    t = np.asarray(colour.cctf_decoding((np.arange(255) + 0.5) / 255.0, function="sRGB"), dtype=np.float64)
    n = 1 << _LUT_BITS
    starts = np.arange(n + 1) / n
    base = np.searchsorted(t, starts[:-1], side="right")
    step = np.full(n, np.inf)
    inside = np.searchsorted(t, starts[1:], side="left") - base  # steps strictly inside each bin
    assert inside.max() <= 1
    step[inside == 1] = t[base[inside == 1]]
    step32 = step.astype(np.float32)
    below = step32 < step
    step32[below] = np.nextafter(step32[below], np.float32(np.inf))
    return base.astype(np.uint8), step, step32


def srgb_encode_8bit(linear: NDArray[np.float64]) -> NDArray[np.uint8]:
    """round(255 · sRGB(clip(linear, 0, 1))) as uint8 (the curve's codes; ``linear`` is clipped in place).

    Exactly the codes of encoding with colour-science and rounding (the curve is
    monotonic, so a code is the number of step thresholds at or below the value), by a
    2¹⁶-bin table and one comparison instead of a fractional power per value: 18 MP × 3
    in under a second rather than ~7 s.
    """
    base, step, step32 = _srgb_8bit_tables()
    x = np.clip(linear, 0.0, 1.0, out=linear)
    idx = (x * (1 << _LUT_BITS)).astype(np.int32)  # × 2¹⁶ is exact, the cast truncates: the bin
    np.minimum(idx, (1 << _LUT_BITS) - 1, out=idx)
    out = base[idx]
    out += (step32 if x.dtype == np.float32 else step)[idx] <= x
    return out


PNG_COMPRESSION = 1
"""zlib level of the lossless PNG an uncompressed output is saved as (OpenCV ``IMWRITE_PNG_COMPRESSION``,
0-9): the fastest that compresses at all; the pixels are the same at every level."""


def encode_png_bgr(bgr8: NDArray[np.uint8]) -> bytes:
    """Lossless PNG bytes of an 8-bit BGR image (OpenCV's order): what an uncompressed output saves."""
    ok, buf = cv2.imencode(".png", bgr8, [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION])
    if not ok:
        raise RuntimeError("png: OpenCV could not encode the image")
    return buf.tobytes()


def encode_jpeg(rgb8: NDArray[np.uint8], camera: Camera) -> bytes:
    """JPEG bytes of an RGB image at the camera's quality and chroma subsampling."""
    return encode_jpeg_bgr(np.ascontiguousarray(rgb8[..., ::-1]), camera)


def encode_jpeg_bgr(bgr8: NDArray[np.uint8], camera: Camera) -> bytes:
    """JPEG bytes of a BGR image (OpenCV's order: no copy) at the camera's quality and chroma subsampling."""
    if camera.isp.chroma_subsampling not in SUBSAMPLING_FLAGS:
        raise ValueError(
            f"isp.chroma_subsampling: expected one of {', '.join(SUBSAMPLING_FLAGS)}, "
            f"got {camera.isp.chroma_subsampling!r}"
        )
    params = [
        cv2.IMWRITE_JPEG_QUALITY,
        camera.isp.jpeg_quality,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
        SUBSAMPLING_FLAGS[camera.isp.chroma_subsampling],
    ]
    ok, buf = cv2.imencode(".jpg", bgr8, params)
    if not ok:
        raise RuntimeError("jpeg: OpenCV could not encode the image")
    return buf.tobytes()
