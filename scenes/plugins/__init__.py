"""The project's Mitsuba plugins, one per module, registered here in one place.

* ``marker_face`` (:mod:`scenes.plugins.marker_face`): the LED / lit-face area emitter
  with a cosine-power or tabulated angular pattern.
* ``diffuse_sheet`` (:mod:`scenes.plugins.diffuse_sheet`): a thin Lambertian
  reflector/transmitter (paper).

Both are written in Python; Dr.Jit traces them into the same compiled kernels as the
C++ plugins in the LLVM and CUDA variants. They support the mono and RGB variants
(grey), which is all the project renders with.
"""

from __future__ import annotations

import mitsuba as mi

from scenes.plugins.diffuse_sheet import diffuse_sheet_class
from scenes.plugins.marker_face import marker_face_class

PLUGINS = {
    "marker_face": ("emitter", marker_face_class),
    "diffuse_sheet": ("bsdf", diffuse_sheet_class),
}
"""Plugin name → (Mitsuba plugin kind, factory building the class for the active variant)."""

_REGISTERED: set[str] = set()


def register_plugins() -> None:
    """Register every plugin of :data:`PLUGINS` with the active Mitsuba variant (idempotent).

    Each factory builds its class against the active variant's ``mi.Emitter`` / ``mi.BSDF``.
    """
    variant = mi.variant()
    if variant in _REGISTERED:
        return
    register = {"emitter": mi.register_emitter, "bsdf": mi.register_bsdf}
    for name, (kind, factory) in PLUGINS.items():
        cls = factory()
        register[kind](name, lambda props, cls=cls: cls(props))
    _REGISTERED.add(variant)
