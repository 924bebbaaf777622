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


MAX_NESTING = 16
"""Deepest nesting of tables and arrays a data file may have (the package's files use 3; a
file nested thousands deep would exhaust Python's recursion in the readers)."""


def nesting_depth(value: object) -> int:
    """How deeply tables (dicts) and arrays (lists) nest in ``value`` (0 for a scalar), counted without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list | tuple) else None
        if children is None:
            continue
        deepest = max(deepest, depth + 1)
        stack.extend((child, depth + 1) for child in children)
    return deepest


def load_sourced(path: str | Path) -> tuple[dict[str, Any], dict[str, str]]:
    """Load a data file; return (values, provenance by dotted key)."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read data file ({exc})") from exc
    except RecursionError:
        raw = None
    if raw is None or nesting_depth(raw) > MAX_NESTING:
        raise DataFileError(f"{path}: expected tables and arrays nested at most {MAX_NESTING} deep, got deeper")
    provenance: dict[str, str] = {}
    try:
        values = _strip(raw, "", provenance)
    except DataFileError as exc:
        raise DataFileError(f"{path}: {exc}") from None
    return values, provenance


DATA_DIR = Path(__file__).resolve().parent / "data"


_MISSING = object()


class Fields:
    """Checked access to the values of one table of a data file.

    Every accessor names the file and the dotted field in its error, in one line
    (``camera file rpi.toml: geometry.pixel_pitch_um: expected a number > 0, got -1``),
    so a hand-written hardware file is checked field by field before any work.

    Parameters
    ----------
    values
        The table's plain values (as :func:`load_sourced` returns them).
    file
        How errors name the file.
    prefix
        Dotted path of this table inside the file ("" for the top level).
    """

    def __init__(self, values: dict[str, Any], file: str, prefix: str = "") -> None:
        self.values, self.file, self.prefix = values, file, prefix

    def _fail(self, key: str, expected: str, got: object) -> DataFileError:
        return DataFileError(f"{self.file}: {self.prefix}{key}: expected {expected}, got {got!r}")

    def has(self, key: str) -> bool:
        """Whether the table has ``key``."""
        return key in self.values

    def _get(self, key: str, default: object, expected: str) -> Any:
        if key in self.values:
            return self.values[key]
        if default is _MISSING:
            raise self._fail(key, expected, "nothing (missing)")
        return default

    def table(self, key: str, default: object = _MISSING) -> Fields:
        """The sub-table ``key``."""
        value = self._get(key, default, "a table")
        if not isinstance(value, dict):
            raise self._fail(key, "a table", value)
        return Fields(value, self.file, f"{self.prefix}{key}.")

    def text(self, key: str, choices: tuple[str, ...] | None = None, default: object = _MISSING) -> str:
        """The string ``key``, one of ``choices`` when given."""
        expected = f"one of {', '.join(choices)}" if choices else "a string"
        value = self._get(key, default, expected)
        if not isinstance(value, str) or (choices and value not in choices):
            raise self._fail(key, expected, value)
        return value

    def number(
        self,
        key: str,
        *,
        minimum: float | None = None,
        maximum: float | None = None,
        positive: bool = False,
        integer: bool = False,
        default: object = _MISSING,
    ) -> float:
        """The finite number ``key`` (a float, or an int when ``integer``) within the bounds."""
        expected = _number_words(minimum, maximum, positive, integer)
        value = self._get(key, default, expected)
        if not _in_bounds(value, minimum, maximum, positive, integer):
            raise self._fail(key, expected, value)
        return int(value) if integer else float(value)

    def numbers(
        self, key: str, *, length: int | None = None, minimum: float | None = None, positive: bool = False
    ) -> tuple[float, ...]:
        """The list of finite numbers ``key`` (of ``length`` items when given)."""
        words = _number_words(minimum, None, positive, False).replace("a number", "numbers")
        expected = f"a list of {length or 'one or more'} {words}"
        value = self._get(key, _MISSING, expected)
        if (
            not isinstance(value, list)
            or not value
            or (length is not None and len(value) != length)
            or not all(_in_bounds(v, minimum, None, positive, False) for v in value)
        ):
            raise self._fail(key, expected, value)
        return tuple(float(v) for v in value)


def _number_words(minimum, maximum, positive, integer) -> str:
    bounds = ["> 0"] if positive else []
    if minimum is not None:
        bounds.append(f">= {minimum:g}")
    if maximum is not None:
        bounds.append(f"<= {maximum:g}")
    return ("an integer" if integer else "a number") + (" " + " and ".join(bounds) if bounds else "")


def _in_bounds(value, minimum, maximum, positive, integer) -> bool:
    if isinstance(value, bool) or not isinstance(value, int | float) or value != value or abs(value) == float("inf"):
        return False
    if integer and float(value) != int(value):
        return False
    return not (
        (positive and value <= 0)
        or (minimum is not None and value < minimum)
        or (maximum is not None and value > maximum)
    )
