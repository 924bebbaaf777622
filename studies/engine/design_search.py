"""The design search: a resumable, deterministic multi-objective search over a design space.

Generic: the caller gives the design space (:class:`DesignSpace`, every parameter with its unit
and where its range comes from), the metrics its ``evaluate(design) -> {metric: value}`` returns
(:class:`Metric`), the objectives (:class:`Objective`: a metric to maximise or minimise) and the
constraints (:class:`Constraint`: ``metric <= bound`` or ``metric >= bound``). :func:`search`
asks optuna's multivariate TPE sampler (MOTPE for several objectives) for designs one batch at a
time, evaluates them and tells optuna the results; the Pareto front is optuna's own
(``Study.best_trials``, feasible trials only). Nothing here optimises or sorts by hand.

Constraints reach optuna as named constraint values (``Trial.set_constraint``, the replacement
of the ``constraints_func`` that optuna 5 deprecates): feasible when ``<= 0``, so
``metric >= bound`` is told as ``bound - metric``. An infeasible design is never on the front.
When no evaluated design meets the constraints the result says so (``feasible == 0`` and a
sentence naming the constraint never met); when a constraint cannot be met at all given the
bounds the caller declared for its metric, :func:`search` says so at once and evaluates nothing.

Resumable and deterministic
---------------------------
The search lives in ``<out>/search.journal`` (optuna's ``JournalStorage`` on a
``JournalFileBackend``: one JSON line per change, appended and fsynced), together with what
defines it (space, metrics, objectives, constraints, seed, batch size, sampler settings, the
caller's ``context`` and the optuna version). A search stopped at any point (Ctrl-C, a kill, an
``evaluate`` that raised) continues with ``resume=True``; resuming with anything that defines the
search changed is a one-line error naming the first difference, and starting without ``resume``
on a folder that holds a search is a one-line error (partial results are never overwritten).

Optuna does not store its sampler's random state, so the sampler is made afresh for every design:
evaluation ``i`` is drawn by ``TPESampler(seed=trial_seed(seed, i))`` on an in-memory mirror of
the search holding exactly the evaluations before ``i``'s batch (in evaluation order) and the
designs already asked in the batch. That mirror is rebuilt from the journal on resume, so design
``i`` is a function of the seed, ``i``, the batch size and the evaluations before its batch
only: a search stopped after k evaluations and resumed to N gives the same N evaluations, and
the same front, as one run to N without a stop. A trial that was running when the search
stopped is marked failed in the journal on resume and its evaluation redone; the
numbering of optuna's trials in the journal may therefore skip, the evaluation index
(``trial`` in the results) does not.

An evaluation whose objective or constraint metrics are not all finite counts as an evaluation
(it is in the trials, ``status`` ``non-finite``, never feasible) but the sampler learns nothing
from it (optuna cannot rank a NaN).

Parallel evaluation
-------------------
``workers > 1`` asks ``workers`` designs at once (each with its own seeded sampler, seeing the
same history and the designs asked before it in the batch, as running trials), evaluates them
in a process pool (``evaluate`` must then be a module-level function) and tells them in order.
The batch size shapes which designs are drawn, so it is part of what defines the search:
``workers=4`` gives other designs than ``workers=1`` (each deterministic), and a search cannot
be resumed with another ``workers``.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import optuna
import pandas as pd
from optuna.distributions import BaseDistribution, CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import TrialState, create_trial

from scenes.render_cache import atomic_write_bytes
from studies.engine.runner import stop_pool, worker_start, worker_threads
from studies.engine.strict_json import decode_non_finite, dumps, encode_non_finite

__all__ = [
    "DIRECTIONS",
    "JOURNAL_NAME",
    "OPERATORS",
    "PARAM_KINDS",
    "Constraint",
    "DesignSpace",
    "FrontPoint",
    "Metric",
    "Objective",
    "Param",
    "Progress",
    "SearchResult",
    "choice_param",
    "float_param",
    "int_param",
    "search",
    "trial_seed",
    "write_results",
]

PARAM_KINDS = ("float", "int", "choice")
"""Kinds of design parameter: a real number in [low, high] (optionally log-uniform), an integer
in [low, high], or one of a set of values."""

DIRECTIONS = ("maximize", "minimize")
"""Directions of an objective (optuna's spelling)."""

OPERATORS = ("<=", ">=")
"""Operators of a constraint ``metric <op> bound``."""

JOURNAL_NAME = "search.journal"
"""The search's optuna journal in the caller's ``out`` folder."""

STUDY_NAME = "design-search"
"""The optuna study's name in the journal."""

FORMAT = 1
"""Version of what the journal's study records (``spec``) and of ``summary.json``."""

RESERVED_COLUMNS = ("trial", "feasible", "violation", "status", "on_front")
"""Columns of the trials table besides the parameters and metrics: no parameter or metric may
take these names."""

CHOICE_TYPES = (str, int, float, bool)
"""Types a choice's values may have (JSON scalars, columns of a CSV)."""


def _number(x: Any) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool | np.bool_)


def _integer(x: Any) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool | np.bool_)


def _nearest(word: str, options: Iterable[str]) -> str:
    options = list(options)
    close = difflib.get_close_matches(word, options, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"expected one of {', '.join(repr(o) for o in options)}{hint}"


def _name_check(where: str, name: Any) -> None:
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"{where}: expected a name (letters, digits, underscores), got {name!r}")
    if name in RESERVED_COLUMNS:
        raise ValueError(f"{where}: {name!r} is a column of the trials table (reserved: {', '.join(RESERVED_COLUMNS)})")


# --- the design space ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Param:
    """One design parameter and where its range comes from.

    Attributes
    ----------
    name
        Its name (an identifier; the key in a design, a column of the trials table). Put the
        unit in the name where it has one, as the project does (``offset_mm``).
    kind
        ``"float"`` (a real number in [low, high]), ``"int"`` (an integer in [low, high]) or
        ``"choice"`` (one of ``values``).
    low, high
        Bounds in ``unit``, both included; ``low < high``. None for a choice.
    log
        Draw on the log scale (``low > 0`` for a float, ``low >= 1`` for an int): for a quantity
        that varies by factors (a drive current, a focal length).
    values
        The values of a choice (at least 2, distinct; strings, numbers or booleans); empty otherwise.
    unit
        Unit of the values (empty if dimensionless or a choice).
    source, assumed
        Exactly one: where the range or the values come from (a data sheet, a drawing), or why
        they are reasonable.
    """

    name: str
    kind: str
    low: float | int | None = None
    high: float | int | None = None
    log: bool = False
    values: tuple = ()
    unit: str = ""
    source: str = ""
    assumed: str = ""

    def __post_init__(self) -> None:
        _name_check("space: parameter name", self.name)
        where = f"space.{self.name}"
        if self.kind not in PARAM_KINDS:
            raise ValueError(f"{where}.kind: {_nearest(str(self.kind), PARAM_KINDS)}, got {self.kind!r}")
        if not isinstance(self.log, bool):
            raise ValueError(f"{where}.log: expected true or false, got {self.log!r}")
        for key in ("unit", "source", "assumed"):
            if not isinstance(getattr(self, key), str):
                raise ValueError(f"{where}.{key}: expected a string, got {getattr(self, key)!r}")
        reasons = [key for key in ("source", "assumed") if getattr(self, key).strip()]
        if len(reasons) != 1:
            got = "both" if reasons else "neither"
            raise ValueError(
                f"{where}: needs exactly one of 'source' or 'assumed' (where the range comes from), got {got}"
            )
        if self.kind == "choice":
            self._check_choice(where)
        else:
            self._check_range(where)

    def _check_choice(self, where: str) -> None:
        for key in ("low", "high"):
            if getattr(self, key) is not None:
                raise ValueError(f"{where}.{key}: a choice has values, not bounds")
        if self.log:
            raise ValueError(f"{where}.log: a choice has no scale")
        if isinstance(self.values, str | bytes) or not isinstance(self.values, Sequence):
            raise ValueError(f"{where}.values: expected a list of values, got {self.values!r}")
        values = tuple(self.values)
        if len(values) < 2:
            raise ValueError(f"{where}.values: expected at least 2 values, got {len(values)}")
        for i, v in enumerate(values):
            if not isinstance(v, CHOICE_TYPES) or (isinstance(v, float) and not math.isfinite(v)):
                raise ValueError(f"{where}.values[{i}]: expected a string, a finite number or a boolean, got {v!r}")
        for i, v in enumerate(values):
            if any(type(v) is type(w) and v == w for w in values[:i]):
                raise ValueError(f"{where}.values[{i}]: {v!r} is listed twice")
        object.__setattr__(self, "values", values)

    def _check_range(self, where: str) -> None:
        if self.values:
            raise ValueError(f"{where}.values: a {self.kind} parameter has low and high, not values")
        integer = self.kind == "int"
        for key in ("low", "high"):
            x = getattr(self, key)
            if x is None:
                raise ValueError(f"{where}.{key}: missing (a {self.kind} parameter needs low and high)")
            if integer and not _integer(x):
                raise ValueError(f"{where}.{key}: expected an integer, got {x!r}")
            if not _number(x) or not math.isfinite(x):
                raise ValueError(f"{where}.{key}: expected a finite number, got {x!r}")
            object.__setattr__(self, key, int(x) if integer else float(x))
        if not self.low < self.high:
            raise ValueError(f"{where}.low: expected a number < high, got {self.low!r} >= {self.high!r}")
        if self.log and (self.low < 1 if integer else self.low <= 0):
            need = ">= 1" if integer else "> 0"
            raise ValueError(f"{where}.low: a log-scale parameter needs low {need}, got {self.low!r}")

    @property
    def reason(self) -> str:
        """``"source: …"`` or ``"assumed: …"``: where the range comes from."""
        return f"source: {self.source}" if self.source.strip() else f"assumed: {self.assumed}"

    def distribution(self) -> BaseDistribution:
        """The parameter as an optuna distribution."""
        if self.kind == "float":
            return FloatDistribution(self.low, self.high, log=self.log)
        if self.kind == "int":
            return IntDistribution(self.low, self.high, log=self.log)
        return CategoricalDistribution(self.values)

    def describe(self) -> str:
        """One line: ``offset_mm in [2, 20] mm (log)`` or ``led in {'a', 'b'}``."""
        if self.kind == "choice":
            return f"{self.name} in {{{', '.join(repr(v) for v in self.values)}}}"
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name} in [{self.low:g}, {self.high:g}]{unit}{' (log)' if self.log else ''}"

    def to_dict(self) -> dict:
        """The parameter as a JSON-able table (what :meth:`DesignSpace.from_dict` reads), without its name."""
        d: dict[str, Any] = {"kind": self.kind}
        if self.kind == "choice":
            d["values"] = list(self.values)
        else:
            d.update(low=self.low, high=self.high, log=self.log)
        if self.unit:
            d["unit"] = self.unit
        if self.source.strip():
            d["source"] = self.source
        else:
            d["assumed"] = self.assumed
        return d


PARAM_KEYS = ("kind", "low", "high", "log", "values", "unit", "source", "assumed")
"""Keys of a parameter's table in :meth:`DesignSpace.from_dict`."""


def float_param(
    name: str, low: float, high: float, *, unit: str = "", log: bool = False, source: str = "", assumed: str = ""
) -> Param:
    """A real parameter in [low, high] ``unit`` (log-uniform with ``log``); one of ``source``/``assumed``."""
    return Param(name, "float", low, high, log=log, unit=unit, source=source, assumed=assumed)


def int_param(
    name: str, low: int, high: int, *, unit: str = "", log: bool = False, source: str = "", assumed: str = ""
) -> Param:
    """An integer parameter in [low, high] ``unit``; one of ``source``/``assumed``."""
    return Param(name, "int", low, high, log=log, unit=unit, source=source, assumed=assumed)


def choice_param(name: str, values: Sequence, *, unit: str = "", source: str = "", assumed: str = "") -> Param:
    """A parameter taking one of ``values``; one of ``source``/``assumed``."""
    return Param(name, "choice", values=tuple(values), unit=unit, source=source, assumed=assumed)


@dataclass(frozen=True)
class DesignSpace:
    """The design parameters, in order (the order of the columns and of a design's keys).

    Attributes
    ----------
    params
        The parameters (at least one, distinct names).
    """

    params: tuple[Param, ...]

    def __post_init__(self) -> None:
        if isinstance(self.params, Param) or not isinstance(self.params, Iterable):
            raise ValueError(f"space: expected a sequence of parameters, got {self.params!r}")
        params = tuple(self.params)
        if not params:
            raise ValueError("space: expected at least one parameter, got none")
        seen: set[str] = set()
        for i, p in enumerate(params):
            if not isinstance(p, Param):
                raise ValueError(f"space: parameter {i}: expected a Param, got {p!r}")
            if p.name in seen:
                raise ValueError(f"space.{p.name}: defined twice")
            seen.add(p.name)
        object.__setattr__(self, "params", params)

    @staticmethod
    def from_dict(table: Mapping[str, Mapping[str, Any]]) -> DesignSpace:
        """A space from plain tables (a TOML file's or :meth:`to_dict`'s), one per parameter::

            {"offset_mm": {"kind": "float", "low": 2, "high": 20, "unit": "mm", "source": "…"},
             "led": {"kind": "choice", "values": ["a", "b"], "assumed": "…"}}

        Raises
        ------
        ValueError
            One line naming the field (``space.offset_mm.low: missing …``); a key no parameter
            has is named with the nearest valid key.
        """
        if not isinstance(table, Mapping):
            raise ValueError(f"space: expected a table of parameters, got {table!r}")
        params = []
        for name, entry in table.items():
            if not isinstance(entry, Mapping):
                raise ValueError(f"space.{name}: expected a table (kind, low, high, ...), got {entry!r}")
            for key in entry:
                if key not in PARAM_KEYS:
                    raise ValueError(f"space.{name}.{key}: unknown key ({_nearest(str(key), PARAM_KEYS)})")
            if "kind" not in entry:
                raise ValueError(f"space.{name}.kind: missing (one of {', '.join(PARAM_KINDS)})")
            values = entry.get("values", ())
            params.append(
                Param(
                    name,
                    entry["kind"],
                    entry.get("low"),
                    entry.get("high"),
                    log=entry.get("log", False),
                    values=tuple(values) if isinstance(values, list | tuple) else values,
                    unit=entry.get("unit", ""),
                    source=entry.get("source", ""),
                    assumed=entry.get("assumed", ""),
                )
            )
        return DesignSpace(tuple(params))

    def to_dict(self) -> dict[str, dict]:
        """The space as JSON-able tables (what :meth:`from_dict` reads)."""
        return {p.name: p.to_dict() for p in self.params}

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names, in order."""
        return tuple(p.name for p in self.params)

    def distributions(self) -> dict[str, BaseDistribution]:
        """Name → optuna distribution."""
        return {p.name: p.distribution() for p in self.params}

    def __iter__(self):
        return iter(self.params)

    def __len__(self) -> int:
        return len(self.params)


# --- metrics, objectives, constraints ------------------------------------------------------------


@dataclass(frozen=True)
class Metric:
    """One number ``evaluate`` returns for a design.

    Attributes
    ----------
    name
        Its name (an identifier; a column of the trials table), with its unit in it where it has
        one (``far_limit_m``).
    unit
        Unit, for listings (empty if dimensionless).
    low, high
        Bounds the metric cannot leave whatever the design (a success rate lies in [0, 1]), or
        None. They let :func:`search` see at once that a constraint cannot be met, and every
        evaluation is checked against them.
    """

    name: str
    unit: str = ""
    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        _name_check("metrics: metric name", self.name)
        where = f"metrics.{self.name}"
        if not isinstance(self.unit, str):
            raise ValueError(f"{where}.unit: expected a string, got {self.unit!r}")
        for key in ("low", "high"):
            x = getattr(self, key)
            if x is not None:
                if not _number(x) or not math.isfinite(x):
                    raise ValueError(f"{where}.{key}: expected a finite number or nothing, got {x!r}")
                object.__setattr__(self, key, float(x))
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"{where}.low: expected a number < high, got {self.low!r} >= {self.high!r}")

    def describe_range(self) -> str:
        """``[0, 1]``, ``[0, ∞)``, ``(-∞, 5]``; with the unit."""
        lo = f"[{self.low:g}" if self.low is not None else "(-∞"
        hi = f"{self.high:g}]" if self.high is not None else "∞)"
        return f"{lo}, {hi}{' ' + self.unit if self.unit else ''}"

    def to_dict(self) -> dict:
        """The metric as a JSON-able table."""
        return {"name": self.name, "unit": self.unit, "low": self.low, "high": self.high}


@dataclass(frozen=True)
class Objective:
    """A metric to maximise or minimise.

    Attributes
    ----------
    metric
        The metric's name (one of the declared :class:`Metric` s).
    direction
        ``"maximize"`` or ``"minimize"``.
    """

    metric: str
    direction: str

    def __post_init__(self) -> None:
        if not isinstance(self.metric, str) or not self.metric:
            raise ValueError(f"objective.metric: expected a metric name, got {self.metric!r}")
        if self.direction not in DIRECTIONS:
            raise ValueError(
                f"objective.direction: {_nearest(str(self.direction), DIRECTIONS)}, got {self.direction!r}"
            )

    @property
    def sign(self) -> float:
        """+1 to maximise, -1 to minimise: ``sign * value`` is larger for a better design."""
        return 1.0 if self.direction == "maximize" else -1.0

    def describe(self) -> str:
        """``maximize far_limit_m``."""
        return f"{self.direction} {self.metric}"

    def to_dict(self) -> dict:
        """The objective as a JSON-able table."""
        return {"metric": self.metric, "direction": self.direction}


@dataclass(frozen=True)
class Constraint:
    """A bound a feasible design's metric must keep: ``metric <= bound`` or ``metric >= bound``.

    Attributes
    ----------
    metric
        The metric's name (one of the declared :class:`Metric` s).
    op
        ``"<="`` or ``">="``.
    bound
        The bound, in the metric's unit (finite).
    """

    metric: str
    op: str
    bound: float

    def __post_init__(self) -> None:
        if not isinstance(self.metric, str) or not self.metric:
            raise ValueError(f"constraint.metric: expected a metric name, got {self.metric!r}")
        if self.op not in OPERATORS:
            raise ValueError(f"constraint.op: {_nearest(str(self.op), OPERATORS)}, got {self.op!r}")
        if not _number(self.bound) or not math.isfinite(self.bound):
            raise ValueError(f"constraint.bound: expected a finite number, got {self.bound!r}")
        object.__setattr__(self, "bound", float(self.bound))

    def violation(self, value: float) -> float:
        """How far ``value`` is on the wrong side of the bound (optuna's constraint value: ``<= 0`` is feasible)."""
        return value - self.bound if self.op == "<=" else self.bound - value

    def met_by(self, value: float) -> bool:
        """Whether ``value`` keeps the bound (equality included)."""
        return self.violation(value) <= 0

    def describe(self) -> str:
        """``far_limit_m >= 5`` (also the constraint's name in optuna)."""
        return f"{self.metric} {self.op} {self.bound:g}"

    def impossible_within(self, metric: Metric) -> bool:
        """Whether no value within ``metric``'s declared bounds can meet the constraint."""
        if self.op == ">=":
            return metric.high is not None and metric.high < self.bound
        return metric.low is not None and metric.low > self.bound

    def to_dict(self) -> dict:
        """The constraint as a JSON-able table."""
        return {"metric": self.metric, "op": self.op, "bound": self.bound}


# --- results -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FrontPoint:
    """A design on the Pareto front.

    Attributes
    ----------
    trial
        Its evaluation index (0 for the first design evaluated).
    design
        Parameter name → value.
    metrics
        Metric name → value (every declared metric).
    """

    trial: int
    design: Mapping[str, Any]
    metrics: Mapping[str, float]

    def to_dict(self) -> dict:
        """The point as a JSON-able table."""
        return {"trial": self.trial, "design": dict(self.design), "metrics": dict(self.metrics)}


@dataclass(frozen=True)
class Progress:
    """Where a search stands, for a progress display (passed to ``search``'s ``progress``).

    Attributes
    ----------
    done
        Evaluations finished (those of earlier parts of a resumed search included).
    total
        Evaluations the search is to make (``trials``).
    feasible
        Finished evaluations that meet every constraint (with finite objectives).
    best
        Objective metric → best value among the feasible evaluations (each objective on its
        own; the designs may differ); empty while none is feasible.
    """

    done: int
    total: int
    feasible: int
    best: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class SearchResult:
    """What a search found, over its first ``requested`` evaluations.

    Attributes
    ----------
    front
        The Pareto front (feasible designs no other feasible design dominates), best first by
        the first objective, then by the next ones, then by trial.
    trials
        Every evaluation, one row each in evaluation order: ``trial``, the parameters, the
        metrics, ``feasible`` (meets every constraint, objectives finite), ``violation`` (sum of
        the constraints' shortfalls, in their metrics' units; 0 when met), ``status`` (``ok``, or
        ``non-finite`` when an objective or constraint metric was not finite) and ``on_front``.
    evaluations
        Evaluations the result holds (``requested`` unless the search was found infeasible
        before evaluating).
    evaluated_now
        Of those, how many this call made (the rest came from the journal).
    requested
        The ``trials`` asked for.
    feasible
        Evaluations that meet every constraint.
    non_finite
        Evaluations with a non-finite objective or constraint metric.
    infeasible
        A sentence saying which constraint was never met when ``feasible == 0``; empty otherwise.
    wall_s
        Wall time of this call, s (not of earlier parts of a resumed search).
    seed
        The search's seed.
    space, metrics, objectives, constraints
        What defined the search.
    """

    front: tuple[FrontPoint, ...]
    trials: pd.DataFrame
    evaluations: int
    evaluated_now: int
    requested: int
    feasible: int
    non_finite: int
    infeasible: str
    wall_s: float
    seed: int
    space: DesignSpace
    metrics: tuple[Metric, ...]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...]

    def front_frame(self) -> pd.DataFrame:
        """The front as a table: ``trial``, the parameters, the metrics (best first)."""
        columns = ["trial", *self.space.names, *(m.name for m in self.metrics)]
        rows = [{"trial": p.trial, **p.design, **p.metrics} for p in self.front]
        return pd.DataFrame(rows, columns=columns)

    def summary(self) -> dict:
        """What ``summary.json`` holds: the front, the counts, feasibility, the seed and what
        defined the search (JSON-able; no wall time, so it is the same after a stop and resume)."""
        return {
            "format": FORMAT,
            "seed": self.seed,
            "requested": self.requested,
            "evaluations": self.evaluations,
            "feasible": self.feasible,
            "non_finite": self.non_finite,
            "front_size": len(self.front),
            "infeasible": self.infeasible or None,
            "objectives": [o.to_dict() for o in self.objectives],
            "constraints": [c.to_dict() for c in self.constraints],
            "metrics": [m.to_dict() for m in self.metrics],
            "space": self.space.to_dict(),
            "front": [p.to_dict() for p in self.front],
            "optuna": optuna.__version__,
        }


def write_results(result: SearchResult, out: Path | str) -> tuple[Path, Path, Path]:
    """Write ``front.csv``, ``trials.csv`` and ``summary.json`` into ``out``, each atomically
    (a temporary file renamed into place: a reader never sees half a file).

    Parameters
    ----------
    result
        What :func:`search` returned.
    out
        The folder (created if missing).

    Returns
    -------
    The three paths written.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = (out / "front.csv", out / "trials.csv", out / "summary.json")
    # every float to 17 significant digits (exact): pandas writes numpy's str(), which is 12 digits once
    # numpy's printing is in its 1.13 legacy mode (colour-science sets that on import)
    atomic_write_bytes(paths[0], result.front_frame().to_csv(index=False, float_format="%.17g").encode())
    atomic_write_bytes(paths[1], result.trials.to_csv(index=False, float_format="%.17g").encode())
    atomic_write_bytes(paths[2], (dumps(result.summary(), indent=2) + "\n").encode())
    return paths


# --- the search ----------------------------------------------------------------------------------


def trial_seed(seed: int, index: int) -> int:
    """The sampler's seed for evaluation ``index`` of a search seeded ``seed`` (a 32-bit hash of both)."""
    return int(np.random.SeedSequence([seed, index]).generate_state(1)[0])


@dataclass(frozen=True)
class _Evaluation:
    """One finished evaluation as the journal holds it."""

    index: int
    design: dict[str, Any]
    metrics: dict[str, float]


@dataclass(frozen=True)
class _Problem:
    """The validated inputs of a search."""

    space: DesignSpace
    metrics: tuple[Metric, ...]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...]

    @property
    def scored(self) -> tuple[str, ...]:
        """Metrics that must be finite for the sampler to use an evaluation."""
        names = [o.metric for o in self.objectives] + [c.metric for c in self.constraints]
        return tuple(dict.fromkeys(names))

    def values(self, metrics: Mapping[str, float]) -> list[float]:
        return [metrics[o.metric] for o in self.objectives]

    def finite(self, metrics: Mapping[str, float]) -> bool:
        return all(math.isfinite(metrics[name]) for name in self.scored)

    def violations(self, metrics: Mapping[str, float]) -> dict[str, float]:
        return {c.describe(): c.violation(metrics[c.metric]) for c in self.constraints}

    def feasible(self, metrics: Mapping[str, float]) -> bool:
        return self.finite(metrics) and all(v <= 0 for v in self.violations(metrics).values())


def _coerce(items: Any, kind: type, what: str, label: str) -> tuple:
    if isinstance(items, str | kind) or not isinstance(items, Iterable):
        raise ValueError(f"{what}: expected a list of {label}s, got {items!r}")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, kind):
            out.append(item)
            continue
        if isinstance(item, str) or not isinstance(item, Sequence):
            raise ValueError(f"{what}[{i}]: expected a {kind.__name__} or a tuple, got {item!r}")
        try:
            out.append(kind(*item))
        except TypeError as exc:
            raise ValueError(f"{what}[{i}]: expected {label}, got {item!r}") from exc
        except ValueError as exc:
            message = str(exc)
            prefix = kind.__name__.lower()
            raise ValueError(
                f"{what}[{i}]{message[len(prefix) :]}" if message.startswith(prefix) else message
            ) from None
    return tuple(out)


def _problem(space: Any, metrics: Any, objectives: Any, constraints: Any) -> _Problem:
    if not isinstance(space, DesignSpace):
        raise ValueError(f"space: expected a DesignSpace, got {type(space).__name__}")
    if isinstance(metrics, str | Metric) or not isinstance(metrics, Iterable):
        raise ValueError(f"metrics: expected a list of metrics, got {metrics!r}")
    declared: dict[str, Metric] = {}
    for m in metrics:
        m = Metric(m) if isinstance(m, str) else m
        if not isinstance(m, Metric):
            raise ValueError(f"metrics: expected a Metric or a name, got {m!r}")
        if m.name in declared:
            raise ValueError(f"metrics.{m.name}: declared twice")
        if m.name in space.names:
            raise ValueError(f"metrics.{m.name}: also the name of a design parameter")
        declared[m.name] = m
    if not declared:
        raise ValueError("metrics: expected at least one metric, got none")
    names = ", ".join(declared)
    objs = _coerce(objectives, Objective, "objectives", "(metric, direction)")
    if not objs:
        raise ValueError("objectives: expected at least one objective, got none")
    for i, o in enumerate(objs):
        if o.metric not in declared:
            raise ValueError(f"objectives[{i}].metric: unknown metric {o.metric!r} (declared: {names})")
        if o.metric in [p.metric for p in objs[:i]]:
            raise ValueError(f"objectives[{i}].metric: {o.metric!r} is already an objective")
    cons = _coerce(constraints, Constraint, "constraints", "(metric, op, bound)")
    for i, c in enumerate(cons):
        if c.metric not in declared:
            raise ValueError(f"constraints[{i}].metric: unknown metric {c.metric!r} (declared: {names})")
        if c in cons[:i]:
            raise ValueError(f"constraints[{i}]: repeats {c.describe()!r}")
    return _Problem(space, tuple(declared.values()), objs, cons)


def _check_int(where: str, x: Any, least: int) -> int:
    if not _integer(x) or x < least:
        raise ValueError(f"{where}: expected an integer >= {least}, got {x!r}")
    return int(x)


def _spec(problem: _Problem, seed: int, workers: int, startup_trials: int, context: Any) -> dict:
    return {
        "format": FORMAT,
        "space": problem.space.to_dict(),
        "metrics": [m.to_dict() for m in problem.metrics],
        "objectives": [o.to_dict() for o in problem.objectives],
        "constraints": [c.to_dict() for c in problem.constraints],
        "seed": seed,
        "workers": workers,
        "sampler": {"name": "TPESampler", "multivariate": True, "n_startup_trials": startup_trials},
        "context": context,
        "optuna": optuna.__version__,
    }


def _first_difference(stored: Any, given: Any, path: str) -> str | None:
    if isinstance(stored, dict) and isinstance(given, dict):
        for key in [*stored, *(k for k in given if k not in stored)]:
            if key not in stored or key not in given:
                return f"{path}.{key}: {'not in the stored search' if key not in stored else 'not in the given search'}"
            found = _first_difference(stored[key], given[key], f"{path}.{key}")
            if found:
                return found
        return None
    if isinstance(stored, list) and isinstance(given, list) and len(stored) == len(given):
        for i, (a, b) in enumerate(zip(stored, given, strict=True)):
            found = _first_difference(a, b, f"{path}[{i}]")
            if found:
                return found
        return None
    if stored == given and type(stored) is type(given):
        return None

    def short(x: Any) -> str:
        text = json.dumps(x)
        return text if len(text) <= 80 else text[:77] + "..."

    return f"{path}: stored {short(stored)}, given {short(given)}"


def _journal_holds_search(path: Path) -> bool:
    return path.is_file() and path.stat().st_size > 0


def _repair_journal(path: Path) -> None:
    """Drop a last line a kill cut short (optuna writes whole lines ending in a newline; a line
    without one was never finished, and appending after it would corrupt the next)."""
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with open(path, "r+b") as f:
            f.truncate(data.rfind(b"\n") + 1)


def _storage(path: Path) -> JournalStorage:
    return JournalStorage(JournalFileBackend(str(path)))


def _stored_evaluations(study: optuna.Study) -> dict[int, _Evaluation]:
    found: dict[int, _Evaluation] = {}
    for t in study.get_trials(deepcopy=False):
        if "metrics" not in t.user_attrs or "index" not in t.user_attrs:
            continue
        metrics = decode_non_finite(t.user_attrs["metrics"], t.user_attrs.get("non_finite", []))
        found.setdefault(int(t.user_attrs["index"]), _Evaluation(int(t.user_attrs["index"]), dict(t.params), metrics))
    return found


def _add_to_mirror(mirror: optuna.Study, problem: _Problem, e: _Evaluation, distributions: dict) -> None:
    """Append a stored evaluation to the sampler's mirror as the loop would have told it."""
    if problem.finite(e.metrics):
        trial = create_trial(
            values=problem.values(e.metrics),
            params=e.design,
            distributions=distributions,
            constraints=problem.violations(e.metrics) or None,
        )
    else:
        trial = create_trial(state=TrialState.FAIL, params=e.design, distributions=distributions)
    mirror.add_trial(trial)


def _tell(study: optuna.Study, trial: optuna.Trial, problem: _Problem, metrics: Mapping[str, float]) -> None:
    if not problem.finite(metrics):
        study.tell(trial, state=TrialState.FAIL)
        return
    for name, value in problem.violations(metrics).items():
        trial.set_constraint(name, value)
    study.tell(trial, problem.values(metrics))


def _checked_metrics(raw: Any, problem: _Problem, index: int) -> dict[str, float]:
    where = f"evaluate: trial {index}"
    if not isinstance(raw, Mapping):
        raise ValueError(f"{where}: expected a dict of metric name → value, got {type(raw).__name__}")
    declared = {m.name: m for m in problem.metrics}
    for key in raw:
        if key not in declared:
            raise ValueError(f"{where}: returned an undeclared metric {key!r} ({_nearest(str(key), declared)})")
    metrics = {}
    for name, m in declared.items():
        if name not in raw:
            raise ValueError(f"{where}: returned no {name!r} (declared: {', '.join(declared)})")
        value = raw[name]
        if not (_number(value) or isinstance(value, bool | np.bool_)):
            raise ValueError(f"{where}: {name} = {value!r} is not a number")
        value = float(value)
        if math.isfinite(value) and ((m.low is not None and value < m.low) or (m.high is not None and value > m.high)):
            raise ValueError(f"{where}: {name} = {value!r} is outside its declared bounds {m.describe_range()}")
        metrics[name] = value
    return metrics


def _best(problem: _Problem, evaluations: Iterable[_Evaluation]) -> dict[str, float]:
    best: dict[str, float] = {}
    for e in evaluations:
        if problem.feasible(e.metrics):
            for o in problem.objectives:
                v = e.metrics[o.metric]
                if o.metric not in best or o.sign * v > o.sign * best[o.metric]:
                    best[o.metric] = v
    return best


def _never_met(problem: _Problem, evaluations: Sequence[_Evaluation]) -> str:
    """The sentence for a finished search with no feasible evaluation."""
    n = len(evaluations)
    usable = [e for e in evaluations if problem.finite(e.metrics)]
    if not usable:
        return (
            f"no feasible design in {n} evaluations: every one gave a non-finite value of {', '.join(problem.scored)}"
        )
    never, partly = [], []
    for c in problem.constraints:
        met = sum(c.met_by(e.metrics[c.metric]) for e in usable)
        if met == 0:
            values = [e.metrics[c.metric] for e in usable]
            closest = max(values) if c.op == ">=" else min(values)
            never.append(f"{c.describe()} (closest {closest:g})")
        else:
            partly.append(f"{c.describe()} met by {met}")
    if never:
        return f"no feasible design in {n} evaluations: no design met {' nor '.join(never)}"
    return f"no feasible design in {n} evaluations: no design met all constraints at once ({', '.join(partly)})"


def _result(
    problem: _Problem,
    mirror: optuna.Study | None,
    evaluations: Sequence[_Evaluation],
    *,
    requested: int,
    evaluated_now: int,
    seed: int,
    started: float,
    infeasible: str = "",
) -> SearchResult:
    front_indices = [t.number for t in mirror.best_trials] if mirror is not None and evaluations else []
    by_index = {e.index: e for e in evaluations}
    on_front = set(front_indices)

    def rank(i: int) -> tuple:
        m = by_index[i].metrics
        return (*(-o.sign * m[o.metric] for o in problem.objectives), i)

    front = tuple(
        FrontPoint(i, dict(by_index[i].design), dict(by_index[i].metrics)) for i in sorted(front_indices, key=rank)
    )
    rows = []
    for e in evaluations:
        finite = problem.finite(e.metrics)
        shortfall = sum((max(0.0, v) for v in problem.violations(e.metrics).values()), 0.0) if finite else math.nan
        rows.append(
            {
                "trial": e.index,
                **e.design,
                **e.metrics,
                "feasible": problem.feasible(e.metrics),
                "violation": shortfall,
                "status": "ok" if finite else "non-finite",
                "on_front": e.index in on_front,
            }
        )
    columns = ["trial", *problem.space.names, *(m.name for m in problem.metrics), *RESERVED_COLUMNS[1:]]
    trials = pd.DataFrame(rows, columns=columns)
    feasible = int(trials["feasible"].sum()) if rows else 0
    if feasible == 0 and not infeasible and evaluations:
        infeasible = _never_met(problem, evaluations)
    return SearchResult(
        front=front,
        trials=trials,
        evaluations=len(evaluations),
        evaluated_now=evaluated_now,
        requested=requested,
        feasible=feasible,
        non_finite=int((trials["status"] == "non-finite").sum()) if rows else 0,
        infeasible=infeasible,
        wall_s=time.perf_counter() - started,
        seed=seed,
        space=problem.space,
        metrics=problem.metrics,
        objectives=problem.objectives,
        constraints=problem.constraints,
    )


class _quiet_optuna:
    """Optuna's INFO lines and its experimental-feature warnings off inside the block."""

    def __enter__(self):
        self.verbosity = optuna.logging.get_verbosity()
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self.warnings = warnings.catch_warnings()
        self.warnings.__enter__()
        warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
        return self

    def __exit__(self, *exc):
        self.warnings.__exit__(*exc)
        optuna.logging.set_verbosity(self.verbosity)
        return False


def search(
    space: DesignSpace,
    evaluate: Callable[[dict[str, Any]], Mapping[str, float]],
    objectives: Sequence[Objective | tuple[str, str]],
    constraints: Sequence[Constraint | tuple[str, str, float]] = (),
    *,
    metrics: Sequence[Metric | str],
    trials: int,
    seed: int,
    out: Path | str,
    resume: bool = False,
    workers: int = 1,
    startup_trials: int = 10,
    context: Mapping[str, Any] | None = None,
    progress: Callable[[Progress], None] | None = None,
) -> SearchResult:
    """Search ``space`` for the designs that best meet ``objectives`` within ``constraints``.

    Parameters
    ----------
    space
        The design parameters.
    evaluate
        ``evaluate(design) -> {metric: value}``: a design is parameter name → value (float, int
        or the choice's value); it must return every declared metric (a float; NaN where it could
        not be measured) and no other. Deterministic, for the search to be: a resumed search
        re-evaluates nothing it has stored, and redoes an evaluation a stop cut short. With
        ``workers > 1`` it must be a module-level function (sent to the pool by name).
    objectives
        :class:`Objective` s or ``(metric, "maximize" | "minimize")`` tuples; at least one.
    constraints
        :class:`Constraint` s or ``(metric, "<=" | ">=", bound)`` tuples; possibly none.
    metrics
        The metrics ``evaluate`` returns: :class:`Metric` s (with their bounds where known) or names.
    trials
        Evaluations the search is to hold (>= 1). Resuming with a larger number continues the
        search; with a smaller one the result covers the first ``trials`` evaluations.
    seed
        Seed (>= 0): the same seed gives the same designs, another gives others.
    out
        Folder of the search: its journal is ``out/search.journal`` (see :data:`JOURNAL_NAME`).
    resume
        Continue the search in ``out`` (or start one when it holds none). Without it, a folder
        that holds a search is an error.
    workers
        Designs asked and evaluated at once, in a process pool when > 1 (see the module's
        docstring: the batch size is part of what defines the search).
    startup_trials
        Evaluations drawn at random (independently, uniform on each parameter's scale) before
        TPE models the results; optuna's default, 10.
    context
        Anything else that defines the search (the settings behind ``evaluate``), JSON-able: stored
        in the journal and compared on resume like the rest.
    progress
        Called with a :class:`Progress` once at the start (the stored evaluations) and after
        every evaluation.

    Returns
    -------
    SearchResult
        The front, every evaluation and the counts; write them with :func:`write_results`.

    Raises
    ------
    ValueError
        One line naming the field, for a bad space, metric, objective, constraint or argument
        (before anything is evaluated or written), a resume whose definition differs from the
        stored search, or an ``evaluate`` that returns other than the declared metrics.
    FileExistsError
        ``out`` holds a search and ``resume`` is off.
    KeyboardInterrupt
        Re-raised after a Ctrl-C, the journal left resumable (the interrupted evaluations are
        marked failed and redone on resume). Any exception ``evaluate`` raises is re-raised the
        same way, after the batch's other evaluations are stored.

    Examples
    --------
    >>> space = DesignSpace((
    ...     float_param("x", 0.0, 1.0, unit="m", assumed="toy"),
    ...     choice_param("led", ["red", "green"], assumed="toy"),
    ... ))
    >>> def evaluate(design):
    ...     bonus = 0.1 if design["led"] == "green" else 0.0
    ...     return {"score": bonus - (design["x"] - 0.3) ** 2, "cost": design["x"]}
    >>> result = search(space, evaluate, [("score", "maximize")], [("cost", "<=", 0.8)],
    ...                 metrics=["score", "cost"], trials=40, seed=1, out=tmp_path)  # doctest: +SKIP
    >>> result.front[0].design  # doctest: +SKIP
    {'x': 0.298..., 'led': 'green'}
    >>> write_results(result, tmp_path)  # doctest: +SKIP
    """
    started = time.perf_counter()
    problem = _problem(space, metrics, objectives, constraints)
    if not callable(evaluate):
        raise ValueError(f"evaluate: expected a function, got {evaluate!r}")
    trials = _check_int("trials", trials, 1)
    seed = _check_int("seed", seed, 0)
    workers = _check_int("workers", workers, 1)
    startup_trials = _check_int("startup_trials", startup_trials, 1)
    if progress is not None and not callable(progress):
        raise ValueError(f"progress: expected a function or None, got {progress!r}")
    if not isinstance(resume, bool):
        raise ValueError(f"resume: expected true or false, got {resume!r}")
    if context is not None and not isinstance(context, Mapping):
        raise ValueError(f"context: expected a table or None, got {context!r}")
    try:
        context = json.loads(json.dumps(dict(context), allow_nan=False)) if context is not None else None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"context: expected JSON-able values ({exc})") from None
    spec = _spec(problem, seed, workers, startup_trials, context)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out: {out} is not a folder")
    journal = out / JOURNAL_NAME
    holds = _journal_holds_search(journal)
    if holds and not resume:
        raise FileExistsError(
            f"{journal}: holds a search already; pass resume=True to continue it, or choose another out"
        )
    if holds:
        _repair_journal(journal)
        with _quiet_optuna():
            try:
                stored = optuna.load_study(study_name=STUDY_NAME, storage=_storage(journal))
            except KeyError:  # a stop before the study was made: nothing to resume
                stored = None
        if stored is not None and "spec" not in stored.user_attrs and stored.get_trials(deepcopy=False):
            raise ValueError(f"{journal}: holds trials but not what defines their search (not a design search?)")
        if stored is not None and "spec" in stored.user_attrs:
            difference = _first_difference(stored.user_attrs["spec"], spec, "search")
            if difference:
                raise ValueError(f"resume: {difference} (the journal {journal} holds another search)")

    declared = {m.name: m for m in problem.metrics}
    impossible = [
        f"{c.describe()} ({c.metric} lies in {declared[c.metric].describe_range()})"
        for c in problem.constraints
        if c.impossible_within(declared[c.metric])
    ]
    if impossible:
        sentence = f"no design can be feasible, so none was evaluated: no value can meet {' nor '.join(impossible)}"
        return _result(
            problem, None, [], requested=trials, evaluated_now=0, seed=seed, started=started, infeasible=sentence
        )

    with _quiet_optuna():
        return _run(problem, evaluate, spec, journal, trials, seed, workers, startup_trials, progress, started)


def _run(
    problem: _Problem,
    evaluate: Callable,
    spec: dict,
    journal: Path,
    trials: int,
    seed: int,
    workers: int,
    startup_trials: int,
    progress: Callable[[Progress], None] | None,
    started: float,
) -> SearchResult:
    journal.parent.mkdir(parents=True, exist_ok=True)
    directions = [o.direction for o in problem.objectives]
    study = optuna.create_study(
        storage=_storage(journal),
        study_name=STUDY_NAME,
        directions=directions,
        sampler=optuna.samplers.RandomSampler(seed=0),  # never samples: every design is enqueued
        load_if_exists=True,
    )
    if "spec" not in study.user_attrs:
        study.set_user_attr("spec", spec)
    # a stop left these: a design enqueued but not asked (the next ask would take it) and
    # evaluations cut short; they are failed trials now, their evaluations redone below
    while study.get_trials(deepcopy=False, states=(TrialState.WAITING,)):
        study.tell(study.ask(), state=TrialState.FAIL)
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        study.tell(t.number, state=TrialState.FAIL)
    stored = _stored_evaluations(study)
    first_missing = next(i for i in range(len(stored) + 1) if i not in stored)
    distributions = problem.space.distributions()
    mirror = optuna.create_study(directions=directions)
    if first_missing >= trials:
        for i in range(trials):
            _add_to_mirror(mirror, problem, stored[i], distributions)
        evaluations = [stored[i] for i in range(trials)]
        return _result(problem, mirror, evaluations, requested=trials, evaluated_now=0, seed=seed, started=started)

    start = (first_missing // workers) * workers
    for i in range(start):
        _add_to_mirror(mirror, problem, stored[i], distributions)
    done = {i: stored[i] for i in range(start)}
    now = 0

    def report() -> None:
        if progress is not None:
            ordered = [done[i] for i in sorted(done)]
            feasible = sum(problem.feasible(e.metrics) for e in ordered)
            progress(Progress(len(done), trials, feasible, _best(problem, ordered)))

    report()
    pool = (
        ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=worker_start, initargs=(os.getpid(),))
        if workers > 1
        else None
    )
    try:
        with worker_threads(workers) if pool is not None else nullcontext():
            for batch_start in range(start, trials, workers):
                batch = range(batch_start, min(batch_start + workers, trials))
                now += _batch(problem, evaluate, study, mirror, stored, done, batch, seed, startup_trials, pool, report)
    except KeyboardInterrupt:
        if pool is not None:
            stop_pool(pool)
            pool = None
        raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
    evaluations = [done[i] for i in range(trials)]
    return _result(problem, mirror, evaluations, requested=trials, evaluated_now=now, seed=seed, started=started)


def _batch(
    problem: _Problem,
    evaluate: Callable,
    study: optuna.Study,
    mirror: optuna.Study,
    stored: Mapping[int, _Evaluation],
    done: dict[int, _Evaluation],
    batch: range,
    seed: int,
    startup_trials: int,
    pool: ProcessPoolExecutor | None,
    report: Callable[[], None],
) -> int:
    """Ask, evaluate and tell one batch; returns how many evaluations it made."""
    distributions = problem.space.distributions()
    asked: dict[int, optuna.Trial] = {}
    for i in batch:
        mirror.sampler = optuna.samplers.TPESampler(
            multivariate=True, n_startup_trials=startup_trials, seed=trial_seed(seed, i)
        )
        asked[i] = mirror.ask(fixed_distributions=distributions)
        if i in stored and stored[i].design != asked[i].params:
            raise RuntimeError(
                f"resume: trial {i}'s design {asked[i].params} is not the stored {stored[i].design}: "
                "the sampler does not repeat itself here (another numpy or optuna build?)"
            )
    pending = [i for i in batch if i not in stored]
    running: dict[int, optuna.Trial] = {}
    for i in pending:
        study.enqueue_trial(asked[i].params, user_attrs={"index": i})
        running[i] = study.ask(fixed_distributions=distributions)
    outcomes: dict[int, Any] = {}
    error: BaseException | None = None
    try:
        if pool is None:
            for i in pending:
                try:
                    outcomes[i] = _checked_metrics(evaluate(dict(asked[i].params)), problem, i)
                except Exception as exc:  # told as a failed trial below, then re-raised
                    outcomes[i] = exc
                    break
        else:
            futures: dict[int, Future] = {i: pool.submit(evaluate, dict(asked[i].params)) for i in pending}
            for i, future in futures.items():
                try:
                    outcomes[i] = _checked_metrics(future.result(), problem, i)
                except Exception as exc:
                    outcomes[i] = exc
    except KeyboardInterrupt:
        for trial in running.values():
            trial.set_user_attr("interrupted", True)
            study.tell(trial, state=TrialState.FAIL)
        raise
    made = 0
    for i in batch:
        if i in stored:
            e = stored[i]
        elif isinstance(outcomes.get(i), dict):
            e = _Evaluation(i, dict(asked[i].params), outcomes[i])
            metrics, non_finite = encode_non_finite(e.metrics)
            running[i].set_user_attr("metrics", metrics)
            if non_finite:
                running[i].set_user_attr("non_finite", non_finite)
            _tell(study, running[i], problem, e.metrics)
            made += 1
        else:
            outcome = outcomes.get(i)
            if isinstance(outcome, BaseException) and error is None:
                error = outcome
            if i in running:
                if outcome is not None:
                    running[i].set_user_attr("error", f"{type(outcome).__name__}: {outcome}".splitlines()[0])
                study.tell(running[i], state=TrialState.FAIL)
            continue
        _tell(mirror, asked[i], problem, e.metrics)
        done[i] = e
        report()
    if error is not None:
        raise error
    return made
