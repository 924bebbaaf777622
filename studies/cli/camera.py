"""Camera commands: ``capture`` (what a camera saves), ``emva1288`` (a photon-transfer data set) and
``ring`` (a ring of cameras' blind zone)."""

from __future__ import annotations

import time
from typing import Annotated

import cv2
import numpy as np
import typer

from camera_models.camera import load_camera
from camera_models.capture import capture as run_capture
from camera_models.capture import marker_core_saturation
from camera_models.emva import EmvaSetup, green_qe, write_dataset
from camera_models.exposure import manual_exposure
from camera_models.optics import RadialMapping, check_f_number
from pipeline.angles import Intrinsics
from pipeline.detect import detect as run_detect
from pipeline.ring import STUDY_BLIND_ZONE_M, blind_zone_m
from scenes.background import render_background
from scenes.render import render as render_scenario
from scenes.render_cache import RenderCache, atomic_write_bytes
from scenes.scenario import Scenario
from scenes.view import camera_geometry
from studies.cli import options as opt
from studies.cli.common import UsageError, check_render_cache, console
from studies.cli.out_folder import prepare_out_dir
from studies.engine import strict_json
from studies.engine.scoring import CLIPPED_CORES

__all__ = ["COMMANDS", "WORKING_SETTING", "capture", "capture_warnings", "emva1288", "ring"]


def _gain(cam, iso: float | None, gain: int | None) -> float:
    """The analog gain of ``--iso`` (ISO bodies) or ``--gain`` (UVC gain code), refusing the
    setting the body does not have."""
    s = cam.sensor
    if s.uses_iso:
        if gain is not None:
            raise UsageError(f"gain: expected no --gain ({cam.name} sets its gain as an ISO: use --iso), got {gain}")
        return s.analog_gain(iso=cam.exposure.iso if iso is None else iso)
    if iso is not None:
        raise UsageError(f"iso: expected no --iso ({cam.name} has no ISO setting: use --gain), got {iso:g}")
    return s.analog_gain(gain_code=s.gain_code_min if gain is None else gain)


WORKING_SETTING = "--led-current-ma 2 --foam --paper-sheets 3"
"""The studies' LED setting (brightness-diffuser's window: 2 mA behind foam + 3 white sheets),
named by :func:`capture_warnings`."""


def capture_warnings(markers: list[dict], side: str, detected_side: str | None) -> list[str]:
    """One line each for what makes a capture useless for telling the side: marker cores
    mostly clipped (> :data:`studies.engine.scoring.CLIPPED_CORES` of a core's pixels at the
    clip level, so the camera saves them white or off-colour), and a detector (best tracker)
    that names another side or none.

    Parameters
    ----------
    markers : :func:`camera_models.capture.marker_core_saturation` of the capture.
    side : the side that faces the camera.
    detected_side : the side the detector named (None: no five markers found).

    Returns
    -------
    Warning lines ([] when the capture is usable).
    """
    lines = []
    fractions = [m["saturated_fraction"] for m in markers if m["core_pixels"]]
    clipped = [f for f in fractions if f > CLIPPED_CORES]
    if clipped:
        lines.append(
            f"warning: {len(clipped)} of {len(markers)} marker cores clipped (mean {100 * np.mean(fractions):.0f} % "
            f"of core pixels at the clip level): their colour is lost; dim the LED or diffuse it (the studies use "
            f"{WORKING_SETTING})"
        )
    if detected_side != side:
        named = f"names the side {detected_side}" if detected_side else "finds no five markers"
        lines.append(
            f"warning: the detector (best tracker) {named}, not {side}: this capture does not show the side's colour"
            + ("" if clipped else f" (the studies use {WORKING_SETTING})")
        )
    return lines


def emva1288(
    out: opt.Out,
    camera: opt.Camera = "canon-t6-18mm",
    iso: opt.Iso = None,
    gain: opt.Gain = None,
    wavelength_nm: Annotated[float, typer.Option("--wavelength-nm", help="Light wavelength, nm.")] = 530.0,
    seed: opt.Seed = 0,
) -> None:
    """Write an EMVA 1288 photon-transfer data set (descriptor file + PNG frames) from the sensor model.

    Prints the model's true parameters as JSON (qe, K_DN_per_e, dark_noise_e,
    saturation_e, wavelength_nm, pixel_area_um2) for comparison with an EMVA 1288 analysis.
    """
    cam = load_camera(camera)
    analog_gain = _gain(cam, iso, gain)
    green_qe(cam, wavelength_nm)  # validates the wavelength
    if seed < 0:
        raise UsageError(f"seed: expected an integer >= 0, got {seed}")
    prepare_out_dir(out)
    truth = write_dataset(cam, analog_gain, out, seed=seed, setup=EmvaSetup(wavelength_nm=wavelength_nm))
    truth.update(iso=iso if cam.sensor.uses_iso else None, gain_code=gain)
    print(strict_json.dumps(truth, indent=2))
    console.print(f"wrote {out}/descriptor.txt and images/ (process with the emva1288 package)")


@opt.scenario_command
def capture(
    out: opt.Out,
    scenario: Scenario,
    iso: opt.Iso = None,
    gain: opt.Gain = None,
    exposure_s: Annotated[
        float | None,
        typer.Option("--exposure-s", help="Exposure time, s (manual).", show_default="the camera's exposure"),
    ] = None,
    f_number: Annotated[
        float | None, typer.Option("--f-number", help="Working f-number.", show_default="the lens's")
    ] = None,
    no_cache: opt.NoCache = False,
) -> None:
    """Simulate what the camera saves: its image (JPEG, or PNG for an uncompressed output), raw mosaic
    (16-bit PNG), full-frame preview and capture.json."""
    camera, seed = scenario.camera, scenario.render.seed
    cam = load_camera(camera)
    if f_number is not None:
        check_f_number(f_number)
    _gain(cam, iso, gain)  # --gain on an ISO body, --iso on a UVC one: refused, never silently ignored
    given = [name for name, value in (("iso", iso), ("gain", gain), ("exposure_s", exposure_s)) if value is not None]
    exposure = None
    if given:
        if cam.exposure.mode == "auto":
            raise UsageError(
                f"{given[0]}: expected no manual exposure setting ({camera} exposes automatically), "
                f"got --{given[0].replace('_', '-')}"
            )
        exposure = manual_exposure(cam, exposure_s, iso, gain)
    if not no_cache:
        check_render_cache()
    prepare_out_dir(out)
    cache = None if no_cache else RenderCache()
    t0 = time.perf_counter()
    with console.status(f"rendering {scenario.beacon} {scenario.side} at {scenario.range_m} m ..."):
        radiance = render_scenario(scenario, cache)
        background = render_background(scenario, cache)
    with console.status(f"capturing with {camera} ..."):
        cap = run_capture(radiance, cam, seed, background=background, exposure=exposure, f_number=f_number)
    image_file = f"image{cap.image.suffix}"  # image.jpg, or image.png for an uncompressed output (isp.output)
    atomic_write_bytes(out / image_file, cap.image.encoded)
    _ok, raw_png = cv2.imencode(".png", cap.raw)
    atomic_write_bytes(out / "raw.png", raw_png.tobytes())
    h, w = cap.image.rgb8.shape[:2]
    step = max(1, int(np.ceil(max(w, h) / 1600)))
    _ok, preview = cv2.imencode(".png", np.ascontiguousarray(cap.image.rgb8[::step, ::step, ::-1]))
    atomic_write_bytes(out / "preview.png", preview.tobytes())
    markers = marker_core_saturation(cap, cam, scenario)
    bgr = cv2.imdecode(np.frombuffer(cap.image.encoded, np.uint8), cv2.IMREAD_COLOR)  # what was saved
    seen = run_detect(bgr, Intrinsics.from_geometry(camera_geometry(camera)), beacon=scenario.beacon)
    warnings = capture_warnings(markers, scenario.side, seen.side if seen.markers else None)
    meta = {
        "scenario": scenario.to_dict(),
        "camera": camera,
        "seed": seed,
        "f_number": f_number if f_number is not None else cam.lens.f_number,
        "exposure": cap.exposure.to_dict(),
        "K_DN_per_e": cam.sensor.K_DN_per_e(cap.exposure.analog_gain),
        "saturated_fraction_frame": cap.saturated_fraction,
        "markers_ground_truth_px": markers,
        "detected_side": seen.side if seen.markers else None,
        "warnings": warnings,
        "raw": {
            "cfa": cam.sensor.cfa,
            "black_level_DN": cam.sensor.black_level_DN,
            "white_level_DN": cam.sensor.white_level_DN,
            "x0": cap.x0,
            "y0": cap.y0,
        },
        "white_balance_gains": [float(g) for g in cap.image.wb_gains],
        "jpeg": (
            {"quality": cam.isp.jpeg_quality, "chroma_subsampling": cam.isp.chroma_subsampling}
            if cam.isp.output == "jpeg"
            else None  # the camera saves an uncompressed frame (isp.output), a lossless PNG
        ),
        "pixel_grid": radiance.grid.to_dict(),
        "seconds": round(time.perf_counter() - t0, 3),
        "files": {"image": image_file, "raw": "raw.png", "preview": "preview.png"},
    }
    atomic_write_bytes(out / "capture.json", strict_json.dumps(meta, indent=2).encode())
    console.print(
        f"wrote {out}/ ({image_file}, raw.png, preview.png, capture.json): exposure {cap.exposure.exposure_s:.4g} s, "
        f"gain x{cap.exposure.analog_gain:.3g}, {100 * cap.saturated_fraction:.3f} % of pixels clipped"
    )
    for line in warnings:
        console.print(line, style="yellow", soft_wrap=True)


def ring(
    camera: opt.Camera = "spedal-920",
    cameras_n: Annotated[int, typer.Option("--cameras-n", help="Cameras on the ring (the study: 6).")] = 6,
    radius_m: Annotated[float, typer.Option("--radius-m", help="Ring radius, m (the study: 0.2).")] = 0.2,
    json_out: opt.Json = False,
) -> None:
    """The blind zone of a ring of cameras facing outward (pipeline.ring), from the camera's lens, beside
    the study's 507 mm for its hexagon of Spedal 920 webcams."""
    if cameras_n < 2:
        raise UsageError(f"cameras-n: expected an integer >= 2, got {cameras_n}")
    if not radius_m > 0:
        raise UsageError(f"radius-m: expected a ring radius > 0 m, got {radius_m:g}")
    cam = load_camera(camera)
    fov = RadialMapping(cam).horizontal_fov_deg()
    pinhole = cam.geometry.horizontal_fov_deg
    rho = blind_zone_m(cameras_n, radius_m, np.radians(min(fov, 179.9)))
    record = {
        "camera": camera,
        "cameras": cameras_n,
        "radius_m": radius_m,
        "horizontal_fov_deg": fov,
        "pinhole_horizontal_fov_deg": pinhole,
        "blind_zone_m": None if not np.isfinite(rho) else rho,
        "study_blind_zone_m": STUDY_BLIND_ZONE_M,
    }
    if json_out:
        print(strict_json.dumps(record, indent=2))
        return
    reach = f"{rho * 1e3:.0f} mm" if np.isfinite(rho) else "unbounded (adjacent fields never meet)"
    console.print(
        f"{cameras_n} × {camera} on a {radius_m * 1e3:g} mm ring, {fov:.1f}° across each frame through its lens "
        f"({pinhole:.1f}° as a pinhole): blind to {reach} from the centre; the study states "
        f"{STUDY_BLIND_ZONE_M * 1e3:.0f} mm for its six Spedal 920 webcams"
    )


COMMANDS = {"capture": capture, "emva1288": emva1288, "ring": ring}
