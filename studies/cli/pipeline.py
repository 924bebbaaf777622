"""Commands for real images: ``detect`` (the robot's answer for one image) and ``calibrate``
(a camera calibration from checkerboard photos).

``detect`` takes its intrinsics from exactly one source: a camera model (``--camera``),
a calibration file (``--calibration``, optionally with ``--camera`` when made for that
camera) or explicit values (``--fx`` [``--fy --cx --cy``], optionally ``--dist``). The
image may be the frame those describe, a crop of it (``--crop-origin``) or a resized copy
of it (same aspect ratio: the intrinsics are scaled); with explicit values it is its own
frame. Every option is checked before the image is read, and nothing is written."""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from pipeline.angles import Intrinsics, intrinsics_from_values
from pipeline.calibration import Calibration, check_dist_coeffs, check_pattern, load_calibration
from pipeline.calibration import calibrate as run_calibrate
from pipeline.detect import ESTIMATORS, REAL_PHOTO_FALSE_POSITIVES, TRACKERS, check_resize
from pipeline.detect import detect as run_detect
from pipeline.failures import Failure
from pipeline.image_io import load_image
from scenes.beacon import beacon_design
from scenes.view import camera_geometry
from studies.cli import options as opt
from studies.cli.common import UsageError, console
from studies.engine import strict_json

__all__ = ["COMMANDS", "RING_CAMERAS", "calibrate", "detect"]

RING_CAMERAS = 6
"""Cameras on the study's ring (numbered 0..5)."""


def _crop_origin(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        u, v = (int(p) for p in text.split(","))
    except ValueError:
        raise UsageError(f"crop-origin: expected U,V in pixels, got {text!r}") from None
    if u < 0 or v < 0:
        raise UsageError(f"crop-origin: expected U,V ≥ 0 px, got {text!r}")
    return u, v


def _dist(text: str | None):
    if text is None:
        return None
    try:
        values = [float(t) for t in text.split(",")]
    except ValueError:
        raise UsageError(f"dist: expected comma-separated coefficients k1,k2,p1,p2[,k3], got {text!r}") from None
    return check_dist_coeffs(values)


def _check_sources(camera, calibration, fx, fy, cx, cy, dist, crop_origin) -> None:
    """One source of intrinsics, and no option that contradicts it (one-line errors)."""
    given = [f"--{n}" for n, v in (("fy", fy), ("cx", cx), ("cy", cy)) if v is not None]
    if given and fx is None:
        raise UsageError(f"fx: expected --fx (focal length, px) with {', '.join(given)}, got none")
    if fx is not None and camera is not None:
        raise UsageError("fx: expected the intrinsics from one source, --camera or --fx/--fy/--cx/--cy, got both")
    if fx is not None and calibration is not None:
        raise UsageError("fx: expected the intrinsics from one source, --calibration or --fx/--fy/--cx/--cy, got both")
    if dist is not None and calibration is not None:
        raise UsageError(
            "dist: expected the distortion from one source, --calibration (it has its own) or --dist, got both"
        )
    if fx is None and camera is None and calibration is None:
        raise UsageError(
            "camera: expected the intrinsics: --camera NAME, --calibration FILE or --fx [--fy --cx --cy] px, got none"
        )
    if fx is not None and crop_origin is not None:
        raise UsageError(
            "crop-origin: expected --camera or --calibration with it (the full frame's size and intrinsics); "
            "with --fx/--fy/--cx/--cy the image is the whole frame"
        )
    for name, value in (("fx", fx), ("fy", fy)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UsageError(f"{name}: expected a focal length > 0 px, got {value!r}")
    for name, value in (("cx", cx), ("cy", cy)):
        if value is not None and not math.isfinite(value):
            raise UsageError(f"{name}: expected a principal point in px, got {value!r}")


def _fit_to_image(frame: Intrinsics | Calibration, size: tuple[int, int], what: str, crop: bool, notes: list[str]):
    """The frame's intrinsics (or calibration) for an image of ``size``: the frame, a crop or a resized copy."""
    fw, fh = (frame.width_px, frame.height_px)
    if crop or size == (fw, fh):
        return frame
    fitted = frame.resized_to(*size)
    if fitted is None:
        raise UsageError(
            f"image: {size[0]}×{size[1]} px is neither {what}'s {fw}×{fh} px frame nor a resized copy of it "
            "(for a crop give --crop-origin; for another image size give --calibration or --fx/--fy/--cx/--cy)"
        )
    notes.append(f"the image is a {100 * size[0] / fw:.4g} % copy of {what}'s {fw}×{fh} px frame: intrinsics scaled")
    return fitted


def detect(
    image: Annotated[Path, typer.Argument(help="JPEG, PNG, TIFF or camera raw (e.g. Canon .CR2), any size.")],
    camera: Annotated[
        str | None,
        typer.Option("--camera", help="Camera model (see 'beacon-sim cameras'): its intrinsics.", show_default="none"),
    ] = None,
    calibration: Annotated[
        Path | None,
        typer.Option(
            "--calibration", help="Calibration JSON from 'beacon-sim calibrate': intrinsics.", show_default="none"
        ),
    ] = None,
    fx: Annotated[
        float | None, typer.Option("--fx", help="Focal length along u, px (explicit intrinsics).", show_default="none")
    ] = None,
    fy: Annotated[float | None, typer.Option("--fy", help="Focal length along v, px.", show_default="--fx")] = None,
    cx: Annotated[
        float | None, typer.Option("--cx", help="Principal point u, px.", show_default="image centre")
    ] = None,
    cy: Annotated[
        float | None, typer.Option("--cy", help="Principal point v, px.", show_default="image centre")
    ] = None,
    dist: Annotated[
        str | None,
        typer.Option(
            "--dist", help="Lens distortion k1,k2,p1,p2[,k3] (OpenCV) with --camera or --fx.", show_default="none"
        ),
    ] = None,
    resize: Annotated[
        float | None,
        typer.Option(
            "--resize",
            help="Tracker's processing scale in (0, 1], e.g. 0.5 as the study did for the T6.",
            show_default="the tracker's own",
        ),
    ] = None,
    tracker: Annotated[str, typer.Option("--tracker", help="thesis (the study's) or best.")] = "best",
    estimator: Annotated[str, typer.Option("--estimator", help="thesis (the study's) or best.")] = "best",
    beacon: Annotated[str, typer.Option("--beacon", help="Beacon design: v1 or v2.")] = "v2",
    alpha: Annotated[float, typer.Option("--alpha", help="Undistortion alpha (0: valid pixels, 1: all).")] = 0.0,
    crop_origin: Annotated[
        str | None,
        typer.Option(
            "--crop-origin",
            help="U,V of the image's top-left pixel in the full frame (crops).",
            show_default="the whole frame",
        ),
    ] = None,
    ring_camera: Annotated[
        int | None,
        typer.Option(
            "--ring-camera",
            help="Camera number on the 6-camera ring: report the robot's pose.",
            show_default="no ring pose",
        ),
    ] = None,
    json_out: opt.Json = False,
) -> None:
    """Find the beacon side in an image and estimate the camera's range and attitude."""
    # every option first: nothing is read before they are all known to be usable
    for name, value, allowed in (("tracker", tracker, TRACKERS), ("estimator", estimator, ESTIMATORS)):
        if value not in allowed:
            raise UsageError(f"{name}: expected one of {', '.join(allowed)}, got {value!r}")
    beacon_design(beacon)
    if not (math.isfinite(alpha) and 0.0 <= alpha <= 1.0):
        raise UsageError(f"alpha: expected a value in [0, 1], got {alpha!r}")
    check_resize(resize)
    if ring_camera is not None and not 0 <= ring_camera < RING_CAMERAS:
        raise UsageError(f"ring-camera: expected 0..{RING_CAMERAS - 1}, got {ring_camera}")
    origin = _crop_origin(crop_origin)
    _check_sources(camera, calibration, fx, fy, cx, cy, dist, origin)
    coeffs = _dist(dist)
    nominal = Intrinsics.from_geometry(camera_geometry(camera)) if camera is not None else None
    cal = load_calibration(calibration) if calibration is not None else None
    if cal is not None and nominal is not None and nominal.resized_to(cal.width_px, cal.height_px) is None:
        raise UsageError(
            f"calibration: made for {cal.width_px}×{cal.height_px} px, not for {camera}'s "
            f"{nominal.width_px}×{nominal.height_px} px frame or a resized copy of it; give one of them"
        )
    pixels = load_image(image)
    size = (int(pixels.shape[1]), int(pixels.shape[0]))
    notes: list[str] = []
    if cal is not None:
        cal = _fit_to_image(cal, size, "the calibration", origin is not None, notes)
        intrinsics, source = cal.intrinsics(), f"calibration {calibration}"
        notes += [f"calibration warning: {w}" for w in cal.warnings]
    elif nominal is not None:
        intrinsics, source = _fit_to_image(nominal, size, camera, origin is not None, notes), f"camera {camera}"
    else:
        try:
            intrinsics = intrinsics_from_values(*size, fx, fy, cx, cy)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        source = "explicit"
    if coeffs is not None:
        cal = Calibration.from_intrinsics(intrinsics, coeffs)
    result = run_detect(
        pixels, intrinsics, tracker=tracker, estimator=estimator, beacon=beacon, calibration=cal, alpha=alpha,
        crop_origin_px=origin, ring_camera=ring_camera, resize=resize,
    )  # fmt: skip
    if result.failure is Failure.IMAGE:
        raise UsageError(result.reason)
    out = result.to_dict()
    out["image"] = str(image)
    out["camera"] = camera
    k = cal.camera_matrix if cal is not None else intrinsics.matrix()
    out["intrinsics"] = {
        "source": source, "fx": float(k[0, 0]), "fy": float(k[1, 1]), "cx": float(k[0, 2]), "cy": float(k[1, 2]),
        "width_px": intrinsics.width_px, "height_px": intrinsics.height_px,
        "dist_coeffs": None if cal is None else cal.dist_coeffs.tolist(),
    }  # fmt: skip
    out["resize"] = resize
    out["notes"] = [*notes, *out["notes"]]
    if tracker == "thesis":
        out["notes"].append(REAL_PHOTO_FALSE_POSITIVES.note("thesis"))
    if json_out:
        print(strict_json.dumps(out, indent=2))
        return
    _print_detection(out)


def _print_detection(out: dict) -> None:
    console = Console(soft_wrap=True)
    if not out["markers"]:
        console.print(f"no target: {out['reason']}", markup=False)
    else:
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
            console.print(f"no pose: {out['reason']}", markup=False)
        else:
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
        console.print(f"note: {note}", markup=False)


def _check_out_file(out: Path) -> None:
    """``out`` can be written as a file: not a directory, below a writable directory (none is created here)."""
    if out.is_dir():
        raise UsageError(f"out: expected a file name for the calibration (JSON), got the directory {out}")
    if out.exists() and not os.access(out, os.W_OK):
        raise UsageError(f"out: cannot write to {out} (not writable)")
    parent = out.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise UsageError(f"out: cannot write {out}: {parent} is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"out: cannot write to {parent} (not writable)")


def _check_photos(images: list[Path]) -> None:
    """At least three existing files, none given twice, no two with the same content."""
    if len(images) < 3:
        raise UsageError(f"images: expected at least 3 checkerboard photos, got {len(images)}")
    seen: dict[Path, int] = {}
    digests: dict[str, int] = {}
    for k, path in enumerate(images):
        if not path.is_file():
            raise UsageError(f"images[{k}]: no such file: {path}")
        real = path.resolve()
        if real in seen:
            raise UsageError(f"images: expected distinct photos, got {path} twice (images {seen[real]} and {k})")
        seen[real] = k
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        if digest in digests:
            j = digests[digest]
            raise UsageError(
                f"images: expected distinct photos, got the same file content twice ({images[j]} and {path}, "
                f"images {j} and {k}); remove one"
            )
        digests[digest] = k


def calibrate(
    images: Annotated[list[Path], typer.Argument(help="Checkerboard photos (same size, at least 3).")],
    out: Annotated[Path, typer.Option("--out", help="Calibration file to write (JSON).")],
    pattern: Annotated[str, typer.Option("--pattern", help="Inner corners per row x per column.")] = "8x6",
    square_mm: Annotated[float, typer.Option("--square-mm", help="Square size, mm.")] = 24.4,
    resize: Annotated[
        float | None,
        typer.Option(
            "--resize",
            help="Find the board on a copy resized by this scale in (0, 1] (faster on large photos).",
            show_default="full size",
        ),
    ] = None,
) -> None:
    """Calibrate a camera from checkerboard photos (OpenCV calibrateCamera) and write a JSON file.

    Refuses a repeated photo, views of the board in the same place and sets with fewer
    than three board orientations; warns when the principal point is far from the centre
    or fx and fy differ."""
    try:
        cols, rows = (int(p) for p in pattern.lower().split("x"))
    except ValueError:
        raise UsageError(f"pattern: expected COLSxROWS inner corners, e.g. 8x6, got {pattern!r}") from None
    try:
        check_pattern((cols, rows))
    except ValueError:
        raise UsageError(
            f"pattern: expected COLSxROWS inner corners, 3 to 200 each, e.g. 8x6, got {pattern!r}"
        ) from None
    if not (math.isfinite(square_mm) and square_mm > 0):
        raise UsageError(f"square-mm: expected a size > 0 mm, got {square_mm!r}")
    check_resize(resize)
    _check_out_file(out)
    _check_photos(list(images))
    cal = run_calibrate(
        list(images), (cols, rows), square_mm * 1e-3, resize=resize, names=[str(p) for p in images]
    )  # paths: one image in memory at a time
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        cal.save(out)
    except OSError as exc:
        raise UsageError(f"out: cannot write {out} ({exc.strerror or exc})") from None
    k = cal.camera_matrix
    console.print(
        f"wrote {out}: {cal.n_images} of {len(images)} views, RMS {cal.rms_px:.3f} px, "
        f"fx {k[0, 0]:.1f}, fy {k[1, 1]:.1f}, cx {k[0, 2]:.1f}, cy {k[1, 2]:.1f} px",
        soft_wrap=True,
        markup=False,
    )
    for warning in cal.warnings:
        console.print(f"warning: {warning}", soft_wrap=True, markup=False)


COMMANDS = {"detect": detect, "calibrate": calibrate}
