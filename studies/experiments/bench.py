"""Benchmarks: speed as ratios measured side by side in one run on one machine.

``two_stage_vs_brute_force`` — time to render the same V2 marker (foam + 1 matched
sheet, 5 m, 10° off axis, T6 + 18 mm, 4× oversampled 20 × 20 px crop) to the same
RMS error with the two-stage method (near-field precompute + textured face) and with
brute-force volumetric path tracing. Each method's per-pass noise σ (per-pixel
standard deviation over independent passes, RMS over the marker's pixels, divided by
the marker's mean radiance) and time per pass t are measured; reaching an RMS error ε
takes t·(σ/ε)² (Monte-Carlo error falls as 1/√samples), plus, for the two-stage
method, its near-field precompute, which is also reported apart because it is paid
once per marker configuration and cached.
"""

from __future__ import annotations

import json
import math
import os
import random
import resource
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import replace
from functools import partial
from pathlib import Path

import cv2
import numpy as np
from scipy import stats

from camera_models.camera import load_camera
from camera_models.capture import capture
from camera_models.exposure import manual_exposure
from camera_models.isp import encode_jpeg
from pipeline.angles import Intrinsics
from pipeline.binary_blobs import detect_two_level
from pipeline.detect import detect
from pipeline.thesis_tracker import ThesisTrackerSettings, blob_detector_params, colour_mask
from scenes.background import render_background
from scenes.beacon import SIDE_ANGLE_RAD, beacon_design
from scenes.led import led_for_side
from scenes.near_field import STATS, NearFieldSettings, housing_leak, marker_emission
from scenes.render import render, with_led_current
from scenes.render_cache import RenderCache, atomic_write_bytes
from scenes.scenario import RenderSettings, Scenario
from studies.catalog import replication
from studies.engine import strict_json
from studies.engine.frame import render_batch_key, simulate_frame
from studies.engine.run_log import total_seconds
from studies.engine.runner import run_tasks, set_hugepage_advice, worker_threads
from studies.engine.sweep import Execution, run_frames, sweep_in_chunks
from studies.engine.tasks import GRID_AXES, RENDER, frame_tasks
from studies.experiments import equivalence
from studies.experiments.two_stage_check import MarkerView, brute_force_scene, render_passes, two_stage_scene

__all__ = [
    "BENCH_SCENARIO",
    "FULL_STUDIES",
    "RECORDED_RUNS",
    "STUDY_MIX",
    "WHOLE_FRAME_CAMERAS",
    "blob_grouping",
    "cold_renders",
    "equivalence_statistics",
    "frame_vs_memcpy",
    "full_grid_estimate",
    "grid_sample",
    "hugepage_advice",
    "recorded_runs",
    "replication_tables",
    "reuse_vs_rerender",
    "speckle_mask",
    "study_mix",
    "two_stage_vs_brute_force",
    "variant_ratio",
    "warm_frames",
    "whole_frame_paths",
    "workers_and_dask",
]


def _relative_noise(images: np.ndarray, mask: np.ndarray, reference: np.ndarray) -> float:
    """Normalised RMS noise of one pass: √(mean over the marker of the per-pixel
    variance across passes) / mean radiance of the marker."""
    var = images[:, mask].var(axis=0, ddof=1)
    return float(np.sqrt(var.mean()) / reference[mask].mean())


def two_stage_vs_brute_force(target_rms: float = 0.01, passes: int = 16, brute_spp: int = 256) -> dict:
    """Measure the two-stage speed-up at equal RMS error (see module docstring)."""

    view = MarkerView()
    near = NearFieldSettings()
    with tempfile.TemporaryDirectory() as tmp:
        cache = RenderCache(Path(tmp))
        t0 = time.perf_counter()
        marker_emission(beacon_design("v2"), led_for_side(view.side), view.housing, view.config, view.side, cache, near)
        precompute_s = time.perf_counter() - t0
        two = render_passes(two_stage_scene(view, 16, near, cache), passes)
    brute = render_passes(brute_force_scene(view, brute_spp), passes)
    reference = two.images.mean(axis=0)
    mask = reference > 0.01 * reference.max()
    sigma_two = _relative_noise(two.images, mask, reference)
    sigma_brute = _relative_noise(brute.images, mask, reference)
    t_two = two.seconds_per_pass * (sigma_two / target_rms) ** 2
    t_brute = brute.seconds_per_pass * (sigma_brute / target_rms) ** 2
    return {
        "target_rms": target_rms,
        "two_stage": {
            "spp_per_pass": two.spp_per_pass,
            "seconds_per_pass": two.seconds_per_pass,
            "rms_per_pass": sigma_two,
            "near_field_precompute_s": precompute_s,
            "seconds_to_target": t_two + precompute_s,
            "seconds_to_target_cached": t_two,
        },
        "brute_force": {
            "spp_per_pass": brute.spp_per_pass,
            "seconds_per_pass": brute.seconds_per_pass,
            "rms_per_pass": sigma_brute,
            "seconds_to_target": t_brute,
        },
        "ratio": t_brute / (t_two + precompute_s),
        "ratio_cached": t_brute / t_two,
    }


# -- render reuse, full frame, workers, Dask, variant ----------------------------------------
BENCH_SCENARIO = {
    "beacon": "v2",
    "side": "red",
    "range_m": 5.0,
    "yaw_deg": 10.0,
    "camera": "canon-t6-18mm",
    "environment": "dark",
    "foam": True,
    "paper_sheets": 1,
    "paper_colour": "matched",
}


def reuse_vs_rerender(frames: int = 100, rerendered: int = 4) -> dict:
    """A sweep of ``frames`` frames over LED drive, ISO and noise seed, with the render
    reused (rendered once, rescaled in memory by linearity, the lens's work on it reused)
    versus re-rendered for every frame.

    Both time render + camera (optics, sensor, ISP, JPEG) per frame. The re-rendering
    side runs ``rerendered`` frames and scales to ``frames`` (each costs the same render).
    """

    settings = RenderSettings(spp=4, oversampling=2, crop="beacon")
    camera = load_camera(BENCH_SCENARIO["camera"])
    currents, isos = (2.0, 5.0, 10.0, 20.0), (800.0, 1600.0, 3200.0, 6400.0)
    grid = [(currents[i % 4], isos[(i // 4) % 4], i) for i in range(frames)]
    render(Scenario(**BENCH_SCENARIO, render=settings))  # compile kernels and near field once, untimed

    t0 = time.perf_counter()
    base = render(Scenario(**BENCH_SCENARIO, render=settings), None)  # the one render
    for current, iso, seed in grid:
        capture(with_led_current(base, current), camera, seed, None, manual_exposure(camera, iso=iso), full=False)
    reuse_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    for current, iso, seed in grid[:rerendered]:
        radiance = render(Scenario(**BENCH_SCENARIO, led_current_mA=current, render=settings), None)
        capture(radiance, camera, seed, None, manual_exposure(camera, iso=iso), full=False)
    rerender_s = (time.perf_counter() - t0) * frames / rerendered
    return {
        "frames": frames,
        "reuse_s": reuse_s,
        "rerender_s": rerender_s,
        "rerender_frames_timed": rerendered,
        "ratio": rerender_s / reuse_s,
    }


def frame_vs_memcpy(repeats: int = 3, scenario: dict = BENCH_SCENARIO) -> dict:
    """One full frame (default the T6's) through optics, sensor, ISP (JPEG) and both
    detectors, versus a plain copy of the same frame's bytes (18 MP × 3 × 8 bit for the T6)."""

    scenario = Scenario(**scenario, led_current_mA=2.0, render=RenderSettings(spp=4, oversampling=2))
    camera = load_camera(scenario.camera)
    intrinsics = Intrinsics.from_geometry(camera.geometry)
    radiance = render(scenario)
    stages = {"camera_s": [], "decode_s": [], "detect_s": []}
    for seed in range(repeats):
        t0 = time.perf_counter()
        cap = capture(radiance, camera, seed, None, full=True)
        t1 = time.perf_counter()
        image = cv2.imdecode(np.frombuffer(cap.image.encoded, np.uint8), cv2.IMREAD_COLOR)
        t2 = time.perf_counter()
        for tracker in ("thesis", "best"):
            detect(image, intrinsics, tracker=tracker, estimator="best")
        t3 = time.perf_counter()
        for k, v in zip(stages, (t1 - t0, t2 - t1, t3 - t2), strict=True):
            stages[k].append(v)
    frame = np.ascontiguousarray(cap.image.rgb8)
    copies = []
    for _ in range(20):
        t0 = time.perf_counter()
        frame.copy()
        copies.append(time.perf_counter() - t0)
    codec = []  # the floor of any saved-JPEG frame: encoding it and reading it back
    for _ in range(3):
        t0 = time.perf_counter()
        jpeg = encode_jpeg(frame, camera)
        cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        codec.append(time.perf_counter() - t0)
    per_frame = float(np.median([sum(x) for x in zip(*stages.values(), strict=True)]))
    memcpy = float(np.median(copies))
    return {
        "frame_s": per_frame,
        "memcpy_s": memcpy,
        "ratio": per_frame / memcpy,
        **{k: float(np.median(v)) for k, v in stages.items()},
        "jpeg_encode_decode_s": float(np.median(codec)),
        "jpeg_codec_vs_memcpy": float(np.median(codec)) / memcpy,
        "frame_bytes": int(frame.nbytes),
    }


def hugepage_advice(repeats: int = 3, scenario: dict = BENCH_SCENARIO) -> dict:
    """One whole frame (default the T6's) through the camera and both detectors with numpy's
    huge-page advice on (numpy's default on Linux) and off (the command line's,
    :func:`studies.engine.runner.no_hugepage_advice`), alternating in this process; wall and
    kernel (system) CPU time per frame, medians, and whether the saved bytes agree."""
    scenario = Scenario(**scenario, led_current_mA=2.0, render=RenderSettings(spp=4, oversampling=2))
    camera = load_camera(scenario.camera)
    intrinsics = Intrinsics.from_geometry(camera.geometry)
    radiance = render(scenario)
    times: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    saved: dict[bool, bytes] = {}
    before = set_hugepage_advice(True)
    try:
        for seed in range(repeats):
            for advice in (True, False):
                set_hugepage_advice(advice)
                t0, k0 = time.perf_counter(), os.times().system
                cap = capture(radiance, camera, seed, None, full=True)
                image = cv2.imdecode(np.frombuffer(cap.image.encoded, np.uint8), cv2.IMREAD_COLOR)
                for tracker in ("thesis", "best"):
                    detect(image, intrinsics, tracker=tracker, estimator="best")
                times[advice].append((time.perf_counter() - t0, os.times().system - k0))
                saved[advice] = cap.image.encoded
    finally:
        set_hugepage_advice(before)
    on, off = (np.median(np.array(times[a]), axis=0) for a in (True, False))
    return {
        "advice_on_s": float(on[0]),
        "advice_off_s": float(off[0]),
        "ratio": float(on[0] / off[0]),
        "advice_on_kernel_s": float(on[1]),
        "advice_off_kernel_s": float(off[1]),
        "same_bytes": saved[True] == saved[False],
        "repeats": repeats,
    }


WHOLE_FRAME_CAMERAS = ("canon-t6-18mm", "logitech-c270")
"""The DSLR and a webcam whose whole saved frames :func:`whole_frame_paths` times."""


def whole_frame_paths(repeats: int = 3, scenario: dict = BENCH_SCENARIO) -> dict:
    """Whole frames of the DSLR and a webcam by the fast camera path and by the reference path it
    replaced (numpy sensor, float ISP: ``capture(reference=True)``), side by side, by stage:
    optics and mosaic, sensor, ISP and JPEG encoding, JPEG decoding, both detectors (median
    of ``repeats`` frames each, s), and each frame against a memcpy of its bytes."""
    from camera_models.capture import background_electrons_per_s, frame_meter, full_frame_mosaic
    from camera_models.exposure import auto_exposure
    from camera_models.isp import process
    from camera_models.isp_reference import reference_process
    from camera_models.optics import optical_image
    from camera_models.sensor import SensorSettings
    from camera_models.sensor_paths import expose
    from scenes.background import render_background

    out = {}
    for name in WHOLE_FRAME_CAMERAS:
        sc = Scenario(**{**scenario, "camera": name}, led_current_mA=2.0, render=RenderSettings(spp=4, oversampling=2))
        camera = load_camera(name)
        intrinsics = Intrinsics.from_geometry(camera.geometry)
        radiance, background = render(sc), render_background(sc)
        paths = {}
        for path in ("fast", "reference"):
            names = ("optics_s", "sensor_s", "isp_jpeg_s", "decode_s", "detect_s")
            stages: dict[str, list[float]] = {k: [] for k in names}
            for seed in range(repeats):
                t0 = time.perf_counter()
                n = camera.lens.f_number
                opt = optical_image(radiance, camera, 1.0, n)
                bg = background_electrons_per_s(background, camera, n)
                if camera.exposure.mode == "auto":
                    ex = auto_exposure(camera, frame_meter(opt.electrons_rgb, opt.x0, opt.y0, camera, bg))
                else:
                    ex = manual_exposure(camera)
                t = ex.exposure_s
                mean = full_frame_mosaic(opt.electrons_rgb * t, opt.x0, opt.y0, camera, bg * t)
                t1 = time.perf_counter()
                settings = SensorSettings(t, ex.analog_gain)
                raw = expose(mean, camera.sensor, settings, seed, path="numpy" if path == "reference" else None)
                t2 = time.perf_counter()
                if path == "reference":
                    img = reference_process(raw, camera)
                else:
                    img = process(raw, camera, analog_gain=ex.analog_gain)
                t3 = time.perf_counter()
                image = cv2.imdecode(np.frombuffer(img.encoded, np.uint8), cv2.IMREAD_COLOR)
                t4 = time.perf_counter()
                for tracker in ("thesis", "best"):
                    detect(image, intrinsics, tracker=tracker, estimator="best")
                t5 = time.perf_counter()
                for k, v in zip(stages, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4), strict=True):
                    stages[k].append(v)
            medians = {k: float(np.median(v)) for k, v in stages.items()}
            paths[path] = {"frame_s": float(np.median([sum(x) for x in zip(*stages.values(), strict=True)])), **medians}
        copies = []
        for _ in range(20):
            t0 = time.perf_counter()
            image.copy()
            copies.append(time.perf_counter() - t0)
        memcpy = float(np.median(copies))
        out[name] = {
            **{f"{path}_{k}": v for path, d in paths.items() for k, v in d.items()},
            "memcpy_s": memcpy,
            "fast_vs_memcpy": paths["fast"]["frame_s"] / memcpy,
            "reference_vs_fast": paths["reference"]["frame_s"] / paths["fast"]["frame_s"],
            "frame_bytes": int(image.nbytes),
        }
    return out


STUDY_MIX = ("range_limit", "brightness_diffuser", "webcam_vs_dslr")
"""The studies whose quick forms make the warm-frame mix (the main job's three studies)."""


def study_mix(per_study: int = 8, seed: int = 0) -> list[dict]:
    """``per_study`` frame tasks (or all of them, where a study has fewer) drawn at random from
    each quick study of :data:`STUDY_MIX`, as the study makes them (whole frames, its estimators)."""
    from importlib import import_module

    from studies.engine.tasks import grid_conditions

    rng = random.Random(seed)
    tasks = []
    for name in STUDY_MIX:
        options = import_module(f"studies.catalog.{name}").default_options(quick=True)
        estimators = None if name == "webcam_vs_dslr" else ["best"]
        population = frame_tasks(grid_conditions(options), options, estimators=estimators)
        tasks += rng.sample(population, min(per_study, len(population)))
    return tasks


def warm_frames(per_study: int = 8, repeats: int = 2) -> dict:
    """Median time of a warm frame over the study mix (:func:`study_mix`): the render
    cached, the camera model on the whole frame and every detector the study runs, as
    :func:`studies.engine.frame.simulate_frame` does in a study; and the same tasks on the
    crop around the beacon (the path the issue's 68 ms was measured on), side by side.

    Renders come from the render cache (filled by a first, untimed pass when missing,
    as after the main job). Each frame's time is the smallest of ``repeats``.
    """

    tasks = study_mix(per_study)
    crops = [{k: v for k, v in t.items() if k != "full_frame"} for t in tasks]
    for t in tasks:
        simulate_frame(t)  # renders and near fields into the cache, untimed
    out = {}
    for label, work in (("full", tasks), ("crop", crops)):
        times = []
        for t in work:
            best = math.inf
            for _ in range(repeats):
                t0 = time.perf_counter()
                simulate_frame(t)
                best = min(best, time.perf_counter() - t0)
            times.append(best)
        out[label] = {
            "median_ms": 1e3 * float(np.median(times)),
            "mean_ms": 1e3 * float(np.mean(times)),
            "max_ms": 1e3 * float(np.max(times)),
            "by_camera_median_ms": {
                cam: 1e3
                * float(np.median([x for x, t in zip(times, work, strict=True) if t["scenario"]["camera"] == cam]))
                for cam in sorted({t["scenario"]["camera"] for t in work})
            },
        }
    return {"frames": len(tasks), "studies": list(STUDY_MIX), **out}


def cold_renders(geometries: int = 6) -> dict:
    """Near fields of new diffuser configurations, then renders of new geometries after a
    worker's first render, with empty caches: in a child process whose render cache and
    Dr.Jit kernel cache (``$HOME/.drjit``) are new temporary folders.

    ``near_field_s``: the exit-radiance and housing-leak renders of the bench marker (V2
    red) behind foam alone (six viewing angles, the studies' slowest configuration) at the
    studies' near-field sampling, paid once per configuration and colour; ``near_fields``
    also has foam + 1 matched sheet (one angle). ``cold_render_s``: the median time to
    render a geometry (a new range and yaw: new camera pose, new crop) once the process has
    rendered one, as a study worker does for every pose after its first, by the studies'
    render (the lit faces by primary rays, :mod:`scenes.direct_view`); beside it the same
    geometries wholly path-traced (``cold_render_path_s``: ``direct = "path"``, the renders
    before issue 24, and through ``mitsuba.render``), each geometry rendered by the three
    in turn. A dark room has no background to render; ``room_background_s`` is the lit
    room's, paid once per camera and band of range, yaw and height.
    """
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "HOME": tmp, "BEACON_SIM_CACHE": str(Path(tmp) / "cache")}
        code = (
            "import json; from studies.experiments.bench import _cold_renders;"
            f"print(json.dumps(_cold_renders({int(geometries)})))"
        )
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=900)
    if proc.returncode != 0:
        raise RuntimeError(f"cold renders failed: {proc.stderr.strip()[-300:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _cold_renders(geometries: int) -> dict:
    """:func:`cold_renders` in this process (its caches must be empty)."""
    from scenes.assemble import scene_spec
    from scenes.render import render_unit_groups

    near_fields = {}
    for label, foam, sheets in (("foam", True, 0), ("foam_1_matched", True, 1)):
        scenario = Scenario(**{**BENCH_SCENARIO, "foam": foam, "paper_sheets": sheets}, render=RenderSettings(**RENDER))
        near_fields[label] = _near_field_seconds(scenario, scenario.side)
    render(Scenario(**BENCH_SCENARIO, render=RenderSettings(**RENDER)))  # the worker's first render, untimed
    # the room's whole-frame background: none in the dark (zero, nothing rendered); in the lit
    # room one render per camera and band of range, yaw and height (scenes.background)
    lit = Scenario(**{**BENCH_SCENARIO, "environment": "lit-room"}, render=RenderSettings(**RENDER))
    t0 = time.perf_counter()
    render_background(lit)
    room_background_s = time.perf_counter() - t0
    times: dict[str, list[float]] = {"primary": [], "path": [], "mitsuba_render": []}
    for k in range(geometries):
        geometry = {"range_m": 3.0 + 0.9 * k, "yaw_deg": -25.0 + 10.0 * k}
        scenario = Scenario(**{**BENCH_SCENARIO, **geometry}, render=RenderSettings(**RENDER))
        path = replace(scenario, render=replace(scenario.render, direct="path"))
        runs = {
            "primary": partial(render, scenario),  # what a study renders (uncached: cache=None)
            "path": partial(render, path),  # everything path-traced (the reference)
            "mitsuba_render": partial(
                render_unit_groups, scene_spec(path), path.render.spp, path.render.seed, reuse_kernels=False
            ),
        }
        for label, run in runs.items():
            t0 = time.perf_counter()
            run()
            times[label].append(time.perf_counter() - t0)
    return {
        "near_field_s": near_fields["foam"],
        "near_fields": near_fields,
        "cold_render_s": float(np.median(times["primary"])),
        "cold_render_path_s": float(np.median(times["path"])),
        "cold_render_mitsuba_render_s": float(np.median(times["mitsuba_render"])),
        "room_background_s": room_background_s,
        "ratio": float(np.median(times["path"]) / np.median(times["primary"])),
        "each_s": times,
        "render": dict(RENDER),
    }


@contextmanager
def _temporary_render_cache():
    """A new, empty render cache (``BEACON_SIM_CACHE``) for the block; yields its parent folder."""
    with tempfile.TemporaryDirectory() as tmp, _render_cache_at(Path(tmp) / "cache"):
        yield Path(tmp)


@contextmanager
def _render_cache_at(folder: Path):
    """The render cache (``BEACON_SIM_CACHE``) in ``folder`` for the block, the previous one after."""
    saved = os.environ.get("BEACON_SIM_CACHE")
    os.environ["BEACON_SIM_CACHE"] = str(folder)
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop("BEACON_SIM_CACHE", None)
        else:
            os.environ["BEACON_SIM_CACHE"] = saved


def _sweep_tasks(n: int, render_seed: int) -> list[dict]:
    """``n`` study frame tasks, each a distinct pose (its own render), as in a range sweep."""
    return [
        {
            "scenario": {**BENCH_SCENARIO, "led_current_mA": 2.0, "range_m": 4.0 + 0.25 * k},
            "render": {**RENDER, "seed": render_seed},
            "seed": 0,
            "trackers": ["best"],
            "estimators": ["best"],
        }
        for k in range(n)
    ]


def workers_and_dask(tasks: int = 12) -> dict:
    """Study throughput on the same kind of frame tasks — each renders its own pose — with
    1 and 2 single-threaded local worker processes and on a 2-worker Dask LocalCluster,
    plus one worker using every core (Dr.Jit and OpenCV threads) for comparison. Each
    configuration uses its own render seed, so none finds another's renders in the cache;
    the near-field marker render they share is computed beforehand (untimed)."""

    from dask.distributed import LocalCluster

    times = {}
    with _temporary_render_cache() as tmp:
        warm = _sweep_tasks(1, 0)[0]
        simulate_frame({**warm, "scenario": {**warm["scenario"], "range_m": 20.0}})  # near field, untimed
        for k, label in enumerate(("workers_1", "workers_2", "dask_2", "workers_1_all_cores")):
            work = _sweep_tasks(tasks, render_seed=1000 + k)
            t0 = time.perf_counter()
            if label == "dask_2":
                # `--scheduler ADDRESS` connects to a running cluster: its start-up is
                # timed apart, like the local pool's, whose processes start inside run_tasks
                with (
                    worker_threads(2, 1),
                    LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
                ):
                    times["dask_start"] = time.perf_counter() - t0
                    t0 = time.perf_counter()
                    run_tasks(work, Path(tmp) / label, simulate_frame, scheduler=cluster.scheduler_address)
                    times[label] = time.perf_counter() - t0
                continue
            elif label == "workers_1_all_cores":
                with worker_threads(1):
                    run_tasks(work, Path(tmp) / label, simulate_frame, workers=1)
            else:  # single-threaded worker processes, each task alone
                n = int(label[-1])
                run_tasks(work, Path(tmp) / label, simulate_frame, workers=n, threads_per_worker=1, isolated=True)
            times[label] = time.perf_counter() - t0
    return {
        "tasks": tasks,
        **{f"{k}_s": v for k, v in times.items()},
        "workers_2_vs_1": times["workers_1"] / times["workers_2"],
        "dask_overhead": times["dask_2"] / times["workers_2"] - 1.0,
        "dask_overhead_with_cluster_start": (times["dask_start"] + times["dask_2"]) / times["workers_2"] - 1.0,
        "all_cores_1_worker_vs_2_workers": times["workers_1_all_cores"] / times["workers_2"],
    }


def _grid_batches() -> tuple[list[dict], dict[str, dict]]:
    """The complete replication grid's geometries (at its first drive) and its render
    batches (a geometry and jittered pose with all its drives and seeds), keyed by
    :func:`render_batch_key`."""
    options = replication.default_options(quick=False)
    geometries = [c for c in replication.conditions(options) if c["led_current_mA"] == options.currents_mA[0]]
    # one task per geometry and jittered pose names every render batch of the grid (the
    # jitter does not depend on the drive), without building all 2.15 M frame tasks
    one_per_pose = replace(options, seeds=options.jitter_poses)
    return geometries, {render_batch_key(t): g for g in geometries for t in frame_tasks([g], one_per_pose)}


def _near_field_configs(geometries: list[dict]) -> set[tuple]:
    """The near fields a grid's geometries need: one per diffuser configuration and side."""
    return {(g["foam"], g["paper_sheets"], g["side"]) for g in geometries}


def _batch_tasks(keys: list[str], batch_geometry: dict[str, dict]) -> dict[str, list[dict]]:
    """Each render batch's frame tasks: every drive and seed of its geometry and pose."""
    options = replication.default_options(quick=False)
    groups = {}
    for key in keys:
        drives = [{**batch_geometry[key], "led_current_mA": c} for c in options.currents_mA]
        groups[key] = [t for t in frame_tasks(drives, options, estimators=["best"]) if render_batch_key(t) == key]
    return groups


def _grid_hours(per_batch_s: np.ndarray, n_batches: int, near_field_s: float) -> list[float]:
    """Student-t 95 % interval, in hours, of a grid of ``n_batches`` render batches whose
    batches take ``per_batch_s`` seconds as sampled, plus ``near_field_s``."""
    half = stats.t.ppf(0.975, len(per_batch_s) - 1) * per_batch_s.std(ddof=1) / np.sqrt(len(per_batch_s))
    return [(max(per_batch_s.mean() + d, 0.0) * n_batches + near_field_s) / 3600.0 for d in (-half, half)]


def full_grid_estimate(batches: int = 8, seed: int = 0) -> dict:
    """Time of the complete replication grid (:mod:`studies.catalog.replication`, full form) on
    this machine, extrapolated from a random sample of its render batches (a geometry
    with all its drives and seeds), run with 2 workers once with an empty render cache
    (cold) and once more with the renders cached but every frame recomputed (warm).

    Near-field marker renders (one per diffuser configuration and colour) are made
    beforehand and counted apart, at their measured time each.
    """

    options = replication.default_options(quick=False)
    geometries, batch_geometry = _grid_batches()
    sample = random.Random(seed).sample(sorted(batch_geometry), batches)
    groups = _batch_tasks(sample, batch_geometry)
    work = [t for key in sample for t in groups[key]]
    near_fields = _near_field_configs(geometries)
    with _temporary_render_cache() as tmp:
        near_s = [x for key in sample for x in _task_near_field_seconds(groups[key][0])]  # untimed in the batches
        t0 = time.perf_counter()
        run_frames(work, Path(tmp) / "cold", Execution(workers=2))
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_frames(work, Path(tmp) / "warm", Execution(workers=2))
        warm = time.perf_counter() - t0
        per_batch = _batch_seconds(Path(tmp) / "cold", groups)
    scale = len(batch_geometry) / batches
    near_field_s = float(np.mean(near_s)) * len(near_fields) if near_s else 0.0  # the sample's mean per near field
    # the sample's spread: batch times (frame seconds summed per batch, scaled so they add up
    # to the measured wall time) give the interval of the mean batch
    per_batch *= cold / per_batch.sum()
    return {
        "frames": len(geometries) * len(options.currents_mA) * options.seeds,
        "render_batches": len(batch_geometry),
        "sampled_batches": batches,
        "sampled_frames": len(work),
        "sample_cold_s": cold,
        "sample_warm_s": warm,
        "near_fields": len(near_fields),
        "near_fields_s": near_field_s,
        "cold_h": (cold * scale + near_field_s) / 3600.0,
        "cold_h_95": _grid_hours(per_batch, len(batch_geometry), near_field_s),
        "warm_h": warm * scale / 3600.0,
        "cold_ms_per_frame": 1e3 * cold / len(work),
        "warm_ms_per_frame": 1e3 * warm / len(work),
    }


def grid_sample(out: Path, fraction: float = 0.01, seed: int = 0, execution: Execution = Execution(workers=2)) -> dict:
    """Run a random ``fraction`` of the replication grid's render batches cold and report
    the measured time beside the grid's extrapolation from it.

    Resumable: the frames, the render cache (``out/cache``, empty at the first start) and
    each segment's wall time stay in ``out``; running again with the same arguments goes
    on where an interrupted run stopped (a segment stopped by Ctrl-C counts up to that
    moment, one killed outright up to its last finished frame, saved every 10 s). The
    near fields the sample needs are computed first, each timed; the frames then run as
    ``execution`` says. The grid's cold time is extrapolated as (frame wall time) × (grid batches /
    sampled batches) + (mean near field) × (the grid's near fields), with a Student-t 95 %
    interval from the spread of the batches' frame seconds.

    Parameters
    ----------
    out
        Output folder; ``summary.json`` is written there once every frame is done.
    fraction
        Fraction of the grid's render batches, in (0, 1].
    seed
        Seed of the random choice of batches.
    execution
        Where the frames run (2 local workers by default, as the bench's other figures).

    Returns
    -------
    dict
        The summary (times in seconds and hours).
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction: expected a number in (0, 1], got {fraction!r}")
    options = replication.default_options(quick=False)
    geometries, batch_geometry = _grid_batches()
    n = max(2, round(fraction * len(batch_geometry)))
    sample = random.Random(seed).sample(sorted(batch_geometry), n)
    out.mkdir(parents=True, exist_ok=True)
    state_path = out / "segments.json"
    state = json.loads(state_path.read_text()) if state_path.exists() else {"near_fields_s": [], "frames_wall_s": []}
    if state.get("batches", sample) != sample:
        raise ValueError(f"out: {out} holds a sample of other batches (fraction or seed differ); expected a new folder")
    state["batches"] = sample
    groups = _batch_tasks(sample, batch_geometry)
    work = [t for key in sample for t in groups[key]]
    with _render_cache_at(out / "cache"):
        for key in sample:  # near fields a batch needs and no earlier segment computed
            state["near_fields_s"] += _task_near_field_seconds(groups[key][0])
            atomic_write_bytes(state_path, strict_json.dumps(state).encode())
        state["frames_wall_s"].append(0.0)
        atomic_write_bytes(state_path, strict_json.dumps(state).encode())
        t0 = time.perf_counter()
        try:
            timed = replace(execution, progress=_segment_clock(execution.progress, state, state_path, t0))
            run_frames(work, out / "frames", timed, description="grid sample")
        finally:
            state["frames_wall_s"][-1] = time.perf_counter() - t0
            atomic_write_bytes(state_path, strict_json.dumps(state).encode())
    frames_s = float(sum(state["frames_wall_s"]))
    near = state["near_fields_s"]
    per_batch = _batch_seconds(out / "frames", groups)
    worker_s = float(per_batch.sum())
    per_batch *= frames_s / worker_s
    grid_near_s = float(np.mean(near)) * len(_near_field_configs(geometries)) if near else 0.0
    summary = {
        "fraction": fraction,
        "seed": seed,
        "workers": execution.workers,
        "render_batches": n,
        "frames": len(work),
        "grid_render_batches": len(batch_geometry),
        "grid_frames": len(geometries) * len(options.currents_mA) * options.seeds,
        "measured_s": frames_s + float(sum(near)),
        "frames_wall_s": frames_s,
        "frames_worker_s": worker_s,
        "segments": len(state["frames_wall_s"]),
        "near_fields": len(near),
        "near_fields_s": float(sum(near)),
        "ms_per_frame": 1e3 * frames_s / len(work),
        "grid_cold_h": (frames_s * len(batch_geometry) / n + grid_near_s) / 3600.0,
        "grid_cold_h_95": _grid_hours(per_batch, len(batch_geometry), grid_near_s),
    }
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def _segment_clock(progress, state: dict, path: Path, t0: float, every_s: float = 10.0):
    """``progress`` (a :data:`studies.engine.runner.Progress`) that also keeps the running
    segment's wall time, up to its last finished task, in ``state["frames_wall_s"][-1]``
    and saves ``state`` to ``path`` at most every ``every_s`` seconds."""

    @contextmanager
    def clocked(description: str, total: int, done: int):
        saved = [time.perf_counter()]
        with progress(description, total, done) as advance:

            def step() -> None:
                advance()
                now = time.perf_counter()
                state["frames_wall_s"][-1] = now - t0
                if now - saved[0] >= every_s:
                    atomic_write_bytes(path, strict_json.dumps(state).encode())
                    saved[0] = now

            yield step

    return clocked


def _near_field_seconds(scenario: Scenario, side: str) -> float | None:
    """Seconds to compute the near fields of one side's markers in ``scenario`` (exit
    radiance and housing leak, at the scenario's near-field sampling), or None when they
    were already computed (cached)."""
    args = (scenario.design, led_for_side(side), scenario.housing, scenario.diffuser, side)
    near = NearFieldSettings(spp=scenario.render.near_field_spp)
    before = STATS.renders
    t0 = time.perf_counter()
    if not scenario.diffuser.is_bare:
        marker_emission(*args, settings=near)
    housing_leak(*args, settings=near)
    return time.perf_counter() - t0 if STATS.renders > before else None


def _task_near_field_seconds(task: dict) -> list[float]:
    """:func:`_near_field_seconds` of every side a frame task's render needs, leaving out cached ones."""
    scenario = Scenario(**task["scenario"], render=RenderSettings(**task["render"]))
    seconds = (_near_field_seconds(scenario, side) for side in SIDE_ANGLE_RAD)
    return [x for x in seconds if x is not None]


def _batch_seconds(out: Path, groups: dict[str, list[dict]]) -> np.ndarray:
    """Seconds each render batch's frames took in their workers (``frame_s`` of
    ``out/machine.csv``, summed per batch), in the order of ``groups``."""
    import pandas as pd

    from studies.engine.frame import FRAME_VERSION
    from studies.engine.runner import MACHINE_LOG, task_key

    log = pd.read_csv(out / MACHINE_LOG, dtype={"task": str})
    seconds = log[(log.field == "frame_s") & (log.row == 0)].set_index("task").value.astype(float)
    return np.array(
        [sum(seconds[task_key(simulate_frame, t, FRAME_VERSION)[:16]] for t in tasks) for tasks in groups.values()]
    )


def variant_ratio() -> dict:
    """The same small render with the active (LLVM/CUDA) variant and the scalar one, each
    in its own process (a process keeps one backend)."""

    code = (
        "import time; from scenes.render import render; from scenes.scenario import Scenario, RenderSettings;"
        "from scenes.mitsuba_variant import select_variant; v = select_variant().variant;"
        "s = Scenario(range_m=8.0, render=RenderSettings(spp=2, oversampling=1, crop='target'));"
        "render(s, groups=['led:red']); t = time.perf_counter(); render(s, groups=['led:red']);"
        "print(v, time.perf_counter() - t)"
    )
    out = {}
    for backend in ("", "scalar"):
        env = {**os.environ, "BEACON_SIM_VARIANT": backend} if backend else dict(os.environ)
        env.pop("BEACON_SIM_VARIANT", None) if not backend else None
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=900)
        if proc.returncode != 0:
            raise RuntimeError(f"variant benchmark ({backend or 'default'}) failed: {proc.stderr.strip()[-300:]}")
        name, seconds = proc.stdout.split()[-2:]
        out["scalar" if backend else "fast"] = {"variant": name, "seconds": float(seconds)}
    return {**out, "ratio": out["scalar"]["seconds"] / out["fast"]["seconds"]}


def replication_tables(workers: int = 2, template_tasks: int = 8, fit_groups: int = 16) -> dict:
    """The replication study's table work at the full grid's size: tasks, content keys,
    chunk tables and results.parquet (:func:`studies.engine.sweep.sweep_in_chunks`), run twice
    into a temporary directory — the second time with every chunk stored, as a re-run
    with a warm cache is — and the max-range fits, timed on ``fit_groups`` of the grid's
    768 groups and scaled to all of them on ``workers`` processes.

    Frames are not simulated: each task's rows are stand-ins, the rows of one of
    ``template_tasks`` simulated frames of the grid (cycled) with the task's own
    scenario, seed and nominal pose, so the tables have the real columns and types (the
    fits' times depend on the outcomes, so they are indicative). Returns wall times (s),
    the parent's peak resident memory (MiB) and the table's size.
    """
    options = replication.default_options(quick=False)
    rng = random.Random(0)
    one = [  # random single conditions of the grid
        replace(options, **{field: (rng.choice(getattr(options, field)),) for field in GRID_AXES.values()})
        for _ in range(template_tasks)
    ]
    conditions = [c for o in one for c in replication.conditions(o)]
    tasks = frame_tasks(conditions, replace(options, seeds=1), estimators=["best"])
    template_rows = [simulate_frame(t) for t in tasks]
    rss_templates = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def stand_in(tasks, out, execution, description):
        rows = []
        for i, t in enumerate(tasks):
            for row in template_rows[i % len(template_rows)]:
                rows.append(
                    {
                        **row,
                        **t["scenario"],
                        "seed": t["seed"],
                        "nominal_range_m": t["nominal"]["range_m"],
                        "nominal_yaw_deg": t["nominal"]["yaw_deg"],
                    }
                )
        return rows

    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label in ("first", "rerun"):
            t0 = time.perf_counter()
            frame = sweep_in_chunks("replication", replication.chunks(options), options, Path(tmp), frames=stand_in)
            times[label] = time.perf_counter() - t0
    groups = frame[frame.tracker == "best"].groupby(list(replication.MAX_RANGE_BY), sort=True)
    sample = rng.sample(sorted(groups.groups), fit_groups)
    t0 = time.perf_counter()
    for key in sample:
        replication.group_max_range(groups.get_group(key))
    fit_s = (time.perf_counter() - t0) / fit_groups
    return {
        "frames": len(frame) // 2,
        "rows": len(frame),
        "columns": frame.shape[1],
        "tables_first_run_s": times["first"],
        "tables_rerun_s": times["rerun"],
        "fit_s_per_group": fit_s,
        "fits_s_on_workers": fit_s * groups.ngroups / workers,
        "parent_peak_rss_MiB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "parent_peak_rss_after_templates_MiB": rss_templates,
    }


def speckle_mask(seed: int, size: tuple[int, int], level: int, close: int, erode: int) -> np.ndarray:
    """The study tracker's inverted, padded mask of a noisy dark frame (V ~ 20 ± 8 codes, spatially
    correlated over ~1.5 px) at a low V threshold, as its thresholds derived from noisy close-range
    captures give: specks, clumps and chains, thousands of blobs with the morphology off or
    turned down."""
    rng = np.random.default_rng(seed)
    v = np.clip(rng.normal(20, 6, size) + cv2.GaussianBlur(rng.normal(0, 6, size), (0, 0), 1.5), 0, 255)
    hsv = np.dstack([np.full(size, 90, np.uint8), np.full(size, 100, np.uint8), v.astype(np.uint8)])
    settings = ThesisTrackerSettings(close_iterations=close, erode_iterations=erode)
    mask = colour_mask(hsv, [((0, 0, level), (180, 255, 255))], settings)
    return cv2.copyMakeBorder(255 - mask, 64, 64, 64, 64, cv2.BORDER_CONSTANT, value=255)


def blob_grouping(size: tuple[int, int] = (400, 600), level: int = 22) -> dict:
    """The study tracker's blob detection on a speckle mask (:func:`speckle_mask`, morphology off):
    OpenCV's ``SimpleBlobDetector`` (17 threshold levels, grouping quadratic in the blobs) against
    :func:`pipeline.binary_blobs.detect_two_level` (one level, the same keypoints), s."""
    image = speckle_mask(0, size, level, 0, 0)
    params = blob_detector_params(ThesisTrackerSettings())
    t0 = time.perf_counter()
    points, sizes = detect_two_level(image, params)
    t1 = time.perf_counter()
    keypoints = cv2.SimpleBlobDetector_create(params).detect(image)
    t2 = time.perf_counter()
    same = np.array_equal(points, np.array([k.pt for k in keypoints], np.float32).reshape(-1, 2)) and np.array_equal(
        sizes, np.array([k.size for k in keypoints], np.float32)
    )
    return {
        "blobs": len(keypoints),
        "one_level_s": t1 - t0,
        "opencv_s": t2 - t1,
        "ratio": (t2 - t1) / (t1 - t0),
        "identical": bool(same),
    }


def equivalence_statistics(frames: int = 20) -> dict:
    """The fast camera path against the reference: :func:`studies.experiments.equivalence.summary`
    (photon transfer, dark-frame χ², false blobs on ``frames`` dark C270 frames per path)."""
    return equivalence.summary(frames)


RECORDED_RUNS = Path(__file__).resolve().parents[2] / "results"
"""Where the recorded runs live: ``main-job/runs.json`` and ``full/<study>.runs.json``."""
FULL_STUDIES = ("range-limit", "webcam-vs-dslr", "brightness-diffuser", "validate")


def recorded_runs(folder: Path = RECORDED_RUNS) -> dict:
    """Wall times of the runs too long to repeat in a benchmark, as their commands recorded
    them (:mod:`studies.engine.run_log`): the main job cold on a fresh clone
    (``main-job/runs.json``) and each full study cold (``full/<study>.runs.json``); None
    where no record is kept. Each entry: seconds (the parts' sum), parts, frames."""

    def entry(path: Path) -> dict | None:
        if not path.is_file():
            return None
        parts = json.loads(path.read_text())["parts"]
        last = parts[-1]
        return {
            "s": total_seconds(parts),
            "parts": len(parts),
            "frames": last["frames"],
            "finished_utc": last["finished_utc"],
            "complete": last.get("complete", True),
        }

    studies = {name: entry(folder / "full" / f"{name}.runs.json") for name in FULL_STUDIES}
    all_done = all(v is not None and v["complete"] for v in studies.values())
    return {
        "main_job": entry(folder / "main-job" / "runs.json"),
        "full_studies": studies,
        "full_studies_s": sum(v["s"] for v in studies.values()) if all_done else None,
    }
