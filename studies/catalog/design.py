"""``beacon-sim design``: search the beacon's design for the one that reaches farthest with a camera.

A design (:data:`SPACE`) is a parametric beacon (:class:`scenes.parametric_beacon.BeaconParameters`:
in-plane and out-of-plane marker offsets, lit face, the side's LED part where its colour has more
than one) with what a run sets per side (LED drive, foam, paper sheets), and, for an
interchangeable-lens body, the lens's focal length, and the side's colour: its LED's dominant
wavelength within its colour's band (:func:`hue_range`) (:func:`space_for`).
Each design is evaluated by a sequential range-limit run (:mod:`studies.catalog.range_limit`) of
one camera at one yaw: its far limit (P(correct pose) ≥ 0.95, or the level the target asks for,
best tracker; "≥ the farthest range tried" counts as that range), the optical power of one side
(five LEDs' radiant flux at the drive, :meth:`scenes.led.Led.radiant_flux_W`) and the target's span
(:attr:`BeaconParameters.span_mm`).
The search (:func:`studies.engine.design_search.search`: optuna's multivariate TPE, resumable from
``out/search.journal``) maximises the far limit and minimises power and span within the user's
budget (power per side, span), and the report puts the front beside V2 as built (foam + one matched
sheet) at the drive that spends the same power per side.

A design must work over the target's yaws: its far limit is the smallest over them. It is the
nominal point's (noise and pose only) unless the target runs each design at N points of the
unknowns too (``--uncertainty N``, N + 1 times the frames) and scores it by the noise + physics
interval's lower end (``--at low``: the design that reaches farthest even for unlucky hardware)
or the points' median (``--at median``).

Outputs in ``out``: ``search.journal``, ``front.csv``, ``trials.csv``, ``summary.json`` (the
search's), ``design.json`` (the front beside V2, the budget, counts and wall time), ``report.html``,
``beacons/`` (each candidate's beacon file) and ``evaluations/`` (each design's range-limit run).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from camera_models.lens_variant import register_lens_variant
from pipeline.tracker import ideal_chroma
from scenes.led import HUE_BANDS_NM, SIDE_COLOURS, led_for_side, led_part_names, side_led
from scenes.parametric_beacon import BeaconParameters
from scenes.render_cache import atomic_write_bytes
from studies.catalog import range_limit
from studies.engine import strict_json
from studies.engine.design_search import (
    Constraint,
    DesignSpace,
    Metric,
    Objective,
    choice_param,
    float_param,
    int_param,
    search,
    write_results,
)
from studies.engine.max_range import P_WORKING, check_p_working
from studies.engine.report import Report
from studies.engine.run_log import resumed_seconds
from studies.engine.sequential import SequentialDesign
from studies.engine.sweep import Execution
from studies.engine.tasks import StudyOptions

__all__ = [
    "AT",
    "MARKERS",
    "NAME",
    "SPACE",
    "Budget",
    "Target",
    "current_for_side_power",
    "evaluate_design",
    "hue_range",
    "run",
    "scored_far_limit",
    "space_for",
    "v2_at",
]

NAME = "design"
MARKERS = 5
"""LEDs of one side."""
V2_AS_BUILT = {"foam": True, "paper_sheets": 1}
"""V2's diffusers as built (docs/source-study.md §2: foam and one sheet of paper)."""

SPACE = DesignSpace(
    (
        float_param("arm_length_mm", 30.0, 150.0, unit="mm",
                    assumed="from a compact cross (V1: 45 mm) to a 0.3 m target a dropped node can carry; the "
                    "study proposes larger in-plane offsets (as issue 27 reports its closing proposals)"),
        float_param("out_of_plane_mm", 10.0, 65.0, unit="mm",
                    assumed="V2's 46 mm within what V2's node allows: the targets' backs must clear the node "
                    "(d_t 140 - housing depth 15 - arm width 8 - node radius 50 = 67 mm, scenes/data/beacons/v2.toml); "
                    "the study proposes a shorter out-of-plane arm (as issue 27 reports its closing proposals)"),
        float_param("lit_face_diameter_mm", 6.0, 25.0, unit="mm",
                    assumed="from a bare 5 mm LED's lens (plus a margin) to a 25 mm diffuser window"),
        float_param("led_current_mA", 0.5, 20.0, log=True, unit="mA",
                    assumed="dimmed drives like the study's potentiometers (docs/source-study.md §2.9; the registry's "
                    "led_drive goes to 0.05 mA) up to the datasheets' 20 mA test current"),
        choice_param("foam", [True, False], assumed="with or without the foam disc behind the paper (docs/source-study.md §2.8, §3)"),  # noqa: E501
        int_param("paper_sheets", 0, 3, assumed="0-3 sheets of paper in front of the LED (the study used one)"),
    )
)  # fmt: skip
"""The design parameters and where their ranges come from."""
METRICS = (Metric("far_limit_m", "m", 0.0, 20.0), Metric("side_power_mW", "mW", 0.0), Metric("span_mm", "mm", 0.0))
OBJECTIVES = (
    Objective("far_limit_m", "maximize"),
    Objective("side_power_mW", "minimize"),
    Objective("span_mm", "minimize"),
)


AT = ("nominal", "low", "median")
"""Which far limit a design is scored by: the nominal point's, or over the points of the unknowns
(:attr:`Target.physics`) the noise + physics interval's lower end or the points' median."""


@dataclass(frozen=True)
class Target:
    """What a design is evaluated on.

    Attributes
    ----------
    camera, side
        The camera and the beacon side it sees.
    yaws_deg
        The yaws the design must work at, degrees: its far limit is the smallest over them.
    quick
        A coarser range grid per design.
    focal_lengths_mm
        (low, high): also search the lens of an interchangeable-lens body
        (:mod:`camera_models.lens_variant`).
    physics, physics_source
        Points of the unknowns each design also runs at (``--uncertainty``), and what they are.
    at
        One of :data:`AT`: the far limit scored (``low`` and ``median`` need ``physics``).
    p_working
        The probability of a correct pose the far limit stands for (0.5 < p < 1; the engine's
        :data:`~studies.engine.max_range.P_WORKING` by default).
    side_colour
        Also search the side's colour: its LED's dominant wavelength (:func:`hue_range`).
    """

    camera: str
    side: str = "red"
    yaws_deg: tuple[float, ...] = (30.0,)
    quick: bool = False
    focal_lengths_mm: tuple[float, float] | None = None
    physics: tuple[dict, ...] = ()
    physics_source: str = ""
    at: str = "nominal"
    p_working: float = P_WORKING
    side_colour: bool = False

    def __post_init__(self) -> None:
        check_p_working(self.p_working)
        if not self.yaws_deg or not all(0 <= y <= 90 for y in self.yaws_deg):
            raise ValueError(f"yaws_deg: expected angles in [0, 90], got {list(self.yaws_deg)}")
        if self.at not in AT:
            raise ValueError(f"at: expected one of {', '.join(AT)}, got {self.at!r}")
        if self.at != "nominal" and not self.physics:
            raise ValueError(f"at: {self.at!r} needs points of the unknowns (--uncertainty N), got none")


def space_for(target: Target) -> DesignSpace:
    """:data:`SPACE`, with the LED part when the side's colour has more than one
    (:func:`scenes.led.led_part_names`), and the lens's focal length and the side's colour
    (:func:`hue_range`) when the target searches them."""
    params = list(SPACE.params)
    parts = led_part_names(target.side)
    if len(parts) > 1:
        params.append(choice_param("led", parts, assumed=f"the {target.side} parts of scenes/data/leds.toml "
                                   "and led_parts.toml, each with its datasheet figures"))  # fmt: skip
    if target.focal_lengths_mm is not None:
        low, high = target.focal_lengths_mm
        params.append(float_param("focal_length_mm", float(low), float(high), log=True, unit="mm",
                                  assumed="the user's range of lenses for the body (--focal-length-mm), each at the "
                                  "base lens's f-number, blur and distortion"))  # fmt: skip
    if target.side_colour:
        low, high = hue_range(target.side)
        params.append(float_param("dominant_wavelength_nm", low, high, unit="nm",
                                  assumed=f"the {target.side} LED's dominant wavelength: the band {target.side} 5 mm "
                                  "lamps are made in (scenes.led.HUE_BANDS_NM), as far as the side's colour stays "
                                  "at least as far from every other side's as the study's closest pair "
                                  "(hue_range)"))  # fmt: skip
    return SPACE if len(params) == len(SPACE.params) else DesignSpace(tuple(params))


def _chroma_distances(hues: dict[str, float]) -> dict[tuple[str, str], float]:
    """Distance between each pair of sides' references of the better tracker (ideal-sRGB (r, g),
    :func:`pipeline.tracker.ideal_chroma`), the sides at the dominant wavelengths given (else their
    default parts')."""
    chroma = {c: np.array(ideal_chroma(side_led(c, None, hues.get(c)))) for c in SIDE_COLOURS}
    pairs = [(a, b) for i, a in enumerate(SIDE_COLOURS) for b in SIDE_COLOURS[i + 1 :]]
    return {(a, b): float(np.hypot(*(chroma[a] - chroma[b]))) for a, b in pairs}


@lru_cache(maxsize=8)
def hue_range(side: str, step_nm: float = 1.0) -> tuple[float, float]:
    """The dominant wavelengths (nm) the design search gives a side: the stretch of its colour's band
    (:data:`scenes.led.HUE_BANDS_NM`) around its default part's wavelength where its reference
    chromaticity stays at least as far from every other side's as the study's own closest pair
    (red and yellow), so the better tracker can name it as surely as it names the study's colours.
    Scanned in ``step_nm`` steps (the datasheets' 1 nm resolution of the dominant wavelength).

    >>> hue_range("yellow")  # towards amber, yellow crowds red
    (583.0, 590.0)
    """
    low, high = HUE_BANDS_NM[side]
    closest = min(_chroma_distances({}).values())
    default = led_for_side(side).dominant_wavelength_nm

    def apart(nm: float) -> bool:
        dist = _chroma_distances({side: nm})
        return min(d for pair, d in dist.items() if side in pair) >= closest - 1e-12

    grid = np.arange(low, high + step_nm / 2, step_nm)
    ok = [apart(float(nm)) for nm in grid]
    k = int(np.argmin(np.abs(grid - default)))
    lo = hi = k
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    while hi < len(grid) - 1 and ok[hi + 1]:
        hi += 1
    return float(grid[lo]), float(grid[hi])


@dataclass(frozen=True)
class Budget:
    """The user's constraints: optical power of one side, mW, and the target's span, mm (None: no limit)."""

    side_power_mW: float = 10.0
    span_mm: float | None = None

    def constraints(self) -> tuple[Constraint, ...]:
        out = [Constraint("side_power_mW", "<=", float(self.side_power_mW))]
        if self.span_mm is not None:
            out.append(Constraint("span_mm", "<=", float(self.span_mm)))
        return tuple(out)


def side_power_mW(side: str, current_mA: float, part: str | None = None, hue_nm: float | None = None) -> float:
    """Optical power of one side's five LEDs at ``current_mA``, mW: the ``part`` named (default: the
    side colour's default part, :func:`scenes.led.led_parts`), at dominant wavelength ``hue_nm`` (default
    the part's; its luminous intensity kept, :meth:`scenes.beacon.BeaconDesign.led`)."""
    return MARKERS * 1e3 * side_led(side, part, hue_nm).radiant_flux_W(current_mA)


def current_for_side_power(side: str, power_mW: float, part: str | None = None, hue_nm: float | None = None) -> float:
    """The drive current at which one side's five LEDs (``part``, default the colour's, at ``hue_nm``)
    emit ``power_mW`` of optical power, mA (:meth:`scenes.led.LED.current_for_flux_mA`: not linear where
    γ ≠ 1)."""
    return side_led(side, part, hue_nm).current_for_flux_mA(power_mW / (MARKERS * 1e3))


def _options(target: Target, beacon: str, design: dict) -> StudyOptions:
    return StudyOptions(
        cameras=(target.camera,),
        beacons=(beacon,),
        sides=(target.side,),
        yaws_deg=tuple(float(y) for y in target.yaws_deg),
        currents_mA=(round(float(design["led_current_mA"]), 6),),
        diffusers=((bool(design["foam"]), int(design["paper_sheets"]), "matched"),),
        ranges_m=(2.0, 5.0, 8.0, 12.0) if target.quick else (2.0, 4.0, 6.0, 8.0, 10.0, 12.0),
        seeds=2 if target.quick else 3,
        jitter_poses=1 if target.quick else 2,
        physics=target.physics,
        physics_source=target.physics_source,
    )


def evaluate_design(design: dict, target: Target, out: Path, execution: Execution = Execution()) -> dict[str, float]:
    """A design's metrics: its beacon registered, a sequential range-limit run of ``target`` in
    ``out/evaluations/<beacon>``, the far limit of its best-tracker record."""
    part = design.get("led", target.side)
    hue = design.get("dominant_wavelength_nm")
    hue = None if hue is None else round(float(hue), 1)
    params = BeaconParameters(
        arm_length_mm=round(float(design["arm_length_mm"]), 3),
        out_of_plane_mm=round(float(design["out_of_plane_mm"]), 3),
        lit_face_diameter_mm=round(float(design["lit_face_diameter_mm"]), 3),
        leds=((target.side, part),) if part != target.side else (),
        hues_nm=((target.side, hue),) if hue is not None else (),
    )
    beacon = params.register(out / "beacons")
    if "focal_length_mm" in design:
        lens = round(float(design["focal_length_mm"]), 3)
        target = replace(target, camera=register_lens_variant(target.camera, lens, out / "cameras"))
    options = _options(target, beacon, design)
    options.validate()
    run_out = (
        out / "evaluations" / f"{beacon}-{options.currents_mA[0]:g}mA-{int(design['foam'])}-{design['paper_sheets']}"
    )
    summary = range_limit.run(
        run_out,
        options,
        execution,
        design=SequentialDesign(target_relative=0.2, max_range_m=20.0, p_working=target.p_working),
    )
    return {
        "far_limit_m": min(scored_far_limit(rec, target.at) for rec in summary["max_range"]),
        "side_power_mW": side_power_mW(target.side, float(design["led_current_mA"]), part, hue),
        "span_mm": params.span_mm,
    }


def scored_far_limit(rec: dict, at: str) -> float:
    """A range-limit record's far limit as a design is scored (:data:`AT`), m; one that reaches the
    farthest range tried counts as that range (its limit is at least that)."""
    farthest = float(rec["farthest_tested_m"])
    if at == "nominal":
        return farthest if rec.get("at_least") else max(float(rec["max_range_m"]), 0.0)
    value = rec["far_physics"]["low" if at == "low" else "median"]
    return farthest if value is None else min(float(value), farthest)


def v2_at(budget: Budget, target: Target) -> dict:
    """V2 as built at the drive that spends the budget's power per side (its datasheet maximum if lower)."""
    current = min(
        current_for_side_power(target.side, budget.side_power_mW), led_for_side(target.side).reference_current_mA
    )
    v2 = BeaconParameters.of("v2")
    return {
        "arm_length_mm": v2.arm_length_mm,
        "out_of_plane_mm": v2.out_of_plane_mm,
        "lit_face_diameter_mm": v2.lit_face_diameter_mm,
        "led_current_mA": round(current, 6),
        **V2_AS_BUILT,
    }


def run(
    out: Path,
    target: Target,
    budget: Budget,
    *,
    trials: int = 40,
    seed: int = 0,
    resume: bool = False,
    execution: Execution = Execution(),
    progress: Callable | None = None,
) -> dict:
    """Search the designs into ``out`` (module docstring); returns what ``design.json`` holds."""
    t0 = time.perf_counter()
    out = Path(out)
    context = {"target": target.__dict__, "budget": budget.__dict__}
    result = search(
        space_for(target),
        lambda d: evaluate_design(d, target, out, execution),
        OBJECTIVES,
        budget.constraints(),
        metrics=METRICS,
        trials=trials,
        seed=seed,
        out=out,
        resume=resume,
        context=context,
        progress=progress,
    )
    write_results(result, out)
    reference = v2_at(budget, target)
    v2 = {"design": reference, "metrics": evaluate_design(reference, target, out, execution)}
    summary = {
        "study": NAME,
        "target": target.__dict__,
        "budget": budget.__dict__,
        "evaluations": result.evaluations,
        "feasible": result.feasible,
        "infeasible": result.infeasible,
        "front": [{"trial": p.trial, "design": p.design, "metrics": p.metrics} for p in result.front],
        "v2_at_budget": v2,
        "wall_s": resumed_seconds(out, NAME) + time.perf_counter() - t0,  # with the parts it resumes
    }
    atomic_write_bytes(out / "design.json", strict_json.dumps(summary, indent=2).encode())
    _report(out, summary)
    return summary


COLUMNS = {
    "trial": "design",
    "far_limit_m": "far limit, m",
    "side_power_mW": "power per side, mW",
    "span_mm": "span, mm",
    "arm_length_mm": "arms, mm",
    "out_of_plane_mm": "centre out, mm",
    "lit_face_diameter_mm": "lit face, mm",
    "led_current_mA": "drive, mA",
    "foam": "foam",
    "paper_sheets": "sheets",
}
"""The report table's columns and their headers (``led``, ``focal_length_mm`` and ``dominant_wavelength_nm``
added when searched)."""


def _far(far_limit_m: float, p_working: float) -> str:
    return f"{far_limit_m:.3g} m" if far_limit_m > 0 else f"none (no range reaches P ≥ {p_working:g})"


def _report(out: Path, summary: dict) -> None:
    t, b, v2 = summary["target"], summary["budget"], summary["v2_at_budget"]
    level = float(t.get("p_working", P_WORKING))
    yaws = " to ".join(f"{y:g}" for y in sorted({min(t["yaws_deg"]), max(t["yaws_deg"])}))
    rep = Report(f"Design search: the beacon that reaches farthest with {t['camera']} at {yaws}°")
    span = f" and a span under {b['span_mm']:g} mm" if b.get("span_mm") else ""
    lead = [
        f"{summary['evaluations']} designs evaluated ({summary['feasible']} within {b['side_power_mW']:g} mW per "
        f"side{span}); each a sequential range-limit run of the {t['side']} side, its far limit where "
        f"P(correct pose) falls to {level:g}.",
        f"V2 as built at the same budget ({v2['design']['led_current_mA']:.3g} mA, foam + 1 sheet): far limit "
        f"{_far(v2['metrics']['far_limit_m'], level)} at {v2['metrics']['side_power_mW']:.3g} mW per side.",
    ]
    if summary["front"]:
        best = max(summary["front"], key=lambda p: p["metrics"]["far_limit_m"])
        d, m = best["design"], best["metrics"]
        lead.append(
            f"Farthest on the front: {_far(m['far_limit_m'], level)} with {d['arm_length_mm']:.0f} mm arms, the centre "
            f"marker {d['out_of_plane_mm']:.0f} mm out, {d['lit_face_diameter_mm']:.0f} mm lit faces, "
            f"{d['led_current_mA']:.3g} mA, {'foam + ' if d['foam'] else ''}{d['paper_sheets']} "
            f"sheet{'' if d['paper_sheets'] == 1 else 's'}"
            + (f", the {d['led']} LED part" if "led" in d else "")
            + (f", a {d['focal_length_mm']:.3g} mm lens" if "focal_length_mm" in d else "")
            + (f", the side's LED at {d['dominant_wavelength_nm']:.4g} nm" if "dominant_wavelength_nm" in d else "")
            + f" ({m['side_power_mW']:.3g} mW per side, {m['span_mm']:.0f} mm span)."
        )
    else:
        lead.append(summary["infeasible"] or "No design met the budget.")
    rep.lead(lead)
    rows = [{**p["design"], **p["metrics"], "trial": p["trial"]} for p in summary["front"]]
    rows.append({**v2["design"], **v2["metrics"], "trial": "V2 as built"})
    searched = {key for p in summary["front"] for key in p["design"]}
    added = (("led", "LED part"), ("focal_length_mm", "lens, mm"), ("dominant_wavelength_nm", "λD, nm"))
    columns = {**COLUMNS, **{k: v for k, v in added if k in searched}}
    default_nm = led_for_side(t["side"]).dominant_wavelength_nm
    # V2 as built: the colour's default part at its datasheet colour
    rows = [{**r, "led": r.get("led", t["side"]), "dominant_wavelength_nm": r.get("dominant_wavelength_nm", default_nm)}
            for r in rows]  # fmt: skip
    rep.table(
        pd.DataFrame(rows).reindex(columns=list(columns)),
        "The Pareto front (far limit, power per side, span) and V2 at the same budget",
        labels=columns,
        float_format="{:.3g}",
    )
    scored = {
        "nominal": "far limits of the nominal point (noise and pose only)",
        "low": "far limits scored at the lower end of each design's noise + physics interval",
        "median": "far limits scored at the median over the points of the unknowns",
    }[t.get("at", "nominal")]
    rep.text(
        f"Run time {summary['wall_s']:.0f} s (this run's and the interrupted parts' it resumed; runs.json lists "
        f"every part); {scored}, the worst of the yaws; a design still working at the "
        "farthest range its run tried counts as that range: its limit is at least that.",
        note=True,
    )
    if (out / "trials.csv").is_file():
        rep.figure(
            _trials_figure(pd.read_csv(out / "trials.csv"), v2, b["side_power_mW"]),
            "Every design evaluated: far limit against power per side (marker area: span), the Pareto front ringed, "
            "V2 as built at the budget a star, the budget a dashed line",
        )
    rep.write(out / "report.html")


def _trials_figure(trials: pd.DataFrame, v2: dict, budget_mW: float):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ok = trials[trials.status == "ok"] if "status" in trials else trials
    size = 12 + 60 * (ok.span_mm - ok.span_mm.min()) / max(float(np.ptp(ok.span_mm)), 1e-9)
    ax.scatter(ok.side_power_mW, ok.far_limit_m, s=size, c="C0", alpha=0.6, label="designs")
    front = ok[ok.on_front.astype(bool)]
    ax.scatter(front.side_power_mW, front.far_limit_m, s=120, facecolors="none", edgecolors="k", label="front")
    ax.scatter([v2["metrics"]["side_power_mW"]], [v2["metrics"]["far_limit_m"]], marker="*", s=200, c="C3",
               label="V2 as built")  # fmt: skip
    ax.axvline(budget_mW, color="0.5", ls="--", lw=1)
    ax.set_xscale("log")
    plain = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    ax.xaxis.set_major_formatter(plain)
    ax.xaxis.set_minor_formatter(plain)
    ax.set_xlabel("optical power per side, mW")
    ax.set_ylabel("far limit, m")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
