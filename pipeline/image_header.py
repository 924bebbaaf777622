"""An image file's pixel size read from its header, before anything is decoded.

A decoder allocates the whole image before it reads a pixel: a 3.6 MB PNG that claims
25000 × 25000 px of 16-bit colour made OpenCV hold 7.6 GB for a minute before the size
check after decoding refused it (and above 2^30 px OpenCV itself fails with an error of
its own). :func:`header_size` reads only the first bytes of the file:

* PNG: the ``IHDR`` chunk (width, height, bit depth, colour type);
* JPEG: the first start-of-frame segment (``SOF0``-``SOF15``), skipping the segments
  before it by their lengths (an EXIF thumbnail lies inside one of them);
* TIFF (classic, either byte order): the first image file directory's width, length,
  samples per pixel and bits per sample (OpenCV decodes only that first page);
* anything else OpenCV might decode (BMP, WebP, PNM, JPEG 2000, ...): Pillow's lazy
  ``Image.open``, which reads only the header (Pillow comes with matplotlib).

The answer is an :class:`ImageHeader`, or ``None`` when the header cannot be read (the
caller then refuses the file).
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

__all__ = ["HEADER_BYTES", "ImageHeader", "header_size"]

HEADER_BYTES = 1 << 20
"""Most bytes read from the start of a file to find its size (a JPEG's EXIF and ICC
segments come before its frame header; they are at most 64 KiB each)."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}
"""Samples per pixel by PNG colour type (a palette image decodes to colour)."""
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
"""JPEG start-of-frame markers (``0xC4``, ``0xC8`` and ``0xCC`` are not frames)."""
_JPEG_STANDALONE = {0x01, *range(0xD0, 0xD8)}
"""JPEG markers without a length field."""


@dataclass(frozen=True)
class ImageHeader:
    """What a header says about the image it starts.

    Attributes
    ----------
    format
        ``PNG``, ``JPEG``, ``TIFF`` or Pillow's name of the format.
    width_px, height_px
        Image size, px.
    channels
        Samples per pixel (1 grey, 3 colour, 4 with alpha).
    bytes_per_sample
        1 for 8-bit samples, 2 for 9- to 16-bit, 4 above.
    """

    format: str
    width_px: int
    height_px: int
    channels: int = 3
    bytes_per_sample: int = 1

    @property
    def pixels(self) -> int:
        """Width × height, px."""
        return self.width_px * self.height_px

    @property
    def decoded_bytes(self) -> int:
        """Bytes the decoded image holds."""
        return self.pixels * self.channels * self.bytes_per_sample


def header_size(path: str | Path) -> ImageHeader | None:
    """The :class:`ImageHeader` of the image file ``path``, or ``None`` when its header cannot be read."""
    with open(path, "rb") as f:
        head = f.read(HEADER_BYTES)
        if head.startswith(_PNG_SIGNATURE):
            return _png(head)
        if head.startswith(b"\xff\xd8"):
            return _jpeg(head)
        if head[:4] in (b"II*\x00", b"MM\x00*"):
            return _tiff(f, head[:2])
    return _pillow(path)


def _bytes_per_sample(bits: int) -> int:
    return 1 if bits <= 8 else 2 if bits <= 16 else 4


def _png(head: bytes) -> ImageHeader | None:
    if len(head) < 29 or head[12:16] != b"IHDR":
        return None
    width, height, depth, colour = struct.unpack(">IIBB", head[16:26])
    return ImageHeader("PNG", width, height, _PNG_CHANNELS.get(colour, 4), _bytes_per_sample(depth))


def _jpeg(head: bytes) -> ImageHeader | None:
    i = 2
    while i + 4 <= len(head):
        if head[i] != 0xFF:
            return None
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _JPEG_STANDALONE:
            i += 2
            continue
        (length,) = struct.unpack(">H", head[i + 2 : i + 4])
        if marker in _JPEG_SOF:
            if length < 8 or i + 10 > len(head):
                return None
            bits, height, width, channels = struct.unpack(">BHHB", head[i + 4 : i + 10])
            if height == 0:  # height given later (a DNL segment): not read here
                return None
            return ImageHeader("JPEG", width, height, max(channels, 1), _bytes_per_sample(bits))
        if marker in (0xD9, 0xDA) or length < 2:  # end of image or scan data before any frame
            return None
        i += 2 + length
    return None


_TIFF_TYPES = {3: ("H", 2), 4: ("I", 4)}
"""TIFF field types a size may have: SHORT and LONG (format character, bytes)."""


def _tiff(f, order: bytes) -> ImageHeader | None:
    e = "<" if order == b"II" else ">"
    try:
        f.seek(4)
        (offset,) = struct.unpack(e + "I", f.read(4))
        f.seek(offset)
        (count,) = struct.unpack(e + "H", f.read(2))
        entries = f.read(12 * min(count, 4096))
    except (OSError, struct.error, OverflowError):
        return None
    tags: dict[int, int] = {}
    for k in range(len(entries) // 12):
        tag, kind, n = struct.unpack(e + "HHI", entries[12 * k : 12 * k + 8])
        if kind in _TIFF_TYPES and n >= 1:
            char, size = _TIFF_TYPES[kind]
            tags[tag] = struct.unpack(e + char, entries[12 * k + 8 : 12 * k + 8 + size])[0]
    if 256 not in tags or 257 not in tags:
        return None
    return ImageHeader("TIFF", tags[256], tags[257], tags.get(277, 1), _bytes_per_sample(tags.get(258, 1)))


def _pillow(path: str | Path) -> ImageHeader | None:
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow comes with matplotlib
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # DecompressionBombWarning: the caller applies its own limit
            with Image.open(path) as image:
                width, height = image.size
                channels = len(image.getbands())
    except Image.DecompressionBombError as exc:  # above Pillow's own limit: far above ours
        return ImageHeader("image", *_bomb_size(str(exc)))
    except Exception:  # Pillow raises many types for files it cannot identify
        return None
    return ImageHeader(image.format or "image", width, height, channels)


def _bomb_size(message: str) -> tuple[int, int]:
    """(width, height) whose product is the pixel count Pillow's message names (its exact size is not kept)."""
    digits = [int(t) for t in message.replace(",", " ").split() if t.isdigit()]
    return (digits[0] if digits else 1 << 31), 1
