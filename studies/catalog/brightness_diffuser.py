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
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.beacon import beacon_design
from scenes.led import led_for_side
from scenes.render_cache import atomic_write_bytes
from studies.engine.metrics import wilson_interval
from studies.engine.report import Report
from studies.engine.scoring import detection_success
from studies.engine.sweep import Execution, sweep
from studies.engine.tasks import StudyOptions, grid_conditions

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
    frame = sweep(NAME, grid_conditions(options), options, out, execution=execution, estimators=["best"])
    table = configuration_table(frame)
    summary = {"study": NAME, "recommended": recommend(table), "configurations": table.to_dict("records")}
    _report(out, options, table, summary)
    atomic_write_bytes(out / "summary.json", json.dumps(summary, indent=2, allow_nan=True).encode())
    return summary


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
            p_detect=p,
            p_low=lo,
            p_high=hi,
            colour_correct=float(np.mean([bool(r["side_correct"]) for r in g.to_dict("records")])),
            core_saturation=float(np.nanmean(g.core_saturated_fraction_mean)),
            r_chroma=float(np.nanmean(chroma[:, 0])),
            g_chroma=float(np.nanmean(chroma[:, 1])),
            led_power_mW=1e3 * led_for_side(rec["side"]).radiant_flux_W(rec["led_current_mA"]),
        )
        markers = len(beacon_design(str(g.beacon.iloc[0])).marker_positions_m())
        rec["side_power_mW"] = markers * rec["led_power_mW"]  # every LED of the side at this drive
        rec["in_window"] = bool(p >= 0.95 and rec["core_saturation"] < 0.5)
        out.append(rec)
    return pd.DataFrame(out)


def recommend(table) -> list[dict]:
    """Per camera and side: of the configurations in the window at every range studied
    (best tracker), the one with the least core saturation at its worst range, ties
    broken by the lower LED power; ``p_detect`` is its lowest over the ranges."""
    out = []
    best = table[table.tracker == "best"]
    config = ["led_current_mA", "foam", "paper_sheets", "paper_colour"]
    for (cam, side), g in best.groupby(["camera", "side"]):
        per_config = g.groupby(config, as_index=False).agg(
            in_window=("in_window", "all"),
            core_saturation=("core_saturation", "max"),
            p_detect=("p_detect", "min"),
            led_power_mW=("led_power_mW", "first"),
            side_power_mW=("side_power_mW", "first"),
        )
        window = per_config[per_config.in_window]
        if window.empty:
            out.append({"camera": cam, "side": side, "window": "empty"})
            continue
        pick = window.sort_values(["core_saturation", "led_power_mW"]).iloc[0]
        out.append(
            {
                "camera": cam,
                "side": side,
                "window": f"{len(window)} of {len(per_config)} configurations",
                "led_current_mA": float(pick.led_current_mA),
                "led_power_mW": float(pick.led_power_mW),
                "side_power_mW": float(pick.side_power_mW),
                "foam": bool(pick.foam),
                "paper_sheets": int(pick.paper_sheets),
                "paper_colour": str(pick.paper_colour),
                "p_detect": float(pick.p_detect),
                "core_saturation": float(pick.core_saturation),
            }
        )
    return out


def _report(out: Path, options: StudyOptions, table, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rep = Report("LED brightness × diffusers: detection, colour and saturation")
    rep.text(
        f"Cameras {', '.join(options.cameras)}; sides {', '.join(options.sides)}; ranges "
        f"{', '.join(f'{r:g}' for r in options.ranges_m)} m; LED currents "
        f"{', '.join(f'{c:g}' for c in options.currents_mA)} mA; diffusers (foam, sheets, paper) "
        f"{'; '.join(f'{int(f)}, {n}, {c}' for f, n, c in options.diffusers)}; {options.seeds} seeds each."
    )
    rep.heading("Recommended operating window")
    rep.table(
        pd.DataFrame(summary["recommended"]),
        "Per camera and side (best tracker): P ≥ 0.95 and cores < 50 % clipped at every range",
    )
    best = table[table.tracker == "best"]
    for (cam, side, r), g in best.groupby(["camera", "side", "nominal_range_m"]):
        labels = [
            f"{'foam' if f else 'no foam'}, {n} {c}"
            for f, n, c in g[["foam", "paper_sheets", "paper_colour"]].drop_duplicates().itertuples(index=False)
        ]
        currents = sorted(set(g.led_current_mA))
        fig, axes = plt.subplots(1, 3, figsize=(13, 0.45 * len(labels) + 1.8), sharey=True)
        for ax, metric, title, cmap in zip(
            axes,
            ("p_detect", "colour_correct", "core_saturation"),
            ("P(correct detection)", "P(correct colour)", "core saturation fraction"),
            ("viridis", "viridis", "magma"),
            strict=True,
        ):
            grid = np.full((len(labels), len(currents)), np.nan)
            for row in g.itertuples(index=False):
                label = f"{'foam' if row.foam else 'no foam'}, {row.paper_sheets} {row.paper_colour}"
                grid[labels.index(label), currents.index(row.led_current_mA)] = getattr(row, metric)
            im = ax.imshow(grid, vmin=0, vmax=1, cmap=cmap, aspect="auto")
            ax.set_xticks(range(len(currents)), [f"{c:g}" for c in currents])
            ax.set_xlabel("LED current, mA")
            ax.set_title(title, fontsize=10)
            for (i, j), v in np.ndenumerate(grid):
                if np.isfinite(v):
                    ax.text(
                        j, i, f"{v:.2f}", ha="center", va="center", fontsize=7, color="white" if v < 0.5 else "black"
                    )
            fig.colorbar(im, ax=ax, fraction=0.04)
        axes[0].set_yticks(range(len(labels)), labels)
        rep.figure(fig, f"{cam}, {side} side, {r:g} m (best tracker)")
    rep.heading("All configurations")
    rep.table(table.drop(columns=["r_chroma", "g_chroma"]), "Per configuration and tracker")
    rep.write(out / "report.html")
