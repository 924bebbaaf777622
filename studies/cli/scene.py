"""The ``render`` command: spectral radiance of a scenario on a camera's pixel grid."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from scenes.marker_photometry import marker_figures
from scenes.radiance_io import write_band_cube_exr, write_preview_png, write_radiance_exr
from scenes.render import render as render_scenario
from scenes.render import side_current_mA
from scenes.render_cache import RenderCache, atomic_write_bytes
from scenes.scenario import Scenario
from scenes.view import project
from studies.cli import options as opt
from studies.cli.common import check_render_cache, console
from studies.cli.out_folder import prepare_out_dir
from studies.engine import strict_json

__all__ = ["COMMANDS", "render", "write_render"]


@opt.scenario_command
def render(
    out: opt.Out,
    scenario: Scenario,
    cube: Annotated[bool, typer.Option("--cube", help="Also write the 10 nm band cube (radiance_cube.exr).")] = False,
    no_cache: opt.NoCache = False,
) -> None:
    """Render spectral radiance of a beacon on a camera's pixel grid (crop around the beacon)."""
    if not no_cache:
        check_render_cache()
    prepare_out_dir(out)
    write_render(out, scenario, None if no_cache else RenderCache(), cube=cube)


def write_render(out: Path, scenario, cache, cube: bool = False) -> dict:
    """Render ``scenario`` and write radiance.exr, preview.png and render.json to ``out``."""
    t0 = time.perf_counter()
    with console.status(f"rendering {scenario.beacon} {scenario.side} at {scenario.range_m} m ..."):
        radiance = render_scenario(scenario, cache)
    elapsed = time.perf_counter() - t0
    files = {
        "radiance": _atomic(out / "radiance.exr", lambda p: write_radiance_exr(p, radiance)).name,
        "preview": _atomic(out / "preview.png", lambda p: write_preview_png(p, radiance)).name,
    }
    if cube:
        files["band_cube"] = _atomic(out / "radiance_cube.exr", lambda p: write_band_cube_exr(p, radiance)).name
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
    for c in meta["components"]:
        if c["name"].startswith("led:"):
            c["led_current_mA"] = side_current_mA(scenario, c["name"][4:])
    atomic_write_bytes(out / "render.json", strict_json.dumps(meta, indent=2).encode())
    console.print(
        f"wrote {out}/ ({', '.join(files.values())}, render.json) "
        f"in {elapsed:.1f} s{' [cache]' if radiance.from_cache else ''}"
    )
    return meta


def _atomic(path: Path, write: Callable[[Path], object]) -> Path:
    """``write`` a file under a hidden partial name, then rename it into place: an interrupted
    run never leaves a half-written file under the final name."""
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")
    write(partial)
    os.replace(partial, path)
    return path


COMMANDS = {"render": render}
