"""A camera body with another focal length: the lens a builder would put on an interchangeable-lens body.

:func:`lens_variant_text` writes the camera file of ``camera`` with ``focal_length_mm`` replaced
(and a name and description that say so); everything else, the body, the lens's f-number, blur,
distortion and glare, is the base camera's, which is an assumption the file states: a longer lens of
the same family at the same f-number. :func:`register_lens_variant` registers it like a user's
camera (:func:`scenes.hardware.add_hardware_file`), so renders, captures and detection all use it.
Only cameras whose file gives ``focal_length_mm`` can take another lens (a webcam's fixed lens is
given by its field of view).

Example
-------
>>> text = lens_variant_text("raspberry-pi-hq-6mm", 25.0)
>>> 'focal_length_mm = { value = 25.0' in text
True
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from camera_models.camera import load_camera
from scenes.hardware import add_hardware_file, hardware_source

__all__ = ["lens_variant_name", "lens_variant_text", "register_lens_variant"]

_FOCAL = re.compile(r"^focal_length_mm\s*=.*$", re.M)


def lens_variant_name(camera: str, focal_length_mm: float) -> str:
    """The variant's camera name: ``<camera>-f<focal>mm``."""
    return f"{camera}-f{focal_length_mm:.4g}mm"


def lens_variant_text(camera: str, focal_length_mm: float) -> str:
    """The camera file of ``camera`` with a ``focal_length_mm`` lens (ValueError, one line, for a camera
    whose file has no focal length or a focal length out of (0, 2000] mm)."""
    if not (
        isinstance(focal_length_mm, int | float) and math.isfinite(focal_length_mm) and 0 < focal_length_mm <= 2000
    ):
        raise ValueError(f"focal_length_mm: expected a focal length in (0, 2000] mm, got {focal_length_mm!r}")
    text = hardware_source("camera", camera).text
    if not _FOCAL.search(text) or re.search(r"^diagonal_fov_deg\s*=", text, re.M):
        raise ValueError(f"camera: {camera} has a fixed lens (its file gives no interchangeable focal length)")
    why = (
        f"a design candidate: {camera}'s body with a {focal_length_mm:g} mm lens of the same family at the same "
        "f-number, blur, distortion and glare (the base lens's, assumed)"
    )
    text = _FOCAL.sub(f'focal_length_mm = {{ value = {float(focal_length_mm)!r}, assumed = "{why}" }}', text, count=1)
    text = re.sub(r"^name\s*=.*$", f'name = "{lens_variant_name(camera, focal_length_mm)}"', text, count=1, flags=re.M)
    return re.sub(
        r"^description\s*=.*$",
        f'description = "{camera} with a {focal_length_mm:g} mm lens"',
        text,
        count=1,
        flags=re.M,
    )


def register_lens_variant(camera: str, focal_length_mm: float, folder: Path) -> str:
    """Write the variant's file into ``folder``, register it and check it loads; returns its name."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{lens_variant_name(camera, focal_length_mm)}.toml"
    path.write_text(lens_variant_text(camera, focal_length_mm))
    name = add_hardware_file("camera", path)
    load_camera(name)  # every field checked now, not at the first capture
    return name
