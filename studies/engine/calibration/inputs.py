"""The calibration's inputs: the varying unknowns as a typed record, mapped to and from the unit cube.

Every point is held as its coordinates ``q`` in the unit hypercube ``[0, 1]^d`` (one dimension
per input), exactly as :func:`studies.engine.unknowns.sample` maps its scrambled Sobol' points:
a ``uniform`` input is ``low + q (high - low)``, a ``loguniform`` one is linear in ``log x``
(``low (high/low)^q``), and a ``choice`` input takes equal shares of its dimension (choice ``i``
of ``k`` for ``i/k <= q < (i+1)/k``).

The emulators see *features* rather than ``q``: the continuous coordinates as they are (so a
log-uniform input is emulated on the log scale) and each categorical input **one-hot** encoded.
One-hot rather than ordinal because the registry's choices (paper colours, spectral-sensitivity
sets, the tracked side) have no order: an ordinal code would tell a stationary kernel that the
first and third choice are further apart than the first and second, and would let the GP
interpolate between categories. One-hot keeps every pair of choices at the same distance up to
the per-column length scales the ARD kernel learns, and needs no emulator per category (which
would divide the design among the categories). A categorical input with many choices costs one
feature per choice.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from studies.engine.unknowns import Unknown

__all__ = ["Input", "InputSpace"]


@dataclass(frozen=True)
class Input:
    """One varying input of the simulator.

    Attributes
    ----------
    name
        Its name (the unknown's name in the registry).
    low, high
        Bounds of a continuous input, in ``unit``; None for a categorical one.
    log
        Whether the input is log-uniform (mapped to the unit interval on the log scale).
    choices
        The values of a categorical input; empty for a continuous one.
    unit
        Unit of the values (empty if dimensionless).
    """

    name: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    choices: tuple = ()
    unit: str = ""

    def __post_init__(self) -> None:
        if self.choices:
            if len(self.choices) < 2 or self.low is not None or self.high is not None or self.log:
                raise ValueError(f"{self.name}: a categorical input has >= 2 choices and no bounds")
            return
        if self.low is None or self.high is None or not (math.isfinite(self.low) and math.isfinite(self.high)):
            raise ValueError(f"{self.name}: a continuous input needs finite low and high")
        if not self.low < self.high:
            raise ValueError(f"{self.name}: needs low < high, got {self.low!r}, {self.high!r}")
        if self.log and self.low <= 0:
            raise ValueError(f"{self.name}: a log-scale input needs low > 0, got {self.low!r}")

    @property
    def categorical(self) -> bool:
        """Whether the input is a choice among values."""
        return bool(self.choices)

    @property
    def n_features(self) -> int:
        """Columns the input takes in the emulators' features (one per choice, else one)."""
        return len(self.choices) if self.choices else 1

    def choice_index(self, q: np.ndarray) -> np.ndarray:
        """Index of the choice at unit coordinates ``q`` (equal shares of the interval)."""
        k = len(self.choices)
        return np.minimum((np.asarray(q) * k).astype(int), k - 1)

    def from_unit(self, q: np.ndarray) -> list:
        """Values (plain Python) at unit coordinates ``q``."""
        q = np.clip(np.asarray(q, dtype=float), 0.0, 1.0)
        if self.categorical:
            return [self.choices[i] for i in self.choice_index(q)]
        if self.log:
            x = np.exp(math.log(self.low) + q * math.log(self.high / self.low))
        else:
            x = self.low + q * (self.high - self.low)
        return [float(v) for v in np.clip(x, self.low, self.high)]

    def to_unit(self, values: Iterable[Any]) -> np.ndarray:
        """Unit coordinates of ``values`` (a choice maps to the centre of its share)."""
        values = list(values)
        if self.categorical:
            k = len(self.choices)
            return np.array([(self.choices.index(v) + 0.5) / k for v in values], dtype=float)
        x = np.asarray(values, dtype=float)
        if self.log:
            return (np.log(x) - math.log(self.low)) / math.log(self.high / self.low)
        return (x - self.low) / (self.high - self.low)

    def to_json(self) -> dict:
        """The record as JSON-able values."""
        return {
            "name": self.name,
            "low": self.low,
            "high": self.high,
            "log": self.log,
            "choices": list(self.choices),
            "unit": self.unit,
        }

    @staticmethod
    def from_json(d: Mapping) -> Input:
        """The record from :meth:`to_json`'s values."""
        return Input(d["name"], d["low"], d["high"], bool(d["log"]), tuple(d["choices"]), d["unit"])


@dataclass(frozen=True)
class InputSpace:
    """The inputs, in order: dimension ``j`` of every unit-cube point is ``inputs[j]``."""

    inputs: tuple[Input, ...]

    def __post_init__(self) -> None:
        names = [i.name for i in self.inputs]
        if not names:
            raise ValueError("InputSpace: no inputs")
        if len(set(names)) != len(names):
            raise ValueError(f"InputSpace: duplicate input names in {names}")

    @staticmethod
    def from_unknowns(unknowns: Mapping[str, Unknown]) -> InputSpace:
        """The varying unknowns of a registry (:func:`studies.engine.unknowns.load_unknowns`), in its order.

        ``uniform`` → continuous, ``loguniform`` → continuous on the log scale, ``choice`` →
        categorical; ``fixed`` unknowns are not inputs (the caller holds them at their nominal).
        """
        out = []
        for u in unknowns.values():
            if u.kind == "fixed":
                continue
            if u.kind == "choice":
                out.append(Input(u.name, choices=tuple(u.choices), unit=u.unit))
            else:
                out.append(Input(u.name, u.low, u.high, log=u.kind == "loguniform", unit=u.unit))
        return InputSpace(tuple(out))

    @property
    def names(self) -> tuple[str, ...]:
        """The inputs' names, in dimension order."""
        return tuple(i.name for i in self.inputs)

    @property
    def dim(self) -> int:
        """Dimensions of the unit cube."""
        return len(self.inputs)

    @property
    def n_features(self) -> int:
        """Columns of :meth:`features`."""
        return sum(i.n_features for i in self.inputs)

    def features(self, q: np.ndarray) -> np.ndarray:
        """The emulators' inputs at unit points ``q`` (n, d): continuous coordinates, categoricals one-hot."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != self.dim:
            raise ValueError(f"features: expected points with {self.dim} coordinates, got {q.shape[1]}")
        columns = []
        for j, inp in enumerate(self.inputs):
            if inp.categorical:
                columns.append(np.eye(len(inp.choices))[inp.choice_index(q[:, j])])
            else:
                columns.append(q[:, j : j + 1])
        return np.hstack(columns)

    def values(self, q: np.ndarray) -> list[dict[str, Any]]:
        """The points as name → value dicts (the form :func:`studies.engine.unknowns.apply` takes)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        columns = {inp.name: inp.from_unit(q[:, j]) for j, inp in enumerate(self.inputs)}
        return [{name: columns[name][i] for name in self.names} for i in range(q.shape[0])]

    def to_unit(self, values: Sequence[Mapping[str, Any]]) -> np.ndarray:
        """Unit points (n, d) of name → value dicts."""
        return np.column_stack([inp.to_unit([v[inp.name] for v in values]) for inp in self.inputs])

    def to_json(self) -> list[dict]:
        """The inputs as JSON-able values."""
        return [i.to_json() for i in self.inputs]

    @staticmethod
    def from_json(items: Sequence[Mapping]) -> InputSpace:
        """The space from :meth:`to_json`'s values."""
        return InputSpace(tuple(Input.from_json(d) for d in items))
