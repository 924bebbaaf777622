"""Reading images from disk and normalising arrays for the trackers.

Files: JPEG, PNG and TIFF through OpenCV (8 or 16 bit, grey, colour or with alpha), and
camera raw files (Canon .CR2/.CR3 and other LibRaw formats) through ``rawpy``, developed
with the camera's white balance to 16-bit sRGB. A bad file raises ``ValueError`` with
a one-line message starting ``image:``.

Arrays: :func:`as_bgr` turns anything array-like into a 3-channel BGR image, or says in
one line why it cannot (the trackers then report "no target" with that reason).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

RAW_SUFFIXES = {".cr2", ".cr3", ".crw", ".nef", ".arw", ".dng", ".raf", ".orf", ".rw2", ".pef"}
MAX_PIXELS = 200_000_000
"""Images larger than this are refused (memory), px."""


def load_image(path: str | Path) -> NDArray:
    """Read an image file as BGR (uint8 or uint16), or raise ``ValueError('image: …')``."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"image: no such file: {p}")
    if p.suffix.lower() in RAW_SUFFIXES:
        return _load_raw(p)
    data = np.fromfile(p, dtype=np.uint8)
    if data.size == 0:
        raise ValueError(f"image: empty file: {p}")
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
    if image is None:
        raise ValueError(f"image: cannot decode {p.name} (expected JPEG, PNG, TIFF or camera raw)")
    return image


def _load_raw(p: Path) -> NDArray:
    import rawpy

    try:
        with rawpy.imread(str(p)) as raw:
            rgb = raw.postprocess(use_camera_wb=True, output_bps=16, no_auto_bright=True)
    except Exception as exc:  # rawpy raises several LibRaw error types
        raise ValueError(f"image: cannot read camera raw {p.name} ({type(exc).__name__})") from None
    return np.ascontiguousarray(rgb[..., ::-1])


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
