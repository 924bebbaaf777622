"""Values of the scene data files a scenario may replace: the unknowns that decide blob size and colour.

The LEDs' luminous intensity bin, the foam's optical depth and thickness, the paper's sheet
transmittance and the beacon's lit-face diameter are read from ``scenes/data`` files, each with
its source or assumption; none of them was measured for the built hardware
(``studies/data/unknowns.toml`` gives their ranges). A :class:`scenes.scenario.Scenario` may
replace them (``Scenario.data``: path → value), so that a calibration can vary them per frame.

Each settable path is a :class:`DataPath` in :data:`DATA_PATHS`, with how it acts:

``gain``    it only scales emitted light (the LED's intensity): light transport is linear, so a
            cached render is rescaled exactly and no render key changes
``render``  it changes the near field or the geometry (foam, paper, lit face): it is part of the
            scene description and so of every render-cache key

Paths name the data file and the key as the files do (``leds.red.luminous_intensity_cd`` is
``luminous_intensity_cd`` of table ``red`` in ``scenes/data/leds.toml``;
``beacons.v2.lit_face_diameter_mm`` is a key of ``scenes/data/beacons/v2.toml``, and applies to
scenarios of that beacon only).

>>> check_data_overrides({"leds.red.luminous_intensity_cd": 6.0}, beacon="v2")
(('leds.red.luminous_intensity_cd', 6.0),)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from scenes.beacon import HOUSING_FINISHES
from scenes.led import SIDE_COLOURS

__all__ = ["DATA_PATHS", "GAIN", "RENDER", "DataPath", "check_data_overrides", "data_path"]

GAIN = "gain"
RENDER = "render"


@dataclass(frozen=True)
class DataPath:
    """One settable data-file value.

    Attributes
    ----------
    pattern
        The path, with ``{colour}`` or ``{beacon}`` standing for a side colour or a beacon name.
    acts
        :data:`GAIN` or :data:`RENDER` (module docstring).
    low, high
        Physically possible values (exclusive low, inclusive high), in ``unit``: the bounds of the
        model, not the unknown's plausible range (that is the registry's).
    unit
        Unit of the value.
    why
        Where the bounds come from.
    """

    pattern: str
    acts: str
    low: float
    high: float
    unit: str
    why: str
    closed_low: bool = False
    """Whether ``low`` itself is allowed (an opaque wall's transmittance 0), else only values above it."""


DATA_PATHS: dict[str, DataPath] = {
    p.pattern: p
    for p in (
        DataPath(
            "leds.{colour}.luminous_intensity_cd",
            GAIN,
            0.0,
            1000.0,
            "cd",
            "any positive intensity; 1000 cd at 20 mA is far beyond any 5 mm lamp (guards against a unit slip)",
        ),
        DataPath(
            "diffusers.foam.reduced_optical_depth",
            RENDER,
            0.0,
            100.0,
            "",
            "τ' > 0; at τ' = 100 the foam passes under 1 % (scenes.diffusers.foam_transmittance_diffusion)",
        ),
        DataPath(
            "diffusers.foam.thickness_mm",
            RENDER,
            0.0,
            5.5,
            "mm",
            "the near-field geometry (scenes/near_field.py): the foam's top lies 0.5 mm under the face and "
            "the LED's lens 6 mm under it, so a thicker disc would overlap the LED",
        ),
        DataPath(
            "diffusers.paper.sheet_transmittance",
            RENDER,
            0.0,
            1.0,
            "",
            "0 < T, and T + R ≤ 1 with the file's sheet reflectance (no negative absorption: checked by "
            "scenes.diffusers.DiffuserConfig.validate)",
        ),
        DataPath(
            "beacons.{beacon}.lit_face_diameter_mm",
            RENDER,
            5.0,
            30.0,
            "mm",
            "the bore must hold the LED's 5 mm lens (scenes/data/leds.toml); at 30 mm the faces of V1's markers, "
            "45 mm apart, would nearly touch",
        ),
        DataPath(
            "beacons.{beacon}.housing_transmittance.{finish}",
            RENDER,
            0.0,
            1.0,
            "",
            "0 (opaque) to 1 - the finish's reflectance (checked by scenes.beacon.BeaconDesign)",
            closed_low=True,
        ),
    )
}
"""The settable paths (:class:`DataPath` by pattern)."""


def data_path(path: str) -> tuple[DataPath, dict[str, str]]:
    """The :class:`DataPath` a concrete path matches, and what its placeholders stand for.

    >>> data_path("leds.green.luminous_intensity_cd")[1]
    {'colour': 'green'}
    """
    parts = path.split(".") if isinstance(path, str) else []
    for pattern, spec in DATA_PATHS.items():
        want = pattern.split(".")
        if len(want) != len(parts):
            continue
        bound: dict[str, str] = {}
        for w, p in zip(want, parts, strict=True):
            if w == "{colour}" and p in SIDE_COLOURS:
                bound["colour"] = p
            elif w == "{beacon}" and p.isidentifier():
                bound["beacon"] = p
            elif w == "{finish}" and p in HOUSING_FINISHES:
                bound["finish"] = p
            elif w != p:
                break
        else:
            return spec, bound
    expected = ", ".join(DATA_PATHS)
    raise ValueError(f"data: {path!r} is not a settable data-file value (expected one of {expected})")


def check_data_overrides(overrides: Mapping[str, Any] | tuple, *, beacon: str) -> tuple[tuple[str, float], ...]:
    """The overrides as a sorted tuple of (path, value), checked: each path settable, each value a finite
    number within its :class:`DataPath` bounds, beacon paths only for ``beacon``.

    Raises
    ------
    ValueError
        One line naming the path and what was expected.
    """
    items = overrides.items() if isinstance(overrides, Mapping) else overrides
    out: dict[str, float] = {}
    for item in items:
        if not (isinstance(item, tuple | list) and len(item) == 2):
            raise ValueError(f"data: expected path → value pairs, got {item!r}")
        path, value = item
        spec, bound = data_path(path)
        if bound.get("beacon", beacon) != beacon:
            raise ValueError(f"data.{path}: names beacon {bound['beacon']!r}, but the scenario's beacon is {beacon!r}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ValueError(f"data.{path}: expected a finite number, got {value!r}")
        above = spec.low <= float(value) if spec.closed_low else spec.low < float(value)
        if not (above and float(value) <= spec.high):
            unit = f" {spec.unit}" if spec.unit else ""
            low = "<=" if spec.closed_low else "<"
            raise ValueError(
                f"data.{path}: expected {spec.low:g} {low} value <= {spec.high:g}{unit} ({spec.why}), got {value!r}"
            )
        if path in out:
            raise ValueError(f"data.{path}: given more than once")
        out[path] = float(value)
    return tuple(sorted(out.items()))
