"""Camera commands of ``beacon-sim``: ``cameras`` (with lens and sensor figures), ``emva1288``, ``capture``.

Imported by :mod:`studies.cli`, which registers every command defined here on ``app``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from studies.cli import (
    BeaconOpt,
    CameraOpt,
    CurrentOpt,
    EnvOpt,
    FoamOpt,
    HeightOpt,
    HousingOpt,
    OversamplingOpt,
    PaperColourOpt,
    RangeOpt,
    SeedOpt,
    SheetsOpt,
    SideOpt,
    SppOpt,
    UsageError,
    YawOpt,
    app,
    console,
    prepare_out_dir,
)

IsoOpt = Annotated[float | None, typer.Option("--iso", help="ISO (DSLR).")]
GainOpt = Annotated[int | None, typer.Option("--gain", help="UVC gain code (webcam).")]


def camera_rows() -> list[dict]:
    """Key figures of every camera."""
    from camera_models.camera import load_camera
    from camera_models.geometry import camera_names

    rows = []
    for name in camera_names():
        c = load_camera(name)
        g, s = c.geometry, c.sensor
        rows.append(
            {
                "name": name,
                "description": g.description,
                "width_px": g.width_px,
                "height_px": g.height_px,
                "pixel_pitch_um": g.pixel_pitch_um,
                "focal_length_mm": round(g.focal_length_mm, 4),
                "horizontal_fov_deg": round(g.horizontal_fov_deg, 2),
                "pixel_angle_mrad": round(1e3 / g.focal_length_px, 4),
                "f_number": c.lens.f_number,
                "distortion": c.lens.distortion_model,
                "peak_qe_green": round(float(s.qe_rgb[1].max()), 3),
                "full_well_e": s.full_well_e,
                "adc_bits": s.adc_bits,
                "exposure_mode": c.exposure.mode,
                "jpeg": f"q{c.isp.jpeg_quality} {c.isp.chroma_subsampling}",
            }
        )
    return rows


@app.command()
def cameras(json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """List the camera models with their key figures (grid, lens, sensor, exposure, JPEG)."""
    rows = camera_rows()
    if json_out:
        print(json.dumps(rows, indent=2))
        return
    table = Table(title="Cameras")
    cols = ("name", "resolution", "pixel µm", "focal mm", "HFOV °", "f/", "QE", "well e⁻", "bits", "exposure", "JPEG")
    for col in cols:
        table.add_column(col)
    for r in rows:
        table.add_row(
            r["name"],
            f"{r['width_px']}×{r['height_px']}",
            f"{r['pixel_pitch_um']:g}",
            f"{r['focal_length_mm']:.2f}",
            f"{r['horizontal_fov_deg']:.1f}",
            f"{r['f_number']:g}",
            f"{r['peak_qe_green']:.2f}",
            f"{r['full_well_e']:.0f}",
            str(r["adc_bits"]),
            r["exposure_mode"],
            r["jpeg"],
        )
    Console().print(table)


def _gain(cam, iso: float | None, gain: int | None) -> float:
    s = cam.sensor
    if s.uses_iso:
        if gain is not None:
            raise UsageError(f"gain: {cam.name} sets its gain as an ISO; use --iso")
        return s.analog_gain(iso=cam.exposure.iso if iso is None else iso)
    if iso is not None:
        raise UsageError(f"iso: {cam.name} has no ISO setting; use --gain (UVC gain code)")
    return s.analog_gain(gain_code=s.gain_code_min if gain is None else gain)


@app.command("emva1288")
def emva1288_cmd(
    out: Annotated[Path, typer.Option("--out", help="Output directory.")],
    camera: CameraOpt = "canon-t6-18mm",
    iso: IsoOpt = None,
    gain: GainOpt = None,
    wavelength_nm: Annotated[float, typer.Option("--wavelength-nm", help="Light wavelength, nm.")] = 530.0,
    seed: SeedOpt = 0,
) -> None:
    """Write an EMVA 1288 photon-transfer data set (descriptor file + PNG frames) from the sensor model.

    Prints the model's true parameters as JSON (qe, K_DN_per_e, dark_noise_e,
    saturation_e, wavelength_nm, pixel_area_um2) for comparison with an EMVA 1288 analysis.
    """
    from camera_models.camera import load_camera
    from camera_models.emva import EmvaSetup, green_qe, write_dataset

    cam = load_camera(camera)
    analog_gain = _gain(cam, iso, gain)
    green_qe(cam, wavelength_nm)  # validates the wavelength
    if seed < 0:
        raise UsageError(f"seed: expected an integer >= 0, got {seed}")
    prepare_out_dir(out)
    truth = write_dataset(cam, analog_gain, out, seed=seed, setup=EmvaSetup(wavelength_nm=wavelength_nm))
    truth.update(iso=iso if cam.sensor.uses_iso else None, gain_code=gain)
    print(json.dumps(truth, indent=2))
    console.print(f"wrote {out}/descriptor.txt and images/ (process with the emva1288 package)")


@app.command()
def capture(
    out: Annotated[Path, typer.Option("--out", help="Output directory.")],
    beacon: BeaconOpt = "v2",
    side: SideOpt = "red",
    range_m: RangeOpt = 5.0,
    yaw_deg: YawOpt = 10.0,
    camera: CameraOpt = "canon-t6-18mm",
    environment: EnvOpt = "dark",
    led_current_ma: CurrentOpt = None,
    camera_height_m: HeightOpt = 0.0,
    housing: HousingOpt = "black",
    foam: FoamOpt = False,
    paper_sheets: SheetsOpt = 0,
    paper_colour: PaperColourOpt = "white",
    spp: SppOpt = 16,
    oversampling: OversamplingOpt = 3,
    seed: SeedOpt = 0,
    iso: IsoOpt = None,
    gain: GainOpt = None,
    exposure_s: Annotated[
        float | None, typer.Option("--exposure-s", help="Exposure time, s (manual; default the camera's).")
    ] = None,
    f_number: Annotated[float | None, typer.Option("--f-number", help="Working f-number (default the lens's).")] = None,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Render even if a cached render exists.")] = False,
) -> None:
    """Simulate what the camera saves: JPEG, raw mosaic (16-bit PNG), full-frame preview and capture.json."""
    import cv2
    import numpy as np

    from camera_models.camera import load_camera
    from camera_models.capture import capture as run_capture
    from camera_models.capture import marker_core_saturation
    from camera_models.exposure import manual_exposure
    from camera_models.optics import check_f_number
    from scenes.background import render_background
    from scenes.render import render as render_scenario
    from scenes.render_cache import RenderCache, atomic_write_bytes
    from scenes.scenario import RenderSettings, Scenario

    cam = load_camera(camera)
    if f_number is not None:
        check_f_number(f_number)
    exposure = None
    if iso is not None or gain is not None or exposure_s is not None:
        if cam.exposure.mode == "auto":
            raise UsageError(f"exposure_s: {camera} exposes automatically; its exposure cannot be set")
        exposure = manual_exposure(cam, exposure_s, iso, gain)
    scenario = Scenario(
        beacon=beacon,
        side=side,
        range_m=range_m,
        yaw_deg=yaw_deg,
        camera=camera,
        environment=environment,
        led_current_mA=led_current_ma,
        camera_height_m=camera_height_m,
        housing=housing,
        foam=foam,
        paper_sheets=paper_sheets,
        paper_colour=paper_colour,
        render=RenderSettings(spp=spp, oversampling=oversampling, seed=seed),
    )
    prepare_out_dir(out)
    cache = None if no_cache else RenderCache()
    t0 = time.perf_counter()
    with console.status(f"rendering {scenario.beacon} {scenario.side} at {scenario.range_m} m ..."):
        radiance = render_scenario(scenario, cache)
        background = render_background(scenario, cache)
    with console.status(f"capturing with {camera} ..."):
        cap = run_capture(radiance, cam, seed, background=background, exposure=exposure, f_number=f_number)
    atomic_write_bytes(out / "image.jpg", cap.image.jpeg)
    _ok, raw_png = cv2.imencode(".png", cap.raw)
    atomic_write_bytes(out / "raw.png", raw_png.tobytes())
    h, w = cap.image.rgb8.shape[:2]
    step = max(1, int(np.ceil(max(w, h) / 1600)))
    _ok, preview = cv2.imencode(".png", np.ascontiguousarray(cap.image.rgb8[::step, ::step, ::-1]))
    atomic_write_bytes(out / "preview.png", preview.tobytes())
    markers = marker_core_saturation(cap, cam, scenario)
    meta = {
        "scenario": scenario.to_dict(),
        "camera": camera,
        "seed": seed,
        "f_number": f_number if f_number is not None else cam.lens.f_number,
        "exposure": cap.exposure.to_dict(),
        "K_DN_per_e": cam.sensor.K_DN_per_e(cap.exposure.analog_gain),
        "saturated_fraction_frame": cap.saturated_fraction,
        "markers_ground_truth_px": markers,
        "raw": {
            "cfa": cam.sensor.cfa,
            "black_level_DN": cam.sensor.black_level_DN,
            "white_level_DN": cam.sensor.white_level_DN,
            "x0": cap.x0,
            "y0": cap.y0,
        },
        "white_balance_gains": [float(g) for g in cap.image.wb_gains],
        "jpeg": {"quality": cam.isp.jpeg_quality, "chroma_subsampling": cam.isp.chroma_subsampling},
        "pixel_grid": radiance.grid.to_dict(),
        "seconds": round(time.perf_counter() - t0, 3),
        "files": {"image": "image.jpg", "raw": "raw.png", "preview": "preview.png"},
    }
    atomic_write_bytes(out / "capture.json", json.dumps(meta, indent=2).encode())
    console.print(
        f"wrote {out}/ (image.jpg, raw.png, preview.png, capture.json): exposure {cap.exposure.exposure_s:.4g} s, "
        f"gain x{cap.exposure.analog_gain:.3g}, {100 * cap.saturated_fraction:.3f} % of pixels clipped"
    )


@app.command("saturation-table")
def saturation_table_cmd(
    out: Annotated[Path, typer.Option("--out", help="Output directory.")],
    camera: Annotated[
        list[str] | None, typer.Option("--camera", help="Camera model (repeat for several; default all four).")
    ] = None,
    spp: Annotated[int, typer.Option("--spp", help="Samples per rendered sub-pixel.")] = 4,
    oversampling: Annotated[
        int, typer.Option("--oversampling", help="Rendered sub-pixels per camera pixel, per axis.")
    ] = 2,
    seed: SeedOpt = 0,
) -> None:
    """Marker-core saturation per camera, LED drive (2-20 mA) and diffuser (bare; foam + 0/1/3 sheets) at 2 m and 5 m.

    V2 red side, yaw 0, dark, white paper, through render → capture. Writes
    saturation_table.csv (one row per marker) and saturation_table.md (summary,
    webcam auto-exposure values).
    """
    from camera_models.geometry import camera_names
    from studies.saturation_table import CAMERAS, saturation_rows, summary_markdown, write_csv

    cameras = tuple(camera) if camera else CAMERAS
    for name in cameras:
        if name not in camera_names():
            raise UsageError(f"camera: expected one of {', '.join(camera_names())}, got {name!r}")
    if seed < 0:
        raise UsageError(f"seed: expected an integer >= 0, got {seed}")
    prepare_out_dir(out)
    rows = saturation_rows(cameras, spp=spp, oversampling=oversampling, seed=seed, progress=console.print)
    write_csv(rows, out / "saturation_table.csv")
    (out / "saturation_table.md").write_text(summary_markdown(rows), encoding="utf-8")
    console.print(f"wrote {out}/saturation_table.csv ({len(rows)} rows) and saturation_table.md")
