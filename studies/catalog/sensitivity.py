"""``beacon-sim sensitivity``: which unknown decides a camera's far limit, so which to measure first.

A sequential range-limit run (:mod:`studies.catalog.range_limit`) of one camera × beacon × side ×
drive × yaw, at the nominal point and at N points of the unknowns (scrambled Sobol' over their
registry ranges, or a calibration's NROY set where it covered them:
:func:`studies.catalog.prediction_set.physics_points`), gives two outputs per point: the far limit
(m; "≥ the farthest range tried" counts as that range, said so) and the fraction of correct poses at
:data:`PROBE_RANGE_M`. Each point's far limit costs a range-limit unit (tens to a hundred frames), so
the indices are computed on a Gaussian-process emulator of the N direct runs
(:func:`studies.engine.sensitivity.emulate`, its leave-one-out error stated): Morris screening over
every unknown that acts on the camera and beacon, then Sobol' first-order and total indices (SALib)
on the :data:`SOBOL_INPUTS` the screening ranks first. The report says, in words, which measurement
would narrow each output most.

Outputs in ``out``: ``range-limit/`` (the frames, their tables and report), ``sensitivity.json``
(per output: the points' values, Morris and Sobol' records, the emulator's diagnostics, the
sentences), ``report.html``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.catalog import prediction_set, range_limit
from studies.engine import strict_json
from studies.engine.calibration.inputs import InputSpace
from studies.engine.max_range import estimate_max_range
from studies.engine.report import Report
from studies.engine.run_log import resumed_seconds
from studies.engine.scoring import pose_success
from studies.engine.sensitivity import emulate, explain, morris, sobol
from studies.engine.sequential import SequentialDesign
from studies.engine.sweep import Execution
from studies.engine.tasks import StudyOptions
from studies.engine.unknowns import Unknown, load_unknowns, nominal

__all__ = [
    "NAME",
    "PROBE_RANGE_M",
    "SOBOL_INPUTS",
    "UNIT_BUDGET_GRIDS",
    "Setting",
    "acting_space",
    "check",
    "point_outputs",
    "run",
    "study_options",
]

NAME = "sensitivity"
PROBE_RANGE_M = 5.0
"""Range of the second output, m (the issue asks for the ranking at 5 m and at the far limit)."""
SOBOL_INPUTS = 5
"""Inputs the Sobol' indices are computed for: the first by Morris μ*."""
OUTPUTS = {"far_limit_m": "the far limit", "p_correct_5m": f"P(correct pose) at {PROBE_RANGE_M:g} m"}
UNIT_BUDGET_GRIDS = 12
"""Coarse grids of frames one point's range-limit run may spend (the coarse grid and about seven
rounds of 12 frames). Assumed, a cost bound: a point whose P stays near 0.95 over a stretch of ranges
cannot have its far limit decided by any number of frames (:mod:`studies.engine.sequential`), and
without a cap such points took the design's whole budget (V2 + T6 18 mm: 11 of 17 points still open
after 56 frames each, at 35-85 s a frame with noise reduction on); the point's fit at the cap is its value."""


@dataclass(frozen=True)
class Setting:
    """The one unit whose outputs are analysed (a camera, beacon, side, LED drive and yaw)."""

    camera: str
    beacon: str = "v2"
    side: str = "red"
    led_current_mA: float = 2.0
    yaw_deg: float = 0.0


def check(setting: Setting) -> None:
    """Refuse a setting no study could run, in one line naming the field (before any work)."""
    study_options(setting).validate()


def acting_space(setting: Setting, names: list[str]) -> tuple[InputSpace, dict[str, Unknown]]:
    """The varying unknowns among ``names`` that act on ``setting``'s camera and beacon (others are
    inert there, and an emulator should not be asked about them), as an input space."""
    registry = load_unknowns()
    acting = {}
    for n in names:
        u = registry[n]
        if u.kind == "fixed" or (u.cameras and setting.camera not in u.cameras):
            continue
        if u.path.startswith("beacons.") and u.path.split(".")[1] != setting.beacon:
            continue
        acting[n] = u
    return InputSpace.from_unknowns(acting), acting


def study_options(
    setting: Setting, physics: tuple[dict, ...] = (), source: str = "", quick: bool = True
) -> StudyOptions:
    """The range-limit options of one unit (the setting's camera, beacon, side, yaw and current) at the
    points ``physics`` (``source`` says what they are), on the quick grid or the full one."""
    return StudyOptions(
        cameras=(setting.camera,),
        beacons=(setting.beacon,),
        sides=(setting.side,),
        yaws_deg=(float(setting.yaw_deg),),
        currents_mA=(float(setting.led_current_mA),),
        ranges_m=(2.0, PROBE_RANGE_M, 8.0, 12.0) if quick else (2.0, 4.0, PROBE_RANGE_M, 6.0, 8.0, 10.0, 12.0),
        seeds=2 if quick else 3,
        jitter_poses=1 if quick else 2,
        physics=physics,
        physics_source=source,
    )


def point_outputs(frame: pd.DataFrame, points: int) -> pd.DataFrame:
    """Per point of the unknowns: the far limit (m; "≥" counted as the farthest range tried, with
    ``at_least``) and the fraction of correct poses at :data:`PROBE_RANGE_M` (best tracker)."""
    best = frame[(frame.tracker == "best") & frame["point"].notna()]
    rows = []
    for i in range(points):
        g = best[best["point"] == i]
        mr = estimate_max_range(g.to_dict("records")) if len(g) else None
        probe = g[np.isclose(g.nominal_range_m, PROBE_RANGE_M)]
        rows.append(
            {
                "point": i,
                "far_limit_m": math.nan if mr is None else max(float(mr.max_range_m), 0.0),
                "at_least": bool(mr and mr.at_least),
                "p_correct_5m": float(np.mean([pose_success(r) for r in probe.to_dict("records")]))
                if len(probe)
                else math.nan,
                "frames": len(g),
            }
        )
    return pd.DataFrame(rows)


def run(
    out: Path,
    setting: Setting,
    *,
    points: int = 32,
    calibration: Path | None = None,
    seed: int = 0,
    quick: bool = False,
    execution: Execution = Execution(),
) -> dict:
    """Run the analysis into ``out``; returns what ``sensitivity.json`` holds (module docstring)."""
    t0 = time.perf_counter()
    out = Path(out)
    physics, source = prediction_set.physics_points(points, seed=seed, calibration=calibration, choices_apart=True)
    options = study_options(setting, physics, source, quick)
    options.validate()
    coarse = len(options.ranges_m) * options.seeds
    design = SequentialDesign(target_relative=0.2, max_range_m=20.0, unit_budget_frames=UNIT_BUDGET_GRIDS * coarse)
    range_limit.run(out / "range-limit", options, execution, design=design)
    frame = pd.read_parquet(out / "range-limit" / "results.parquet")
    outputs = point_outputs(frame, len(physics))
    space, acting = acting_space(setting, list(physics[0]))
    design_q = space.to_unit([{n: p[n] for n in space.names} for p in physics])
    analyses = {}
    for column, label in OUTPUTS.items():
        y = outputs[column].to_numpy(dtype=float)
        if np.nanstd(y) == 0 or np.isfinite(y).sum() < 4:
            analyses[column] = {"output": label, "sentences": [f"{label}: the same at every point; nothing to rank"]}
            continue
        model = emulate(space, design_q, y, output=column, seed=seed)
        screen = morris(model, space, trajectories=50, levels=4, seed=seed)
        top = list(screen.ranked()[:SOBOL_INPUTS])
        indices = sobol(model, space, inputs=top, n=1024, seed=seed, nominal=nominal(acting))
        analyses[column] = {
            "output": label,
            "emulator": model.describe(),
            "relative_error": model.relative_error,
            "morris": screen.to_json(),
            "sobol": indices.to_json(),
            "sentences": list(explain(indices, output=label, unknowns=acting, emulated=model)),
        }
    summary = {
        "study": NAME,
        "setting": setting.__dict__,
        "points": len(physics),
        "source": source,
        "censored_far_limits": int(outputs.at_least.sum()),
        "outputs": outputs.to_dict("records"),
        "analyses": analyses,
        "wall_s": resumed_seconds(out, NAME) + time.perf_counter() - t0,  # with the parts it resumes
    }
    atomic_write_bytes(out / "sensitivity.json", strict_json.dumps(summary, indent=2).encode())
    _report(out, summary)
    return summary


def _report(out: Path, summary: dict) -> None:
    s = summary["setting"]
    rep = Report(f"Which unknown to measure first: {s['camera']}, {s['beacon']} {s['side']} side, {s['yaw_deg']:g}°")
    lead = [f"At {summary['source']}: each point a sequential range-limit run."]
    for a in summary["analyses"].values():
        lead += a["sentences"][:2]
    if summary["censored_far_limits"]:
        lead.append(
            f"{summary['censored_far_limits']} points still worked at the farthest range tried: their far limit "
            "counts as that range, which understates the spread the unknowns make."
        )
    rep.lead(lead)
    for a in summary["analyses"].values():
        rep.heading(a["output"][0].upper() + a["output"][1:])
        for sentence in a["sentences"]:
            rep.text(sentence)
        if "sobol" in a:
            sob = a["sobol"]
            rep.figure(
                _sobol_figure(sob),
                f"Share of the variance of {a['output']} each unknown explains, on the emulator: alone (first "
                "order, S1) and with its interactions (total, ST), 95 % bootstrap whiskers",
            )
            rep.table(
                pd.DataFrame(
                    {
                        "unknown": sob["inputs"],
                        "S1": sob["s1"],
                        "S1 ±": sob["s1_conf"],
                        "ST": sob["st"],
                        "ST ±": sob["st_conf"],
                    }
                ),
                "Sobol' indices (first order and total, 95 % bootstrap half-widths), on the emulator",
                float_format="{:.2f}",
            )
            mor = a["morris"]
            rep.table(
                pd.DataFrame({"unknown": mor["inputs"], "μ*": mor["mu_star"], "σ": mor["sigma"]})
                .sort_values("μ*", ascending=False)
                .head(12),
                "Morris screening (the twelve largest μ*, in the output's unit over each unknown's range)",
                float_format="{:.3g}",
            )
    rep.heading("The points")
    rep.table(pd.DataFrame(summary["outputs"]), "Each point's outputs (best tracker)", float_format="{:.3g}")
    rep.text(
        f"Run time {summary['wall_s']:.0f} s: this run's and the interrupted parts' it resumed (a finished "
        "study run again reads its stored frames; runs.json lists every part).",
        note=True,
    )
    rep.write(out / "report.html")


def _sobol_figure(sob: dict):
    """Horizontal bars of each input's first-order and total Sobol' index, largest total on top."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = np.argsort(sob["st"])
    names = [sob["inputs"][i] for i in order]
    y = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(7.0, 0.45 * len(names) + 1.2))
    for shift, key, label in ((-0.18, "s1", "alone (S1)"), (0.18, "st", "with interactions (ST)")):
        values = np.asarray(sob[key], dtype=float)[order]
        err = np.asarray(sob[f"{key}_conf"], dtype=float)[order]
        ax.barh(y + shift, values, height=0.34, xerr=err, capsize=2, label=label)
    ax.set_yticks(y, names)
    ax.set_xlim(0.0, max(1.0, float(np.nanmax(np.asarray(sob["st"], dtype=float)))))
    ax.set_xlabel("share of the output's variance")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return fig
