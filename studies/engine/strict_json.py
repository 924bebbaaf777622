"""Standard JSON (RFC 8259) for every file the program writes: no bare ``NaN`` or ``Infinity``.

Python's :func:`json.dumps` writes non-finite floats as ``NaN``/``Infinity`` by default, which
is not JSON (JavaScript's ``JSON.parse`` and most strict parsers refuse it). Every writer goes
through :func:`dumps`, which writes each non-finite float as ``null``. Where an infinity means
something (a far limit's interval "open above", colour samples that do not overlap) the record
carries that meaning in a field of its own beside the number (``high_open``,
``no_overlap``), so readers never need the infinity back.

Task records (``<out>/tasks/``) must give back exactly the rows that were stored, NaN included,
so :func:`encode_non_finite` also lists where the non-finite values were
(``[path..., "nan" | "inf" | "-inf"]``) and :func:`decode_non_finite` puts them back.
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["decode_non_finite", "dumps", "encode_non_finite", "strict_json"]


def strict_json(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, ±inf) replaced by None, recursively through
    dicts, lists and tuples (tuples become lists).

    Parameters
    ----------
    value : any JSON-able value.

    Returns
    -------
    The same structure, writable with ``json.dumps(..., allow_nan=False)``.
    """
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value


def dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`strict_json` (``value``) with ``allow_nan=False``: standard JSON.

    Parameters
    ----------
    value : any JSON-able value.
    **kwargs : passed to :func:`json.dumps` (``indent``, ``sort_keys``, ...).
    """
    return json.dumps(strict_json(value), allow_nan=False, **kwargs)


def _name(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")


def encode_non_finite(value: Any) -> tuple[Any, list[list]]:
    """``value`` as :func:`strict_json` writes it, and where its non-finite floats were.

    Returns
    -------
    ``(clean, places)``: ``clean`` has None at each non-finite float; ``places`` lists each one
    as its path of keys and indices followed by ``"nan"``, ``"inf"`` or ``"-inf"``.
    """
    places: list[list] = []

    def walk(v: Any, path: list) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            places.append([*path, _name(v)])
            return None
        if isinstance(v, dict):
            return {k: walk(x, [*path, k]) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [walk(x, [*path, i]) for i, x in enumerate(v)]
        return v

    return walk(value, []), places


def decode_non_finite(clean: Any, places: list[list]) -> Any:
    """Undo :func:`encode_non_finite` in place: put each listed non-finite float back; returns ``clean``."""
    for place in places:
        *path, name = place
        target = clean
        for step in path[:-1]:
            target = target[step]
        target[path[-1]] = float(name)
    return clean
