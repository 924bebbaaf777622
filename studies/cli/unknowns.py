"""The ``unknowns`` command: the inputs the source study did not give, with their ranges and reasons
(``studies/data/unknowns.toml``; a table, or ``--json``)."""

from __future__ import annotations

from studies.cli import options as opt
from studies.cli.common import print_table
from studies.engine import strict_json
from studies.engine.unknowns import load_unknowns

__all__ = ["COMMANDS", "unknown_rows", "unknowns"]


def unknown_rows() -> list[dict]:
    """Every unknown as plain data: name, target, kind, range, nominal, unit, cameras, how it acts, reason."""
    registry = load_unknowns()
    return [
        {
            "name": u.name,
            "target": u.target,
            "kind": u.kind,
            "low": u.low,
            "high": u.high,
            "choices": list(u.choices),
            "range": u.describe_range(),
            "nominal": u.nominal,
            "unit": u.unit,
            "cameras": list(u.cameras),
            "acts": u.acts,
            "provenance": u.provenance,
        }
        for u in registry.values()
    ]


def unknowns(json_out: opt.Json = False) -> None:
    """List the unknowns: what the source study did not give, its range and why (any run can fix or sample them)."""
    rows = unknown_rows()
    if json_out:
        print(strict_json.dumps(rows, indent=2, ensure_ascii=False))
        return
    print_table(
        "Unknowns (studies/data/unknowns.toml; every one settable per frame task. Acts: gain = rescales a "
        "render exactly, render = changes the scene rendered, camera = the camera model)",
        ("name", "target", "range", "nominal", "cameras", "acts", "source / assumed"),
        [
            (
                r["name"],
                r["target"],
                r["range"],
                _text(r["nominal"]),
                ", ".join(r["cameras"]) or "all",
                r["acts"],
                r["provenance"],
            )
            for r in rows
        ],
    )


def _text(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    return f"{value:g}" if isinstance(value, float) else str(value)


COMMANDS = {"unknowns": unknowns}
