"""Commands for real images: ``detect`` (the robot's answer for one image) and ``calibrate``
(a camera calibration from checkerboard photos)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from pipeline.angles import Intrinsics
from pipeline.calibration import calibrate as run_calibrate
from pipeline.calibration import load_calibration
from pipeline.detect import detect as run_detect
from pipeline.failures import Failure
from pipeline.image_io import load_image
from scenes.view import camera_geometry
from studies.cli import options as opt
from studies.cli.common import UsageError, console, prepare_out_dir


def _crop_origin(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        u, v = (int(p) for p in text.split(","))
    except ValueError:
        raise UsageError(f"crop-origin: expected U,V in pixels, got {text!r}") from None
    return u, v


def detect(
    image: Annotated[Path, typer.Argument(help="JPEG, PNG, TIFF or camera raw (e.g. Canon .CR2) at full resolution.")],
    camera: Annotated[str, typer.Option("--camera", help="Camera model (see 'beacon-sim cameras').")],
    calibration: Annotated[
        Path | None, typer.Option("--calibration", help="Calibration JSON from 'beacon-sim calibrate'.")
    ] = None,
    tracker: Annotated[str, typer.Option("--tracker", help="thesis (the study's) or best.")] = "best",
    estimator: Annotated[str, typer.Option("--estimator", help="thesis (the study's) or best.")] = "best",
    beacon: Annotated[str, typer.Option("--beacon", help="Beacon design: v1 or v2.")] = "v2",
    alpha: Annotated[float, typer.Option("--alpha", help="Undistortion alpha (0: valid pixels, 1: all).")] = 0.0,
    crop_origin: Annotated[
        str | None, typer.Option("--crop-origin", help="U,V of the image's top-left pixel in the full frame (crops).")
    ] = None,
    ring_camera: Annotated[
        int | None, typer.Option("--ring-camera", help="Camera number on the 6-camera ring: report the robot's pose.")
    ] = None,
    json_out: opt.Json = False,
) -> None:
    """Find the beacon side in an image and estimate the camera's range and attitude."""
    cal = load_calibration(calibration) if calibration is not None else None
    pixels = load_image(image)
    intrinsics = Intrinsics.from_geometry(camera_geometry(camera))
    result = run_detect(
        pixels, intrinsics, tracker=tracker, estimator=estimator, beacon=beacon, calibration=cal, alpha=alpha,
        crop_origin_px=_crop_origin(crop_origin), ring_camera=ring_camera,
    )  # fmt: skip
    if result.failure is Failure.IMAGE:
        raise UsageError(result.reason)
    out = result.to_dict()
    out["image"] = str(image)
    out["camera"] = camera
    if json_out:
        print(json.dumps(out, indent=2))
        return
    _print_detection(out)


def _print_detection(out: dict) -> None:
    console = Console()
    if not out["markers"]:
        console.print(f"no target: {out['reason']}")
        return
    table = Table(title=f"{out['image']}: side {out['side'] or 'unknown'} ({out['tracker']} tracker)")
    for col in ("marker", "u px", "v px", "azimuth mrad", "elevation mrad"):
        table.add_column(col)
    for m in out["markers"]:
        table.add_row(
            str(m["id"]),
            f"{m['u']:.2f}",
            f"{m['v']:.2f}",
            f"{1e3 * m['azimuth_rad']:.3f}",
            f"{1e3 * m['elevation_rad']:.3f}",
        )
    console.print(table)
    if out["range_m"] is None:
        console.print(f"no pose: {out['reason']}")
        return
    console.print(
        f"range {out['range_m']:.4f} m; yaw {out['yaw_deg']:.2f}°, pitch {out['pitch_deg']:.2f}°, "
        f"roll {out['roll_deg']:.2f}° ({out['estimator']} estimator)"
    )
    g = out["global"]
    if g:
        console.print(
            f"global: x {g['x_m']:.3f} m, y {g['y_m']:.3f} m, z {g['z_m']:.3f} m, yaw {g['yaw_deg']:.2f}°, "
            f"pitch {g['pitch_deg']:.2f}°, roll {g['roll_deg']:.2f}°"
        )
    for note in out["notes"]:
        console.print(f"note: {note}")


def calibrate(
    images: Annotated[list[Path], typer.Argument(help="Checkerboard photos (same size).")],
    out: Annotated[Path, typer.Option("--out", help="Calibration file to write (JSON).")],
    pattern: Annotated[str, typer.Option("--pattern", help="Inner corners per row x per column.")] = "8x6",
    square_mm: Annotated[float, typer.Option("--square-mm", help="Square size, mm.")] = 24.4,
) -> None:
    """Calibrate a camera from checkerboard photos (OpenCV calibrateCamera) and write a JSON file."""
    try:
        cols, rows = (int(p) for p in pattern.lower().split("x"))
    except ValueError:
        raise UsageError(f"pattern: expected COLSxROWS inner corners, e.g. 8x6, got {pattern!r}") from None
    if not square_mm > 0:
        raise UsageError(f"square-mm: expected a size > 0 mm, got {square_mm!r}")
    if out.parent != Path():
        prepare_out_dir(out.parent)
    cal = run_calibrate(list(images), (cols, rows), square_mm * 1e-3)  # paths: one image in memory at a time
    cal.save(out)
    k = cal.camera_matrix
    console.print(
        f"wrote {out}: {cal.n_images} of {len(images)} views, RMS {cal.rms_px:.3f} px, "
        f"fx {k[0, 0]:.1f}, fy {k[1, 1]:.1f}, cx {k[0, 2]:.1f}, cy {k[1, 2]:.1f} px"
    )


COMMANDS = {"detect": detect, "calibrate": calibrate}
