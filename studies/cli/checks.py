"""Checks of the model against independent answers, each a command that prints JSON:
``two-stage-check`` (two-stage marker vs brute-force volumetric rendering),
``lens-calibration`` (the study's checkerboard calibration through our lens model) and
``estimator-montecarlo`` (pose estimators against the Cramér–Rao bound)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from camera_models.camera import load_camera
from pipeline.calibration import CV_MODELS
from scenes.near_field import NearFieldSettings
from studies.cli import options as opt
from studies.cli.common import UsageError, console
from studies.experiments import estimator_montecarlo, lens_calibration, two_stage_check


def two_stage_check_command(
    view_deg: Annotated[float, typer.Option("--view-deg", help="Viewing angle off the marker's axis, degrees.")] = 10.0,
    range_m: opt.RangeM = 5.0,
    brute_spp: Annotated[int, typer.Option("--brute-spp", help="Samples per pixel of each brute-force pass.")] = 1024,
    brute_passes: Annotated[int, typer.Option("--brute-passes", help="Independent brute-force passes.")] = 32,
    near_field_spp: Annotated[int, typer.Option("--near-field-spp", help="Samples of the near-field render.")] = 256,
) -> None:
    """Render one diffused marker two-stage and brute force; print fluxes, their z-score and the profile χ²."""
    for name, value in (("brute-spp", brute_spp), ("brute-passes", brute_passes), ("near-field-spp", near_field_spp)):
        if value < 2:
            raise UsageError(f"{name}: expected an integer >= 2, got {value}")
    view = two_stage_check.MarkerView(range_m=range_m, view_deg=view_deg)
    with console.status("rendering the marker both ways ..."):
        result = two_stage_check.compare(view, brute_spp, brute_passes, NearFieldSettings(spp=near_field_spp))
    print(json.dumps(result.to_dict(), indent=2))


def lens_calibration_command(
    camera: opt.Camera = "canon-t6-18mm",
    model: Annotated[
        str, typer.Option("--model", help=f"Distortion model: {', '.join((*CV_MODELS, 'fisheye'))}.")
    ] = "rational",
    scale: Annotated[int, typer.Option("--scale", help="Reduce the pixel grid by this integer factor (speed).")] = 4,
) -> None:
    """Render the study's checkerboard through the lens model in 20 poses, calibrate with OpenCV, compare."""
    if scale < 1:
        raise UsageError(f"scale: expected an integer >= 1, got {scale}")
    load_camera(camera)  # validates the name
    with console.status(f"calibrating {camera} from rendered boards ..."):
        result = lens_calibration.calibrate(lens_calibration.scaled_camera(camera, scale), model)
    out = {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in result.__dict__.items()}
    print(json.dumps(out, indent=2))


def estimator_montecarlo_command(
    camera: opt.Camera = "canon-t6-18mm",
    range_m: opt.RangeM = 3.0,
    yaw_deg: opt.YawDeg = 20.0,
    sigma_px: Annotated[float, typer.Option("--sigma-px", help="Centroid noise, px (1 σ).")] = 0.3,
    trials: Annotated[int, typer.Option("--trials", help="Monte-Carlo trials.")] = 500,
    seed: opt.Seed = 0,
) -> None:
    """RMS range and attitude errors of each pose estimator beside the Cramér–Rao bound."""
    if trials < 2:
        raise UsageError(f"trials: expected an integer >= 2, got {trials}")
    if not sigma_px > 0:
        raise UsageError(f"sigma-px: expected a noise > 0 px, got {sigma_px}")
    result = estimator_montecarlo.pose_error_trials(camera, range_m, yaw_deg, sigma_px, trials, seed)
    print(json.dumps(result, indent=2))


COMMANDS = {
    "two-stage-check": two_stage_check_command,
    "lens-calibration": lens_calibration_command,
    "estimator-montecarlo": estimator_montecarlo_command,
}
