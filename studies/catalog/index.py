"""The main job's index page: one decision first, from the three studies' summaries, then the evidence.

The page opens with the camera to use, chosen by :data:`RULE` (:func:`decide`) from the
far limits of ``range-limit`` (the one study that sweeps every camera at 0° and 30°, with
a sequential design deciding each far limit), then one picture of those far limits with
their 95 % intervals (:func:`far_limit_png`, written beside ``index.html``), then a table
with one row per camera whose every column comes from one study, named in its header and
in each cell: the working ranges and what limits them from ``range-limit``, the LED drive
and diffuser from ``brightness-diffuser``, the colour separability from ``webcam-vs-dslr``.
A camera range-limit did not sweep has no range there (another study's sweep is not mixed
into the column).

:func:`answers` is pure (summaries in, records out); :func:`write_index` reads the
summaries and writes ``index.html``, ``far-limits.png`` and ``answers.json`` (standard
JSON: :func:`strict_json`), whose ``decision`` holds the chosen camera, the rule and
whether the evidence could choose.
"""

from __future__ import annotations

import html
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.catalog import brightness_diffuser, range_limit, webcam_vs_dslr
from studies.engine.report import FIGURE_DPI, Provenance, Report, join_words, page_context, provenance
from studies.engine.sequential import design_evidence
from studies.engine.strict_json import strict_json
from studies.engine.uncertainty import nominal_rows

__all__ = [
    "ANSWER_LABELS",
    "BY_RANGE",
    "BY_SEPARABILITY",
    "CHOSEN",
    "FIGURE_NAME",
    "NONE",
    "RULE",
    "STUDY_TITLES",
    "TIE",
    "YAW_STYLES",
    "Decision",
    "FarLimit",
    "answers",
    "decide",
    "decision_yaw",
    "far_limit_figure",
    "far_limit_png",
    "range_limit_diffusers",
    "write_index",
]

STUDY_TITLES = {
    range_limit.NAME: "how far, versus yaw (working range per camera)",
    brightness_diffuser.NAME: "which LED drive and diffuser (operating window)",
    webcam_vs_dslr.NAME: "which camera keeps the colours (separability, confusion, mosaic)",
}
"""The studies the index reads, with what each answers."""
ANSWER_LABELS = {
    "camera": "camera",
    "near_yaw": "working range, nearly square on (range-limit)",
    "far_yaw": "working range, most oblique (range-limit)",
    "led_setting": "LED drive and diffuser (brightness-diffuser)",
    "colour": "colour separability (webcam-vs-dslr)",
    "limit": "what limits it (range-limit)",
}
"""Columns of the answer table and their headers, each naming its study (the yaw columns name their yaw)."""
FIGURE_NAME = "far-limits.png"
"""The picture of the far limits, written beside ``index.html``."""
RULE = (
    "Rule: the camera with the largest far limit at the largest yaw tried ({yaw}; range-limit, best tracker) is "
    "chosen when its 95 % interval overlaps no other camera's; a limit open above (≥ the farthest range tried) "
    "overlaps every interval reaching above its lower bound. Cameras whose intervals overlap the largest one are "
    "tied, and the tie goes to the one whose sides' colours separate best (the largest smallest Mahalanobis "
    "distance between two sides, webcam-vs-dslr); when that cannot tell them apart (not measured, or equal), the "
    "evidence cannot choose."
)
"""The decision rule as the page states it (``{yaw}``: the yaw decided at)."""

CHOSEN, TIE, NONE = "chosen", "tie", "none"
""":attr:`Decision.status`: a camera chosen; a tie nothing breaks; no camera works."""
BY_RANGE, BY_SEPARABILITY = "far limit", "colour separability"
""":attr:`Decision.broken_by`: what decided the choice."""


@dataclass(frozen=True)
class FarLimit:
    """One camera's far limit at one yaw, as the rule compares it.

    ``estimate_m``: the far limit (the farthest range tried when open above; 0 when no range
    works); ``low_m``/``high_m``: its 95 % interval (``high_m`` = inf: open above);
    ``open_above``: "≥ the farthest range tried"; ``decided``: the sequential design met its
    target (None: a fixed grid, no design); ``text``/``interval``: the summary's words;
    ``farthest_tried_m``: the farthest range tried.
    """

    camera: str
    yaw_deg: float
    estimate_m: float
    low_m: float
    high_m: float
    open_above: bool
    decided: bool | None
    text: str
    interval: str
    farthest_tried_m: float
    physics: dict | None = None
    """The noise + physics interval (``--uncertainty``: low, high (None: ≥ the farthest tried), rate,
    points, order), None without it."""
    physics_text: str = ""

    @classmethod
    def from_record(cls, rec: Mapping) -> FarLimit:
        """From a range-limit ``max_range`` record (a non-finite bound stored as null reads as open)."""
        high = _number(rec.get("high_m"), math.inf)
        return cls(
            camera=str(rec["camera"]),
            yaw_deg=float(rec["yaw_deg"]),
            estimate_m=max(_number(rec.get("max_range_m"), 0.0), 0.0),
            low_m=max(_number(rec.get("low_m"), 0.0), 0.0),
            high_m=high,
            open_above=bool(rec.get("at_least")) or not math.isfinite(high),
            decided=None if rec.get("far_decided") is None else bool(rec["far_decided"]),
            text=str(rec.get("far_limit", "")),
            interval=str(rec.get("far_interval", "")),
            farthest_tried_m=_number(rec.get("farthest_tested_m"), 0.0),
            physics=rec.get("far_physics"),
            physics_text=str(rec.get("far_interval_physics", "")),
        )

    @property
    def works(self) -> bool:
        """Some range reaches P ≥ 0.95."""
        return self.estimate_m > 0

    @property
    def physics_span_m(self) -> tuple[float, float] | None:
        """The noise + physics interval as (low, high) in m (high = inf: ≥ the farthest tried; 0: no
        range works), None without ``--uncertainty``."""
        if not self.physics:
            return None
        high = self.physics.get("high")
        return max(_number(self.physics.get("low"), 0.0), 0.0), math.inf if high is None else float(high)

    def overlaps(self, other: FarLimit) -> bool:
        """The two 95 % intervals share a point (an open-above one reaches every range past its lower bound)."""
        return self.low_m <= other.high_m and other.low_m <= self.high_m

    def to_dict(self) -> dict:
        """For answers.json: ``high_m`` null when open above."""
        return {
            "camera": self.camera,
            "yaw_deg": self.yaw_deg,
            "far_limit_m": self.estimate_m,
            "low_m": self.low_m,
            "high_m": self.high_m if math.isfinite(self.high_m) else None,
            "open_above": self.open_above,
            "decided": self.decided,
            "far_limit": self.text,
            "far_interval": self.interval,
            **({"far_physics": self.physics, "far_interval_physics": self.physics_text} if self.physics else {}),
        }


@dataclass(frozen=True)
class Decision:
    """Which camera the rule chose (:data:`RULE`).

    ``status``: :data:`CHOSEN`, :data:`TIE` (the intervals overlap and separability does not
    break it) or :data:`NONE` (no camera works at ``yaw_deg``, or nothing to compare);
    ``camera``: the chosen one (None unless chosen); ``broken_by``: :data:`BY_RANGE` or
    :data:`BY_SEPARABILITY`; ``contenders``: the cameras whose intervals overlap the largest
    far limit (itself first); ``limits``: every camera's far limit at ``yaw_deg``, largest
    first; ``separability``: (camera, smallest Mahalanobis distance or None) of the contenders.
    """

    status: str
    camera: str | None
    yaw_deg: float | None
    broken_by: str | None
    contenders: tuple[str, ...]
    limits: tuple[FarLimit, ...]
    separability: tuple[tuple[str, float | None], ...]

    def to_dict(self, rule: str, headline: str) -> dict:
        """For answers.json, with the rule and the page's first line."""
        return {
            "status": self.status,
            "camera": self.camera,
            "yaw_deg": self.yaw_deg,
            "broken_by": self.broken_by,
            "tie": self.status == TIE,
            "contenders": list(self.contenders),
            "limits": [lim.to_dict() for lim in self.limits],
            "separability": [
                {
                    "camera": cam,
                    "min_mahalanobis": d if d is None or math.isfinite(d) else None,
                    "perfect": d == math.inf,
                }
                for cam, d in self.separability
            ],
            "rule": rule,
            "headline": headline,
        }


def decide(limits: Sequence[FarLimit], separability: Mapping[str, float | None]) -> Decision:
    """Apply :data:`RULE` to the far limits of every camera at one yaw.

    Parameters
    ----------
    limits : one :class:`FarLimit` per camera, all at the same yaw.
    separability : camera → its sides' smallest Mahalanobis distance (inf: perfect; None
        or absent: not measured).

    Returns
    -------
    The :class:`Decision`: the camera whose interval lies above every other's; else, among
    those overlapping the largest far limit, the one with the strictly largest separability;
    else a tie.
    """
    ordered = tuple(sorted(limits, key=lambda x: (-x.estimate_m, not x.open_above, -x.low_m, x.camera)))
    yaw = ordered[0].yaw_deg if ordered else None
    if not ordered or not ordered[0].works:
        return Decision(NONE, None, yaw, None, (), ordered, ())
    leader = ordered[0]
    contenders = tuple(x.camera for x in ordered if x.overlaps(leader))
    if len(contenders) == 1:
        return Decision(CHOSEN, leader.camera, yaw, BY_RANGE, contenders, ordered, ())
    seps = tuple((cam, _finite_or_inf(separability.get(cam))) for cam in contenders)
    known = [d for _, d in seps if d is not None]
    if len(known) == len(seps):
        best = max(known)
        top = [cam for cam, d in seps if d == best]
        if len(top) == 1:
            return Decision(CHOSEN, top[0], yaw, BY_SEPARABILITY, contenders, ordered, seps)
    return Decision(TIE, None, yaw, None, contenders, ordered, seps)


def decision_yaw(limits: Sequence[FarLimit]) -> float | None:
    """The yaw the rule decides at: the largest yaw at which some camera works, else the largest yaw."""
    yaws = sorted({x.yaw_deg for x in limits})
    working = [y for y in yaws if any(x.works for x in limits if x.yaw_deg == y)]
    return (working or yaws or [None])[-1]


def answers(summaries: Mapping[str, dict], diffusers: Mapping[str, str] | None = None) -> dict:
    """The index's answers from the studies' summaries (study name → summary.json content).

    Parameters
    ----------
    summaries : the studies' summaries.
    diffusers : camera → the diffuser range-limit ran it behind, in words (from its results
        table; absent: not stated).

    Returns
    -------
    ``{"headline", "rule", "decision", "verdict", "cameras", "yaws_deg", "evidence", "agreement"}``:
    the page's first line, the rule stated, the :class:`Decision` as a dict
    (:meth:`Decision.to_dict`), the lead's lines, one record per camera (``camera``,
    ``near_yaw``/``far_yaw``/``limit`` from range-limit, ``led_setting`` from
    brightness-diffuser, ``colour`` from webcam-vs-dslr: words, each also as ``<key>_lines``;
    ``near_yaw_record``/``far_yaw_record``: the range-limit records; ``led_current_mA``: the
    recommended drive; ``colour_record``), the two yaws, the evidence note and how the
    webcam-vs-dslr ranking relates to the decision ("" when it agrees or was not run).
    """
    rl = summaries.get(range_limit.NAME) or {}
    bd = summaries.get(brightness_diffuser.NAME) or {}
    wv = summaries.get(webcam_vs_dslr.NAME) or {}
    ranges = pd.DataFrame(rl.get("max_range", []))
    recommended = pd.DataFrame(bd.get("recommended", []))
    yaws = sorted(set(ranges.yaw_deg)) if not ranges.empty else []
    yaw_pair = [yaws[0], yaws[-1]] if yaws else []
    per_camera = {cam: _range_records(ranges, cam, yaws) for cam in _range_cameras(ranges)}
    limits = [FarLimit.from_record(r) for recs in per_camera.values() for r in recs.values()]
    yaw = decision_yaw(limits)
    seps = {cam: _separability(wv, cam, _drive(recs)) for cam, recs in per_camera.items()}
    decision = decide([x for x in limits if x.yaw_deg == yaw], {c: s[1] for c, s in seps.items()})
    order = [x.camera for x in decision.limits]
    order += [c for c in per_camera if c not in order]
    if decision.camera is not None:
        order = [decision.camera] + [c for c in order if c != decision.camera]
    records = []
    for cam in _cameras(order, recommended, wv):
        recs = per_camera.get(cam, {})
        chosen = [recs.get(y) for y in yaw_pair] if yaw_pair else [None, None]
        rec: dict = {"camera": cam}
        where = _range_source(recs, (diffusers or {}).get(cam))
        for slot, r in zip(("near_yaw", "far_yaw"), chosen, strict=True):
            rec[f"{slot}_lines"] = _working_lines(r, where) if r is not None else ["not in range-limit"]
            rec[f"{slot}_record"] = r
        has_range = any(r is not None for r in chosen)
        rec["limit_lines"] = _limit_lines(chosen, yaw_pair) if has_range else ["not in range-limit"]
        rec["led_setting_lines"], rec["led_current_mA"] = _led_lines(recommended, cam)
        current = _drive(recs) if recs else rec["led_current_mA"]
        rec["colour_lines"], rec["colour_record"] = _colour_lines(wv, cam, current)
        for key in ("near_yaw", "far_yaw", "limit", "led_setting", "colour"):
            rec[key] = "; ".join(rec.get(f"{key}_lines", []))
        records.append(rec)
    rule = RULE.format(yaw=f"{yaw:g}°" if yaw is not None else "–")
    led = {cam: _led_records(recommended, cam) for cam in per_camera}
    headline = _headline(decision, per_camera, seps, led, diffusers or {}, yaws)
    return {
        "headline": headline,
        "rule": rule,
        "decision": decision.to_dict(rule, headline),
        "verdict": [headline, *_comparison(decision, yaws)],
        "cameras": records,
        "yaws_deg": yaw_pair,
        "evidence": _evidence(rl, bd, wv),
        "agreement": _agreement(decision, rl, wv),
    }


def _number(value, missing: float) -> float:
    """A summary's number: null/None (a non-finite value written as standard JSON) → ``missing``."""
    if value is None:
        return missing
    try:
        return float(value)
    except (TypeError, ValueError):
        return missing


def _finite_or_inf(value: float | None) -> float | None:
    """A separability: None stays None (not measured), NaN → None."""
    if value is None or value != value:
        return None
    return float(value)


def _range_cameras(ranges: pd.DataFrame) -> list[str]:
    return [] if ranges.empty else sorted(set(ranges.camera))


def _cameras(order: list[str], recommended: pd.DataFrame, wv: dict) -> list[str]:
    """Every camera named by a study: range-limit's in the decision's order first."""
    out = list(order)
    out += [c for c in (recommended.camera if not recommended.empty else []) if c not in out]
    out += [r["camera"] for r in wv.get("ranking", []) if r["camera"] not in out]
    return out


def _range_records(ranges: pd.DataFrame, cam: str, yaws: list[float]) -> dict[float, dict]:
    """The camera's range-limit records per yaw, for the beacon, side and drive whose far
    limits are largest on average."""
    if ranges.empty or cam not in set(ranges.camera):
        return {}
    g = ranges[ranges.camera == cam]
    reach = g.groupby(["beacon", "side", "led_current_mA"]).max_range_m.mean()
    beacon, side, current = reach.idxmax()
    sel = g[(g.beacon == beacon) & (g.side == side) & (g.led_current_mA == current)]
    out: dict[float, dict] = {}
    for yaw in yaws:
        hit = sel[sel.yaw_deg == yaw]
        if len(hit):
            out[yaw] = {k: _plain(v) for k, v in hit.iloc[0].items()}
    return out


def _plain(value):
    """A pandas cell as a plain Python value (NaN from a missing field → None)."""
    value = value.item() if hasattr(value, "item") else value
    return None if isinstance(value, float) and value != value else value


def _drive(recs: Mapping[float, dict]) -> float | None:
    """The LED drive range-limit ran a camera at, mA."""
    return next((float(r["led_current_mA"]) for r in recs.values()), None)


def _range_source(recs: Mapping[float, dict], diffuser: str | None) -> str:
    """Where a camera's range cells come from: "range-limit: V2 red side, 2 mA behind foam + 1 matched sheet"."""
    if not recs:
        return ""
    r = next(iter(recs.values()))
    behind = f" behind {diffuser}" if diffuser else ""
    return f"range-limit: {str(r['beacon']).upper()} {r['side']} side, {r['led_current_mA']:g} mA{behind}"


def _working_lines(r: dict, where: str) -> list[str]:
    """A range-limit record as lines: the working range, the far limit's interval, how many
    frames decided it (sequential design), the failures nearer than the best range and the
    source (study, beacon, side, drive, frames)."""
    lines = [r["working_range"], f"far limit 95 % interval: {r['far_interval']}"]
    if r.get("far_interval_physics"):
        lines.append(f"with the unknowns (noise + physics): {r['far_interval_physics']}")
    if r.get("near_interval_physics"):
        lines.append(f"near limit with the unknowns (noise + physics): {r['near_interval_physics']}")
    if r.get("decision"):
        lines.append(r["decision"])
    if r.get("near_failures"):
        lines.append(r["failures_nearer"])
    lines.append(where if r.get("decision") else f"{where}, {r['frames']} frames")
    return lines


def _limit_lines(chosen: list[dict | None], yaws: list[float]) -> list[str]:
    lines = []
    for yaw, r in zip(yaws, chosen, strict=True):
        if r is None:
            continue
        cause = r["limiting_cause"]
        if r["max_range_m"] <= 0:
            text = f"{yaw:g}°: {cause} at every range"
        elif cause.startswith("not reached"):
            text = f"{yaw:g}°: {cause}"
        else:
            text = f"{yaw:g}°: {cause} beyond {r['far_limit']}"
        if r.get("near_failures"):
            text += f"; {r['near_cause']} nearer than {r['fitted_from_m']:g} m"
        lines.append(text)
    return lines


def _led_lines(recommended: pd.DataFrame, cam: str) -> tuple[list[str], float | None]:
    """The recommended drive and diffuser per side in words
    (:func:`studies.catalog.brightness_diffuser.recommendation_text`; the last line names the
    study), and the first side with a window's drive, mA (None: no window, or not run)."""
    records = _led_records(recommended, cam)
    if not records:
        return ["not in brightness-diffuser"], None
    lines = [f"{r['side']}: {brightness_diffuser.recommendation_text(r)}" for r in records.values()]
    current = next((float(r["led_current_mA"]) for r in records.values() if r.get("window") != "empty"), None)
    return [*lines, f"brightness-diffuser: {_sides_text(list(records))}"], current


def _led_records(recommended: pd.DataFrame, cam: str) -> dict[str, dict]:
    """brightness-diffuser's ``recommended`` records of a camera, by side."""
    if recommended.empty:
        return {}
    return {str(r["side"]): r for r in recommended[recommended.camera == cam].to_dict("records")}


def _sides_text(sides: Sequence[str]) -> str:
    """ "red side", "green and red sides"."""
    names = sorted(dict.fromkeys(sides))
    if len(names) == 1:
        return f"{names[0]} side"
    return f"{', '.join(names[:-1])} and {names[-1]} sides"


def _separability_record(wv: dict, cam: str, current: float | None) -> dict | None:
    """webcam-vs-dslr's separability record of a camera at ``current`` where it ran it, else
    at the camera's ranking drive, else its first."""
    seps = [s for s in wv.get("colour_separability", []) if s["camera"] == cam]
    if not seps:
        return None
    ranked = next((r["at_led_current_mA"] for r in wv.get("ranking", []) if r["camera"] == cam), None)
    return next((s for s in seps if s["led_current_mA"] == current), None) or next(
        (s for s in seps if s["led_current_mA"] == ranked), seps[0]
    )


def _separability(wv: dict, cam: str, current: float | None) -> tuple[dict | None, float | None]:
    """The record and its smallest Mahalanobis distance (inf: perfect; None: not measured)."""
    sep = _separability_record(wv, cam, current)
    if sep is None:
        return None, None
    pairs = sep.get("pairs", [])
    d = sep.get("min_mahalanobis")
    if d is None:  # a non-finite value written as standard JSON: perfect when a pair has no overlap
        return sep, (math.inf if pairs and any(p.get("bayes_error") == 0.0 for p in pairs) else None)
    return sep, _finite_or_inf(float(d))


def _colour_lines(wv: dict, cam: str, current: float | None) -> tuple[list[str], dict | None]:
    """Separability at ``current`` (range-limit's drive) where webcam-vs-dslr ran it, else at
    the camera's ranking drive, with the sides and frames it rests on."""
    sep = _separability_record(wv, cam, current)
    if sep is None:
        return ["not in webcam-vs-dslr"], None
    paired = {side for p in sep.get("pairs", []) for side in str(p["pair"]).split("-")}
    sides = sorted(paired or sep.get("mean_srgb", {}))
    lines = [
        webcam_vs_dslr.separability_text(_with_floats(sep)),  # with the observed right-colour count
        f"webcam-vs-dslr: {_sides_text(sides) if sides else 'sides not recorded'}, {sep['led_current_mA']:g} mA, "
        f"{sep.get('frames', '?')} frames",
    ]
    if sep.get("separability_interval_physics"):
        lines.insert(1, f"with the unknowns (noise + physics): closest pair {sep['separability_interval_physics']}")
    return lines, sep


def _with_floats(sep: dict) -> dict:
    """A separability record whose nulls (non-finite values in standard JSON) read as numbers again."""
    pairs = []
    for p in sep.get("pairs", []):
        d = p.get("mahalanobis")
        if d is None:
            d = math.inf if p.get("bayes_error") == 0.0 else math.nan
        pairs.append({**p, "mahalanobis": float(d)})
    return {**sep, "pairs": pairs}


def _m(value: float) -> str:
    text = f"{value:.1f}"
    return text[:-2] if text.endswith(".0") else text


def _near_text(r: dict) -> str:
    return f"≤ {_m(r['nearest_tested_m'])} m" if r.get("near_at_most") else f"{_m(r['near_limit_m'])} m"


def _reach_text(recs: Mapping[float, dict], yaws: list[float]) -> str:
    """ "from ≤ 2 m to 18.9 m at 0° (95 %: 15.2 to 19.9 m) and to 18.9 m at 30° (95 %: …)"."""
    parts = []
    first_near = None
    for yaw in yaws:
        r = recs.get(yaw)
        if r is None:
            continue
        if r["max_range_m"] <= 0:
            parts.append(f"at no range at {yaw:g}° ({r['working_range']})")
            continue
        near = _near_text(r)
        frm = f"from {near} " if first_near is None or near != first_near else ""
        first_near = first_near or near
        physics = f"; noise + physics: {r['far_interval_physics']}" if r.get("far_interval_physics") else ""
        parts.append(f"{frm}to {r['far_limit']} at {yaw:g}° (95 %: {r['far_interval']}{physics})")
    return " and ".join(parts)


def _setting_text(recs: Mapping[float, dict], diffuser: str | None, led: Mapping[str, dict]) -> str:
    """The LED setting the far limits were measured at ("at 2 mA behind foam + 1 matched sheet on the
    red side"), and brightness-diffuser's window for the camera's side (``led``: its records by
    side) when it differs."""
    r = next(iter(recs.values()))
    side = str(r["side"])
    text = f"at {r['led_current_mA']:g} mA" + (f" behind {diffuser}" if diffuser else "") + f" on the {side} side"
    w = led.get(side)
    if w is None:
        return text
    if w.get("window") == "empty":
        return text + " (brightness-diffuser found no drive and diffuser it tried that keeps P ≥ 0.95 unclipped)"
    power = f"{w['led_power_mW']:.2g} mW per LED"
    window = f"{w['led_current_mA']:g} mA behind {w['diffuser']}"
    if diffuser and window == f"{r['led_current_mA']:g} mA behind {diffuser}":
        return text + f", {power}, brightness-diffuser's window too"
    return text + f"; brightness-diffuser's window for it is {window} ({power})"


def _headline(
    decision: Decision,
    per_camera: Mapping[str, Mapping[float, dict]],
    seps: Mapping[str, tuple[dict | None, float | None]],
    led: Mapping[str, Mapping[str, dict]],
    diffusers: Mapping[str, str],
    yaws: list[float],
) -> str:
    """The page's first line: "Use CAMERA: it works from A to B m at 0° (95 %: …) and to C m at 30°, with LED …"."""
    if not decision.limits:
        return "No range-limit results: the index cannot say which camera to use."
    yaw = f"{decision.yaw_deg:g}°"
    if decision.status == NONE:
        return "No camera works at any range tried (P ≥ 0.95 nowhere, range-limit): none can be recommended."
    limits = {x.camera: x for x in decision.limits}

    def limit_words(cam: str) -> str:
        return f"{cam} {limits[cam].text} (95 %: {limits[cam].interval})"

    def sep_words(cam: str) -> str:
        d = seps.get(cam, (None, None))[1]
        return f"{cam} not measured" if d is None else f"{cam} {'perfect' if d == math.inf else f'd = {d:.3g}'}"

    if decision.status == TIE:
        return (
            f"The evidence cannot choose between {join_words(decision.contenders)}: their far limits at {yaw} overlap "
            f"({'; '.join(limit_words(c) for c in decision.contenders)}) and colour separability does not break "
            f"the tie ({', '.join(sep_words(c) for c in decision.contenders)}): run with more frames."
        )
    cam = decision.camera
    assert cam is not None
    recs = per_camera[cam]
    setting = _setting_text(recs, diffusers.get(cam), led.get(cam, {}))
    line = f"Use {cam}: it works {_reach_text(recs, yaws)}, with the LED {setting}."
    if decision.yaw_deg != max(yaws):
        line += f" (No camera works at {max(yaws):g}°; decided at {yaw}.)"
    if decision.broken_by == BY_SEPARABILITY:
        others = [c for c in decision.contenders if c != cam]
        line += (
            f" Chosen on colour: its far limit at {yaw} overlaps {join_words(others)}'s "
            f"({'; '.join(limit_words(c) for c in decision.contenders)}), and its colours separate best "
            f"({', '.join(sep_words(c) for c in decision.contenders)})."
        )
    if limits[cam].decided is False:
        line += f" Its far limit at {yaw} is not decided: run with more frames."
    return line


def _comparison(decision: Decision, yaws: list[float]) -> list[str]:
    """Every camera's far limit at the decision's yaw, largest first (one line)."""
    if not decision.limits:
        return []
    items = "; ".join(f"{x.camera} {x.text} (95 %: {x.interval})" for x in decision.limits)
    return [f"Far limits at {decision.yaw_deg:g}° (range-limit, best tracker): {items}."]


def _agreement(decision: Decision, rl: dict, wv: dict) -> str:
    """How webcam-vs-dslr's own ranking relates to the decision (it sweeps fewer yaws and ranges)."""
    ranking = wv.get("ranking", [])
    if not ranking or not rl or decision.camera is None or ranking[0]["camera"] == decision.camera:
        return ""
    first = ranking[0]
    wv_far = max((_number(r.get("farthest_tested_m"), 0.0) for r in wv.get("max_range", [])), default=0.0)
    rl_far = max((_number(r.get("farthest_tested_m"), 0.0) for r in rl.get("max_range", [])), default=0.0)
    wv_yaws = join_words([f"{y:g}°" for y in wv.get("yaws_deg", [])] or ["its yaw"])
    rl_yaws = join_words([f"{y:g}°" for y in sorted({r["yaw_deg"] for r in rl.get("max_range", [])})])
    tied = first.get("tied_on_range") or []
    why = f"tied on range ({first['far_limit']}) with {join_words(tied)}, it is first on colour" if tied else ""
    return (
        f"webcam-vs-dslr ranks {first['camera']} first on its own sweep ({wv_yaws} only, to {_m(wv_far)} m"
        + (f"; {why}" if why else f"; far limit {first['far_limit']}")
        + f"). The decision takes range from range-limit alone, which sweeps every camera at {rl_yaws}, out to "
        f"{_m(rl_far)} m."
    )


def _evidence(rl: dict, bd: dict, wv: dict) -> str:
    parts = []
    if rl.get("design"):
        parts.append(f"range-limit: {design_evidence(rl).removeprefix('Sequential design: ').rstrip('.')}")
    elif rl:
        parts.append(f"range-limit {rl.get('frames_per_point', '?')} frames per range point")
    if bd.get("configurations"):
        parts.append(f"brightness-diffuser {min(c['frames'] for c in bd['configurations'])} per configuration")
    if wv.get("design"):
        parts.append(f"webcam-vs-dslr: {design_evidence(wv).removeprefix('Sequential design: ').rstrip('.')}")
    elif wv.get("max_range"):
        parts.append(f"webcam-vs-dslr {min(r['frames'] for r in wv['max_range'])} frames per camera and drive")
    if not parts:
        return "Evidence: no study summaries found."
    few = "" if rl.get("design") or wv.get("design") else " With so few frames the intervals are wide:"
    return (
        "Evidence: " + "; ".join(parts) + f".{few} An interval from 0 m means the frames cannot exclude that "
        "no range reaches P ≥ 0.95 (that needs ≥ 59 correct frames in a row at one range); '≥' and '≤' mean the "
        "farthest or nearest range tried still worked. Working range: P(correct side, 5 markers numbered, range "
        "within 10 %, yaw within 5°) ≥ 0.95, best tracker."
    )


YAW_STYLES = (("#3b6ea5", "o"), ("#c8553d", "s"), ("#5a8f29", "D"), ("#7b4fa0", "^"))
"""Colour and marker of each yaw in the picture, in yaw order."""


def far_limit_figure(limits: Sequence[FarLimit], order: Sequence[str], chosen: str | None):
    """The picture: per camera (``order``, top down) and yaw, the far limit (marker) with its
    95 % interval (line; an arrow where it is open above), the chosen camera marked; with
    ``--uncertainty`` a wide pale band behind each line, the noise + physics interval (a dot at 0
    when it is "none" at both ends).

    Returns a :class:`matplotlib.figure.Figure` (no pyplot state)."""
    from matplotlib.figure import Figure

    yaws = sorted({x.yaw_deg for x in limits})
    cams = [c for c in order if any(x.camera == c for x in limits)]
    top = max((x.farthest_tried_m for x in limits), default=1.0) or 1.0
    right = top * 1.12
    fig = Figure(figsize=(10.0, 1.3 + 0.75 * max(len(cams), 1)), dpi=FIGURE_DPI)
    ax = fig.add_subplot()
    step = 0.6 / max(len(yaws), 1)
    for j, yaw in enumerate(yaws):
        colour, marker = YAW_STYLES[j % len(YAW_STYLES)]
        for i, cam in enumerate(cams):
            x = next((v for v in limits if v.camera == cam and v.yaw_deg == yaw), None)
            if x is None:
                continue
            y = i + (j - (len(yaws) - 1) / 2) * step
            span = x.physics_span_m
            if span is not None and span[1] > 0:
                band = [span[0], min(span[1], top * 1.05)]
                ax.plot(band, [y, y], color=colour, lw=9, alpha=0.18, solid_capstyle="butt")
            elif span is not None:  # "none" at both ends: a band of no width, shown as a dot at 0
                ax.plot([0.0], [y], marker="o", ms=10, color=colour, alpha=0.25, ls="none", clip_on=False)
            high = min(x.high_m, top)
            ax.plot([x.low_m, high], [y, y], color=colour, lw=2, solid_capstyle="butt")
            ax.plot([x.low_m, x.low_m], [y - 0.08, y + 0.08], color=colour, lw=1.5)
            if math.isfinite(x.high_m):
                ax.plot([high, high], [y - 0.08, y + 0.08], color=colour, lw=1.5)
            else:
                ax.annotate("", xy=(top * 1.05, y), xytext=(top, y), arrowprops={"arrowstyle": "->", "color": colour})
            filled = colour if x.works else "white"
            ax.plot([x.estimate_m], [y], marker=marker, ms=8, color=colour, mfc=filled, ls="none")
            label = f"{x.text} ({x.interval})"
            if span is not None:
                label += f"; with the unknowns {_span_text(span, top)}"
            ax.text(right, y, label, va="center", ha="left", fontsize=9, color=colour, clip_on=False)
        ax.plot([], [], marker=marker, color=colour, lw=2, label=f"{yaw:g}° yaw")
    ax.axvline(top, color="#888", ls=":", lw=1)
    ax.set_yticks(range(len(cams)), [f"{c}  ◀ chosen" if c == chosen else c for c in cams], fontsize=10)
    for label, cam in zip(ax.get_yticklabels(), cams, strict=True):
        if cam == chosen:
            label.set_fontweight("bold")
    ax.set_ylim(len(cams) - 0.5, -0.5)
    ax.set_xlim(0, right)
    ax.set_xlabel(f"far limit (P ≥ 0.95), m (dotted: the farthest range tried, {_m(top)} m)", fontsize=10)
    ax.grid(axis="x", color="#eee")
    ax.legend(fontsize=9, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=len(yaws), frameon=False)
    ax.set_title("range-limit, best tracker", fontsize=10, loc="right")
    return fig


def _span_text(span: tuple[float, float], top: float) -> str:
    """A noise + physics interval in the picture's few words: "none to ≥ 20 m", "4.5 to 10.5 m"."""
    low = "none" if span[0] <= 0 else _m(span[0])
    if span[1] <= 0:
        return "none"
    high = f"≥ {_m(top)}" if math.isinf(span[1]) else _m(span[1])
    return f"{low} to {high} m"


def far_limit_png(limits: Sequence[FarLimit], order: Sequence[str], chosen: str | None) -> bytes:
    """:func:`far_limit_figure` as PNG bytes, the same bytes for the same input (no software or
    date written into the file)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = far_limit_figure(limits, order, chosen)
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIGURE_DPI, bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()


def range_limit_diffusers(study_dir: Path) -> dict[str, str]:
    """camera → the diffuser(s) range-limit ran it behind, in words, from its results table
    (empty when there is none to read).

    Only the nominal frames count: at the points of the unknowns (``--uncertainty``) the paper's
    colour is one of the unknowns, not the study's setting."""
    columns = ["camera", "foam", "paper_sheets", "paper_colour"]
    frame = None
    try:
        if (study_dir / "results.parquet").is_file():
            frame = pd.read_parquet(study_dir / "results.parquet")
        elif (study_dir / "results.csv").is_file():
            frame = pd.read_csv(study_dir / "results.csv", usecols=lambda c: c in [*columns, "point"])
    except (OSError, ValueError, ImportError):
        return {}
    if frame is None or not set(columns) <= set(frame.columns):
        return {}
    out = {}
    for cam, g in nominal_rows(frame)[columns].drop_duplicates().groupby("camera"):
        names = [
            brightness_diffuser.diffuser_text(bool(f), int(n), str(c))
            for f, n, c in g[["foam", "paper_sheets", "paper_colour"]].itertuples(index=False)
        ]
        out[str(cam)] = " or ".join(sorted(dict.fromkeys(names)))
    return out


def write_index(
    out: Path,
    elapsed_s: float | None = None,
    quick: bool | None = None,
    made_by: Provenance | None = None,
    *,
    resumed: bool = False,
) -> dict:
    """Read ``out/<study>/summary.json`` of the three studies and write ``out/index.html``
    (the decision first, the picture, the table, then links), ``out/far-limits.png`` and
    ``out/answers.json``; returns the answers.

    Parameters
    ----------
    out : the main job's output directory.
    elapsed_s : the main job's wall time, s (printed when given).
    resumed : ``elapsed_s`` includes the interrupted parts this run resumed (said on the page).
    quick : the studies ran in their quick form (said on the page); None: not said.
    made_by : the provenance to state (default :func:`studies.engine.report.provenance`).
    """
    out = Path(out)
    summaries = {}
    for name in STUDY_TITLES:
        path = out / name / "summary.json"
        if path.is_file():
            summaries[name] = json.loads(path.read_text())
    result = answers(summaries, range_limit_diffusers(out / range_limit.NAME))
    made_by = made_by or provenance()
    yaws = result["yaws_deg"]
    labels = dict(ANSWER_LABELS)
    if yaws:
        labels["near_yaw"] = f"working range at {yaws[0]:g}° (range-limit)"
        labels["far_yaw"] = f"working range at {yaws[-1]:g}° (range-limit)"
    title = "beacon-sim main job: which camera, what LED setting, how far"
    rep = Report(title)
    rep.lead(result["verdict"])
    rep.text(result["rule"], note=True)
    limits = [FarLimit.from_record(r) for c in result["cameras"] for r in _yaw_records(c)]
    if limits:
        order = [c["camera"] for c in result["cameras"]]
        png = far_limit_png(limits, order, result["decision"]["camera"])
        atomic_write_bytes(out / FIGURE_NAME, png)
        caption = (
            "Far limit (P ≥ 0.95) per camera and yaw (range-limit, best tracker): the marker is the estimate "
            "(hollow: no range works), the line its 95 % interval, an arrow an interval open above. The rule "
            "compares them at the largest yaw."
        )
        physics = next((x.physics for x in limits if x.physics), None)
        if physics:
            caption += (
                f" The wide pale band behind each line is the noise + physics interval: the far limits at "
                f"{physics['points']} points of the unknowns, a predictive interval at {100 * physics['rate']:.0f} % "
                "(a pale dot at 0: none at both ends)."
            )
        rep.html(
            f"<figure><img alt='{html.escape(caption)}' src='{FIGURE_NAME}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
    if result["agreement"]:
        rep.text(result["agreement"], note=True)
    if result["cameras"]:
        rep.html(_answer_table(result["cameras"], labels))
    rep.text(result["evidence"], note=True)
    rep.heading("Reports")
    links = "".join(
        f"<li><a href='{html.escape(name)}/report.html'>{html.escape(name)}</a>: {html.escape(what)}"
        + ("" if name in summaries else " (not run)")
        + "</li>"
        for name, what in STUDY_TITLES.items()
    )
    rep.html(f"<ul>{links}</ul>")
    if elapsed_s is not None:
        result["elapsed_s"] = round(float(elapsed_s), 1)
        rep.text(
            f"Finished in {elapsed_s:.0f} s"
            + (", with the interrupted parts this run resumed" if resumed else "")
            + " (a finished job run again reads its stored frames; runs.json lists every part).",
            note=True,
        )
    result["quick_form"] = quick
    result["provenance"] = made_by.to_dict()
    with page_context(quick=quick, provenance=made_by):
        rep.write(out / "index.html")
    atomic_write_bytes(out / "answers.json", json.dumps(strict_json(result), indent=2, allow_nan=False).encode())
    return result


def _yaw_records(camera: dict) -> list[dict]:
    """A camera record's range-limit records at every yaw it has (the two columns' yaws)."""
    recs = [camera.get("near_yaw_record"), camera.get("far_yaw_record")]
    seen, out = set(), []
    for r in recs:
        if r is not None and r["yaw_deg"] not in seen:
            seen.add(r["yaw_deg"])
            out.append(r)
    return out


def _answer_table(records: list[dict], labels: Mapping[str, str]) -> str:
    """The answers as an HTML table, one row per camera, each cell's lines on lines."""
    head = "".join(f"<th>{html.escape(text)}</th>" for text in labels.values())
    rows = []
    for rec in records:
        cells = [f"<td><b>{html.escape(rec['camera'])}</b></td>"]
        for key in list(labels)[1:]:
            lines = rec.get(f"{key}_lines", [rec.get(key, "")])
            cells.append("<td>" + "<br>".join(html.escape(str(x)) for x in lines) + "</td>")
        rows.append(f"<tr>{''.join(cells)}</tr>")
    caption = "<p><b>Per camera (best tracker): each column from the study its header names</b></p>"
    return f"{caption}<table class='answers'><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
