"""Study ``replication``: the source study's complete grid, for design decisions at scale.

Sweep (full form): V1 and V2 × 4 side colours × 1-10 m × yaw 0-30° in 5° steps × the
four camera/lens models × foam on/off with 0-5 sheets of matched paper × 8 LED drive
levels (log-spaced 0.5-20 mA) × 10 noise seeds over 2 jittered poses, in the dark cave.
Every geometry is rendered once; its 8 drives × 5 seeds reuse that render (linearity).

Outputs: the maximum range (P(correct side, 5 markers numbered, usable pose) ≥ 0.95 for
every side and yaw up to 30°, :mod:`studies.engine.max_range`) per camera, beacon, diffuser and
drive, as heat maps and a table, and the detection probability of every configuration
(``configurations.csv``).
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.max_range import COLUMNS, estimate_max_range
from studies.engine.report import Report
from studies.engine.runner import die_with_parent
from studies.engine.sweep import Execution, sweep_in_chunks
from studies.engine.tables import detection_curve
from studies.engine.tasks import StudyOptions, grid_conditions

__all__ = [
    "DRIVES_MA",
    "MAX_RANGE_BY",
    "NAME",
    "chunks",
    "conditions",
    "configuration_table",
    "default_options",
    "group_max_range",
    "max_range_table",
    "run",
]

NAME = "replication"
DRIVES_MA = tuple(float(f"{c:.3g}") for c in np.geomspace(0.5, 20.0, 8))
"""Eight LED drive levels, log-spaced from a deep dimming (0.5 mA) to the datasheet 20 mA."""
MAX_RANGE_BY = ("camera", "beacon", "foam", "paper_sheets", "led_current_mA")
"""The groups the maximum range is estimated for (pooling sides, yaws and seeds)."""
DIFFUSERS = tuple((foam, n, "matched" if n else "white") for foam in (False, True) for n in range(6))


def default_options(quick: bool) -> StudyOptions:
    """Full grid (issue 7's replication grid), or a small sample of it."""
    if quick:
        return StudyOptions(
            cameras=("logitech-c270", "canon-t6-18mm"),
            ranges_m=(3.0, 8.0),
            yaws_deg=(0.0, 20.0),
            currents_mA=(2.43, 20.0),
            diffusers=((False, 0, "white"), (True, 1, "matched")),
            seeds=2,
            jitter_poses=1,
            frame="crop",  # see below
        )
    return StudyOptions(
        cameras=("logitech-c270", "spedal-920", "canon-t6-18mm", "canon-t6-10mm"),
        beacons=("v1", "v2"),
        sides=("red", "green", "blue", "yellow"),
        ranges_m=tuple(float(r) for r in range(1, 11)),
        yaws_deg=tuple(float(y) for y in range(0, 31, 5)),
        currents_mA=DRIVES_MA,
        diffusers=DIFFUSERS,
        seeds=10,
        jitter_poses=2,
        # the rendered crop only: whole frames cost ~18x more (2.15 M frames); optimistic about
        # false blobs, by the amounts studies.experiments.crop_vs_full measures
        frame="crop",
    )


def conditions(o: StudyOptions) -> list[dict]:
    """Nominal conditions of the sweep (drive innermost, so a render's frames are adjacent)."""
    return grid_conditions(
        o, ("camera", "beacon", "diffuser", "side", "environment", "yaw_deg", "range_m", "led_current_mA")
    )


def chunks(o: StudyOptions) -> list[list[dict]]:
    """The conditions in chunks of one camera, beacon and diffuser (22 400 frames in the
    full grid), the unit in which :func:`studies.engine.sweep.sweep_in_chunks` runs and stores."""

    def label(c: dict) -> tuple:
        return c["camera"], c["beacon"], c["foam"], c["paper_sheets"], c["paper_colour"]

    return [list(group) for _, group in itertools.groupby(conditions(o), key=label)]


def run(out: Path, options: StudyOptions, execution: Execution = Execution()) -> dict:
    """Run the study into ``out``; returns the summary."""
    frame = sweep_in_chunks(NAME, chunks(options), options, out, execution=execution, estimators=["best"])
    summary = {"study": NAME, "max_range": max_range_table(frame, execution.workers).to_dict("records")}
    configurations = configuration_table(frame)
    atomic_write_bytes(out / "configurations.csv", configurations.to_csv(index=False, float_format="%.6g").encode())
    _report(out, options, summary)
    atomic_write_bytes(out / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def max_range_table(frame, workers: int | None = None):
    """Maximum range per camera × beacon × diffuser × drive (best tracker and estimator),
    pooling every side and yaw: the range within which all of them are localised.
    The groups' fits (768 in the full grid, 0.6-15 s each, depending on the outcomes)
    run on ``workers`` processes."""

    keys = list(MAX_RANGE_BY)
    best = frame[frame.tracker == "best"]
    # groups travel as small column tables, made into row dicts one at a time where fitted
    groups = [(key, g[[c for c in COLUMNS if c in g]]) for key, g in best.groupby(keys, sort=True)]
    n = min(workers or os.cpu_count() or 1, len(groups))
    if n > 1:
        spawn = get_context("spawn")
        with ProcessPoolExecutor(n, mp_context=spawn, initializer=die_with_parent, initargs=(os.getpid(),)) as pool:
            fits = list(pool.map(group_max_range, [g for _, g in groups], chunksize=4))
    else:
        fits = [group_max_range(g) for _, g in groups]
    labels = [dict(zip(keys, key, strict=True)) for key, _ in groups]
    return pd.DataFrame([{**label, **fit} for label, fit in zip(labels, fits, strict=True)])


def group_max_range(group) -> dict:
    """Maximum range (:class:`studies.engine.max_range.MaxRange` as a dict) of one group's table."""
    return estimate_max_range(group.to_dict("records"), bootstrap=100).to_dict()


def configuration_table(frame):
    """Detection probability with its Wilson interval per configuration and tracker."""

    by = ["camera", "beacon", "side", "foam", "paper_sheets", "led_current_mA", "nominal_yaw_deg", "tracker"]
    return detection_curve(frame, by)


def _report(out: Path, options: StudyOptions, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = pd.DataFrame(summary["max_range"])
    rep = Report("Replication grid: maximum range per camera, beacon, diffuser and LED drive")
    rep.text(
        f"Cameras {', '.join(options.cameras)}; beacons {', '.join(options.beacons)}; sides "
        f"{', '.join(options.sides)}; ranges {', '.join(f'{r:g}' for r in options.ranges_m)} m; yaw "
        f"{', '.join(f'{y:g}' for y in options.yaws_deg)}°; LED currents "
        f"{', '.join(f'{c:g}' for c in options.currents_mA)} mA; {len(options.diffusers)} diffuser "
        f"configurations; {options.seeds} seeds per point. Maximum range: P(correct side, 5 markers "
        "numbered, range within 10 %, yaw within 5°) ≥ 0.95 over every side and yaw (logistic fit, "
        "best tracker and estimator)."
    )
    for (cam, beacon), g in table.groupby(["camera", "beacon"]):
        labels = [f"{'foam' if f else 'no foam'}, {n} sheets" for f, n in _diffusers_present(g)]
        currents = sorted(set(g.led_current_mA))
        grid = np.full((len(labels), len(currents)), np.nan)
        for row in g.itertuples(index=False):
            label = f"{'foam' if row.foam else 'no foam'}, {row.paper_sheets} sheets"
            grid[labels.index(label), currents.index(row.led_current_mA)] = row.max_range_m
        fig, ax = plt.subplots(figsize=(1.0 * len(currents) + 3, 0.4 * len(labels) + 1.8))
        im = ax.imshow(grid, vmin=0, vmax=max(options.ranges_m), cmap="viridis", aspect="auto")
        for (i, j), v in np.ndenumerate(grid):
            if np.isfinite(v):
                ax.text(j, i, f"{v:.1f}", ha="center", va="center", fontsize=7, color="white" if v < 5 else "black")
        ax.set_xticks(range(len(currents)), [f"{c:g}" for c in currents])
        ax.set_yticks(range(len(labels)), labels)
        ax.set_xlabel("LED current, mA")
        fig.colorbar(im, ax=ax, fraction=0.04, label="maximum range, m")
        rep.figure(fig, f"{cam}, {beacon}: maximum range (m) over every side and yaw, by diffuser and LED drive")
    rep.heading("Maximum range and limiting cause")
    rep.table(table, "Per camera, beacon, diffuser and drive (best tracker); high_m = inf: never failed")
    rep.write(out / "report.html")


def _diffusers_present(g) -> list[tuple[bool, int]]:
    """The (foam, sheets) pairs present in a group, in sweep order."""
    return sorted({(bool(f), int(n)) for f, n in zip(g.foam, g.paper_sheets, strict=True)})
