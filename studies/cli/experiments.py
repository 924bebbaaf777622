"""Experiments: one-off measurements on the engine's frame path (end-to-end detection table,
marker saturation table, diffuser mosaic) and the speed benchmark."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Annotated

import pandas as pd
import typer
from rich.console import Console
from rich.table import Table

from camera_models.camera import load_camera
from scenes.led import led_part_names
from scenes.mitsuba_variant import active_variant
from scenes.render_cache import atomic_write_bytes
from scenes.scenario import RenderSettings, Scenario
from scenes.view import camera_names
from studies.catalog import unknowns_search as search
from studies.cli import options as opt
from studies.cli.common import (
    UsageError,
    check_finite,
    check_render_cache,
    check_render_work,
    check_seeds,
    check_workers,
    console,
    execution,
    out_path,
    parse_list,
    physics_points,
    physics_source,
    print_table,
    rich_progress,
)
from studies.cli.out_folder import prepare_out_dir
from studies.engine import colour_reach as reach
from studies.engine import strict_json
from studies.engine.run_log import timed_part
from studies.engine.tasks import STUDY_CAMERAS
from studies.experiments import bench as b
from studies.experiments import crop_vs_full as cvf
from studies.experiments import diffuser_mosaic as mosaic
from studies.experiments import e2e_detection as e2e
from studies.experiments import saturation_table as saturation
from studies.experiments import tracker_pruning as pruning

__all__ = [
    "COMMANDS",
    "MAX_SAMPLES",
    "bench",
    "calibrate_unknowns",
    "colour_reach",
    "crop_vs_full",
    "design",
    "diffuser_mosaic",
    "e2e_detection",
    "saturation_table",
    "sensitivity",
    "tracker_pruning",
    "unknowns_search",
]

MAX_SAMPLES = 2**16
"""Most points an unknowns search accepts: each is scored on every close-range condition, side
and seed, about 40 frames, so 2^16 points are millions of frames."""


def _cameras(text: str | None, default) -> tuple[str, ...]:
    """``--cameras`` (comma-separated) validated against the camera files, or ``default``."""
    names = parse_list("cameras", text)
    if names is None:
        return tuple(default)
    if not names:
        raise UsageError(f"cameras: expected at least one of {', '.join(camera_names())}, got {text!r}")
    for name in names:
        if name not in camera_names():
            raise UsageError(f"cameras: expected some of {', '.join(camera_names())}, got {name!r}")
    return names


def e2e_detection(
    out: Annotated[
        Path,
        typer.Option(
            "--out", parser=out_path, metavar="DIR", help="Output directory (re-run to resume; tables, summary.md)."
        ),
    ],
    seeds: Annotated[
        int | None,
        typer.Option("--seeds", help="Sensor-noise seeds per condition, 0..N-1.", show_default="3; 1 with --quick"),
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="Ranges 1, 3, 5 m × yaws 0, 15, 30° and one seed (unless --seeds).")
    ] = False,
    full_frame_check: Annotated[
        bool | None,
        typer.Option(
            "--full-frame-check/--no-full-frame-check",
            help="Also detect on one full 18 MP frame (2 m, 15°), compare with the crop.",
            show_default="on; off with --quick",
        ),
    ] = None,
    workers: opt.Workers = None,
) -> None:
    """Issue 5's end-to-end table: T6 + 18 mm captures of the V2 red side, 1-5 m × 0-30°, both trackers × estimators."""
    check_seeds("seeds", seeds)
    options = e2e.default_options(quick, seeds)
    options.validate()
    run_on = execution(workers)
    prepare_out_dir(out)
    console.print(e2e.describe(options))
    t0 = time.perf_counter()
    result = e2e.run(
        out,
        options,
        run_on,
        full_frame=full_frame_check if full_frame_check is not None else not quick,
    )
    console.print(f"wrote {', '.join(str(p) for p in result.paths.values())} in {time.perf_counter() - t0:.0f} s")


def saturation_table(
    out: opt.Out,
    cameras: Annotated[
        str | None,
        typer.Option(
            "--cameras", help="Comma-separated camera names (see 'beacon-sim cameras').", show_default="all four"
        ),
    ] = None,
    spp: opt.Spp = 4,
    oversampling: opt.Oversampling = 2,
    seed: opt.Seed = 0,
    workers: opt.Workers = None,
) -> None:
    """Marker-core saturation per camera, LED drive (2-20 mA) and diffuser (bare; foam + 0/1/3 sheets) at 2 m and 5 m.

    V2 red side, yaw 0, dark, white paper, through render → capture. Writes
    saturation_table.csv (one row per marker) and saturation_table.md (summary,
    webcam auto-exposure values); re-run to resume.
    """

    names = _cameras(cameras, saturation.CAMERAS)
    RenderSettings(spp=spp, oversampling=oversampling, seed=seed).validate()
    check_workers(workers)
    check_render_cache()
    tasks = saturation.saturation_tasks(names, spp=spp, oversampling=oversampling, seed=seed)
    seen = set()
    for task in tasks:  # the largest renders (each camera at its closest range) must be feasible
        key = json.dumps([task["scenario"]["camera"], task["scenario"]["range_m"], task["render"]], sort_keys=True)
        if key not in seen:
            seen.add(key)
            check_render_work(Scenario(**task["scenario"], render=RenderSettings(**task["render"])))
    prepare_out_dir(out)
    rows = saturation.saturation_rows(out, tasks, workers=workers, progress=rich_progress)
    partial = out / ".saturation_table.csv.partial"
    saturation.write_csv(rows, partial)
    os.replace(partial, out / "saturation_table.csv")  # never a half-written table under the final name
    atomic_write_bytes(out / "saturation_table.md", saturation.summary_markdown(rows).encode())
    console.print(f"wrote {out}/saturation_table.csv ({len(rows)} rows) and saturation_table.md")


def diffuser_mosaic(out: opt.Out) -> None:
    """The diffuser mosaic: one marker at 150 mm behind 0-5 sheets of paper, without and with foam (PNG + JSON)."""
    check_render_cache()
    prepare_out_dir(out)
    with console.status("rendering the diffuser mosaic ..."):
        fluxes = mosaic.diffuser_mosaic(out / "diffuser_mosaic.png")
    atomic_write_bytes(out / "diffuser_mosaic.json", strict_json.dumps(fluxes, indent=2).encode())
    console.print(f"wrote {out}/diffuser_mosaic.png and diffuser_mosaic.json")


def colour_reach(
    out: opt.Out,
    cameras: opt.Cameras = None,
) -> None:
    """Which of the study's colour boxes each camera's rendering of each LED can enter at any exposure (no render).

    Sweeps highlight mode, white balance, crosstalk, paper and the LED's wavelength bin
    (studies/engine/colour_reach.py). Writes reach.csv (one row per setting), summary.json
    (per camera and side: whether any setting reaches the side's own box, and which) and
    trajectories.png.
    """
    names = _cameras(cameras, STUDY_CAMERAS)
    prepare_out_dir(out)
    cameras = {n: load_camera(n) for n in names}
    with console.status("colour curves of every camera, LED and setting ..."):
        table = pd.DataFrame(reach.reach_table(cameras))
        reach.trajectory_figure(cameras, out / "trajectories.png")
    summary = {}
    for (cam, side), g in table.groupby(["camera", "side"], sort=False):
        ok = g[g.own_box]
        summary.setdefault(cam, {})[side] = {
            "reachable": bool(len(ok)),
            "settings_tried": len(g),
            "settings_reaching": len(ok),
            **{k: sorted(set(ok[k]), key=str) for k in ("highlight", "white_balance", "crosstalk", "paper_colour")},
            "exposure_range": [float(ok.own_low.min()), float(ok.own_high.max())] if len(ok) else None,
        }
    atomic_write_bytes(out / "reach.csv", table.to_csv(index=False, float_format="%.4g").encode())
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    t = Table("camera", "side", "own box reached", "with")
    for cam, sides in summary.items():
        for side, v in sides.items():
            got = f"{v['settings_reaching']} of {v['settings_tried']} settings" if v["reachable"] else "never"
            how = (
                ""
                if not v["reachable"]
                else f"highlight {'/'.join(v['highlight'])}, paper {'/'.join(v['paper_colour'])}"
            )
            t.add_row(cam, side, got, how)
    Console().print(t)
    console.print(f"wrote {out}/reach.csv, summary.json and trajectories.png")


def bench(
    json_out: opt.Json = False,
    skip_scalar: Annotated[bool, typer.Option("--skip-scalar", help="Skip the slow scalar-variant timing.")] = False,
    grid_tables: Annotated[
        bool,
        typer.Option(
            "--grid-tables",
            help="Instead: time the replication study's tables at the full grid's size (stand-in frames, ~6 min).",
        ),
    ] = False,
    grid_sample: Annotated[
        float | None,
        typer.Option(
            "--grid-sample",
            metavar="FRACTION",
            help="Instead: run this random fraction of the replication grid's render batches cold and "
            "extrapolate the grid from the measured time (0.01: ~21 500 frames, hours on 2 cores; "
            "resumes in --out).",
            show_default="off: the full benchmark",
        ),
    ] = None,
    out: Annotated[
        Path,
        typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory of --grid-sample."),
    ] = Path("out/grid-sample"),
    workers: Annotated[int, typer.Option("--workers", help="Local worker processes of --grid-sample.")] = 2,
    seed: Annotated[int, typer.Option("--seed", help="Seed of --grid-sample's choice of render batches.")] = 0,
) -> None:
    """Measure speed-ups as ratios, side by side in one run on this machine."""

    if grid_sample is not None:
        check_finite("grid-sample", grid_sample, 1e-6, 1.0)
        run = execution(workers)
        prepare_out_dir(out)
        summary = b.grid_sample(out, grid_sample, seed, run)
        if json_out:
            print(strict_json.dumps(summary, indent=2))
            return
        print_table(
            f"replication grid sample ({active_variant().variant}, {os.cpu_count()} CPUs, {workers} workers)",
            ("measurement", "result"),
            [
                ("render batches / frames run", f"{summary['render_batches']:,} / {summary['frames']:,}"),
                ("measured, cold", f"{summary['measured_s'] / 60:.1f} min"),
                ("  of which near fields", f"{summary['near_fields']} in {summary['near_fields_s'] / 60:.1f} min"),
                ("  per frame", f"{summary['ms_per_frame']:.0f} ms"),
                (
                    f"grid ({summary['grid_frames']:,} frames), extrapolated",
                    f"{summary['grid_cold_h']:.1f} h (95 %: {summary['grid_cold_h_95'][0]:.1f}-"
                    f"{summary['grid_cold_h_95'][1]:.1f} h)",
                ),
            ],
        )
        console.print(f"wrote {out}/summary.json")
        return

    if grid_tables:
        with console.status("bench: replication tables at full size ..."):
            print(strict_json.dumps(b.replication_tables(), indent=2))
        return

    steps = [
        ("two_stage_vs_brute_force", b.two_stage_vs_brute_force),
        ("reuse_vs_rerender", b.reuse_vs_rerender),
        ("frame_vs_memcpy", b.frame_vs_memcpy),
        ("hugepage_advice", b.hugepage_advice),
        ("whole_frame_paths", b.whole_frame_paths),
        ("blob_grouping", b.blob_grouping),
        ("warm_frames", b.warm_frames),
        ("cold_renders", b.cold_renders),
        ("workers_and_dask", b.workers_and_dask),
        ("full_grid_estimate", b.full_grid_estimate),
        ("equivalence", b.equivalence_statistics),
        ("recorded_runs", b.recorded_runs),
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
        "hugepage_advice_on_vs_off": details["hugepage_advice"]["ratio"],
        "workers_2_vs_1": details["workers_and_dask"]["workers_2_vs_1"],
        "dask_overhead": details["workers_and_dask"]["dask_overhead"],
        "variant": active_variant().variant,
        "llvm_vs_scalar": details["variant"]["ratio"] if "variant" in details else None,
        "full_grid_cold_h": details["full_grid_estimate"]["cold_h"],
        "full_grid_warm_h": details["full_grid_estimate"]["warm_h"],
        "warm_frame_ms": details["warm_frames"]["full"]["median_ms"],
        "warm_frame_crop_ms": details["warm_frames"]["crop"]["median_ms"],
        "cold_render_s": details["cold_renders"]["cold_render_s"],
        "near_field_s": details["cold_renders"]["near_field_s"],
        "full_frame_s": details["frame_vs_memcpy"]["frame_s"],
        "t6_frame_s": details["whole_frame_paths"]["canon-t6-18mm"]["fast_frame_s"],
        "t6_frame_reference_s": details["whole_frame_paths"]["canon-t6-18mm"]["reference_frame_s"],
        "t6_frame_vs_memcpy": details["whole_frame_paths"]["canon-t6-18mm"]["fast_vs_memcpy"],
        "webcam_frame_s": details["whole_frame_paths"]["logitech-c270"]["fast_frame_s"],
        "webcam_frame_reference_s": details["whole_frame_paths"]["logitech-c270"]["reference_frame_s"],
        "blob_grouping_vs_opencv": details["blob_grouping"]["ratio"],
        "replication_cold_h": details["full_grid_estimate"]["cold_h"],
        "room_background_s": details["cold_renders"]["room_background_s"],
        "equivalence": details["equivalence"],
        "main_job_s": (details["recorded_runs"]["main_job"] or {}).get("s"),
        "full_studies_s": details["recorded_runs"]["full_studies_s"],
        "details": details,
    }
    if json_out:
        print(strict_json.dumps(result, indent=2))
        return
    t = Table(title=f"beacon-sim bench ({result['variant']}, {os.cpu_count()} CPUs)")
    for col in ("measurement", "result", "goal"):
        t.add_column(col)
    warm, cold, frame = details["warm_frames"], details["cold_renders"], details["frame_vs_memcpy"]
    t.add_row(
        f"warm frame, median over {warm['frames']} frames of the quick studies: whole frame / crop",
        f"{warm['full']['median_ms']:.0f} ms / {warm['crop']['median_ms']:.1f} ms",
        "≤ 5 ms",
    )
    t.add_row(
        "cold render per new geometry, after the worker's first (beside: all path-traced)",
        f"{cold['cold_render_s']:.2f} s ({cold['cold_render_path_s']:.2f} s, {cold['ratio']:.1f}×)",
        "≤ 0.3 s",
    )
    t.add_row(
        "  background: dark room none; lit room once per camera and range/yaw/height band",
        f"0 s / {cold['room_background_s']:.2f} s per band",
        "",
    )
    t.add_row(
        "near field of one configuration and colour: foam (6 angles) / foam + 1 sheet (1 angle)",
        f"{cold['near_fields']['foam']:.1f} s / {cold['near_fields']['foam_1_matched']:.1f} s",
        "≤ 5 s",
    )
    t.add_row(
        "full T6 frame (camera + JPEG + both detectors); / memcpy of its bytes",
        f"{frame['frame_s']:.2f} s; {frame['ratio']:.0f}×",
        "≤ 1.0 s; ≤ 130×",
    )
    t.add_row("  floor: JPEG encode + decode alone / memcpy", f"{frame['jpeg_codec_vs_memcpy']:.0f}×", "")
    huge = details["hugepage_advice"]
    t.add_row(
        "  the same frame with numpy's huge-page advice on / off (kernel time beside; same bytes: "
        f"{'yes' if huge['same_bytes'] else 'NO'})",
        f"{huge['ratio']:.1f}× ({huge['advice_on_kernel_s']:.1f} s / {huge['advice_off_kernel_s']:.1f} s)",
        "",
    )
    for name, goal in (("canon-t6-18mm", "≤ 0.4 s; ≤ 40×"), ("logitech-c270", "≤ 0.08 s")):
        w = details["whole_frame_paths"][name]
        t.add_row(
            f"{name} whole frame, fast path (reference path beside); / memcpy",
            f"{w['fast_frame_s']:.2f} s ({w['reference_frame_s']:.2f} s, {w['reference_vs_fast']:.1f}×); "
            f"{w['fast_vs_memcpy']:.0f}×",
            goal,
        )
        t.add_row(
            "  sensor / ISP + JPEG / decode / detectors",
            f"{w['fast_sensor_s']:.2f} / {w['fast_isp_jpeg_s']:.2f} / {w['fast_decode_s']:.2f} / "
            f"{w['fast_detect_s']:.2f} s ({w['reference_sensor_s']:.2f} / {w['reference_isp_jpeg_s']:.2f} s)",
            "",
        )
    blobs = details["blob_grouping"]
    t.add_row(
        f"study tracker's blob detection, {blobs['blobs']:,} noise specks: OpenCV's 17 levels / one level",
        f"{blobs['opencv_s']:.1f} s / {blobs['one_level_s']:.2f} s ({blobs['ratio']:.0f}×, "
        f"{'identical' if blobs['identical'] else 'KEYPOINTS DIFFER'})",
        "identical",
    )
    eq = details["equivalence"]
    for name, c in eq["cameras"].items():
        t.add_row(
            f"equivalence {name} {next(iter(c['setting'].values()))}: photon transfer mean / variance; dark χ² p",
            f"≤ {c['ptc_max_rel_mean_diff']:.2%} / ≤ {c['ptc_max_rel_var_diff']:.2%}; p = {c['dark_chi2_p']:.2f}",
            "≤ 1 % / ≤ 1 %; p > 0.001",
        )
    for tracker, c in eq["false_blobs_c270"].items():
        t.add_row(
            f"  C270 false blobs per dark frame, {tracker} tracker ({eq['frames']} frames per path)",
            f"{c['reference_mean']:.1f} → {c['fast_mean']:.1f} (Mann-Whitney p = {c['p']:.2f})",
            "p > 0.001",
        )
    runs = details["recorded_runs"]
    job = runs["main_job"]
    t.add_row(
        "main job, cold, fresh clone (recorded: results/main-job/runs.json)",
        "no record" if job is None else f"{job['s'] / 60:.1f} min, {job['frames']:,} frames ({job['finished_utc']})",
        "≤ 5 min",
    )
    for name, rec in runs["full_studies"].items():
        t.add_row(
            f"  full {name}, cold (recorded: results/full/{name}.runs.json)",
            "no record"
            if rec is None
            else f"{rec['s'] / 60:.1f} min in {rec['parts']} part(s), {rec['frames']:,} frames",
            "",
        )
    total = runs["full_studies_s"]
    t.add_row("the four full studies, cold", "not all recorded" if total is None else f"{total / 3600:.2f} h", "≤ 1 h")
    t.add_row("100-frame sweep: render reuse vs re-render", f"{result['reuse_vs_rerender']:.1f}×", "≥ 500×")
    grid = details["full_grid_estimate"]
    t.add_row(
        f"replication grid ({grid['frames']:,} frames), extrapolated from {grid['sampled_batches']} render batches",
        f"cold {grid['cold_h']:.0f} h (95 %: {grid['cold_h_95'][0]:.0f}-{grid['cold_h_95'][1]:.0f} h), "
        f"warm {grid['warm_h']:.0f} h",
        "≤ 5 h cold",
    )
    t.add_row("two-stage vs brute-force marker, equal 1 % RMS", f"{result['two_stage_vs_brute_force']:.0f}×", "≥ 100×")
    t.add_row("study throughput, 2 vs 1 workers", f"{result['workers_2_vs_1']:.2f}×", "≥ 1.7×")
    t.add_row("Dask LocalCluster overhead vs local pool", f"{result['dask_overhead']:+.1%}", "≤ 10 %")
    with_start = details["workers_and_dask"]["dask_overhead_with_cluster_start"]
    t.add_row("  the same, counting the cluster's start-up", f"{with_start:+.1%}", "")
    if result["llvm_vs_scalar"] is not None:
        t.add_row(f"{result['variant']} vs scalar, same render", f"{result['llvm_vs_scalar']:.0f}×", "")
    Console().print(t)


def unknowns_search(
    out: opt.Out,
    samples: Annotated[
        int, typer.Option("--samples", help=f"Points of the unknowns to try (Sobol'), 1-{MAX_SAMPLES}.")
    ] = 64,
    seeds: Annotated[int, typer.Option("--seeds", help="Noise seeds per point and side.")] = 1,
    seed: opt.Seed = 0,
    workers: opt.Workers = None,
) -> None:
    """Which unknowns let the study's printed detector see every colour at close range (webcam 150 mm, T6 1 m)."""
    if not 1 <= samples <= MAX_SAMPLES:
        raise UsageError(f"samples: expected an integer in [1, {MAX_SAMPLES}], got {samples}")
    check_seeds("seeds", seeds)
    if not 0 <= seed < 2**32:
        raise UsageError(f"seed: expected an integer in [0, 2^32), got {seed}")
    run_on = execution(workers)
    prepare_out_dir(out)
    t0 = time.perf_counter()
    summary = search.run(out, samples, seeds, seed, run_on)
    console.print(
        f"{summary['consistent_points']} of {samples} points consistent ({time.perf_counter() - t0:.0f} s); "
        f"wrote {out}/samples.csv and summary.json"
    )


def calibrate_unknowns(
    out: opt.Out,
    runs_per_wave: Annotated[
        int | None,
        typer.Option(
            "--runs-per-wave",
            help="Points of the unknowns simulated per wave (3-4096).",
            show_default="40; 8 with --quick",
        ),
    ] = None,
    waves: Annotated[int, typer.Option("--waves", help="Waves at most (at least 3 unless nothing is left), 3-20.")] = 5,
    seeds: Annotated[
        int | None,
        typer.Option("--seeds", help="Noise seeds per point and observation.", show_default="2; 1 with --quick"),
    ] = None,
    order: Annotated[
        int,
        typer.Option(
            "--order",
            help="Rule a point out by the largest (1), second (2) or third (3) largest implausibility over the "
            "outputs (the third tolerates two outputs the model cannot match).",
        ),
    ] = 3,
    observations: Annotated[
        Path | None,
        typer.Option(
            "--observations", metavar="FILE", help="Observations file.", show_default="studies/data/observations.toml"
        ),
    ] = None,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick",
            help="8 runs per wave, 3 waves, one seed, near fields at 256 samples, a small reference sample "
            "(a first look; not a calibration to predict from).",
        ),
    ] = False,
    seed: opt.Seed = 0,
    workers: opt.Workers = None,
) -> None:
    """History-match the unknowns to what the study saw at close range; writes history.json, nroy.csv,
    summary.json and figures (re-run to resume)."""
    from dataclasses import replace

    from studies.catalog import calibration
    from studies.engine.calibration import Settings

    runs = runs_per_wave if runs_per_wave is not None else (8 if quick else 40)
    seeds = seeds if seeds is not None else (1 if quick else 2)
    if not 3 <= runs <= 4096:
        raise UsageError(f"runs-per-wave: expected an integer in [3, 4096], got {runs}")
    if not 3 <= waves <= 20:
        raise UsageError(f"waves: expected an integer in [3, 20], got {waves}")
    check_seeds("seeds", seeds)
    if order not in (1, 2, 3):
        raise UsageError(f"order: expected 1, 2 or 3, got {order}")
    if not 0 <= seed < 2**32:
        raise UsageError(f"seed: expected an integer in [0, 2^32), got {seed}")
    path = calibration.OBSERVATIONS_FILE if observations is None else observations
    try:
        calibration.load_observations(path)  # every observation checked before any work
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    settings = Settings(min_waves=3, max_waves=waves, seed=seed, order=order)
    if quick:
        settings = calibration.quick_settings(settings)
    settings = replace(settings, n_per_wave=runs)  # --runs-per-wave wins over --quick's 8
    run_on = execution(workers)
    check_render_cache()
    prepare_out_dir(out)
    t0 = time.perf_counter()
    result = calibration.run(
        out,
        settings=settings,
        seeds=seeds,
        observations=path,
        execution=run_on,
        render=calibration.QUICK_RENDER if quick else None,
    )
    fractions = ", ".join(f"{w.nroy_fraction:.3g}" for w in result.waves)
    console.print(
        f"{len(result.waves)} waves ({result.stopped}); NROY fraction after each: {fractions}; "
        f"{len(result.nroy_points)} reference points not ruled out ({time.perf_counter() - t0:.0f} s); "
        f"wrote {out}/report.html, history.json, nroy.csv, summary.json"
    )


def sensitivity(
    out: Annotated[
        Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory (re-run to resume).")
    ],
    camera: opt.Camera = "logitech-c270",
    beacon: opt.Beacon = "v2",
    side: opt.Side = "red",
    yaw_deg: Annotated[float, typer.Option("--yaw-deg", help="Beacon yaw, degrees (0-90).")] = 0.0,
    led_current_ma: Annotated[float, typer.Option("--led-current-ma", help="LED drive current, mA.")] = 2.0,
    points: Annotated[
        int, typer.Option("--points", help="Points of the unknowns (direct runs the emulator is fitted to), >= 8.")
    ] = 32,
    physics_from: opt.PhysicsFrom = "registry",
    quick: Annotated[bool, typer.Option("--quick", help="A coarser range grid, two seeds per range.")] = False,
    seed: opt.Seed = 0,
    workers: opt.Workers = None,
    scheduler: opt.Scheduler = None,
) -> None:
    """Rank the unknowns by how much of a camera's far limit (and of P(correct) at 5 m) each explains:
    Morris screening, then Sobol' indices, on an emulator of range-limit runs at points of the unknowns."""
    from studies.catalog import prediction_set
    from studies.catalog import sensitivity as analysis

    if camera not in camera_names():
        raise UsageError(f"camera: expected one of {', '.join(camera_names())}, got {camera!r}")
    if points < 8:
        raise UsageError(f"points: expected an integer >= 8 (an emulator needs several runs), got {points}")
    if not 0 <= yaw_deg <= 90:
        raise UsageError(f"yaw-deg: expected an angle in [0, 90], got {yaw_deg:g}")
    source = physics_source(physics_from)
    setting = analysis.Setting(camera=camera, beacon=beacon, side=side, led_current_mA=led_current_ma, yaw_deg=yaw_deg)
    try:
        analysis.check(setting)
        prediction_set.physics_points(points, seed=seed, calibration=source)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    run_on = execution(workers, scheduler)
    check_render_cache()
    prepare_out_dir(out)
    with timed_part(out, analysis.NAME):
        summary = analysis.run(
            out, setting, points=points, calibration=source, seed=seed, quick=quick, execution=run_on
        )
    for a in summary["analyses"].values():
        console.print(a["sentences"][0])
    console.print(f"sensitivity: {summary['wall_s']:.0f} s; wrote {out}/report.html and sensitivity.json")


def design(
    out: Annotated[
        Path, typer.Option("--out", parser=out_path, metavar="DIR", help="Output directory (--resume to go on).")
    ],
    camera: opt.Camera = "logitech-c270",
    side: opt.Side = "red",
    yaw_deg: Annotated[
        str,
        typer.Option(
            "--yaw-deg", help="Beacon yaws the design must work at, degrees, comma-separated (0,30: the whole range)."
        ),
    ] = "30",
    max_side_power_mw: Annotated[
        float, typer.Option("--max-side-power-mw", help="Optical power budget of one side (five LEDs), mW.")
    ] = 10.0,
    max_span_mm: Annotated[
        float | None,
        typer.Option(
            "--max-span-mm", help="Largest target span (in-plane markers and lit faces), mm.", show_default="none"
        ),
    ] = None,
    focal_length_mm: Annotated[
        str | None,
        typer.Option(
            "--focal-length-mm",
            help="LOW,HIGH: also search the lens of an interchangeable-lens body (e.g. 4,35).",
            show_default="the camera's own lens",
        ),
    ] = None,
    side_colour: Annotated[
        bool,
        typer.Option(
            "--side-colour",
            help="Also search the side's colour: its LED's dominant wavelength within the band lamps of that colour "
            "are made in, as far as it stays as distinct from the other sides as the study's closest pair.",
        ),
    ] = False,
    trials: Annotated[int, typer.Option("--trials", help="Designs to evaluate (each a range-limit run).")] = 40,
    uncertainty: opt.Uncertainty = None,
    physics_from: opt.PhysicsFrom = "calibration",
    at: Annotated[
        str,
        typer.Option(
            "--at",
            help="Score designs by the nominal far limit, or (with --uncertainty) the noise + physics interval's "
            "lower end ('low') or the points' median ('median').",
        ),
    ] = "nominal",
    p_working: Annotated[
        float,
        typer.Option(
            "--p-working",
            help="The probability of a correct pose the far limit stands for (0.5 < P < 1): the design must be "
            "right this often at its far limit.",
        ),
    ] = 0.95,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the search in --out (to --trials).")] = False,
    quick: Annotated[bool, typer.Option("--quick", help="A coarser range grid per design.")] = False,
    seed: opt.Seed = 0,
    workers: opt.Workers = None,
    scheduler: opt.Scheduler = None,
) -> None:
    """Search the beacon's design (marker offsets, lit face, LED part, drive, diffusers; a lens, the side's
    colour) for the far
    limit over the yaws under a power budget: the Pareto front of far limit, power and span, beside V2 at
    the same budget. With --uncertainty N every design also runs at N points of the unknowns and --at says
    which far limit scores it."""
    from studies.catalog import design as search_design
    from studies.cli.common import rich_progress

    if camera not in camera_names():
        raise UsageError(f"camera: expected one of {', '.join(camera_names())}, got {camera!r}")
    yaws = tuple(parse_list("yaw-deg", yaw_deg, float))
    if not all(0 <= y <= 90 for y in yaws):
        raise UsageError(f"yaw-deg: expected angles in [0, 90], got {yaw_deg}")
    if at not in search_design.AT:
        raise UsageError(f"at: expected one of {', '.join(search_design.AT)}, got {at!r}")
    if at != "nominal" and uncertainty is None:
        raise UsageError(f"at: {at!r} needs points of the unknowns (--uncertainty N), got none")
    if not 0.5 < p_working < 1:
        raise UsageError(f"p-working: expected a probability between 0.5 and 1 (exclusive), got {p_working:g}")
    physics, source = physics_points(uncertainty, physics_from)
    ranges = {p.name: p for p in search_design.SPACE.params}
    hues = search_design.hue_range(side) if side_colour else (None,)
    low_mA = ranges["led_current_mA"].low
    least = min(search_design.side_power_mW(side, low_mA, p, nm) for p in led_part_names(side) for nm in hues)
    if not max_side_power_mw >= least:
        raise UsageError(
            f"max-side-power-mw: expected at least {least:.3g} mW (five LEDs at the search's lowest drive, "
            f"{low_mA:g} mA): no design fits {max_side_power_mw:g}"
        )
    smallest = 2 * ranges["arm_length_mm"].low + ranges["lit_face_diameter_mm"].low
    if max_span_mm is not None and not max_span_mm >= smallest:
        raise UsageError(
            f"max-span-mm: expected at least {smallest:g} mm (the smallest design's span), got {max_span_mm:g}"
        )
    if trials < 1:
        raise UsageError(f"trials: expected an integer >= 1, got {trials}")
    lenses = None
    if focal_length_mm is not None:
        lenses = tuple(parse_list("focal-length-mm", focal_length_mm, float))
        if len(lenses) != 2 or not 0 < lenses[0] < lenses[1] <= 2000:
            raise UsageError(
                f"focal-length-mm: expected LOW,HIGH with 0 < LOW < HIGH <= 2000 mm, got {focal_length_mm}"
            )
        try:
            from camera_models.lens_variant import lens_variant_text

            lens_variant_text(camera, lenses[0])
        except ValueError as exc:
            raise UsageError(f"focal-length-mm: {exc}") from None
    target = search_design.Target(
        camera=camera, side=side, yaws_deg=yaws, quick=quick, focal_lengths_mm=lenses, physics=physics,
        physics_source=source, at=at, p_working=p_working, side_colour=side_colour,
    )  # fmt: skip
    budget = search_design.Budget(side_power_mW=max_side_power_mw, span_mm=max_span_mm)
    run_on = execution(workers, scheduler)
    check_render_cache()
    prepare_out_dir(out)
    with rich_progress("design search", trials, 0) as advance, timed_part(out, search_design.NAME):
        try:
            summary = search_design.run(
                out, target, budget, trials=trials, seed=seed, resume=resume, execution=run_on,
                progress=lambda p: advance(),
            )  # fmt: skip
        except (FileExistsError, ValueError) as exc:
            raise UsageError(str(exc).splitlines()[0]) from None
    console.print(
        f"design: {summary['evaluations']} designs, {summary['feasible']} within budget; "
        f"{summary['wall_s']:.0f} s; wrote {out}/report.html and design.json"
    )


def crop_vs_full(
    out: opt.Out,
    cameras: opt.Cameras = None,
    ranges_m: Annotated[
        str | None, typer.Option("--ranges-m", help="Comma-separated ranges, m.", show_default="2,5")
    ] = None,
    currents_ma: Annotated[
        str | None, typer.Option("--currents-ma", help="Comma-separated LED currents, mA.", show_default="20")
    ] = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Noise seeds per condition.")] = cvf.SEEDS,
) -> None:
    """What the detectors see on the rendered crop versus the camera's whole frame (same frames, same seeds).

    V2 red side, yaw 0, dark, foam + 1 matched sheet. Writes crop_vs_full.csv (per frame and
    tracker: blobs, success, range error, time per path), crop_vs_full_summary.csv and
    crop_vs_full.json (with the cost per frame of each path).
    """
    names = _cameras(cameras, STUDY_CAMERAS)
    ranges = parse_list("ranges-m", ranges_m, float) or cvf.RANGES_M
    currents = parse_list("currents-ma", currents_ma, float) or (20.0,)
    check_seeds("seeds", seeds)
    cvf.comparison_tasks(names, ranges, seeds, currents)  # validates every condition before any work
    check_render_cache()
    prepare_out_dir(out)
    t0 = time.perf_counter()
    with console.status(f"crop vs full frame: {len(names)} cameras x {len(ranges)} ranges x {seeds} seeds ..."):
        result = cvf.run(out, names, ranges, seeds, currents)
    for c in result.cost:
        console.print(
            f"{c['camera']}: {c['seconds_crop']:.2f} s per crop frame, {c['seconds_full']:.2f} s per whole frame "
            f"(x{c['ratio']:.1f})"
        )
    console.print(
        f"wrote {out}/crop_vs_full.csv, crop_vs_full_summary.csv, crop_vs_full.json ({time.perf_counter() - t0:.0f} s)"
    )


def tracker_pruning(
    out: opt.Out,
    max_frames: Annotated[
        int | None, typer.Option("--max-frames", help="Use at most this many frames.", show_default="all (~300)")
    ] = None,
    repeats: Annotated[int, typer.Option("--repeats", help="Tracker runs per frame and search (fastest counts).")] = 3,
) -> None:
    """The best tracker's pruned 5-subset search against the full search on the quick grids' frames.

    Checks the answers are identical and measures the saving; writes tracker_pruning.json.
    """
    if max_frames is not None and max_frames < 1:
        raise UsageError(f"max-frames: expected an integer >= 1, got {max_frames}")
    if not 1 <= repeats <= 100:
        raise UsageError(f"repeats: expected an integer 1-100, got {repeats}")
    check_render_cache()
    prepare_out_dir(out)
    with console.status("comparing the pruned and the full search ..."):
        result = pruning.run(max_frames=max_frames, repeats=repeats)
    atomic_write_bytes(out / "tracker_pruning.json", strict_json.dumps(result, indent=1).encode())
    console.print(
        f"{result['identical']} of {result['frames']} frames identical; tracker median "
        f"{result['time_full_ms']['median']:.1f} -> {result['time_pruned_ms']['median']:.1f} ms "
        f"({result['speedup_median']:.1f}x); {100 * result['pruned_fraction']:.1f} % of PnP fits skipped; "
        f"wrote {out / 'tracker_pruning.json'}"
    )


COMMANDS = {
    "e2e-detection": e2e_detection,
    "saturation-table": saturation_table,
    "diffuser-mosaic": diffuser_mosaic,
    "bench": bench,
    "unknowns-search": unknowns_search,
    "calibrate-unknowns": calibrate_unknowns,
    "sensitivity": sensitivity,
    "design": design,
    "colour-reach": colour_reach,
    "crop-vs-full": crop_vs_full,
    "tracker-pruning": tracker_pruning,
}
