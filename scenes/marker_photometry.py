"""Per-marker radiometric figures of a scenario: what each marker sends to the camera.

For each marker of the side facing the camera:

* ``exit_flux_W``: total radiant flux leaving the lit face (all directions), W;
* ``intensity_toward_camera_W_sr``: radiant intensity toward the camera, W·sr⁻¹, from
  the emission model (analytic cosᵐ LED, or the near-field table);
* ``lit_face_radiance_W_m2_sr``: mean radiance of the face seen from the camera,
  I / (A cos θ), W·m⁻²·sr⁻¹;
* ``irradiance_at_camera_W_m2``: the same quantity measured on the render, Σ L·Ω around
  the marker's image (includes stray light), W·m⁻², when a render is given.
"""

from __future__ import annotations

import math

import numpy as np

from scenes import spectra
from scenes.near_field import NearFieldSettings, exit_spectral_factor, marker_emission
from scenes.radiance import SpectralRadiance
from scenes.render import render
from scenes.scenario import Scenario
from scenes.view import project

__all__ = ["marker_figures", "side_to_centre_flux"]


def marker_figures(scenario: Scenario, radiance: SpectralRadiance | None = None) -> list[dict]:
    """Figures for markers 1-5 of the visible side (see module docstring)."""
    design, led, config = scenario.design, scenario.led, scenario.diffuser
    i0 = led.radiant_intensity_W_sr(scenario.current_mA)
    factor, _ = exit_spectral_factor(config, scenario.side, led)
    i0_exit = i0 * spectra.integrate_nm(led.spectral_shape * factor)
    emission = None
    if not config.is_bare:
        emission = marker_emission(
            design,
            led,
            scenario.housing,
            config,
            scenario.side,
            settings=NearFieldSettings(spp=scenario.render.near_field_spp),
        )
    rot, _ = scenario.target_to_world()
    cam = scenario.render_pose().position_m
    positions = scenario.marker_positions_world_m()
    uv = project(scenario.geometry, scenario.render_pose(), positions)
    spacing = min(np.hypot(*(uv[i] - uv[j])) for i in range(5) for j in range(i + 1, 5))
    out = []
    for k, marker in enumerate(design.markers):
        to_cam = cam - positions[k]
        cos_t = float(np.dot(to_cam, rot @ marker.normal) / np.linalg.norm(to_cam))
        theta_deg = math.degrees(math.acos(max(-1.0, min(1.0, cos_t))))
        if cos_t <= 0:
            intensity = 0.0
        elif emission is None:
            intensity = i0 * float(led.relative_intensity(math.radians(theta_deg)))
        else:
            intensity = i0_exit * emission.intensity_per_W_sr(theta_deg)
        flux = led.radiant_flux_W(scenario.current_mA) if emission is None else i0_exit * emission.exit_flux_per_W_sr()
        row = {
            "id": marker.id,
            "u_px": float(uv[k, 0]),
            "v_px": float(uv[k, 1]),
            "view_angle_deg": theta_deg,
            "exit_flux_W": flux,
            "intensity_toward_camera_W_sr": intensity,
            "lit_face_radiance_W_m2_sr": intensity / (design.lit_face_area_m2 * cos_t) if cos_t > 0 else 0.0,
        }
        if radiance is not None:
            row["irradiance_at_camera_W_m2"] = radiance.irradiance_at_pupil_W_m2(
                uv[k, 0], uv[k, 1], 0.45 * spacing, f"led:{scenario.side}"
            )
        out.append(row)
    return out


def side_to_centre_flux(scenario: Scenario, cache=None) -> float:
    """Mean irradiance at the camera's pupil from markers 2-5 over that from marker 1
    (dimensionless), measured on the render of the scenario's side (its LEDs only)."""
    radiance = render(scenario, cache, groups=[f"led:{scenario.side}"])
    uv = project(scenario.geometry, scenario.render_pose(), scenario.marker_positions_world_m())
    spacing = min(np.hypot(*(uv[i] - uv[j])) for i in range(5) for j in range(i + 1, 5))
    flux = [radiance.irradiance_at_pupil_W_m2(u, v, 0.45 * spacing, f"led:{scenario.side}") for u, v in uv]
    return float(np.mean(flux[1:]) / flux[0])
