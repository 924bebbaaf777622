"""Options used by several commands, defined once (typer ``Annotated`` aliases), and the
scenario they describe."""

from __future__ import annotations

import functools
import inspect
import typing
from collections.abc import Callable
from inspect import Parameter
from pathlib import Path
from typing import Annotated

import typer

from scenes.scenario import RenderSettings, Scenario
from studies.cli.common import check_render_work, out_path

__all__ = [
    "SCENARIO_OPTIONS",
    "Beacon",
    "BudgetFrames",
    "Camera",
    "Cameras",
    "CurrentMA",
    "Environment",
    "Foam",
    "Gain",
    "HeightM",
    "Housing",
    "Iso",
    "Json",
    "NoCache",
    "Out",
    "Oversampling",
    "PaperColour",
    "PhysicsFrom",
    "PointBudgetGrids",
    "RangeM",
    "Scheduler",
    "Seed",
    "Seeds",
    "Sheets",
    "Side",
    "Spp",
    "TargetRelative",
    "TargetWidthM",
    "Uncertainty",
    "UnitBudgetFrames",
    "Workers",
    "YawDeg",
    "scenario_command",
    "scenario_from",
]

Out = Annotated[Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory.")]
Json = Annotated[bool, typer.Option("--json", help="Print JSON (for scripts) instead of a table.")]
Beacon = Annotated[str, typer.Option("--beacon", help="Beacon design: v1 or v2.")]
Side = Annotated[str, typer.Option("--side", help="Side facing the camera: red, green, blue, yellow.")]
RangeM = Annotated[float, typer.Option("--range-m", help="Camera to marker 1, m.")]
YawDeg = Annotated[float, typer.Option("--yaw-deg", help="Camera azimuth about the target's vertical axis, degrees.")]
Camera = Annotated[str, typer.Option("--camera", help="Camera model (see 'beacon-sim cameras').")]
Environment = Annotated[str, typer.Option("--environment", help="dark, dark-room or lit-room.")]
CurrentMA = Annotated[
    float | None,
    typer.Option("--led-current-ma", help="LED drive current, mA.", show_default="the LED's datasheet test current"),
]
HeightM = Annotated[float, typer.Option("--camera-height-m", help="Camera height above marker 1, m.")]
Housing = Annotated[str, typer.Option("--housing", help="Housing finish: black or white.")]
Foam = Annotated[bool, typer.Option("--foam/--no-foam", help="Foam disc behind the paper of every marker.")]
Sheets = Annotated[int, typer.Option("--paper-sheets", help="Sheets of paper in front of every LED, 0-5.")]
PaperColour = Annotated[
    str, typer.Option("--paper-colour", help="white, matched (each side's own colour), red, green, blue, yellow.")
]
Spp = Annotated[int, typer.Option("--spp", help="Samples per rendered sub-pixel, 1-65536.")]
Oversampling = Annotated[
    int, typer.Option("--oversampling", help="Rendered sub-pixels per camera pixel, per axis, 1-8.")
]
Seed = Annotated[int, typer.Option("--seed", help="Random seed (same seed, same bytes).")]
NoCache = Annotated[bool, typer.Option("--no-cache", help="Render even if a cached render exists.")]
Iso = Annotated[float | None, typer.Option("--iso", help="ISO (DSLR).", show_default="the camera file's ISO")]
Gain = Annotated[
    int | None, typer.Option("--gain", help="UVC gain code (webcam).", show_default="the lowest gain code")
]
Workers = Annotated[int | None, typer.Option("--workers", help="Local worker processes.", show_default="one per CPU")]
Scheduler = Annotated[
    str | None,
    typer.Option("--scheduler", help="Dask scheduler address (tcp://HOST:PORT).", show_default="local processes"),
]
Seeds = Annotated[int | None, typer.Option("--seeds", help="Noise seeds per condition.", show_default="the study's")]
TargetWidthM = Annotated[
    float | None,
    typer.Option(
        "--target-width-m",
        help="Sequential design: add frames until each range limit's 95 % interval is at most this wide, m.",
        show_default="the study's design",
    ),
]
TargetRelative = Annotated[
    float | None,
    typer.Option(
        "--target-relative",
        help="Sequential design: ... or until both ends lie within ± this fraction of the limit (0.2: ±20 %).",
        show_default="the study's design",
    ),
]
BudgetFrames = Annotated[
    int | None,
    typer.Option(
        "--budget-frames",
        help="Sequential design: frames the study may spend in all, its coarse grid included.",
        show_default="the study's design",
    ),
]
UnitBudgetFrames = Annotated[
    int | None,
    typer.Option(
        "--unit-budget-frames",
        help="Sequential design: frames one range-limit estimate (a unit) may spend, its coarse grid included; "
        "a limit where P stays near 0.95 cannot take the others' frames.",
        show_default="the study's design",
    ),
]
PointBudgetGrids = Annotated[
    float | None,
    typer.Option(
        "--point-budget-grids",
        help="Sequential design with --uncertainty: coarse grids of frames each point's range-limit estimate may "
        "spend (the nominal's keep the design's budget).",
        show_default="2 with --uncertainty",
    ),
]
Uncertainty = Annotated[
    int | None,
    typer.Option(
        "--uncertainty",
        help="Also run at N points of the unknowns and state each limit's noise + physics interval beside its "
        "noise one (16 gives an 88 % interval, 39 a 95 % one).",
        show_default="noise and pose only",
    ),
]
PhysicsFrom = Annotated[
    str,
    typer.Option(
        "--physics-from",
        help="Where --uncertainty's points come from: 'calibration' (the project's: results/calibration/nroy.csv, "
        "or its closest.csv when the NROY set is empty), a calibration's nroy.csv or closest.csv (the unknowns it "
        "covered; the others from their ranges) or 'registry' (every unknown from its range).",
    ),
]
Cameras = Annotated[
    str | None,
    typer.Option(
        "--cameras",
        help="Comma-separated camera names (see 'beacon-sim cameras').",
        show_default="the source study's four: canon-t6-10mm,canon-t6-18mm,logitech-c270,spedal-920",
    ),
]


SCENARIO_OPTIONS = (
    ("beacon", Beacon, "v2"),
    ("side", Side, "red"),
    ("range_m", RangeM, 5.0),
    ("yaw_deg", YawDeg, 10.0),
    ("camera", Camera, "canon-t6-18mm"),
    ("environment", Environment, "dark"),
    ("led_current_ma", CurrentMA, None),
    ("camera_height_m", HeightM, 0.0),
    ("housing", Housing, "black"),
    ("foam", Foam, False),
    ("paper_sheets", Sheets, 0),
    ("paper_colour", PaperColour, "white"),
    ("spp", Spp, 16),
    ("oversampling", Oversampling, 3),
    ("seed", Seed, 0),
)
"""The options that describe a scenario: (parameter, option, default)."""


def scenario_from(
    *,
    beacon: str,
    side: str,
    range_m: float,
    yaw_deg: float,
    camera: str,
    environment: str,
    led_current_ma: float | None,
    camera_height_m: float,
    housing: str,
    foam: bool,
    paper_sheets: int,
    paper_colour: str,
    spp: int,
    oversampling: int,
    seed: int,
) -> Scenario:
    """The :class:`Scenario` the scenario options describe, validated, with a render that can
    finish (:func:`studies.cli.common.check_render_work`)."""
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
    check_render_work(scenario)
    return scenario


def scenario_command(function: Callable) -> Callable:
    """Give a command the scenario options of :data:`SCENARIO_OPTIONS`.

    typer sees them as the command's parameters (after its required ones, before its
    other options); the function itself takes the validated :class:`Scenario` as its
    ``scenario`` argument, so the options and their defaults are written once.
    """
    hints = typing.get_type_hints(function, include_extras=True)
    own = [
        p.replace(kind=Parameter.KEYWORD_ONLY, annotation=hints[p.name])
        for p in inspect.signature(function).parameters.values()
        if p.name != "scenario"
    ]
    added = [Parameter(n, Parameter.KEYWORD_ONLY, default=d, annotation=o) for n, o, d in SCENARIO_OPTIONS]
    required = [p for p in own if p.default is Parameter.empty]
    rest = [p for p in own if p.default is not Parameter.empty]

    @functools.wraps(function)
    def command(**kwargs):
        values = {name: kwargs.pop(name) for name, _, _ in SCENARIO_OPTIONS}
        return function(scenario=scenario_from(**values), **kwargs)

    command.__signature__ = inspect.Signature([*required, *added, *rest], return_annotation=None)
    command.__annotations__ = {p.name: p.annotation for p in [*own, *added]}
    return command
