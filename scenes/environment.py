"""Environments: a cave dark zone, a dark room and a lit room.

Each is a box around the camera-beacon line (floor, ceiling, side walls, a wall behind
the beacon and one behind the camera) with grey diffuse surfaces. Rooms are lit by a
uniformly luminous ceiling, a Lambertian panel whose radiance L is set so that the
*direct* horizontal illuminance at target height under the beacon equals the stated
illuminance E; inter-reflections from the walls add to that, as in a real room.
The ceiling's spectrum is a CIE illuminant from colour-science.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from scenes import spectra
from scenes.sourced import DATA_DIR, load_sourced

__all__ = ["ENVIRONMENT_NAMES", "Environment", "environment", "load_environments"]

ENVIRONMENT_NAMES = ("dark", "dark-room", "lit-room")


@dataclass(frozen=True)
class Environment:
    """An environment definition (lengths in m, illuminance in lux)."""

    name: str
    description: str
    kind: str  # "cave" or "room"
    illuminance_lux: float
    illuminant: str  # CIE illuminant name, or "none"
    wall_reflectance: float
    floor_reflectance: float
    width_m: float
    height_m: float
    back_wall_m: float
    front_wall_m: float

    @property
    def has_ambient(self) -> bool:
        """Whether any light other than the beacon's exists."""
        return self.illuminance_lux > 0.0 and self.illuminant != "none"

    def ceiling_luminance_cd_m2(self, target_height_m: float, s0_m: float, s1_m: float) -> float:
        """Luminance of the luminous ceiling giving the stated direct illuminance, cd·m⁻².

        E = L ∬ cos θ cos θ' / r² dA over the ceiling panel, which spans [s0, s1] along
        the camera-beacon line and the box's width across it, evaluated on a horizontal
        surface at target height on the beacon's axis (2-D trapezoid quadrature).
        """
        if not self.has_ambient:
            return 0.0
        h = self.height_m - target_height_m
        if h <= 0:
            raise ValueError(f"{self.name}: targets above the ceiling")
        xs = np.linspace(s0_m, s1_m, max(201, int(40 * (s1_m - s0_m))))
        ys = np.linspace(-self.width_m / 2, self.width_m / 2, 401)
        r2 = xs[:, None] ** 2 + ys[None, :] ** 2 + h * h
        geometric_sr = np.trapezoid(np.trapezoid(h * h / (r2 * r2), ys, axis=1), xs)
        return self.illuminance_lux / geometric_sr

    def ceiling_radiance_W_m2_sr(self, target_height_m: float, s0_m: float, s1_m: float) -> float:
        """Radiance of the luminous ceiling (integrated over wavelength), W·m⁻²·sr⁻¹."""
        if not self.has_ambient:
            return 0.0
        efficacy = spectra.luminous_efficacy_lm_per_W(spectra.illuminant_shape(self.illuminant))
        return self.ceiling_luminance_cd_m2(target_height_m, s0_m, s1_m) / efficacy

    def spectral_shape(self):
        """Normalised spectrum of the ambient light, nm⁻¹ (None in the dark)."""
        return spectra.illuminant_shape(self.illuminant) if self.has_ambient else None


@lru_cache(maxsize=1)
def load_environments() -> dict[str, Environment]:
    """All environments of ``scenes/data/environments.toml``."""
    values, _ = load_sourced(DATA_DIR / "environments.toml")
    envs = {name: Environment(name=name, **fields) for name, fields in values.items()}
    for env in envs.values():
        if env.kind not in ("cave", "room"):
            raise ValueError(f"environments.toml {env.name}.kind: expected cave|room")
        if env.illuminant != "none":
            spectra.illuminant_shape(env.illuminant)  # fails early on unknown names
        if not math.isfinite(env.illuminance_lux) or env.illuminance_lux < 0:
            raise ValueError(f"environments.toml {env.name}.illuminance_lux: expected >= 0")
    return envs


def environment(name: str) -> Environment:
    """The environment called ``name``."""
    envs = load_environments()
    if name not in envs:
        raise ValueError(f"environment: expected one of {', '.join(envs)}, got {name!r}")
    return envs[name]
