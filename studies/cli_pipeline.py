"""Pipeline commands of ``beacon-sim``: ``detect`` and ``calibrate`` (registered on import)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from studies.cli import UsageError, app, prepare_out_dir


def _crop_origin(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        u, v = (int(p) for p in text.split(","))
    except ValueError:
        raise UsageError(f"crop-origin: expected U,V in pixels, got {text!r}") from None
    return u, v


@app.command("detect")
def detect_command(
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
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Find the beacon side in an image and estimate the camera's range and attitude."""
    from pipeline.calibration import load_calibration
    from pipeline.detect import detect
    from pipeline.image_io import load_image

    cal = load_calibration(calibration) if calibration is not None else None
    pixels = load_image(image)
    result = detect(
        pixels, camera, tracker=tracker, estimator=estimator, beacon=beacon, calibration=cal, alpha=alpha,
        crop_origin_px=_crop_origin(crop_origin), ring_camera=ring_camera,
    )  # fmt: skip
    if result.reason and result.reason.startswith("image:"):
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


@app.command("calibrate")
def calibrate_command(
    images: Annotated[list[Path], typer.Argument(help="Checkerboard photos (same size).")],
    out: Annotated[Path, typer.Option("--out", help="Calibration file to write (JSON).")],
    pattern: Annotated[str, typer.Option("--pattern", help="Inner corners per row x per column.")] = "8x6",
    square_mm: Annotated[float, typer.Option("--square-mm", help="Square size, mm.")] = 24.4,
) -> None:
    """Calibrate a camera from checkerboard photos (OpenCV calibrateCamera) and write a JSON file."""
    from pipeline.calibration import calibrate

    try:
        cols, rows = (int(p) for p in pattern.lower().split("x"))
    except ValueError:
        raise UsageError(f"pattern: expected COLSxROWS inner corners, e.g. 8x6, got {pattern!r}") from None
    if not square_mm > 0:
        raise UsageError(f"square-mm: expected a size > 0 mm, got {square_mm!r}")
    if out.parent != Path():
        prepare_out_dir(out.parent)
    cal = calibrate(list(images), (cols, rows), square_mm * 1e-3)  # paths: one image in memory at a time
    cal.save(out)
    k = cal.camera_matrix
    Console(stderr=True).print(
        f"wrote {out}: {cal.n_images} of {len(images)} views, RMS {cal.rms_px:.3f} px, "
        f"fx {k[0, 0]:.1f}, fy {k[1, 1]:.1f}, cx {k[0, 2]:.1f}, cy {k[1, 2]:.1f} px"
    )


@app.command("e2e-detection")
def e2e_detection_command(
    out: Annotated[Path, typer.Option("--out", help="Output directory (CSV tables, summary.md, config.json).")],
    seeds: Annotated[
        int | None,
        typer.Option("--seeds", help="Sensor-noise seeds per condition, 0..N-1 (default 3; 1 with --quick)."),
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="Ranges 1, 3, 5 m × yaws 0, 15, 30° and one seed (unless --seeds).")
    ] = False,
    full_frame_check: Annotated[
        bool | None,
        typer.Option(
            "--full-frame-check/--no-full-frame-check",
            help="Also detect on one full 18 MP frame (2 m, 15°), compare with the crop (default: not with --quick).",
        ),
    ] = None,
) -> None:
    """Issue 5's end-to-end table: T6 + 18 mm captures of the V2 red side, 1-5 m × 0-30°, both trackers × estimators."""
    from studies.e2e_detection import (
        QUICK_RANGES_M,
        QUICK_YAWS_DEG,
        RANGES_M,
        YAWS_DEG,
        E2EConfig,
        run_e2e,
        write_outputs,
    )
    from studies.e2e_detection import full_frame_check as run_full_frame_check

    n_seeds = seeds if seeds is not None else (1 if quick else 3)
    if n_seeds < 1:
        raise UsageError(f"seeds: expected an integer >= 1, got {seeds}")
    prepare_out_dir(out)
    console = Console(stderr=True)
    config = E2EConfig()
    console.print(config.describe())
    ranges, yaws = (QUICK_RANGES_M, QUICK_YAWS_DEG) if quick else (RANGES_M, YAWS_DEG)
    result = run_e2e(ranges, yaws, range(n_seeds), config, progress=console.print)
    if full_frame_check if full_frame_check is not None else not quick:
        import time

        t0 = time.perf_counter()
        result.full_frame_check = run_full_frame_check(config)
        result.seconds["full_frame_check"] = time.perf_counter() - t0
    paths = write_outputs(result, out)
    console.print(f"wrote {', '.join(str(p) for p in paths.values())} in {result.seconds['total']:.0f} s")
