"""Commands of the robot's view: a traverse through a lava tube with a ring of cameras."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from scenes.dust import extinction_per_m
from studies.cli import options as opt
from studies.cli.common import UsageError, console, execution, out_path, parse_list, rich_progress
from studies.cli.out_folder import prepare_out_dir
from studies.engine.run_log import timed_part

__all__ = ["COMMANDS", "traverse"]


def traverse(
    out: Annotated[Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory.")],
    camera: Annotated[str, typer.Option("--camera", help="Ring camera (see 'beacon-sim cameras').")] = "spedal-920",
    cameras_n: Annotated[int, typer.Option("--cameras-n", help="Cameras on the ring (the study: 6).")] = 6,
    radius_m: Annotated[float, typer.Option("--radius-m", help="Ring radius, m (the study: 0.2).")] = 0.2,
    spacing_m: Annotated[str, typer.Option("--spacing-m", help="Beacon spacings to try, m, comma-separated.")] = (
        "5,10,15,20,25,30,40"
    ),
    path_m: Annotated[float, typer.Option("--path-m", help="Length of the drive, m.")] = 50.0,
    seeds: Annotated[int, typer.Option("--seeds", help="Runs per spacing (slip, noise and detections).")] = 5,
    threshold_m: Annotated[
        float, typer.Option("--threshold-m", help="Position error the answer keeps under along the whole path, m.")
    ] = 1.0,
    detections: Annotated[
        Path | None,
        typer.Option(
            "--detections",
            help="A range-limit summary.json whose measured P(correct) per range and yaw is the camera's detection "
            "probability.",
            show_default="results/full/range-limit.summary.json",
        ),
    ] = None,
    rendered: Annotated[
        bool,
        typer.Option(
            "--rendered",
            help="Render a whole frame for every beacon side a camera sees (up to 1.5x the detection table's "
            "farthest correct range) and detect in it, instead of drawing detections from the table.",
        ),
    ] = False,
    step_m: Annotated[float, typer.Option("--step-m", help="Odometry step, m.")] = 0.25,
    bend_deg: Annotated[
        float,
        typer.Option("--bend-deg", help="The tube turns by this angle (degrees, positive to the left; 0: straight)."),
    ] = 0.0,
    bend_at_m: Annotated[float, typer.Option("--bend-at-m", help="Where along the tube the bend starts, m.")] = 20.0,
    bend_radius_m: Annotated[
        float, typer.Option("--bend-radius-m", help="Radius of the bend's centreline, m (> half the width).")
    ] = 6.0,
    dust_visibility_m: Annotated[
        float | None,
        typer.Option(
            "--dust-visibility-m",
            help="Airborne dust of this visual range (Koschmieder: extinction 3.912 / V per m); needs --rendered.",
            show_default="clear air",
        ),
    ] = None,
    tube_width_m: Annotated[float, typer.Option("--tube-width-m", help="Wall to wall, m.")] = 3.0,
    tube_height_m: Annotated[
        float | None,
        typer.Option("--tube-height-m", help="Floor to ceiling, m (rendered frames).", show_default="5, tube.toml"),
    ] = None,
    slope_deg: Annotated[
        float,
        typer.Option(
            "--slope-deg",
            help="The tube's floor rises by this angle along it (degrees, rendered frames: camera heights and pitch).",
        ),
    ] = 0.0,
    tube_walls: Annotated[
        bool,
        typer.Option(
            "--tube-walls/--no-tube-walls",
            help="Rendered frames hold the tube's basalt walls, ceiling and rough floor (scenes/data/tube.toml); "
            "off: the dark environment's box around each camera-beacon line.",
        ),
    ] = True,
    wall_reflectance: Annotated[
        float | None,
        typer.Option(
            "--wall-reflectance",
            help="Grey reflectance of the tube's walls, ceiling and floor in rendered frames (dusty walls 0.15-0.28).",
            show_default="basalt 0.07",
        ),
    ] = None,
    slip_sd: Annotated[
        float,
        typer.Option(
            "--slip-sd",
            help="The wheels' slip wanders along the run with this standard deviation about the run's drawn slip "
            "(0: constant; pipeline.odometry.LOOSE_SAND: 0-0.15).",
        ),
    ] = 0.0,
    slip_correlation_m: Annotated[
        float,
        typer.Option("--slip-correlation-m", help="Distance over which the slip's changes are correlated (1/e), m."),
    ] = 10.0,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick", help="20 m, spacings 5 and 10 m, two seeds; with --rendered: 10 m in 0.5 m steps, one seed."
        ),
    ] = False,
    beacon: opt.Beacon = "v2",
    workers: opt.Workers = None,
    scheduler: opt.Scheduler = None,
) -> None:
    """Drive a ring of cameras through a lava tube with beacons every D m: per step the detections, their
    fused pose and wheel odometry corrected by it (EKF); the largest spacing that keeps the error under
    the threshold (report.html, summary.json, steps.parquet)."""
    from studies.catalog import traverse as tr

    spacings = parse_list("spacing-m", spacing_m, float)
    if quick:
        spacings, path_m, seeds = ((5.0, 10.0), 10.0, 1) if rendered else ((5.0, 10.0), 20.0, 2)
        step_m = 0.5 if rendered else step_m
    if not spacings or not all(s > 0 for s in spacings):
        raise UsageError(f"spacing-m: expected spacings > 0 m, got {spacing_m}")
    if seeds < 1:
        raise UsageError(f"seeds: expected an integer >= 1, got {seeds}")
    if not threshold_m > 0:
        raise UsageError(f"threshold-m: expected an error > 0 m, got {threshold_m:g}")
    if dust_visibility_m is not None and not dust_visibility_m > 0:
        raise UsageError(f"dust-visibility-m: expected a visual range > 0 m, got {dust_visibility_m:g}")
    if dust_visibility_m is not None and not rendered:
        raise UsageError("dust-visibility-m: dust acts on rendered frames; add --rendered")
    if slope_deg and not rendered:
        raise UsageError("slope-deg: the slope acts on rendered frames; add --rendered")
    if wall_reflectance is not None and not rendered:
        raise UsageError("wall-reflectance: the walls are in rendered frames; add --rendered")
    settings = tr.Traverse(
        camera=camera, cameras_n=cameras_n, radius_m=radius_m, beacon=beacon, path_m=path_m, step_m=step_m,
        bend_deg=bend_deg, bend_at_m=bend_at_m, bend_radius_m=bend_radius_m, slope_deg=slope_deg,
        tube_width_m=tube_width_m, **({} if tube_height_m is None else {"tube_height_m": tube_height_m}),
        tube_walls=tube_walls, wall_reflectance=wall_reflectance,
        odometry={"slip_sd": slip_sd, "slip_correlation_m": slip_correlation_m},
        dust_extinction_per_m=0.0 if dust_visibility_m is None else extinction_per_m(dust_visibility_m),
    )  # fmt: skip
    source = detections or tr.DEFAULT_TABLE
    try:
        settings.validate()
        if not source.is_file():
            raise ValueError(f"detections: expected a range-limit summary.json, {source} is not a file")
        table = tr.DetectionTable.from_summary(source, camera, beacon=beacon)
    except ValueError as exc:
        raise UsageError(str(exc).splitlines()[0]) from None
    run_on = execution(workers, scheduler, cache=rendered)
    prepare_out_dir(out)
    with timed_part(out, tr.NAME):
        summary = tr.run(
            out,
            settings,
            spacings_m=spacings,
            seeds=seeds,
            threshold_m=threshold_m,
            table=table,
            progress=rich_progress,
            rendered=rendered,
            workers=run_on.workers,
            scheduler=run_on.scheduler,
        )
    console.print(f"traverse: {summary['spacing_answer']}; {summary['wall_s']:.0f} s; wrote {out}/report.html")


COMMANDS = {"traverse": traverse}
