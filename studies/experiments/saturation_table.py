"""Issue 4: saturated fraction of each marker's core per camera, LED drive and paper count, at 2 m and 5 m.

Every case is a frame task of :mod:`studies.engine.tasks` through the engine's one
render → capture path (:func:`studies.engine.frame.capture_frame`: Mitsuba render of the
V2 beacon's red side, yaw 0, dark environment, black housing, white paper → lens,
exposure, sensor with noise, ISP), measured by
:func:`camera_models.capture.marker_core_saturation` on the raw mosaic
(:func:`saturation_rows_of`). The webcams meter the whole frame (low-resolution
background render) and run their auto-exposure loop; the T6 uses its camera file's
manual exposure (the study's ISO 6400, 1/60 s).

Diffusers: the bare LED (no foam, no paper) and foam with 0, 1 or 3 sheets of white paper.
LED drive does not change the render (it scales the cached unit render), so the drives
of each (camera, range, diffuser) are one render batch; near-field marker renders are
cached per diffuser configuration. Render settings are modest (4 spp, 2× oversampling,
only the facing target); the capture is of the crop only (the full frame adds nothing
to the markers' pixels: metering uses the background render either way). Tasks run
through :func:`studies.engine.runner.run_tasks` (resumable: rows stored under
``out/tasks``).

Rows (:data:`FIELDS`), one per camera × range (m) × diffuser × drive (mA) × marker: the
core's radius (px) and pixel count, its saturated fraction (0–1) in all and per colour
filter site (R, G, B), the peak and clip levels (DN), the exposure (mode, time in s,
ISO, gain code, analog gain), the auto exposure's last metered mean (fraction of clip)
and whether it settled (:func:`ae_settled`), and the seed.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from camera_models.camera import load_camera
from camera_models.capture import marker_core_saturation
from studies.engine.frame import FRAME_VERSION, capture_frame, render_batch_key
from studies.engine.runner import Progress, no_progress, run_tasks
from studies.engine.tasks import StudyOptions, frame_tasks, grid_conditions

__all__ = [
    "CAMERAS",
    "DIFFUSERS",
    "FIELDS",
    "ORDER",
    "ROWS_VERSION",
    "ae_settled",
    "saturation_rows",
    "saturation_rows_of",
    "saturation_tasks",
    "summary_markdown",
    "write_csv",
]

CAMERAS = ("canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920")
RANGES_M = (2.0, 5.0)
DRIVES_MA = (2.0, 5.0, 10.0, 20.0)
DIFFUSERS = ((False, 0), (True, 0), (True, 1), (True, 3))
"""(foam, paper sheets): the bare LED row, then foam with 0, 1 and 3 sheets."""
ORDER = ("beacon", "side", "environment", "yaw_deg", "camera", "range_m", "diffuser", "led_current_mA")
"""Grid loop order (first outermost): camera, range, diffuser, drive."""
ROWS_VERSION = 1
"""Bump when :func:`saturation_rows_of` changes its rows (with the engine's FRAME_VERSION: the stored rows' version)."""

FIELDS = (
    "camera",
    "range_m",
    "foam",
    "paper_sheets",
    "led_current_mA",
    "marker",
    "core_radius_px",
    "core_pixels",
    "saturated_fraction",
    "saturated_fraction_R",
    "saturated_fraction_G",
    "saturated_fraction_B",
    "peak_DN",
    "clip_DN",
    "exposure_mode",
    "exposure_s",
    "iso",
    "gain_code",
    "analog_gain",
    "ae_metered_mean",
    "ae_settled",
    "seed",
)


def _peak_dn(cap, u: float, v: float, r: float) -> int:
    h, w = cap.raw.shape
    c0, c1 = max(math.floor(u - r) - cap.x0, 0), min(math.ceil(u + r) - cap.x0 + 1, w)
    r0, r1 = max(math.floor(v - r) - cap.y0, 0), min(math.ceil(v + r) - cap.y0 + 1, h)
    patch = cap.raw[r0:r1, c0:c1]
    return int(patch.max()) if patch.size else 0


def ae_settled(history: Sequence[tuple[float, int, float]], tolerance: float = 0.02) -> bool:
    """Whether the last three auto-exposure frames kept the same settings (within ``tolerance``)."""
    if len(history) < 3:
        return False
    last = history[-3:]
    t0, g0 = last[-1][0], last[-1][1]
    return all(abs(t / t0 - 1.0) <= tolerance and g == g0 for t, g, _ in last)


def saturation_tasks(
    cameras: Sequence[str] = CAMERAS,
    ranges_m: Sequence[float] = RANGES_M,
    drives_mA: Sequence[float] = DRIVES_MA,
    diffusers: Sequence[tuple[bool, int]] = DIFFUSERS,
    spp: int = 4,
    oversampling: int = 2,
    seed: int = 0,
) -> list[dict]:
    """Frame tasks of every camera × range (m) × diffuser × drive (mA), in that loop order:
    V2 red side, yaw 0, dark, white paper, no pose jitter; ``seed`` seeds the render and the
    sensor noise. Raises ValueError (one line) for an unknown camera or impossible drive."""
    options = StudyOptions(
        cameras=tuple(cameras),
        ranges_m=tuple(float(r) for r in ranges_m),
        yaws_deg=(0.0,),
        currents_mA=tuple(float(d) for d in drives_mA),
        diffusers=tuple((bool(foam), int(sheets), "white") for foam, sheets in diffusers),
        seeds=1,
        jitter_poses=1,
        render={"spp": spp, "oversampling": oversampling, "crop": "target", "seed": seed},
        frame="crop",  # marker cores only: the rest of the frame does not change them
    )
    options.validate()
    return [{**t, "seed": seed} for t in frame_tasks(grid_conditions(options, ORDER), options)]


def saturation_rows_of(task: dict) -> list[dict]:
    """The :data:`FIELDS` rows (one per marker) of one frame task: captured by the engine, measured on the raw."""
    frame = capture_frame(task)
    cap, cam, scenario = frame.capture, frame.camera, frame.scenario
    clip = min(cam.sensor.white_level_DN, 2**cam.sensor.adc_bits - 1)
    e = cap.exposure
    return [
        {
            "camera": scenario.camera,
            "range_m": float(scenario.range_m),
            "foam": bool(scenario.foam),
            "paper_sheets": int(scenario.paper_sheets),
            "led_current_mA": float(scenario.led_current_mA),
            "marker": m["id"],
            "core_radius_px": round(m["core_radius_px"], 3),
            "core_pixels": m["core_pixels"],
            "saturated_fraction": round(m["saturated_fraction"], 4),
            **{f"saturated_fraction_{c}": round(m["saturated_fraction_cfa"][c], 4) for c in "RGB"},
            "peak_DN": _peak_dn(cap, m["u"], m["v"], m["core_radius_px"]),
            "clip_DN": int(clip),
            "exposure_mode": e.mode,
            "exposure_s": float(e.exposure_s),
            "iso": None if e.iso is None else float(e.iso),
            "gain_code": None if e.gain_code is None else int(e.gain_code),
            "analog_gain": round(float(e.analog_gain), 4),
            "ae_metered_mean": round(float(e.history[-1][2]), 5) if e.history else None,
            "ae_settled": ae_settled(e.history) if e.history else None,
            "seed": int(task["seed"]),
        }
        for m in marker_core_saturation(cap, cam, scenario)
    ]


def saturation_rows(
    out: Path, tasks: list[dict], workers: int | None = None, progress: Progress = no_progress
) -> list[dict]:
    """One row per (camera, range, diffuser, drive, marker) (:data:`FIELDS`) of the tasks of
    :func:`saturation_tasks`, in their order; tasks stored under ``out/tasks``, a re-run
    resumes. ``workers``: local processes (default one per CPU)."""
    return run_tasks(
        tasks,
        out,
        saturation_rows_of,
        version=100 * FRAME_VERSION + ROWS_VERSION,
        workers=workers,
        description="saturation-table",
        progress=progress,
        batch_key=render_batch_key,
    )


def write_csv(rows: list[dict], path: Path) -> None:
    """Write the rows with :data:`FIELDS` as header."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r[k] is None else r[k]) for k in FIELDS})


def _diffuser_label(foam: bool, sheets: int) -> str:
    return "bare LED" if not foam and sheets == 0 else f"foam + {sheets} sheet{'s' if sheets != 1 else ''}"


def summary_markdown(rows: list[dict]) -> str:
    """Short report: mean (min-max over the 5 markers) core saturation per case; webcam exposure per case."""
    cams = list(dict.fromkeys(r["camera"] for r in rows))
    ranges = sorted({r["range_m"] for r in rows})
    drives = sorted({r["led_current_mA"] for r in rows})
    diffs = list(dict.fromkeys((r["foam"], r["paper_sheets"]) for r in rows))
    lines = [
        "# Marker-core saturation: V2 red side, yaw 0, dark, white paper",
        "",
        "Fraction of raw pixels at the clip level inside each marker's lit-face image (at least the",
        "1-px disc), all colour sites together: mean over the 5 markers (min-max when they differ",
        "by more than 0.01). T6: manual ISO 6400, 1/60 s; webcams: their auto exposure, metering",
        "the whole (dark) frame. Render: 4 spp, 2× oversampling, facing target only. With the",
        "Bayer mosaic (¼ R, ½ G, ¼ B sites) a red LED clips the R sites first: 0.25 ≈ R only, 0.75 ≈ R and G,",
        "1.00 = every site (per-site fractions and the peak DN are in the CSV).",
        "",
    ]

    def cell(sel):
        v = [r["saturated_fraction"] for r in sel]
        lo, hi, mean = min(v), max(v), float(np.mean(v))
        return f"{mean:.2f}" if hi - lo <= 0.01 else f"{mean:.2f} ({lo:.2f}-{hi:.2f})"

    for name in cams:
        for rng in ranges:
            sub = [r for r in rows if r["camera"] == name and r["range_m"] == rng]
            if not sub:
                continue
            core = sub[0]["core_pixels"], sub[0]["core_radius_px"]
            lines += [
                f"## {name}, {rng:g} m (marker 1 core: {core[0]} px, radius {core[1]:.2f} px)",
                "",
                "| diffuser | " + " | ".join(f"{d:g} mA" for d in drives) + " |",
                "|---|" + "---|" * len(drives),
            ]
            for foam, sheets in diffs:
                cells = []
                for d in drives:
                    sel = [
                        r for r in sub if (r["foam"], r["paper_sheets"]) == (foam, sheets) and r["led_current_mA"] == d
                    ]
                    cells.append(cell(sel) if sel else "")
                lines.append(f"| {_diffuser_label(foam, sheets)} | " + " | ".join(cells) + " |")
            lines.append("")
    auto = [r for r in rows if r["exposure_mode"] == "auto" and r["marker"] == 1]
    if auto:
        lines += [
            "## Webcam auto exposure (settled values)",
            "",
            "Settings after the auto-exposure loop (settled: the last three frames unchanged) and",
            "the frame mean it metered, as a fraction of clip (its target is "
            f"{load_camera(auto[0]['camera']).exposure.target_mean:g}); 'limits' marks exposure",
            "and gain both at their maxima.",
            "",
            "| camera | range | diffuser | drive | exposure | gain code | analog gain | metered mean | settled |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in auto:
            cam = load_camera(r["camera"])
            at_limits = (
                abs(r["exposure_s"] / cam.exposure.max_exposure_s - 1) < 1e-6
                and r["gain_code"] == cam.sensor.gain_code_max
            )
            state = ("yes" if r["ae_settled"] else "no") + (", limits" if at_limits else "")
            lines.append(
                f"| {r['camera']} | {r['range_m']:g} m | {_diffuser_label(r['foam'], r['paper_sheets'])} | "
                f"{r['led_current_mA']:g} mA | {r['exposure_s'] * 1e3:.2f} ms | {r['gain_code']} | "
                f"{r['analog_gain']:.2f} | {r['ae_metered_mean']:.4f} | {state} |"
            )
        lines.append("")
    return "\n".join(lines)
