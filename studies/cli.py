"""The ``beacon-sim`` command line.

Every command that writes results writes JSON beside its pictures. Bad input ends the
program with one line on stderr naming the field and what was expected (exit code 2).
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.table import Table

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Simulate how cameras see self-lit LED beacons.",
)
console = Console(stderr=True)


class UsageError(ValueError):
    """Bad command-line input (one-line message)."""


def _setup_logging(verbose: bool) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(message)s",
        handlers=[RichHandler(console=console, show_path=False, show_time=False)],
    )
    logging.getLogger("beacon_sim").setLevel(logging.INFO)


@app.callback()
def _root(verbose: Annotated[bool, typer.Option("--verbose", "-v", help="More log output.")] = False):
    _setup_logging(verbose)


def prepare_out_dir(out: Path) -> Path:
    """Create ``out`` and check it is writable, or raise :class:`UsageError`."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UsageError(f"out: cannot write to {out} ({exc.strerror or exc})") from None
    return out


@app.command()
def beacons(json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """List the beacon designs and their marker geometry."""
    from scenes.beacon import load_beacons

    rows = []
    for b in load_beacons().values():
        rows.append(
            {
                "name": b.name,
                "description": b.description,
                "d_t_mm": b.d_t_m * 1e3,
                "lit_face_diameter_mm": b.lit_face_diameter_m * 1e3,
                "markers": [
                    {"id": m.id, "position_mm": (m.position_m * 1e3).round(3).tolist(), "led_axis": m.normal.tolist()}
                    for m in b.markers
                ],
            }
        )
    if json_out:
        print(json.dumps(rows, indent=2))
        return
    table = Table(title="Beacon designs (target frame: x toward viewer, y viewer's left, z down; mm)")
    for col in ("name", "marker", "position (x, y, z) mm", "LED axis", "description"):
        table.add_column(col)
    for r in rows:
        for m in r["markers"]:
            table.add_row(
                r["name"] if m["id"] == 1 else "",
                str(m["id"]),
                "({:.0f}, {:.0f}, {:.0f})".format(*m["position_mm"]),
                "({:+.0f}, {:+.0f}, {:+.0f})".format(*m["led_axis"]),
                r["description"] if m["id"] == 1 else "",
            )
    Console().print(table)


@app.command()
def cameras(json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False) -> None:
    """List the camera models with their key figures."""
    from camera_models.geometry import camera_geometry, camera_names

    rows = []
    for name in camera_names():
        g = camera_geometry(name)
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
            }
        )
    if json_out:
        print(json.dumps(rows, indent=2))
        return
    table = Table(title="Cameras")
    for col in ("name", "resolution", "pixel µm", "focal mm", "HFOV °", "pixel mrad", "description"):
        table.add_column(col)
    for r in rows:
        table.add_row(
            r["name"],
            f"{r['width_px']}×{r['height_px']}",
            f"{r['pixel_pitch_um']:g}",
            f"{r['focal_length_mm']:.2f}",
            f"{r['horizontal_fov_deg']:.1f}",
            f"{r['pixel_angle_mrad']:.3f}",
            r["description"],
        )
    Console().print(table)


# options shared by render and (later) capture
BeaconOpt = Annotated[str, typer.Option("--beacon", help="Beacon design: v1 or v2.")]
SideOpt = Annotated[str, typer.Option("--side", help="Side facing the camera: red, green, blue, yellow.")]
RangeOpt = Annotated[float, typer.Option("--range-m", help="Camera to marker 1, m.")]
YawOpt = Annotated[float, typer.Option("--yaw-deg", help="Camera azimuth about the target's vertical axis, degrees.")]
CameraOpt = Annotated[str, typer.Option("--camera", help="Camera model (see 'beacon-sim cameras').")]
EnvOpt = Annotated[str, typer.Option("--environment", help="dark, dark-room or lit-room.")]
CurrentOpt = Annotated[
    float | None, typer.Option("--led-current-ma", help="LED drive current, mA (default: datasheet test current).")
]
HeightOpt = Annotated[float, typer.Option("--camera-height-m", help="Camera height above marker 1, m.")]
HousingOpt = Annotated[str, typer.Option("--housing", help="Housing finish: black or white.")]
FoamOpt = Annotated[bool, typer.Option("--foam/--no-foam", help="Foam disc behind the paper of every marker.")]
SheetsOpt = Annotated[int, typer.Option("--paper-sheets", help="Sheets of paper in front of every LED, 0-5.")]
PaperColourOpt = Annotated[
    str, typer.Option("--paper-colour", help="white, matched (each side's own colour), red, green, blue, yellow.")
]
SppOpt = Annotated[int, typer.Option("--spp", help="Samples per rendered sub-pixel.")]
OversamplingOpt = Annotated[int, typer.Option("--oversampling", help="Rendered sub-pixels per camera pixel, per axis.")]
SeedOpt = Annotated[int, typer.Option("--seed", help="Random seed (same seed, same bytes).")]


@app.command()
def render(
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
    cube: Annotated[bool, typer.Option("--cube", help="Also write the 10 nm band cube (radiance_cube.exr).")] = False,
    no_cache: Annotated[bool, typer.Option("--no-cache", help="Render even if a cached render exists.")] = False,
) -> None:
    """Render spectral radiance of a beacon on a camera's pixel grid (crop around the beacon)."""
    from scenes.render_cache import RenderCache
    from scenes.scenario import RenderSettings, Scenario

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
    write_render(out, scenario, None if no_cache else RenderCache(), cube=cube)


@app.command()
def bench(
    json_out: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    skip_scalar: Annotated[bool, typer.Option("--skip-scalar", help="Skip the slow scalar-variant timing.")] = False,
    grid_tables: Annotated[
        bool,
        typer.Option(
            "--grid-tables",
            help="Instead: time the replication study's tables at the full grid's size (stand-in frames, ~6 min).",
        ),
    ] = False,
) -> None:
    """Measure speed-ups as ratios, side by side in one run on this machine."""
    from scenes.mitsuba_variant import active_variant
    from studies import bench as b

    if grid_tables:
        with console.status("bench: replication tables at full size ..."):
            print(json.dumps(b.replication_tables(), indent=2))
        return

    steps = [
        ("two_stage_vs_brute_force", b.two_stage_vs_brute_force),
        ("reuse_vs_rerender", b.reuse_vs_rerender),
        ("frame_vs_memcpy", b.frame_vs_memcpy),
        ("workers_and_dask", b.workers_and_dask),
        ("full_grid_estimate", b.full_grid_estimate),
    ]
    if not skip_scalar:
        steps.append(("variant", b.variant_ratio))
    details = {}
    for name, fn in steps:
        with console.status(f"bench: {name} ..."):
            details[name] = fn()
    result = {
        "two_stage_vs_brute_force": details["two_stage_vs_brute_force"]["ratio"],
        "reuse_vs_rerender": details["reuse_vs_rerender"]["ratio"],
        "frame_vs_memcpy": details["frame_vs_memcpy"]["ratio"],
        "workers_2_vs_1": details["workers_and_dask"]["workers_2_vs_1"],
        "dask_overhead": details["workers_and_dask"]["dask_overhead"],
        "variant": active_variant().variant,
        "llvm_vs_scalar": details["variant"]["ratio"] if "variant" in details else None,
        "full_grid_cold_h": details["full_grid_estimate"]["cold_h"],
        "full_grid_warm_h": details["full_grid_estimate"]["warm_h"],
        "details": details,
    }
    if json_out:
        print(json.dumps(result, indent=2))
        return
    t = Table(title=f"beacon-sim bench ({result['variant']})")
    for col in ("measurement", "ratio", "goal"):
        t.add_column(col)
    t.add_row("two-stage vs brute-force marker, equal 1 % RMS", f"{result['two_stage_vs_brute_force']:.0f}×", "≥ 100×")
    t.add_row("100-frame sweep: render reuse vs re-render", f"{result['reuse_vs_rerender']:.1f}×", "≥ 50×")
    t.add_row("full T6 frame (optics+sensor+ISP+detect) / memcpy", f"{result['frame_vs_memcpy']:.0f}×", "≤ 20×")
    codec = details["frame_vs_memcpy"]["jpeg_codec_vs_memcpy"]
    t.add_row("  floor: JPEG encode + decode alone / memcpy", f"{codec:.0f}×", "")
    t.add_row("study throughput, 2 vs 1 workers", f"{result['workers_2_vs_1']:.2f}×", "≥ 1.7×")
    t.add_row("Dask LocalCluster overhead vs local pool", f"{result['dask_overhead']:+.1%}", "≤ 10 %")
    with_start = details["workers_and_dask"]["dask_overhead_with_cluster_start"]
    t.add_row("  the same, counting the cluster's start-up", f"{with_start:+.1%}", "")
    grid = details["full_grid_estimate"]
    t.add_row(
        f"replication grid ({grid['frames']:,} frames), extrapolated from {grid['sampled_batches']} render batches",
        f"cold {grid['cold_h']:.1f} h, warm {grid['warm_h']:.1f} h",
        "< 1 h, < 5 min",
    )
    if result["llvm_vs_scalar"] is not None:
        t.add_row(f"{result['variant']} vs scalar, same render", f"{result['llvm_vs_scalar']:.0f}×", "")
    Console().print(t)


STUDIES = ("webcam-vs-dslr", "brightness-diffuser", "range-limit")
"""The studies the main job runs (quick forms)."""
ALL_STUDIES = (*STUDIES, "replication")


def _study_module(name: str):
    import importlib

    if name not in ALL_STUDIES:
        raise UsageError(f"study: expected one of {', '.join(ALL_STUDIES)}, got {name!r}")
    return importlib.import_module(f"studies.{name.replace('-', '_')}")


def _csv(name: str, text: str | None, convert=str) -> tuple | None:
    """Parse a comma-separated option, or None when not given."""
    if text is None:
        return None
    items = [t.strip() for t in text.split(",") if t.strip()]
    try:
        return tuple(convert(t) for t in items)
    except ValueError:
        raise UsageError(f"{name}: expected a comma-separated list of numbers, got {text!r}") from None


@app.command()
def study(
    name: Annotated[str, typer.Argument(help="webcam-vs-dslr, brightness-diffuser, range-limit or replication.")],
    out: Annotated[Path, typer.Option("--out", help="Output directory (re-run to resume).")],
    quick: Annotated[bool, typer.Option("--quick", help="The small grid the main job runs.")] = False,
    cameras: Annotated[str | None, typer.Option("--cameras", help="Comma-separated camera names.")] = None,
    ranges: Annotated[str | None, typer.Option("--ranges", help="Comma-separated ranges, m.")] = None,
    currents: Annotated[str | None, typer.Option("--currents", help="Comma-separated LED currents, mA.")] = None,
    seeds: Annotated[int | None, typer.Option("--seeds", help="Noise seeds per condition.")] = None,
    workers: Annotated[int | None, typer.Option("--workers", help="Local worker processes (default: CPUs).")] = None,
    scheduler: Annotated[str | None, typer.Option("--scheduler", help="Dask scheduler address.")] = None,
) -> None:
    """Run a study sweep and write report.html, results.csv/.parquet and summary.json."""
    module = _study_module(name)
    options = module.default_options(quick).with_overrides(
        cameras=_csv("cameras", cameras),
        ranges_m=_csv("ranges", ranges, float),
        currents_mA=_csv("currents", currents, float),
        seeds=seeds,
    )
    options.validate()
    if workers is not None and workers < 1:
        raise UsageError(f"workers: expected an integer >= 1, got {workers}")
    prepare_out_dir(out)
    t0 = time.perf_counter()
    module.run(out, options, workers=workers, scheduler=scheduler)
    console.print(f"{name}: report at {out / 'report.html'} ({time.perf_counter() - t0:.0f} s)")


@app.command()
def validate(
    out: Annotated[Path, typer.Option("--out", help="Output directory (re-run to resume).")],
    quick: Annotated[bool, typer.Option("--quick", help="Fewer conditions and seeds.")] = False,
    seeds: Annotated[int | None, typer.Option("--seeds", help="Noise seeds per condition.")] = None,
    workers: Annotated[int | None, typer.Option("--workers", help="Local worker processes (default: CPUs).")] = None,
    scheduler: Annotated[str | None, typer.Option("--scheduler", help="Dask scheduler address.")] = None,
) -> None:
    """Predict the source study's tests with its own detector and settings (validation.csv, report.html)."""
    from studies import validate as validation

    if seeds is not None and seeds < 1:
        raise UsageError(f"seeds: expected an integer >= 1, got {seeds}")
    prepare_out_dir(out)
    t0 = time.perf_counter()
    validation.run(out, quick, workers=workers, scheduler=scheduler, seeds=seeds)
    console.print(f"validate: report at {out / 'report.html'} ({time.perf_counter() - t0:.0f} s)")


@app.command("main-job")
def main_job(
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("out/main-job"),
    workers: Annotated[int | None, typer.Option("--workers", help="Local worker processes (default: CPUs).")] = None,
) -> None:
    """Run the quick versions of the three studies on the built-in defaults."""
    from studies.report import Report

    prepare_out_dir(out)
    t0 = time.perf_counter()
    index = Report("beacon-sim main job: quick studies")
    for name in STUDIES:
        module = _study_module(name)
        options = module.default_options(True)
        options.validate()
        target = prepare_out_dir(out / name)
        module.run(target, options, workers=workers)
        index.parts.append(f"<p><a href='{name}/report.html'>{name}</a></p>")
    index.text(f"Finished in {time.perf_counter() - t0:.0f} s.", note=True)
    index.write(out / "index.html")
    console.print(f"main job done in {time.perf_counter() - t0:.0f} s: open {out / 'index.html'}")


def write_render(out: Path, scenario, cache, cube: bool = False) -> dict:
    """Render ``scenario`` and write radiance.exr, preview.png and render.json to ``out``."""
    from camera_models.geometry import project
    from scenes.marker_photometry import marker_figures
    from scenes.radiance_io import write_band_cube_exr, write_preview_png, write_radiance_exr
    from scenes.render import render as render_scenario

    t0 = time.perf_counter()
    with console.status(f"rendering {scenario.beacon} {scenario.side} at {scenario.range_m} m ..."):
        radiance = render_scenario(scenario, cache)
    elapsed = time.perf_counter() - t0
    files = {
        "radiance": write_radiance_exr(out / "radiance.exr", radiance).name,
        "preview": write_preview_png(out / "preview.png", radiance).name,
    }
    if cube:
        files["band_cube"] = write_band_cube_exr(out / "radiance_cube.exr", radiance).name
    uv = project(scenario.geometry, scenario.camera_pose(), scenario.marker_positions_world_m())
    meta = {
        "marker_configuration": {
            "foam": scenario.foam,
            "paper_sheets": scenario.paper_sheets,
            "paper_colour": scenario.diffuser.paper_colour_for(scenario.side),
            "housing": scenario.housing,
            "led_current_mA": scenario.current_mA,
        },
        "markers": marker_figures(scenario, radiance),
        "scenario": scenario.to_dict(),
        "variant": radiance.variant,
        "from_cache": radiance.from_cache,
        "render_seconds": round(elapsed, 3),
        "pixel_grid": radiance.grid.to_dict(),
        "components": [
            {"name": c.name, "peak_radiance_W_m2_sr": float(c.image_W_m2_sr.max()), "led_current_mA": None}
            for c in radiance.components
        ],
        "markers_ground_truth_px": [{"id": i + 1, "u": float(p[0]), "v": float(p[1])} for i, p in enumerate(uv)],
        "files": files,
    }
    from scenes.render import side_current_mA

    for c in meta["components"]:
        if c["name"].startswith("led:"):
            c["led_current_mA"] = side_current_mA(scenario, c["name"][4:])
    from scenes.render_cache import atomic_write_bytes

    atomic_write_bytes(out / "render.json", json.dumps(meta, indent=2).encode())
    console.print(
        f"wrote {out}/ ({', '.join(files.values())}, render.json) "
        f"in {elapsed:.1f} s{' [cache]' if radiance.from_cache else ''}"
    )
    return meta


def main() -> None:
    """Console-script entry point: turn bad input into one line on stderr."""
    try:
        app(standalone_mode=False)
    except ValueError as exc:  # UsageError, ScenarioError, DataFileError, other validation
        _fail(str(exc))
    except Exception as exc:
        if hasattr(exc, "format_message"):  # click/typer usage errors (NoSuchOption, ...)
            _fail(exc.format_message().replace("\n", " "))
        raise


def _fail(message: str) -> None:
    print(f"beacon-sim: error: {message}", file=sys.stderr)
    sys.exit(2)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()


def _register_command_modules() -> None:
    """Commands defined in other modules register themselves on ``app`` when imported."""
    import importlib

    for name in ("studies.cli_camera", "studies.cli_pipeline"):
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise


_register_command_modules()
