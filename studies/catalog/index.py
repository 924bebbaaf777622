"""The main job's index page: the answers first, from the three studies' summaries, then links.

Per camera it answers "how far, at what LED setting, and why not farther" from the
``summary.json`` of ``range-limit`` (working range at the smallest and largest yaw, with
the far limit's 95 % interval and the failures on either side), ``brightness-diffuser``
(the recommended LED drive and diffuser with its radiant power) and ``webcam-vs-dslr``
(colour separability and the tracker's colour confusion), and names the camera that
reaches farthest at the largest yaw. :func:`answers` is pure (summaries in, records out);
:func:`write_index` reads the summaries and writes ``index.html`` and ``answers.json``.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from scenes.render_cache import atomic_write_bytes
from studies.catalog import brightness_diffuser, range_limit, webcam_vs_dslr
from studies.engine.report import Report
from studies.engine.sequential import design_evidence
from studies.engine.strict_json import strict_json

STUDY_TITLES = {
    range_limit.NAME: "how far, versus yaw (working range per camera)",
    brightness_diffuser.NAME: "which LED drive and diffuser (operating window)",
    webcam_vs_dslr.NAME: "which camera keeps the colours (separability, confusion, mosaic)",
}
"""The studies the index reads, with what each answers."""
ANSWER_LABELS = {
    "camera": "camera",
    "near_yaw": "working range, nearly square on",
    "far_yaw": "working range, most oblique",
    "led_setting": "LED drive and diffuser (radiant power)",
    "colour": "colour separability",
    "limit": "what limits it",
}
"""Columns of the answer table and their headers (the yaw columns name their yaw)."""


def answers(summaries: Mapping[str, dict]) -> dict:
    """The index's answers from the studies' summaries (study name → summary.json content).

    Returns
    -------
    ``{"cameras": [...], "verdict": [sentences], "yaws_deg": [near, far], "evidence": str}``:
    one record per camera with ``camera``, ``near_yaw``/``far_yaw`` (working range with its
    interval and nearer failures), ``led_setting``, ``colour`` and ``limit`` (words; each
    also as ``<key>_lines``), ``near_yaw_record``/``far_yaw_record`` (the range-limit
    records), ``led_current_mA`` (the recommended drive) and ``colour_record``.
    """
    rl = summaries.get(range_limit.NAME) or {}
    bd = summaries.get(brightness_diffuser.NAME) or {}
    wv = summaries.get(webcam_vs_dslr.NAME) or {}
    ranges = pd.DataFrame(rl.get("max_range", []))
    recommended = pd.DataFrame(bd.get("recommended", []))
    cameras = _cameras(ranges, recommended, wv)
    yaws = sorted(set(ranges.yaw_deg)) if not ranges.empty else []
    yaw_pair = [yaws[0], yaws[-1]] if yaws else []
    records = []
    for cam in cameras:
        rec: dict = {"camera": cam}
        chosen = _range_records(ranges, cam, yaw_pair)
        if all(r is None for r in chosen):
            chosen = _webcam_records(wv, cam, yaw_pair)
        for slot, r in zip(("near_yaw", "far_yaw"), chosen, strict=False):
            rec[f"{slot}_lines"] = _working_lines(r) if r is not None else ["not swept"]
            rec[f"{slot}_record"] = r
        has_range = any(r is not None for r in chosen)
        rec["limit_lines"] = _limit_lines(chosen, yaw_pair) if has_range else ["not swept"]
        rec["led_setting_lines"], rec["led_current_mA"] = _led_lines(recommended, cam)
        rec["colour_lines"], rec["colour_record"] = _colour_lines(wv, cam, rec["led_current_mA"])
        for key in ("near_yaw", "far_yaw", "limit", "led_setting", "colour"):
            rec[key] = "; ".join(rec.get(f"{key}_lines", []))
        records.append(rec)
    return {
        "cameras": records,
        "yaws_deg": yaw_pair,
        "verdict": _verdict(records, yaw_pair),
        "evidence": _evidence(rl, bd, wv),
    }


def _cameras(ranges: pd.DataFrame, recommended: pd.DataFrame, wv: dict) -> list[str]:
    """Every camera named by a study: range-limit's first (farthest at the largest yaw first)."""
    order: list[str] = []
    if not ranges.empty:
        top = ranges[ranges.yaw_deg == ranges.yaw_deg.max()]
        reach = top.groupby("camera").max_range_m.max().sort_values(ascending=False, kind="stable")
        order += list(reach.index)
    order += [c for c in (recommended.camera if not recommended.empty else []) if c not in order]
    order += [r["camera"] for r in wv.get("ranking", []) if r["camera"] not in order]
    return order


def _range_records(ranges: pd.DataFrame, cam: str, yaws: list[float]) -> list[dict | None]:
    """The camera's range-limit records at the two yaws, for the beacon, side and drive
    whose far limits are largest on average."""
    if ranges.empty or cam not in set(ranges.camera):
        return [None for _ in yaws]
    g = ranges[ranges.camera == cam]
    reach = g.groupby(["beacon", "side", "led_current_mA"]).max_range_m.mean()
    beacon, side, current = reach.idxmax()
    sel = g[(g.beacon == beacon) & (g.side == side) & (g.led_current_mA == current)]
    out: list[dict | None] = []
    for yaw in yaws:
        hit = sel[sel.yaw_deg == yaw]
        out.append({k: v.item() if hasattr(v, "item") else v for k, v in hit.iloc[0].items()} if len(hit) else None)
    return out


def _webcam_records(wv: dict, cam: str, yaws: list[float]) -> list[dict | None]:
    """For a camera range-limit did not sweep: webcam-vs-dslr's working range at its
    ranking drive, in the slot of the yaw it was swept at (when it swept one yaw only)."""
    swept = wv.get("yaws_deg", [])
    ranked = next((r for r in wv.get("ranking", []) if r["camera"] == cam), None)
    if ranked is None or len(swept) != 1:
        return [None for _ in yaws]
    rec = next(
        (
            r
            for r in wv.get("max_range", [])
            if r["camera"] == cam
            and r["tracker"] == "best"
            and r["led_current_mA"] == ranked["at_led_current_mA"]
            and r["environment"] == ranked["environment"]
            and r["beacon"] == ranked["beacon"]
        ),
        None,
    )
    if rec is None:
        return [None for _ in yaws]
    rec = {**rec, "side": "all sides", "source": f"{webcam_vs_dslr.NAME}, {rec['environment']}"}
    slots = [rec if yaw == swept[0] else None for yaw in yaws]
    if not yaws:
        return [rec]
    return slots


def _working_lines(r: dict) -> list[str]:
    """A range-limit record as lines: the working range, the far limit's interval, how many
    frames decided it (sequential design), the failures nearer than the best range and the
    configuration."""
    lines = [r["working_range"], f"far limit 95 % interval: {r['far_interval']}"]
    if r.get("decision"):
        lines.append(r["decision"])
    if r.get("near_failures"):
        lines.append(r["failures_nearer"])
    where = f"{r['beacon'].upper()} {r['side']}" + ("" if r["side"] == "all sides" else " side")
    lines.append(f"{where}, {r['led_current_mA']:g} mA" + (f" ({r['source']})" if r.get("source") else ""))
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
    """The recommended drive and diffuser per side, as lines, and the first side's drive, mA."""
    if recommended.empty or cam not in set(recommended.camera):
        return ["not in brightness-diffuser"], None
    lines = []
    current = None
    for r in recommended[recommended.camera == cam].to_dict("records"):
        if r.get("window") == "empty":
            lines.append(f"{r['side']}: no setting tried keeps P ≥ 0.95 with cores < 50 % clipped")
            continue
        current = r["led_current_mA"] if current is None else current
        lines += [
            f"{r['side']}: {r['led_current_mA']:g} mA behind {r['diffuser']}",
            f"{r['led_power_mW']:.2g} mW per LED ({r['side_power_mW']:.2g} mW for the side)",
            f"{r['detected']} of {r['frames']} frames detected; {r['window']} in the window",
        ]
    return lines, current


def _colour_lines(wv: dict, cam: str, current: float | None) -> tuple[list[str], dict | None]:
    """Separability at the recommended drive where webcam-vs-dslr ran it, else at the
    camera's ranking drive."""
    seps = [s for s in wv.get("colour_separability", []) if s["camera"] == cam]
    if not seps:
        return ["not in webcam-vs-dslr"], None
    ranked = next((r["at_led_current_mA"] for r in wv.get("ranking", []) if r["camera"] == cam), None)
    sep = next((s for s in seps if s["led_current_mA"] == current), None) or next(
        (s for s in seps if s["led_current_mA"] == ranked), seps[0]
    )
    lines = [
        webcam_vs_dslr.separability_text(sep),
        f"{sep['right_colour']} of {sep['detections']} detections the right colour (at {sep['led_current_mA']:g} mA)",
    ]
    return lines, sep


def _verdict(records: list[dict], yaws: list[float]) -> list[str]:
    """Which camera, at what setting, how far: one sentence per camera, the one that
    reaches farthest at the largest yaw first (with its far limit's interval)."""
    ranged = [r for r in records if r.get("far_yaw_record") is not None or r.get("near_yaw_record") is not None]
    if not ranged:
        return ["No range results: the index cannot say how far any camera works."]
    lines = []
    for i, rec in enumerate(ranged):
        near, far = rec.get("near_yaw_record"), rec.get("far_yaw_record")
        slots = [(yaw, r) for yaw, r in zip(yaws or [0.0], (near, far), strict=False) if r is not None]
        if near is not None and far is not None and len(yaws) > 1 and near["working_range"] == far["working_range"]:
            reach = f"works {far['working_range']} at both {yaws[0]:g}° and {yaws[-1]:g}°"
        else:
            reach = "; ".join(
                (f"works {r['working_range']}" if r["max_range_m"] > 0 else "reaches P ≥ 0.95 at no range")
                + f" at {yaw:g}°"
                for yaw, r in slots
            )
        source = slots[-1][1].get("source")
        if source:
            reach += f" ({source} only)"
        if i == 0:
            reach += f" (far limit 95 % interval {slots[-1][1]['far_interval']})"
        if rec["led_current_mA"] is not None:
            setting = rec["led_setting_lines"][0] + f" ({rec['led_setting_lines'][1].split(' (')[0]})"
        else:
            setting = "no recommended setting"
        colour = rec["colour_lines"][0] if rec.get("colour_record") is not None else "not measured"
        head = rec["camera"]
        if i == 0 and far is not None and len(yaws) > 1:
            head = f"Farthest at {yaws[-1]:g}°: {rec['camera']}"
            ties = [
                o["camera"]
                for o in ranged[1:]
                if o.get("far_yaw_record") is not None
                and o["far_yaw_record"]["max_range_m"] == far["max_range_m"]
                and o["far_yaw_record"]["at_least"] == far["at_least"]
            ]
            if ties and far["max_range_m"] > 0:
                head += f" (tied with {', '.join(ties)})"
        lines.append(f"{head} {reach}. LED: {setting}. Colours: {colour}.")
    return lines


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
    few = "" if rl.get("design") or wv.get("design") else " With so few frames the intervals are wide:"
    return (
        "Evidence: " + "; ".join(parts) + f".{few} An interval from 0 m means the frames cannot exclude that "
        "no range reaches P ≥ 0.95 (that needs ≥ 59 correct frames in a row at one range); '≥' and '≤' mean the "
        "farthest or nearest range tried still worked. Working range: P(correct side, 5 markers numbered, range "
        "within 10 %, yaw within 5°) ≥ 0.95, best tracker."
    )


def write_index(out: Path, elapsed_s: float | None = None) -> dict:
    """Read ``out/<study>/summary.json`` of the three studies and write ``out/index.html``
    (answers first, then links) and ``out/answers.json``; returns the answers.

    Parameters
    ----------
    out : the main job's output directory.
    elapsed_s : the main job's wall time, s (printed when given).
    """
    out = Path(out)
    summaries = {}
    for name in STUDY_TITLES:
        path = out / name / "summary.json"
        if path.is_file():
            summaries[name] = json.loads(path.read_text())
    result = answers(summaries)
    yaws = result["yaws_deg"]
    labels = dict(ANSWER_LABELS)
    if yaws:
        labels["near_yaw"] = f"working range at {yaws[0]:g}°"
        labels["far_yaw"] = f"working range at {yaws[-1]:g}°"
    rep = Report("beacon-sim main job: which camera, what LED setting, how far")
    rep.lead(result["verdict"])
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
        rep.text(f"Finished in {elapsed_s:.0f} s.", note=True)
    rep.write(out / "index.html")
    atomic_write_bytes(out / "answers.json", json.dumps(strict_json(result), indent=2, allow_nan=False).encode())
    return result


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
    caption = "<p><b>Per camera (best tracker)</b></p>"
    return f"{caption}<table class='answers'><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
