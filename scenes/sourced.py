"""Data files whose every number says where it comes from.

A data file is TOML. Each physical quantity is written as an inline table
``{ value = 624, source = "Cree data sheet CLD-CT011.000, typical λD at 20 mA" }`` or
``{ value = 0.5, assumed = "why this value is reasonable" }``. :func:`load_sourced`
checks that every such entry has exactly one of ``source`` / ``assumed`` and returns
the plain values, so a data file without provenance fails loudly when loaded.
Plain strings and booleans (names, part numbers) need no provenance.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any


class DataFileError(ValueError):
    """A data file is malformed or a number in it has no provenance."""


def _strip(node: Any, where: str, provenance: dict[str, str]) -> Any:
    if isinstance(node, dict):
        if "value" in node:
            has = [k for k in ("source", "assumed") if k in node]
            if len(has) != 1:
                raise DataFileError(f"{where}: needs exactly one of 'source' or 'assumed'")
            provenance[where] = f"{has[0]}: {node[has[0]]}"
            return node["value"]
        return {k: _strip(v, f"{where}.{k}" if where else k, provenance) for k, v in node.items()}
    if isinstance(node, list):
        return [_strip(v, f"{where}[{i}]", provenance) for i, v in enumerate(node)]
    if isinstance(node, bool | str):
        return node
    if isinstance(node, int | float):
        raise DataFileError(f"{where}: number {node!r} has no 'source' or 'assumed' note")
    return node


def load_sourced(path: str | Path) -> tuple[dict[str, Any], dict[str, str]]:
    """Load a data file; return (values, provenance by dotted key)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read data file ({exc})") from exc
    provenance: dict[str, str] = {}
    values = _strip(raw, "", provenance)
    return values, provenance


DATA_DIR = Path(__file__).resolve().parent / "data"
