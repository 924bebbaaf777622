"""A parametric beacon: the design choices a builder makes, of which V1 and V2 are two instances.

The built beacons (``scenes/data/beacons/v1.toml``, ``v2.toml``) differ in where the markers sit:
the in-plane markers' offset from the centre (``arm_length_mm``: V1 45 mm, V2 70 mm), the centre
marker's offset out of the plane (``out_of_plane_mm``), which way the in-plane LEDs face, and the
lit face each marker shows. :class:`BeaconParameters` holds those choices; everything else of a
beacon (housing walls and finishes, the node, d_t) comes from a ``base`` beacon's file, with its
sources. The LED part of each side is its colour's default unless ``leds`` names another of that
colour (``scenes/data/led_parts.toml``). :meth:`BeaconParameters.text` writes the beacon file of an
instance (the base's file with the chosen values, each marked ``assumed`` as a design candidate), which
:func:`scenes.hardware.add_hardware_file` registers like any user's beacon (``register``), so the
renderer, the detectors and the pose solvers all see the same geometry.

What a scenario sets per run completes the design: the LED drive, the diffuser stack (foam, paper
sheets and colour) and the housing finish (:class:`scenes.scenario.Scenario`).

Example
-------
>>> p = BeaconParameters.of("v2")
>>> (p.arm_length_mm, p.out_of_plane_mm, p.span_mm)
(70.0, 46.0, 152.0)
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, fields
from pathlib import Path

from scenes.beacon import BeaconDesign, beacon_design
from scenes.hardware import add_hardware_file, hardware_source
from scenes.led import check_hue, led_part

__all__ = ["FACES", "BeaconParameters"]

FACES = ("viewer", "outward")
"""Which way the in-plane LEDs face (``in_plane_leds_face`` of a beacon file)."""

_NUMBERS = ("arm_length_mm", "out_of_plane_mm", "lit_face_diameter_mm")


@dataclass(frozen=True)
class BeaconParameters:
    """The marker geometry of a beacon (mm), on a base beacon's housing and node.

    Attributes
    ----------
    arm_length_mm
        In-plane markers' offset from the centre, mm (> half the lit face, ≤ 2000).
    out_of_plane_mm
        Centre marker's offset in front of the plane, mm (≥ 0).
    lit_face_diameter_mm
        Diameter of each marker's lit face, mm (> 0, ≤ 200).
    in_plane_leds_face
        ``viewer`` (the LEDs' axes toward the viewer) or ``outward`` (along their arms).
    base
        The beacon whose file gives everything else (housing, node, d_t), with its sources.
    leds
        (side, LED part) of the sides that do not use their colour's default part
        (:func:`scenes.led.led_parts`; the file's ``[leds]`` table), sorted by side.
    hues_nm
        (side, dominant wavelength, nm) of the sides given another colour within their colour's band
        (:func:`scenes.led.check_hue`; the file's ``[dominant_wavelength_nm]`` table), sorted by side.
    """

    arm_length_mm: float
    out_of_plane_mm: float
    lit_face_diameter_mm: float
    in_plane_leds_face: str = "viewer"
    base: str = "v2"
    leds: tuple[tuple[str, str], ...] = ()
    hues_nm: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        for name in _NUMBERS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or value != value:
                raise ValueError(f"{name}: expected a number of mm, got {value!r}")
        for name in ("arm_length_mm", "lit_face_diameter_mm"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name}: expected a size > 0 mm, got {getattr(self, name)!r}")
        if self.out_of_plane_mm < 0:
            raise ValueError(f"out_of_plane_mm: expected an offset >= 0 mm, got {self.out_of_plane_mm!r}")
        for side, part in self.leds:
            try:
                led_part(part, side)
            except ValueError as exc:
                raise ValueError(f"leds.{side}: {str(exc).removeprefix('led: ')}") from None
        if list(self.leds) != sorted(dict(self.leds).items()):
            raise ValueError(f"leds: expected (side, part) pairs sorted by side, one per side, got {self.leds!r}")
        for side, nm in self.hues_nm:
            check_hue(side, nm)
        if list(self.hues_nm) != sorted(dict(self.hues_nm).items()):
            raise ValueError(f"hues_nm: expected (side, nm) pairs sorted by side, one per side, got {self.hues_nm!r}")
        if self.in_plane_leds_face not in FACES:
            raise ValueError(f"in_plane_leds_face: expected one of {', '.join(FACES)}, got {self.in_plane_leds_face!r}")

    @classmethod
    def of(cls, name: str) -> BeaconParameters:
        """The parameters of an existing beacon (``v1``, ``v2`` or a user's file)."""
        d: BeaconDesign = beacon_design(name)
        face = re.search(r'^in_plane_leds_face\s*=\s*"(\w+)"', hardware_source("beacon", name).text, re.M)
        return cls(
            arm_length_mm=round(d.arm_length_m * 1e3, 9),
            out_of_plane_mm=round(d.out_of_plane_m * 1e3, 9),
            lit_face_diameter_mm=round(d.lit_face_diameter_m * 1e3, 9),
            in_plane_leds_face=face.group(1) if face else "viewer",
            base=name,
            leds=d.led_parts,
            hues_nm=d.led_dominant_nm,
        )

    @property
    def span_mm(self) -> float:
        """The target's extent across its in-plane markers, lit faces included, mm (its size)."""
        return 2 * self.arm_length_mm + self.lit_face_diameter_mm

    @property
    def name(self) -> str:
        """A name that says what the instance is and cannot clash between different ones."""
        # an empty table is left out, so that names made before it existed stay the same
        tables = ("leds", "hues_nm")
        values = tuple(getattr(self, f.name) for f in fields(self) if f.name not in tables or getattr(self, f.name))
        digest = hashlib.sha256(repr(values).encode()).hexdigest()[:8]
        sizes = f"arm{self.arm_length_mm:.4g}-out{self.out_of_plane_mm:.4g}-face{self.lit_face_diameter_mm:.4g}"
        return f"{self.base}-{sizes}-{digest}"

    def text(self) -> str:
        """The instance's beacon file: the base's file with these values, each ``assumed`` as a candidate."""
        why = "a design candidate (scenes.parametric_beacon), not a built beacon"
        out = []
        in_leds = False
        for line in hardware_source("beacon", self.base).text.splitlines():
            if line.strip().startswith("["):
                in_leds = line.strip() in ("[leds]", "[dominant_wavelength_nm]")
            if in_leds:  # the base's own parts and colours: replaced by this instance's tables below
                continue
            key = line.split("=", 1)[0].strip()
            if key == "name":
                line = f'name = "{self.name}"'
            elif key == "description":
                line = (
                    f'description = "{self.base} with in-plane markers {self.arm_length_mm:g} mm from the centre, '
                    f'centre marker {self.out_of_plane_mm:g} mm in front, {self.lit_face_diameter_mm:g} mm lit faces"'
                )
            elif key in _NUMBERS:
                line = f'{key} = {{ value = {float(getattr(self, key))!r}, assumed = "{why}" }}'
            elif key == "in_plane_leds_face":
                line = f'in_plane_leds_face = "{self.in_plane_leds_face}"'
            out.append(line)
        if self.leds:
            out += ["", "[leds]", *(f'{side} = "{part}"' for side, part in self.leds)]
        if self.hues_nm:
            out += ["", "[dominant_wavelength_nm]"]
            out += [f'{side} = {{ value = {float(nm)!r}, assumed = "{why}" }}' for side, nm in self.hues_nm]
        return "\n".join(out) + "\n"

    def register(self, folder: Path) -> str:
        """Write the instance's file into ``folder`` and register it (:func:`scenes.hardware.add_hardware_file`);
        returns its beacon name. The file is checked as any beacon file is (one-line errors naming the field)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.name}.toml"
        path.write_text(self.text())
        name = add_hardware_file("beacon", path)
        beacon_design(name)  # its geometry checked now (e.g. the node behind the targets), not at the first render
        return name
