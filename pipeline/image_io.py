"""Reading images from disk and normalising arrays for the trackers.

Files: JPEG, PNG and TIFF through OpenCV (8 or 16 bit, grey, colour or with alpha), and
camera raw files (Canon .CR2/.CR3 and other LibRaw formats) through ``rawpy``, developed
with the camera's white balance to 16-bit sRGB. A bad file raises ``ValueError`` with
a one-line message starting ``image:``. The size is read from the file's header first
(:mod:`pipeline.image_header`; LibRaw's for raw files), and an image of more than
:data:`MAX_PIXELS` is refused before anything is decoded.

Arrays: :func:`as_bgr` turns anything array-like into a 3-channel BGR image, or says in
one line why it cannot (the trackers then report "no target" with that reason).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from pipeline.image_header import header_size

__all__ = ["MAX_PIXELS", "as_bgr", "check_size", "load_image", "to_float", "to_uint8"]

RAW_SUFFIXES = {".cr2", ".cr3", ".crw", ".nef", ".arw", ".dng", ".raf", ".orf", ".rw2", ".pef"}
MAX_PIXELS = 200_000_000
"""Images larger than this are refused (memory), px: 2e8 px is the largest sensors made
(200 MP phones), 1.2 GB decoded at 16-bit colour and several times that in the trackers'
working copies. A file's header is checked against it before decoding."""


def load_image(path: str | Path) -> NDArray:
    """Read an image file as BGR (uint8 or uint16), or raise ``ValueError('image: …')``."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"image: no such file: {p}")
    if p.suffix.lower() in RAW_SUFFIXES:
        return _load_raw(p)
    if p.stat().st_size == 0:
        raise ValueError(f"image: empty file: {p}")
    header = header_size(p)
    if header is None:
        raise ValueError(
            f"image: cannot decode {p.name} (expected JPEG, PNG, TIFF or camera raw; its header gives no size)"
        )
    check_size(p.name, header.width_px, header.height_px, header.format)
    data = np.fromfile(p, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
    if image is None:
        raise ValueError(f"image: cannot decode {p.name} (expected JPEG, PNG, TIFF or camera raw)")
    return image


def _load_raw(p: Path) -> NDArray:
    import rawpy

    try:
        with rawpy.imread(str(p)) as raw:  # opens and reads the header; nothing is decoded yet
            sizes = raw.sizes
            check_size(p.name, max(sizes.raw_width, sizes.width), max(sizes.raw_height, sizes.height), "raw")
            rgb = raw.postprocess(use_camera_wb=True, output_bps=16, no_auto_bright=True)
    except ValueError as exc:
        if str(exc).startswith("image: too large"):
            raise
        raise ValueError(f"image: cannot read camera raw {p.name} ({type(exc).__name__})") from None
    except Exception as exc:  # rawpy raises several LibRaw error types
        raise ValueError(f"image: cannot read camera raw {p.name} ({type(exc).__name__})") from None
    return np.ascontiguousarray(rgb[..., ::-1])


def check_size(name: str, width_px: int, height_px: int, what: str = "image") -> None:
    """Refuse an image its header says is empty or larger than :data:`MAX_PIXELS` (``ValueError('image: …')``)."""
    if width_px < 1 or height_px < 1:
        raise ValueError(f"image: {name} is empty ({width_px}×{height_px} px in its {what} header)")
    if width_px * height_px > MAX_PIXELS:
        raise ValueError(
            f"image: too large: {name} is {width_px}×{height_px} px ({width_px * height_px:.3g} px by its "
            f"{what} header), expected at most {MAX_PIXELS:.3g} px"
        )


def as_bgr(image) -> tuple[NDArray | None, str | None]:
    """A 3-channel BGR array (uint8, uint16 or float32 in [0, 1]), or (None, reason)."""
    try:
        arr = np.asarray(image)
    except Exception:
        return None, "image: not an array"
    if arr.dtype == object or arr.dtype.kind not in "buif":
        return None, f"image: unsupported pixel type {arr.dtype}"
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (3, 4)):
        return None, f"image: expected H×W grey or H×W×3/4 colour, got shape {arr.shape}"
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        return None, f"image: empty ({arr.shape[0]}×{arr.shape[1]} px)"
    if arr.shape[0] * arr.shape[1] > MAX_PIXELS:
        return None, f"image: too large ({arr.shape[1]}×{arr.shape[0]} px)"
    if arr.dtype.kind == "b":
        arr = arr.astype(np.uint8) * 255
    elif arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)):
            return None, "image: non-finite pixel values"
        arr = np.clip(arr, 0.0, 1.0).astype(np.float32)
    elif arr.dtype not in (np.uint8, np.uint16):
        info = np.iinfo(arr.dtype)
        if arr.min(initial=0) < 0 or arr.max(initial=0) > 65535 or info.bits > 16:
            arr = np.clip(arr, 0, 65535)
        arr = arr.astype(np.uint16)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    elif arr.shape[2] == 4:
        arr = arr[..., :3]
    return np.ascontiguousarray(arr), None


def to_uint8(bgr: NDArray) -> NDArray[np.uint8]:
    """8-bit copy of a BGR image from :func:`as_bgr` (16 bit keeps the top byte)."""
    if bgr.dtype == np.uint8:
        return bgr
    if bgr.dtype == np.uint16:
        return (bgr >> 8).astype(np.uint8)
    return np.round(bgr * 255.0).astype(np.uint8)


def to_float(bgr: NDArray) -> NDArray[np.float32]:
    """Float copy in [0, 1] of a BGR image from :func:`as_bgr`."""
    if bgr.dtype == np.uint8:
        return bgr.astype(np.float32) / 255.0
    if bgr.dtype == np.uint16:
        return bgr.astype(np.float32) / 65535.0
    return bgr.astype(np.float32)
