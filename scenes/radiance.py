"""Rendered spectral radiance on (part of) a camera's pixel grid.

Light transport is linear, and every surface at beacon scale is grey, so the spectral
radiance of a render is a sum of *components*, one per light source group (each side's
LEDs, the room's ambient light), each an image times a fixed spectrum:

    L(u, v, λ) = Σ_k  image_k(u, v) · shape_k(λ)      [W·m⁻²·sr⁻¹·nm⁻¹]

``image_k`` is the component's radiance integrated over wavelength (W·m⁻²·sr⁻¹) and
``shape_k`` its emission spectrum normalised to unit integral (nm⁻¹) on
:data:`scenes.spectra.WAVELENGTHS_NM`. Changing LED drive or ambient level rescales a
component without re-rendering; a camera integrates each shape against its channel
sensitivities once and sums images.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from scenes import spectra

__all__ = ["PixelGrid", "RadianceComponent", "SpectralRadiance"]


@dataclass(frozen=True)
class PixelGrid:
    """Where rendered pixels lie on the camera's full frame.

    Camera pixels use the OpenCV convention (centre of the top-left pixel at (0, 0)).
    The render covers camera pixels [x0, x0 + width) × [y0, y0 + height), each split
    into ``oversampling``² rendered sub-pixels.

    Attributes
    ----------
    frame_width_px, frame_height_px
        Full-frame size, camera pixels.
    focal_length_px
        Focal length, camera pixels.
    principal_point_px
        (cx, cy), camera pixels.
    x0, y0, width, height
        The rendered crop, camera pixels.
    oversampling
        Rendered sub-pixels per camera pixel along each axis.
    """

    frame_width_px: int
    frame_height_px: int
    focal_length_px: float
    principal_point_px: tuple[float, float]
    x0: int
    y0: int
    width: int
    height: int
    oversampling: int

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns) of the rendered (oversampled) image."""
        return self.height * self.oversampling, self.width * self.oversampling

    def subpixel_centres_px(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Camera-pixel coordinates (u, v) of the rendered sub-pixel centres, 1-D each."""
        s = self.oversampling
        u = self.x0 + (np.arange(self.width * s) + 0.5) / s - 0.5
        v = self.y0 + (np.arange(self.height * s) + 0.5) / s - 0.5
        return u, v

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class RadianceComponent:
    """One light-source group's contribution.

    Attributes
    ----------
    name
        ``led:<side colour>`` or ``ambient``.
    image_W_m2_sr
        Radiance integrated over wavelength, W·m⁻²·sr⁻¹, shape ``PixelGrid.shape``.
    spectral_shape_per_nm
        Normalised emission spectrum on ``WAVELENGTHS_NM``, nm⁻¹.
    unit_key, unit_image, scale
        When the image is a cached unit render times ``scale`` (LED drive, ambient
        level), the unit image and a key naming it (render key and group), so later
        linear stages can do their work once per unit image and rescale.
    """

    name: str
    image_W_m2_sr: NDArray[np.float32]
    spectral_shape_per_nm: NDArray[np.float64]
    unit_key: str | None = None
    unit_image: NDArray[np.float32] | None = None
    scale: float = 1.0

    def scaled(self, factor: float) -> RadianceComponent:
        """This component with its radiance multiplied by ``factor``."""
        return replace(self, image_W_m2_sr=(self.image_W_m2_sr * np.float32(factor)), scale=self.scale * factor)


@dataclass(frozen=True)
class SpectralRadiance:
    """A render: pixel grid, components and the scenario it came from (as a dict)."""

    grid: PixelGrid
    components: tuple[RadianceComponent, ...]
    scenario: dict
    variant: str
    from_cache: bool = False

    def component(self, name: str) -> RadianceComponent:
        """The component called ``name``."""
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(f"component: no {name!r} in {[c.name for c in self.components]}")

    def total_W_m2_sr(self) -> NDArray[np.float64]:
        """Radiance integrated over wavelength, all components, W·m⁻²·sr⁻¹."""
        total = np.zeros(self.grid.shape)
        for c in self.components:
            total += c.image_W_m2_sr
        return total

    def subpixel_solid_angle_sr(self) -> NDArray[np.float64]:
        """Solid angle of each rendered sub-pixel seen through the pinhole, sr.

        Ω = (p/f)² cos³φ per camera pixel, divided by ``oversampling``²; φ is the angle
        of the sub-pixel centre off the optical axis. Shape ``PixelGrid.shape``.
        """
        g = self.grid
        u, v = g.subpixel_centres_px()
        cx, cy = g.principal_point_px
        r2 = ((u[None, :] - cx) ** 2 + (v[:, None] - cy) ** 2) / g.focal_length_px**2
        return (1.0 + r2) ** -1.5 / (g.focal_length_px * g.oversampling) ** 2

    def irradiance_at_pupil_W_m2(
        self, u_px: float, v_px: float, radius_px: float, component: str | None = None
    ) -> float:
        """Irradiance at the camera's entrance pupil from a disc of the image, W·m⁻².

        Σ L·Ω over the sub-pixels within ``radius_px`` (camera pixels) of (u, v): for a
        small source this is its intensity toward the camera over the distance
        squared, I/R². ``component`` restricts the sum to one component.
        """
        u, v = self.grid.subpixel_centres_px()
        inside = (u[None, :] - u_px) ** 2 + (v[:, None] - v_px) ** 2 <= radius_px**2
        image = self.total_W_m2_sr() if component is None else self.component(component).image_W_m2_sr
        return float(np.sum(image * self.subpixel_solid_angle_sr() * inside))

    def band_cube_W_m2_sr_nm(self) -> NDArray[np.float32]:
        """Spectral radiance averaged over the 10 nm bands, W·m⁻²·sr⁻¹·nm⁻¹.

        Shape (rows, columns, bands), bands centred on ``spectra.BAND_CENTRES_NM``.
        """
        cube = np.zeros((*self.grid.shape, spectra.BAND_CENTRES_NM.size), dtype=np.float32)
        for c in self.components:
            bands = spectra.band_average(c.spectral_shape_per_nm).astype(np.float32)
            cube += c.image_W_m2_sr[..., None] * bands
        return cube
