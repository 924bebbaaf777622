"""Study commands: ``study`` (one sweep of the catalog), ``validate`` (the source study's
tests) and ``main-job`` (the quick studies with an index page)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from studies.catalog import MAIN_JOB, MAIN_JOB_DESIGNS, PHYSICS, SEQUENTIAL, STUDIES, prediction_set
from studies.catalog import validate as validation
from studies.catalog.index import write_index
from studies.cli import options as opt
from studies.cli.common import UsageError, check_seeds, console, execution, out_path, parse_list, physics_points
from studies.cli.out_folder import prepare_out_dir
from studies.engine.report import page_context
from studies.engine.run_log import resumed_seconds, timed_part
from studies.engine.sequential import SequentialDesign, candidate_ranges
from studies.engine.sweep import Execution
from studies.engine.tasks import grid_conditions
from studies.engine.uncertainty import POINT_BUDGET_GRIDS

__all__ = ["COMMANDS", "DESIGN_OPTIONS", "main_job", "study", "validate"]

OutResumable = Annotated[
    Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory (re-run to resume).")
]


def _execution(workers: int | None, scheduler: str | None) -> Execution:
    """Validated :class:`Execution` of a sweep (:func:`studies.cli.common.execution`)."""
    return execution(workers, scheduler)


DESIGN_OPTIONS = {
    "target_width_m": "target-width-m",
    "target_relative": "target-relative",
    "budget_frames": "budget-frames",
    "unit_budget_frames": "unit-budget-frames",
    "point_budget_grids": "point-budget-grids",
    "ranges_m": "ranges-m",
}
"""Sequential-design fields set on the command line, and their options."""


def _design(name: str, quick: bool, settings: dict, options) -> SequentialDesign | None:
    """The sequential design of study ``name`` starting from ``options``' grid: its
    ``default_design(quick)`` with the user's ``settings`` (design field → value or None),
    checked; None when none was asked for. A UsageError when the study has none."""
    given = [k for k, v in settings.items() if v is not None]
    if not given:
        return None
    if name not in SEQUENTIAL:
        raise UsageError(
            f"{DESIGN_OPTIONS[given[0]]}: expected a study with a sequential design "
            f"({', '.join(SEQUENTIAL)}), got {name}"
        )
    return _checked(SEQUENTIAL[name].default_design(quick).with_overrides(**settings), options)


def _checked(design: SequentialDesign, options) -> SequentialDesign:
    """``design`` validated for the coarse grid of ``options``, errors named by their option."""
    coarse = len(grid_conditions(options)) * options.seeds
    try:
        design.validate()
        candidate_ranges(options.ranges_m, design)
        if design.budget_frames is not None and design.budget_frames < coarse:
            raise ValueError(
                f"budget_frames: expected at least the coarse grid's {coarse} frames, got {design.budget_frames}"
            )
    except ValueError as e:
        field, _, rest = str(e).partition(":")
        raise UsageError(f"{DESIGN_OPTIONS.get(field, field)}:{rest}") from None
    return design


def _physics(uncertainty: int | None, physics_from: str, names: tuple[str, ...]) -> tuple[tuple[dict, ...], str]:
    """The points of ``--uncertainty`` (:func:`studies.cli.common.physics_points`); a UsageError, before
    any work, when a study of ``names`` cannot state them."""
    refused = [n for n in names if n not in PHYSICS]
    if uncertainty is not None and refused:
        raise UsageError(
            f"uncertainty: expected a study that states it ({', '.join(PHYSICS)}; replication re-runs the source "
            f"study's own configurations), got {refused[0]}"
        )
    return physics_points(uncertainty, physics_from)


def _point_budget(point_budget_grids: float | None, physics: tuple[dict, ...]) -> float | None:
    """``--point-budget-grids``: refused without ``--uncertainty`` (there are no points), else the
    given value or :data:`studies.engine.uncertainty.POINT_BUDGET_GRIDS`."""
    if point_budget_grids is None:
        return POINT_BUDGET_GRIDS if physics else None
    if not physics:
        raise UsageError("point-budget-grids: expected --uncertainty N as well (the budget of each point's estimates)")
    return point_budget_grids


def study(
    name: Annotated[str, typer.Argument(help=f"One of: {', '.join(STUDIES)}.")],
    out: OutResumable,
    quick: Annotated[bool, typer.Option("--quick", help="The small grid the main job runs.")] = False,
    cameras: Annotated[
        str | None,
        typer.Option(
            "--cameras", help="Comma-separated camera names (see 'beacon-sim cameras').", show_default="the study's"
        ),
    ] = None,
    beacons: Annotated[
        str | None,
        typer.Option(
            "--beacons", help="Comma-separated beacon names (see 'beacon-sim beacons').", show_default="the study's"
        ),
    ] = None,
    ranges_m: Annotated[
        str | None, typer.Option("--ranges-m", help="Comma-separated ranges, m.", show_default="the study's")
    ] = None,
    currents_ma: Annotated[
        str | None, typer.Option("--currents-ma", help="Comma-separated LED currents, mA.", show_default="the study's")
    ] = None,
    seeds: opt.Seeds = None,
    target_width_m: opt.TargetWidthM = None,
    target_relative: opt.TargetRelative = None,
    budget_frames: opt.BudgetFrames = None,
    unit_budget_frames: opt.UnitBudgetFrames = None,
    uncertainty: opt.Uncertainty = None,
    physics_from: opt.PhysicsFrom = "calibration",
    point_budget_grids: opt.PointBudgetGrids = None,
    workers: opt.Workers = None,
    scheduler: opt.Scheduler = None,
) -> None:
    """Run a study sweep and write report.html, results.csv/.parquet and summary.json.

    With --target-width-m, --target-relative, --budget-frames or --unit-budget-frames (range-limit, webcam-vs-dslr)
    its ranges are the start of a sequential design that adds frames where the range limits
    are undecided (design.json). With --uncertainty N (every study but replication) it also runs at
    N points of the unknowns and states its answers' noise + physics intervals beside the noise ones."""
    if name not in STUDIES:
        raise UsageError(f"study: expected one of {', '.join(STUDIES)}, got {name!r}")
    module = STUDIES[name]
    check_seeds("seeds", seeds)
    physics, source = _physics(uncertainty, physics_from, (name,))
    options = module.default_options(quick).with_overrides(
        cameras=parse_list("cameras", cameras),
        beacons=parse_list("beacons", beacons),
        ranges_m=parse_list("ranges-m", ranges_m, float),
        currents_mA=parse_list("currents-ma", currents_ma, float),
        seeds=seeds,
        physics=physics or None,
        physics_source=source or None,
    )
    options.validate()
    settings = {
        "target_width_m": target_width_m,
        "target_relative": target_relative,
        "budget_frames": budget_frames,
        "unit_budget_frames": unit_budget_frames,
    }
    design = _design(name, quick, settings, options)
    if design is not None:  # each point's estimates within their own budget
        design = _checked(design.with_overrides(point_budget_grids=_point_budget(point_budget_grids, physics)), options)
    elif point_budget_grids is not None:
        _point_budget(point_budget_grids, physics)  # refused without --uncertainty
        raise UsageError(
            "point-budget-grids: expected a sequential design as well (--target-width-m, --target-relative, "
            "--budget-frames or --unit-budget-frames)"
        )
    execution = _execution(workers, scheduler)
    prepare_out_dir(out, part=name)
    t0 = time.perf_counter()
    with timed_part(out, name), page_context(quick=quick or None):
        if design is None:
            module.run(out, options, execution)
        else:
            module.run(out, options, execution, design=design)
    console.print(f"{name}: report at {out / 'report.html'} ({time.perf_counter() - t0:.0f} s)")


def validate(
    out: OutResumable,
    quick: Annotated[bool, typer.Option("--quick", help="Fewer conditions and seeds.")] = False,
    seeds: opt.Seeds = None,
    calibration: Annotated[
        Path | None,
        typer.Option(
            "--calibration",
            help="nroy.csv of calibrate-unknowns (its NROY set; or its closest.csv, the least implausible points) "
            "or samples.csv of an unknowns search: predict from that set.",
            show_default="results/calibration/nroy.csv, or its closest.csv when the NROY set is empty",
        ),
    ] = None,
    nominal: Annotated[bool, typer.Option("--nominal", help="Ignore --calibration: the unknowns at nominal.")] = False,
    points: Annotated[
        int | None,
        typer.Option(
            "--points", help="Points of the set to run each test at.", show_default="20 of an NROY set, 2 of a search's"
        ),
    ] = None,
    workers: opt.Workers = None,
    scheduler: opt.Scheduler = None,
) -> None:
    """Predict the source study's tests with its own detector and settings (validation.csv, report.html)."""
    check_seeds("seeds", seeds)
    calibration = prediction_set.reference_set() if calibration is None else calibration
    if points is not None and points < 1:
        raise UsageError(f"points: expected an integer >= 1, got {points}")
    if not nominal and not calibration.is_file():
        raise UsageError(
            f"calibration: expected a calibration's nroy.csv or a search's samples.csv, {calibration} is not a file"
        )
    try:
        prediction_set.load(calibration) if not nominal else None
    except ValueError as e:
        raise UsageError(str(e)) from None
    except OSError as e:  # unreadable
        raise UsageError(f"calibration: expected a readable file, got {calibration} ({e.strerror or e})") from None
    execution = _execution(workers, scheduler)
    prepare_out_dir(out)
    t0 = time.perf_counter()
    with timed_part(out, "validate"), page_context(quick=quick or None):
        validation.run(out, quick, execution, seeds=seeds, calibration=None if nominal else calibration, points=points)
    console.print(f"validate: report at {out / 'report.html'} ({time.perf_counter() - t0:.0f} s)")


def main_job(
    out: Annotated[Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory.")] = Path(
        "out/main-job"
    ),
    target_width_m: opt.TargetWidthM = None,
    target_relative: opt.TargetRelative = None,
    budget_frames: opt.BudgetFrames = None,
    unit_budget_frames: opt.UnitBudgetFrames = None,
    uncertainty: opt.Uncertainty = None,
    physics_from: opt.PhysicsFrom = "calibration",
    point_budget_grids: opt.PointBudgetGrids = None,
    workers: opt.Workers = None,
) -> None:
    """Run the quick versions of the three studies on the built-in defaults; range-limit places
    its frames by its sequential design (--target-width-m, --target-relative, --budget-frames,
    --unit-budget-frames)
    and, with --uncertainty N, every study also runs at N points of the unknowns and states its
    answers' noise + physics intervals (far limits, colour separability, the LED setting's P)."""
    physics, source = _physics(uncertainty, physics_from, MAIN_JOB)
    settings = {
        "target_width_m": target_width_m,
        "target_relative": target_relative,
        "budget_frames": budget_frames,
        "unit_budget_frames": unit_budget_frames,
        "point_budget_grids": _point_budget(point_budget_grids, physics),
    }
    designs = {
        n: _checked(SEQUENTIAL[n].default_design(True).with_overrides(**settings), SEQUENTIAL[n].default_options(True))
        for n in MAIN_JOB_DESIGNS
    }
    execution = _execution(workers, None)
    prepare_out_dir(out)
    earlier_s = resumed_seconds(out, "main-job")
    t0 = time.perf_counter()
    with timed_part(out, "main-job"), page_context(quick=True, index_href="../index.html"):
        for name in MAIN_JOB:
            module = STUDIES[name]
            options = module.default_options(True)
            if name in PHYSICS and physics:
                options = options.with_overrides(physics=physics, physics_source=source)
            options.validate()
            if name in designs:
                module.run(prepare_out_dir(out / name), options, execution, design=designs[name])
            else:
                module.run(prepare_out_dir(out / name), options, execution)
        write_index(out, elapsed_s=earlier_s + time.perf_counter() - t0, quick=True, resumed=earlier_s > 0)
    console.print(f"main job done in {time.perf_counter() - t0:.0f} s: open {out / 'index.html'}")


COMMANDS = {"study": study, "validate": validate, "main-job": main_job}
