"""Data files whose every number says where it comes from.

A data file is TOML. Each physical quantity is written as an inline table
``{ value = 624, source = "Cree data sheet CLD-CT011.000, typical λD at 20 mA" }`` or
``{ value = 0.5, assumed = "why this value is reasonable" }``. :func:`load_sourced`
checks that every such entry has exactly one of ``source`` / ``assumed`` and returns
the plain values, so a data file without provenance fails loudly when loaded.
Plain strings and booleans (names, part numbers) need no provenance.
"""

from __future__ import annotations

import difflib
import re
import tomllib
from pathlib import Path
from typing import Any

__all__ = [
    "DATA_DIR",
    "MAX_NESTING",
    "DataFileError",
    "Fields",
    "check_dotted_keys",
    "dotted_key_parts",
    "load_sourced",
    "load_tables",
    "loads_sourced",
]

VALUE_KEYS = ("value", "source", "assumed")
"""The keys of a number's inline table: the value and one of the two provenance notes."""


class DataFileError(ValueError):
    """A data file is malformed or a number in it has no provenance."""


def _strip(node: Any, where: str, provenance: dict[str, str]) -> Any:
    if isinstance(node, dict):
        if "value" in node:
            has = [k for k in ("source", "assumed") if k in node]
            if len(has) != 1:
                raise DataFileError(f"{where}: needs exactly one of 'source' or 'assumed'")
            extra = [k for k in node if k not in VALUE_KEYS]
            if extra:
                raise DataFileError(f"{where}.{extra[0]}: {_unknown(extra[0], VALUE_KEYS)}")
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


_PLAIN = re.compile(r"[^\"'#]+")
_BASIC = re.compile(r'(?:[^"\\\n]|\\.)*"')
_MULTILINE_BASIC = re.compile(r'(?:[^"\\]|\\.|"(?!""))*"""', re.DOTALL)
_DOTTED = re.compile(r"[A-Za-z0-9_-]+(?:[ \t]*\.[ \t]*[A-Za-z0-9_-]+)*")  # no backtracking: linear


def _without_strings(text: str) -> str:
    """``text`` with every TOML string replaced by ``s`` and comments removed, in one linear pass
    (what is left of an unterminated string is dropped: the parser reports it)."""
    out, pos, end = [], 0, len(text)
    while pos < end:
        plain = _PLAIN.match(text, pos)
        if plain:
            out.append(plain.group())
            pos = plain.end()
            continue
        if text.startswith('"""', pos):
            closing = _MULTILINE_BASIC.match(text, pos + 3)
            stop = closing.end() if closing else -1
        elif text.startswith("'''", pos):
            found = text.find("'''", pos + 3)
            stop = found + 3 if found >= 0 else -1
        elif text[pos] == '"':
            closing = _BASIC.match(text, pos + 1)
            stop = closing.end() if closing else -1
        elif text[pos] == "'":
            found = text.find("'", pos + 1)
            stop = found + 1 if found >= 0 and text.find("\n", pos + 1, found) < 0 else -1
        else:  # a comment, to the end of its line
            newline = text.find("\n", pos)
            stop = newline if newline >= 0 else end
            out.append(" ")
            pos = stop
            continue
        if stop < 0:
            break
        out.append(" s ")
        pos = stop
    return "".join(out)


def dotted_key_parts(text: str) -> int:
    """The most parts of any dotted key in the TOML ``text`` (``a.b.c``: 3; 1 without dots).

    Python's ``tomllib`` takes time and memory quadratic in the parts of a dotted key (a key of
    10 000 parts, 20 kB of text, takes 400 MB; 100 000 parts take 40 GB), so a file is checked
    with this linear scan before it is parsed. Numbers such as ``1.5`` count as two parts,
    strings (quoted keys included) as one.
    """
    return max((m.group().count(".") + 1 for m in _DOTTED.finditer(_without_strings(text))), default=1)


def check_dotted_keys(text: str, label: str) -> None:
    """Raise :class:`DataFileError` when a dotted key of ``text`` has more than :data:`MAX_NESTING` parts."""
    parts = dotted_key_parts(text)
    if parts > MAX_NESTING:
        raise DataFileError(
            f"{label}: expected tables and arrays nested at most {MAX_NESTING} deep, got a dotted key of {parts} parts"
        )


def load_tables(path: str | Path, what: str) -> dict[str, Any]:
    """A TOML file of named tables (a registry: ``what`` names its entries in errors), read whole;
    :class:`DataFileError` in one line when it cannot be read or holds none."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read {what} ({str(exc).splitlines()[0]})") from exc
    if not raw:
        raise DataFileError(f"{path}: no {what}")
    return raw


def load_sourced(path: str | Path) -> tuple[dict[str, Any], dict[str, str]]:
    """Load a data file; return (values, provenance by dotted key)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{path}: cannot read data file ({exc})") from exc
    return loads_sourced(text, str(path))


def loads_sourced(text: str, label: str) -> tuple[dict[str, Any], dict[str, str]]:
    """:func:`load_sourced` of a data file's text; errors name the file as ``label``."""
    check_dotted_keys(text, label)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DataFileError(f"{label}: cannot read data file ({exc})") from exc
    except RecursionError:
        raw = None
    if raw is None or nesting_depth(raw) > MAX_NESTING:
        raise DataFileError(f"{label}: expected tables and arrays nested at most {MAX_NESTING} deep, got deeper")
    provenance: dict[str, str] = {}
    try:
        values = _strip(raw, "", provenance)
    except DataFileError as exc:
        raise DataFileError(f"{label}: {exc}") from None
    except RecursionError:
        raise DataFileError(f"{label}: cannot read data file (nested too deeply)") from None
    return values, provenance


def _unknown(key: str, valid) -> str:
    """``unknown field (did you mean 'x'?)``, or the valid names when none is close."""
    valid = sorted(set(valid))
    near = difflib.get_close_matches(key, valid, n=1)
    if near:
        return f"unknown field (did you mean {near[0]!r}?)"
    return f"unknown field (expected one of {', '.join(valid)})" if valid else "unknown field (expected none here)"


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

    def __init__(self, values: dict[str, Any], file: str, prefix: str = "", *, _asked=None) -> None:
        self.values, self.file, self.prefix = values, file, prefix
        # fields asked for, by table (prefix), shared by every Fields of one file: what
        # check_known compares the file's keys with
        self._asked: dict[str, tuple[dict, set[str]]] = {} if _asked is None else _asked
        self._asked.setdefault(prefix, (values, set()))

    def _mark(self, key: str) -> None:
        self._asked[self.prefix][1].add(key)

    def _fail(self, key: str, expected: str, got: object) -> DataFileError:
        return DataFileError(f"{self.file}: {self.prefix}{key}: expected {expected}, got {got!r}")

    def has(self, key: str) -> bool:
        """Whether the table has ``key`` (``key`` is then a field this table may hold)."""
        self._mark(key)
        return key in self.values

    def _get(self, key: str, default: object, expected: str) -> Any:
        self._mark(key)
        if key in self.values:
            return self.values[key]
        if default is _MISSING:
            raise self._fail(key, expected, "nothing (missing)")
        return default

    def _child(self, values: dict, prefix: str) -> Fields:
        return Fields(values, self.file, prefix, _asked=self._asked)

    def table(self, key: str, default: object = _MISSING) -> Fields:
        """The sub-table ``key``."""
        value = self._get(key, default, "a table")
        if not isinstance(value, dict):
            raise self._fail(key, "a table", value)
        return self._child(value, f"{self.prefix}{key}.")

    def tables(self, key: str) -> list[Fields]:
        """The list of tables ``key`` (``[[key]]``; none when missing)."""
        value = self._get(key, [], "a list of tables ([[...]])")
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self._fail(key, "a list of tables ([[...]])", value)
        return [self._child(v, f"{self.prefix}{key}[{i}].") for i, v in enumerate(value)]

    def raw(self, key: str, default: object = _MISSING) -> Any:
        """The value ``key`` unchecked (the caller checks it)."""
        return self._get(key, default, "a value")

    def flag(self, key: str, default: object = _MISSING) -> bool:
        """The boolean ``key``."""
        value = self._get(key, default, "true or false")
        if not isinstance(value, bool):
            raise self._fail(key, "true or false", value)
        return value

    def check_known(self, within: str | None = None) -> None:
        """Raise on the first field no accessor asked for (a misspelt or unknown key), naming it
        and the nearest field the table may hold (``difflib``).

        Parameters
        ----------
        within
            Check only the tables whose dotted path starts with this (default: this table
            and every table below it that was read).
        """
        within = self.prefix if within is None else within
        for prefix, (values, asked) in self._asked.items():
            if not prefix.startswith(within):
                continue
            for key in values:
                if key not in asked:
                    raise DataFileError(f"{self.file}: {prefix}{key}: {_unknown(key, asked)}")

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
        reason: str | None = None,
    ) -> float:
        """The finite number ``key`` (a float, or an int when ``integer``) within the bounds;
        ``reason`` says why the bounds are what they are (in the error, in brackets)."""
        expected = _number_words(minimum, maximum, positive, integer) + (f" ({reason})" if reason else "")
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
