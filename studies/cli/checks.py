"""Checks of the model against independent answers, each a command that prints JSON:
``two-stage-check`` (two-stage marker vs brute-force volumetric rendering),
``lens-calibration`` (the study's checkerboard calibration through our lens model) and
``estimator-montecarlo`` (pose estimators against the Cramér–Rao bound)."""

from __future__ import annotations

from typing import Annotated

import typer

from camera_models.camera import load_camera
from pipeline.calibration import CV_MODELS
from scenes.near_field import NearFieldSettings
from scenes.scenario import Scenario
from studies.cli import options as opt
from studies.cli.common import UsageError, check_finite, console
from studies.engine import strict_json
from studies.experiments import estimator_montecarlo, lens_calibration, two_stage_check

__all__ = ["COMMANDS", "estimator_montecarlo_command", "lens_calibration_command", "two_stage_check_command"]


def two_stage_check_command(
    view_deg: Annotated[float, typer.Option("--view-deg", help="Viewing angle off the marker's axis, degrees.")] = 10.0,
    range_m: opt.RangeM = 5.0,
    brute_spp: Annotated[int, typer.Option("--brute-spp", help="Samples per pixel of each brute-force pass.")] = 1024,
    brute_passes: Annotated[int, typer.Option("--brute-passes", help="Independent brute-force passes.")] = 32,
    near_field_spp: Annotated[int, typer.Option("--near-field-spp", help="Samples of the near-field render.")] = 256,
) -> None:
    """Render one diffused marker two-stage and brute force; print fluxes, their z-score and the profile χ²."""
    # a brute-force pass of 2^16 samples per pixel already takes minutes; 4096 passes of it, days
    limits = (
        ("brute-spp", brute_spp, 2**16),
        ("brute-passes", brute_passes, 4096),
        ("near-field-spp", near_field_spp, 2**20),
    )
    for name, value, most in limits:
        if not 2 <= value <= most:
            raise UsageError(f"{name}: expected an integer in [2, {most}], got {value}")
    check_finite("view-deg", view_deg, -89.0, 89.0, " degrees")
    check_finite("range-m", range_m, 0.05, 100.0, " m (beyond 100 m the marker is far below a pixel)")
    view = two_stage_check.MarkerView(range_m=range_m, view_deg=view_deg)
    with console.status("rendering the marker both ways ..."):
        result = two_stage_check.compare(view, brute_spp, brute_passes, NearFieldSettings(spp=near_field_spp))
    print(strict_json.dumps(result.to_dict(), indent=2))


def lens_calibration_command(
    camera: opt.Camera = "canon-t6-18mm",
    model: Annotated[
        str, typer.Option("--model", help=f"Distortion model: {', '.join((*CV_MODELS, 'fisheye'))}.")
    ] = "rational",
    scale: Annotated[int, typer.Option("--scale", help="Reduce the pixel grid by this integer factor (speed).")] = 4,
) -> None:
    """Render the study's checkerboard through the lens model in 20 poses, calibrate with OpenCV, compare."""
    if not 1 <= scale <= 16:  # beyond 1/16 the webcams' 1280 px grid is under 80 px, too coarse for the board
        raise UsageError(f"scale: expected an integer in [1, 16], got {scale}")
    models = (*CV_MODELS, "fisheye")
    if model not in models:
        raise UsageError(f"model: expected one of {', '.join(models)}, got {model!r}")
    load_camera(camera)  # validates the name
    with console.status(f"calibrating {camera} from rendered boards ..."):
        result = lens_calibration.calibrate(lens_calibration.scaled_camera(camera, scale), model)
    out = {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in result.__dict__.items()}
    print(strict_json.dumps(out, indent=2))


def estimator_montecarlo_command(
    camera: opt.Camera = "canon-t6-18mm",
    range_m: opt.RangeM = 3.0,
    yaw_deg: opt.YawDeg = 20.0,
    sigma_px: Annotated[float, typer.Option("--sigma-px", help="Centroid noise, px (1 σ).")] = 0.3,
    trials: Annotated[int, typer.Option("--trials", help="Monte-Carlo trials.")] = 500,
    seed: opt.Seed = 0,
) -> None:
    """RMS range and attitude errors of each pose estimator beside the Cramér–Rao bound."""
    if not 2 <= trials <= 10**6:
        raise UsageError(f"trials: expected an integer in [2, 1000000], got {trials}")
    check_finite("sigma-px", sigma_px, 1e-6, 100.0, " px")
    if seed < 0:
        raise UsageError(f"seed: expected an integer >= 0, got {seed}")
    Scenario(camera=camera, range_m=range_m, yaw_deg=yaw_deg)  # validates camera, range and yaw
    result = estimator_montecarlo.pose_error_trials(camera, range_m, yaw_deg, sigma_px, trials, seed)
    print(strict_json.dumps(result, indent=2))


COMMANDS = {
    "two-stage-check": two_stage_check_command,
    "lens-calibration": lens_calibration_command,
    "estimator-montecarlo": estimator_montecarlo_command,
}
