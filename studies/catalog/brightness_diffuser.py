"""Study ``brightness-diffuser``: LED drive × foam × paper sheets × paper colour.

For every camera, side and chosen range it sweeps the LED current (log-spaced), foam on
or off, 0-5 sheets and white versus matching paper, and maps the probability of a
correct detection (best tracker; the study's beside it), the colour separability of the
marker from the other sides' reference colours, and the fraction of saturated pixels in
the marker cores. A configuration is in the *operating window* when the estimated
P(correct) ≥ 0.95 (its Wilson interval is reported beside it) and the mean core
saturation is below 50 %, at every range studied; the recommended setting per camera
and side is the window's configuration with the largest margin in saturation, reported
with the radiant power (mW, datasheet model) of one LED and of the side's five LEDs at
that current. Renders do not depend on the current (linearity), so the current sweep
costs no renders.

Frames go where the window is decided (:func:`studies.engine.sweep.sweep_screened`): a setting
is in the window only if every one of its frames is correct at every range (P̂ ≥ 0.95 from 4
frames is 4 of 4), so each setting first gets one frame per range, and the other seeds only
where those were all correct. The window, its size and the recommendation are the full grid's;
a setting ruled out shows the frames it got (often 0 of 1). At points of the unknowns every
seed runs (their P(correct) feeds an interval).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from scenes.beacon import beacon_design
from scenes.render_cache import atomic_write_bytes
from studies.engine import strict_json
from studies.engine.metrics import wilson_interval
from studies.engine.report import Report
from studies.engine.scoring import detection_success
from studies.engine.sweep import Execution, Screening, sweep_screened
from studies.engine.tasks import StudyOptions, grid_conditions
from studies.engine.uncertainty import nominal_rows, physics_interval, physics_note, point_rows

__all__ = [
    "NAME",
    "SETTING",
    "add_physics",
    "configuration_table",
    "default_options",
    "diffuser_text",
    "recommend",
    "recommendation_text",
    "run",
    "setting_of",
    "write_outputs",
]

NAME = "brightness-diffuser"
FULL_DIFFUSERS = tuple(
    (foam, n, colour)
    for foam in (False, True)
    for n in range(6)
    for colour in ("white", "matched")
    if not (n == 0 and colour == "matched")
)


def default_options(quick: bool) -> StudyOptions:
    """Full grid, or the quick one the main job runs."""
    if quick:
        return StudyOptions(
            cameras=("logitech-c270", "canon-t6-18mm"),
            ranges_m=(5.0,),
            currents_mA=(2.0, 20.0),
            diffusers=((False, 0, "white"), (True, 1, "white"), (True, 1, "matched"), (True, 3, "white")),
            seeds=2,
            jitter_poses=1,
        )
    return StudyOptions(
        cameras=("logitech-c270", "spedal-920", "canon-t6-18mm", "canon-t6-10mm"),
        sides=("red", "green", "blue", "yellow"),
        ranges_m=(3.0, 7.0),
        currents_mA=(1.0, 2.0, 5.0, 10.0, 20.0),
        diffusers=FULL_DIFFUSERS,
        seeds=4,
        jitter_poses=2,
    )


def run(out: Path, options: StudyOptions, execution: Execution = Execution()) -> dict:
    """Run the study into ``out``; returns the summary."""
    frame, screening = sweep_screened(
        NAME, grid_conditions(options), options, out, setting_of, estimators=["best"], execution=execution
    )
    return write_outputs(out, options, frame, screening)


SETTING = ("camera", "side", "led_current_mA", "foam", "paper_sheets", "paper_colour")
"""What a setting is: the fields of :func:`configuration_table`'s key but range and tracker."""


def setting_of(record: dict) -> tuple | None:
    """The setting of a nominal condition or of its frames' rows (:data:`SETTING`); None at a
    point of the unknowns (those run every seed)."""
    if record.get("point") is not None:
        return None
    return tuple(record[k] for k in SETTING)


def write_outputs(out: Path, options: StudyOptions, frame: pd.DataFrame, screening: Screening | None = None) -> dict:
    """summary.json and report.html of a finished sweep's results table (``screening``: what a
    screened sweep spent; None for a full grid); returns the summary."""
    table = configuration_table(nominal_rows(frame))
    summary = {"study": NAME, "recommended": recommend(table)}
    if screening is not None:
        summary["screening"] = screening.to_dict()
    summary["configurations"] = table.to_dict("records")
    at_points = point_rows(frame)
    if len(at_points):
        add_physics(summary["recommended"], {int(i): configuration_table(g) for i, g in at_points.groupby("point")})
        summary["physics"] = {"points": len(options.physics), "source": options.physics_source}
    _report(Path(out), options, table, summary)
    atomic_write_bytes(Path(out) / "summary.json", strict_json.dumps(summary, indent=2).encode())
    return summary


def diffuser_text(foam: bool, sheets: int, colour: str) -> str:
    """A diffuser in words: "foam + 3 white sheets", "bare LED", "1 matched sheet"."""
    paper = f"{sheets} {colour} sheet{'s' if sheets != 1 else ''}" if sheets else ""
    if foam:
        return f"foam + {paper}" if paper else "foam"
    return paper or "bare LED"


def configuration_table(frame):
    """One row per camera × side × range × current × diffuser × tracker with the metrics."""

    keys = ["camera", "side", "nominal_range_m", "led_current_mA", "foam", "paper_sheets", "paper_colour", "tracker"]
    out = []
    for key, g in frame.groupby(keys, sort=True):
        rec = dict(zip(keys, key, strict=True))
        k, n = sum(detection_success(r) for r in g.to_dict("records")), len(g)
        p, lo, hi = wilson_interval(k, n)
        chroma = np.array(
            [[r[f"marker{i}_r_chroma"], r[f"marker{i}_g_chroma"]] for r in g.to_dict("records") for i in range(1, 6)]
        )
        rec.update(
            frames=n,
            successes=int(k),
            p_detect=p,
            p_low=lo,
            p_high=hi,
            colour_correct=float(np.mean([bool(r["side_correct"]) for r in g.to_dict("records")])),
            core_saturation=float(np.nanmean(g.core_saturated_fraction_mean)),
            r_chroma=float(np.nanmean(chroma[:, 0])),
            g_chroma=float(np.nanmean(chroma[:, 1])),
        )
        design = beacon_design(str(g.beacon.iloc[0]))
        rec["led_power_mW"] = 1e3 * design.led(rec["side"]).radiant_flux_W(rec["led_current_mA"])
        markers = len(design.marker_positions_m())
        rec["side_power_mW"] = markers * rec["led_power_mW"]  # every LED of the side at this drive
        rec["in_window"] = bool(p >= 0.95 and rec["core_saturation"] < 0.5)
        out.append(rec)
    return pd.DataFrame(out)


def recommend(table) -> list[dict]:
    """Per camera and side: of the configurations in the window at every range studied
    (best tracker), the one with the least core saturation at its worst range, ties
    broken by the lower LED power. ``p_detect`` and ``p_low`` are the lowest over the
    ranges (Wilson 95 % lower bound), ``successes`` of ``frames`` the frames behind them
    summed over the ranges; ``diffuser`` is the configuration in words."""
    out = []
    best = table[table.tracker == "best"]
    config = ["led_current_mA", "foam", "paper_sheets", "paper_colour"]
    for (cam, side), g in best.groupby(["camera", "side"]):
        per_config = g.groupby(config, as_index=False).agg(
            in_window=("in_window", "all"),
            core_saturation=("core_saturation", "max"),
            p_detect=("p_detect", "min"),
            p_low=("p_low", "min"),
            frames=("frames", "sum"),
            successes=("successes", "sum"),
            led_power_mW=("led_power_mW", "first"),
            side_power_mW=("side_power_mW", "first"),
        )
        window = per_config[per_config.in_window]
        if window.empty:
            out.append(
                {"camera": cam, "side": side, "window": "empty", "configurations": len(per_config), "in_window": 0}
            )
            continue
        pick = window.sort_values(["core_saturation", "led_power_mW"]).iloc[0]
        out.append(
            {
                "camera": cam,
                "side": side,
                "window": f"{len(window)} of {len(per_config)} configurations",
                "in_window": len(window),
                "configurations": len(per_config),
                "led_current_mA": float(pick.led_current_mA),
                "led_power_mW": float(pick.led_power_mW),
                "side_power_mW": float(pick.side_power_mW),
                "foam": bool(pick.foam),
                "paper_sheets": int(pick.paper_sheets),
                "paper_colour": str(pick.paper_colour),
                "diffuser": diffuser_text(bool(pick.foam), int(pick.paper_sheets), str(pick.paper_colour)),
                "p_detect": float(pick.p_detect),
                "p_low": float(pick.p_low),
                "frames": int(pick.frames),
                "successes": int(pick.successes),
                "core_saturation": float(pick.core_saturation),
            }
        )
    return out


def add_physics(recommended: list[dict], tables: dict[int, pd.DataFrame]) -> None:
    """Give each recommended setting its noise + physics evidence, from the configuration tables
    at the points of the unknowns (point → :func:`configuration_table` of its rows): ``p_physics``
    and ``p_interval_physics``, the interval of its lowest P(correct) over the ranges
    (:func:`studies.engine.uncertainty.physics_interval`), and ``window_points``, at how many
    points it stays in the operating window."""
    config = ("led_current_mA", "foam", "paper_sheets", "paper_colour")
    for rec in recommended:
        if rec.get("window") == "empty":
            continue
        p, inside = [], 0
        for table in tables.values():
            sel = table[(table.tracker == "best") & (table.camera == rec["camera"]) & (table.side == rec["side"])]
            for c in config:
                sel = sel[sel[c] == rec[c]]
            if sel.empty:
                continue
            p.append(float(sel.p_detect.min()))
            inside += bool(sel.in_window.all())
        if p:
            iv = physics_interval(p)
            rec.update(
                p_physics=iv.to_dict(),
                p_interval_physics=f"{iv.low:.2f} to {iv.high:.2f} ({100 * iv.rate:.0f} %, {iv.points} points)",
                window_points=f"{inside} of {len(p)}",
            )


def recommendation_text(rec: dict) -> str:
    """A ``recommended`` record in words."""
    if rec.get("window") == "empty":
        return f"no setting tried keeps P ≥ 0.95 with cores < 50 % clipped (0 of {rec['configurations']})"
    return (
        f"{rec['led_current_mA']:g} mA behind {rec['diffuser']}: {rec['led_power_mW']:.2g} mW per LED, "
        f"{rec['side_power_mW']:.2g} mW for the side; {rec['successes']} of {rec['frames']} frames correct "
        f"(lowest Wilson 95 % bound {rec['p_low']:.2f}), cores {100 * rec['core_saturation']:.0f} % clipped; "
        f"{rec['window']} in the window"
        + (
            f"; with the unknowns (noise + physics) lowest P(correct) {rec['p_interval_physics']}, in the window at "
            f"{rec['window_points']} points"
            if rec.get("p_interval_physics")
            else ""
        )
    )


def _report(out: Path, options: StudyOptions, table, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("LED brightness × diffusers: detection, colour and saturation")
    lines = [f"{r['camera']}, {r['side']} side: {recommendation_text(r)}." for r in summary["recommended"]]
    spent = summary.get("screening")
    lines.append(
        f"Evidence: {int(table.frames.min()) if len(table) else 0} frames per configuration and range."
        if spent is None
        else f"Evidence: {options.seeds} frames per range for each of the {spent['confirmed']} settings (of "
        f"{spent['units']}) whose first frame was correct at every range, one per range for the rest (a failure "
        f"already rules a setting out): {spent['frames']} frames of the full grid's {spent['grid_frames']}, the "
        "same window."
    )
    lines.append(
        "The window takes the observed fraction (P ≥ 0.95) at face value; with so few frames its Wilson lower "
        "bound is far below 0.95, so it ranks settings rather than proving them."
    )
    rep.lead([*lines, *physics_note(summary)])
    rep.text(
        f"Cameras {', '.join(options.cameras)}; sides {', '.join(options.sides)}; ranges "
        f"{', '.join(f'{r:g}' for r in options.ranges_m)} m; LED drive "
        f"{', '.join(f'{c:g}' for c in options.currents_mA)} mA; diffusers "
        f"{'; '.join(diffuser_text(f, n, c) for f, n, c in options.diffusers)}; {options.seeds} seeds each. "
        "Operating window: P(correct detection) ≥ 0.95 and marker cores < 50 % clipped at every range."
    )
    rep.heading("Recommended operating window")
    rec = pd.DataFrame(summary["recommended"])
    if "diffuser" in rec:
        rec = rec.assign(
            correct=[f"{d:.0f} of {n:.0f}" if n == n else "–" for d, n in zip(rec.successes, rec.frames, strict=True)],
            **{c: rec[c].fillna("–") for c in ("p_interval_physics", "window_points") if c in rec},
        )
        rep.table(
            rec[
                [
                    "camera",
                    "side",
                    "led_current_mA",
                    "diffuser",
                    "led_power_mW",
                    "side_power_mW",
                    "correct",
                    "p_low",
                    "core_saturation",
                    "window",
                    *(c for c in ("p_interval_physics", "window_points") if c in rec),
                ]
            ],
            "Per camera and side (best tracker): the window's setting with the least clipping",
            labels={
                "led_current_mA": "LED drive, mA",
                "led_power_mW": "radiant power per LED, mW",
                "side_power_mW": "per side (all its LEDs), mW",
                "correct": "correct detections",
                "p_low": "P(correct), Wilson 95 % lower bound",
                "core_saturation": "cores clipped (worst range)",
                "window": "settings in the window",
                "p_interval_physics": "lowest P(correct), noise + physics",
                "window_points": "in the window at points",
            },
            formats={
                "led_current_mA": "{:g}",
                "led_power_mW": "{:.2g}",
                "side_power_mW": "{:.2g}",
                "p_low": "{:.2f}",
                "core_saturation": "{:.0%}",
            },
            css_class="keys",
        )
    best = table[table.tracker == "best"]
    window = best.groupby(["camera", "side", *SETTING[2:]]).in_window.all()
    window = {key for key, inside in window.items() if inside}  # in the window at every range
    for (cam, side, r), g in best.groupby(["camera", "side", "nominal_range_m"]):
        rep.figure(
            _heat_maps(plt, g, window),
            f"{cam}, {side} side, {r:g} m (best tracker): per diffuser and LED drive, the fraction of frames "
            "detected correctly (with the frame counts), of correct colour, and the marker cores' clipped fraction; "
            "boxed: in the operating window (at every range).",
        )
    rep.heading("All configurations")
    shown = table.assign(
        diffuser=[
            diffuser_text(bool(f), int(n), str(c))
            for f, n, c in zip(table.foam, table.paper_sheets, table.paper_colour, strict=True)
        ],
        correct=[f"{d} of {n}" for d, n in zip(table.successes, table.frames, strict=True)],
        in_window=["yes" if w else "no" for w in table.in_window],
    )
    rep.table(
        shown[
            [
                "camera",
                "side",
                "nominal_range_m",
                "led_current_mA",
                "diffuser",
                "tracker",
                "correct",
                "p_low",
                "p_high",
                "colour_correct",
                "core_saturation",
                "led_power_mW",
                "in_window",
            ]
        ],
        "Per configuration and tracker",
        labels={
            "nominal_range_m": "range, m",
            "led_current_mA": "LED drive, mA",
            "correct": "correct detections",
            "p_low": "Wilson 95 %: low",
            "p_high": "high",
            "colour_correct": "right colour",
            "core_saturation": "cores clipped",
            "led_power_mW": "power per LED, mW",
            "in_window": "in window",
        },
        formats={
            "nominal_range_m": "{:g}",
            "led_current_mA": "{:g}",
            "p_low": "{:.2f}",
            "p_high": "{:.2f}",
            "colour_correct": "{:.0%}",
            "core_saturation": "{:.0%}",
            "led_power_mW": "{:.2g}",
        },
        css_class="keys",
    )
    rep.write(out / "report.html")


def _heat_maps(plt, g, window: set):
    """Three heat maps (P(correct detection), P(correct colour), core saturation) of one
    camera, side and range: rows the diffusers, columns the LED drives; numbers at 11 pt; the
    settings in ``window`` ((camera, side, drive, foam, sheets, colour) keys) boxed."""
    labels = [
        diffuser_text(bool(f), int(n), str(c))
        for f, n, c in g[["foam", "paper_sheets", "paper_colour"]].drop_duplicates().itertuples(index=False)
    ]
    currents = sorted(set(g.led_current_mA))
    cell_w = min(0.9, 8.0 / (3 * len(currents)))
    fig, axes = plt.subplots(
        1,
        3,
        figsize=(3 * (cell_w * len(currents) + 0.9) + 2.2, 0.5 * len(labels) + 1.7),
        sharey=True,
        constrained_layout=True,
    )
    for ax, metric, title, cmap in zip(
        axes,
        ("p_detect", "colour_correct", "core_saturation"),
        ("P(correct detection)", "P(correct colour)", "cores clipped"),
        ("viridis", "viridis", "magma"),
        strict=True,
    ):
        grid = np.full((len(labels), len(currents)), np.nan)
        text = np.full(grid.shape, "", dtype=object)
        boxed = np.zeros(grid.shape, dtype=bool)
        for row in g.itertuples(index=False):
            i = labels.index(diffuser_text(bool(row.foam), int(row.paper_sheets), str(row.paper_colour)))
            j = currents.index(row.led_current_mA)
            grid[i, j] = getattr(row, metric)
            text[i, j] = f"{row.successes}/{row.frames}" if metric == "p_detect" else f"{grid[i, j]:.2f}"
            boxed[i, j] = (row.camera, row.side, *(getattr(row, k) for k in SETTING[2:])) in window
        im = ax.imshow(grid, vmin=0, vmax=1, cmap=cmap, aspect="auto")
        ax.set_xticks(range(len(currents)), [f"{c:g}" for c in currents], fontsize=10)
        ax.set_xlabel("LED drive, mA", fontsize=10)
        ax.set_title(title, fontsize=11)
        for (i, j), v in np.ndenumerate(grid):
            if np.isfinite(v):
                dark = v < 0.5 if cmap == "viridis" else v < 0.6
                ax.text(j, i, text[i, j], ha="center", va="center", fontsize=11, color="white" if dark else "black")
                if boxed[i, j]:
                    ax.add_patch(plt.Rectangle((j - 0.46, i - 0.46), 0.92, 0.92, fill=False, ec="red", lw=2))
        fig.colorbar(im, ax=ax, fraction=0.08, pad=0.03)
    axes[0].set_yticks(range(len(labels)), labels, fontsize=10)
    return fig
