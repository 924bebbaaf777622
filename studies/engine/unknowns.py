"""Unknowns: the inputs the source study did not give, as one registry (``studies/data/unknowns.toml``).

Each :class:`Unknown` names where it applies (its ``target``), how it may vary (``kind`` with
bounds or choices), its ``nominal`` value and the ``source`` or ``assumed`` reasoning. Any run
can hold them at their nominal values (:func:`nominal`), fix some (:func:`fixed`) or sample
them (:func:`sample`, quasi-random with :mod:`scipy.stats.qmc`), then turn one set of values
into a frame task (:func:`apply`):

``scenario.<field>``                      → ``task["scenario"][field]``
``camera.<lens|sensor|isp|exposure>.<f>`` → ``task["camera_overrides"]["<group>.<f>"]``
                                            (applied by :func:`camera_models.camera.with_overrides`)
``data.<file>.<key path>``                → ``task["scenario"]["data"]["<file>.<key path>"]``: a value of
                                            ``scenes/data/<file>.toml`` replaced for the frame
                                            (:data:`scenes.data_overrides.DATA_PATHS` lists those a scenario
                                            can replace; a ``data.beacons.<name>.`` one applies to that beacon)
``tracker.thesis.<field>``                → ``task["thesis_morphology"][field]``: a morphology setting of the
                                            study's tracker (:data:`TRACKER_FIELDS`) for the sessions in which
                                            the study says it changed it (``min_range_m`` scopes it to them)

Values are keyed by the unknown's name. All functions are pure; the same seed gives the
same samples.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import loguniform, qmc, uniform

from scenes.data_overrides import DATA_PATHS, GAIN, RENDER, data_path
from scenes.scenario import Scenario
from scenes.sourced import DATA_DIR as SCENE_DATA_DIR
from scenes.sourced import DataFileError, load_sourced, load_tables
from scenes.view import camera_names
from studies.engine.frame_task import MORPHOLOGY_FIELDS, FrameTask

__all__ = [
    "CAMERA_GROUPS",
    "KINDS",
    "TRACKER_FIELDS",
    "Unknown",
    "apply",
    "data_file_value",
    "fixed",
    "groups_of",
    "load_unknowns",
    "nominal",
    "sample",
]

UNKNOWNS_FILE = Path(__file__).resolve().parents[1] / "data" / "unknowns.toml"
KINDS = ("uniform", "loguniform", "choice", "fixed")
CAMERA_GROUPS = ("lens", "sensor", "isp", "exposure", "effects")
"""Camera-model parts a run may override (the geometry is fixed by the camera name: the render uses it)."""
TRACKER_FIELDS = MORPHOLOGY_FIELDS
"""Settings of the study's tracker an unknown may set (:data:`studies.engine.frame_task.MORPHOLOGY_FIELDS`)."""
METHODS = ("sobol", "lhs", "random")
_KEYS = {"target", "kind", "low", "high", "choices", "nominal", "unit", "cameras", "min_range_m", "source", "assumed"}


@dataclass(frozen=True)
class Unknown:
    """One unknown input.

    Attributes
    ----------
    name
        Table name in the data file (a Python identifier).
    target
        Where it applies: ``scenario.<field>``, ``camera.<group>.<field>`` or ``data.<file>.<key path>``.
    kind
        ``uniform``, ``loguniform``, ``choice`` or ``fixed``.
    nominal
        Value of a nominal run, in ``unit``.
    low, high
        Bounds of ``uniform`` / ``loguniform`` (inclusive), in ``unit``; None otherwise.
    choices
        Values of ``choice``; empty otherwise.
    unit
        Unit of the values (empty if dimensionless or not a number).
    cameras
        Camera names it applies to; empty means every camera.
    min_range_m
        The nominal range (m) from which it applies (a session of the study's at those ranges);
        None: at every range.
    provenance
        ``"source: …"`` or ``"assumed: …"``: where the range comes from, or why it is reasonable.
    """

    name: str
    target: str
    kind: str
    nominal: Any
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    unit: str = ""
    cameras: tuple[str, ...] = ()
    min_range_m: float | None = None
    provenance: str = ""

    @property
    def namespace(self) -> str:
        """``scenario``, ``camera``, ``data`` or ``tracker``."""
        return self.target.split(".", 1)[0]

    @property
    def path(self) -> str:
        """The target without its namespace (``led_current_mA``, ``lens.f_number``, ``leds.red.…``)."""
        return self.target.split(".", 1)[1]

    @property
    def acts(self) -> str:
        """How it acts on a frame: ``gain`` (rescales the render exactly: the LED drive and intensity
        bins), ``render`` (changes the scene rendered), ``camera`` (the camera model) or ``tracker``
        (the study's tracker on the same saved frame)."""
        if self.namespace in ("camera", "tracker"):
            return self.namespace
        if self.namespace == "data":
            return data_path(self.path)[0].acts
        return GAIN if self.path == "led_current_mA" else RENDER

    def contains(self, value: Any) -> bool:
        """Whether ``value`` is a value this unknown may take."""
        if self.kind == "choice":
            return any(_same(value, c) for c in self.choices)
        if self.kind == "fixed":
            return _same(value, self.nominal)
        return _is_number(value) and self.low <= float(value) <= self.high

    def applies_at(self, range_m: float) -> bool:
        """Whether it acts on a frame at nominal range ``range_m`` (m)."""
        return self.min_range_m is None or range_m >= self.min_range_m

    def describe_range(self) -> str:
        """The range as text: ``0.05-20 mA (loguniform)``, ``black | white``, ``= 3.5``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.kind == "choice":
            return " | ".join(_text(c) for c in self.choices)
        if self.kind == "fixed":
            return f"= {_text(self.nominal)}{unit}"
        return f"{self.low:g}-{self.high:g}{unit} ({self.kind})"


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(float(x))


def _is_count(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= 0


def _same(a: Any, b: Any) -> bool:
    if _is_number(a) and _is_number(b):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=0.0)
    return type(a) is type(b) and a == b


def _text(x: Any) -> str:
    return f"{x:g}" if _is_number(x) else str(x).lower() if isinstance(x, bool) else str(x)


def _parse(name: str, table: Any, where: str) -> Unknown:
    """One table of the data file as an :class:`Unknown`; :class:`DataFileError` naming the field."""
    at = f"{where}: {name}"
    if not isinstance(table, dict):
        raise DataFileError(f"{at}: expected a table")
    if not name.isidentifier():
        raise DataFileError(f"{at}: the name must be a Python identifier (letters, digits, _)")
    extra = sorted(set(table) - _KEYS)
    if extra:
        raise DataFileError(f"{at}.{extra[0]}: unknown key (expected some of {', '.join(sorted(_KEYS))})")
    has = [k for k in ("source", "assumed") if k in table]
    if len(has) != 1 or not isinstance(table[has[0]], str) or len(table[has[0]].strip()) < 20:
        raise DataFileError(f"{at}: needs exactly one of 'source' or 'assumed' with the reasoning (a sentence)")
    for key in ("target", "kind", "nominal"):
        if key not in table:
            raise DataFileError(f"{at}.{key}: missing")
    kind = table["kind"]
    if kind not in KINDS:
        raise DataFileError(f"{at}.kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    _check_target(table["target"], f"{at}.target")
    cameras = table.get("cameras", [])
    if not isinstance(cameras, list) or any(c not in camera_names() for c in cameras):
        raise DataFileError(f"{at}.cameras: expected a list of camera names ({', '.join(camera_names())})")
    if not isinstance(table.get("unit", ""), str):
        raise DataFileError(f"{at}.unit: expected a string")
    min_range = table.get("min_range_m")
    if min_range is not None and (not _is_number(min_range) or min_range <= 0):
        raise DataFileError(f"{at}.min_range_m: expected a range in metres > 0, got {min_range!r}")
    low = high = None
    choices: tuple = ()
    if kind in ("uniform", "loguniform"):
        low, high = table.get("low"), table.get("high")
        if not (_is_number(low) and _is_number(high) and low < high):
            raise DataFileError(f"{at}.low/high: expected finite numbers with low < high, got {low!r}, {high!r}")
        if kind == "loguniform" and low <= 0:
            raise DataFileError(f"{at}.low: a loguniform range needs low > 0, got {low!r}")
        low, high = float(low), float(high)
    elif kind == "choice":
        choices = tuple(table.get("choices") or ())
        if len(choices) < 2:
            raise DataFileError(f"{at}.choices: expected a list of at least 2 values")
    else:
        for key in ("low", "high", "choices"):
            if key in table:
                raise DataFileError(f"{at}.{key}: a fixed unknown has only a nominal value")
    unknown = Unknown(
        name=name,
        target=table["target"],
        kind=kind,
        nominal=_nominal_value(table),
        low=low,
        high=high,
        choices=choices,
        unit=table.get("unit", ""),
        cameras=tuple(cameras),
        min_range_m=None if min_range is None else float(min_range),
        provenance=f"{has[0]}: {table[has[0]]}",
    )
    if not unknown.contains(unknown.nominal):
        raise DataFileError(f"{at}.nominal: {unknown.nominal!r} is outside {unknown.describe_range()}")
    if unknown.namespace == "tracker" and (
        kind not in ("choice", "fixed") or not all(_is_count(v) for v in (*unknown.choices, unknown.nominal))
    ):
        raise DataFileError(f"{at}: a tracker setting takes whole numbers >= 0 (kind choice or fixed)")
    if unknown.namespace == "data" and not _same(data_file_value(unknown.target), unknown.nominal):
        raise DataFileError(
            f"{at}.nominal: {unknown.nominal!r} differs from the data file's {data_file_value(unknown.target)!r}"
        )
    return unknown


def _nominal_value(table: dict) -> Any:
    """The nominal as given, numbers as floats except a choice's and a tracker setting's (whole
    iteration counts)."""
    value = table["nominal"]
    if table["kind"] != "choice" and not table["target"].startswith("tracker.") and _is_number(value):
        return float(value)
    return value


def _check_target(target: Any, at: str) -> None:
    if not isinstance(target, str) or "." not in target:
        raise DataFileError(
            f"{at}: expected 'scenario.<field>', 'camera.<group>.<field>', 'data.<file>.<key>' "
            "or 'tracker.thesis.<field>'"
        )
    namespace, path = target.split(".", 1)
    if namespace == "scenario":
        fields = [f.name for f in dataclasses.fields(Scenario) if f.name not in ("render", "data")]
        if path not in fields:
            raise DataFileError(f"{at}: {path!r} is not a Scenario field (expected one of {', '.join(fields)})")
    elif namespace == "camera":
        group, _, field = path.partition(".")
        if group not in CAMERA_GROUPS or not field:
            raise DataFileError(f"{at}: expected camera.<{'|'.join(CAMERA_GROUPS)}>.<field>, got {target!r}")
    elif namespace == "data":
        try:
            data_file_value(target)
        except (KeyError, TypeError, DataFileError):
            raise DataFileError(f"{at}: {target!r} is not a value of a scenes/data file") from None
        try:
            data_path(path)
        except ValueError:
            raise DataFileError(
                f"{at}: {target!r} is not a value a scenario can replace (expected data.<one of "
                f"{', '.join(DATA_PATHS)}>)"
            ) from None
    elif namespace == "tracker":
        if path not in {f"thesis.{f}" for f in TRACKER_FIELDS}:
            raise DataFileError(f"{at}: expected tracker.thesis.<{'|'.join(TRACKER_FIELDS)}>, got {target!r}")
    else:
        raise DataFileError(f"{at}: namespace must be 'scenario', 'camera', 'data' or 'tracker', got {namespace!r}")


def data_file_value(target: str) -> Any:
    """The value a ``data.<file>.<key path>`` target has in ``scenes/data/<file>.toml`` (KeyError if absent).

    ``<file>`` may go through folders of ``scenes/data``: ``data.beacons.v2.arm_length_mm`` is
    ``arm_length_mm`` of ``scenes/data/beacons/v2.toml``.
    """
    _, *parts = target.split(".")
    depth = 1
    while depth < len(parts) and SCENE_DATA_DIR.joinpath(*parts[:depth]).is_dir():
        depth += 1
    node = _scene_data("/".join(parts[:depth]))
    for key in parts[depth:]:
        node = node[key]
    return node


@lru_cache(maxsize=16)
def _scene_data(file: str) -> dict:
    path = SCENE_DATA_DIR / f"{file}.toml"
    if not all(part.isidentifier() for part in file.split("/")) or not path.is_file():
        raise DataFileError(f"{path}: no such scene data file")
    return load_sourced(path)[0]


def load_unknowns(path: str | Path = UNKNOWNS_FILE) -> dict[str, Unknown]:
    """The registry: name → :class:`Unknown`, in file order, validated (:class:`DataFileError`, one line
    naming the file and the field). Read once per file version (a study at points of the unknowns
    applies them to every frame task); each call returns a dict of its own."""
    try:
        stat = Path(path).stat()
        version = (stat.st_mtime_ns, stat.st_size)
    except OSError:
        version = None  # load_tables names the file that cannot be read
    return dict(_registry(str(path), version))


@lru_cache(maxsize=8)
def _registry(path: str, version: tuple[int, int] | None) -> tuple[tuple[str, Unknown], ...]:
    del version  # part of the cache key only
    raw = load_tables(path, "unknowns")
    return tuple((name, _parse(name, table, path)) for name, table in raw.items())


def nominal(unknowns: dict[str, Unknown]) -> dict[str, Any]:
    """Every unknown at its nominal value (name → value)."""
    return {name: u.nominal for name, u in unknowns.items()}


def fixed(unknowns: dict[str, Unknown], **values: Any) -> dict[str, Unknown]:
    """A new registry with the named unknowns fixed at the given values (each within its range)."""
    out = dict(unknowns)
    for name, value in values.items():
        if name not in unknowns:
            raise ValueError(f"unknowns: no unknown {name!r} (expected one of {', '.join(unknowns)})")
        u = unknowns[name]
        if not u.contains(value):
            raise ValueError(f"unknowns: {name}={value!r} is outside {u.describe_range()}")
        value = float(value) if _is_number(value) and u.kind != "choice" else value
        out[name] = dataclasses.replace(u, kind="fixed", nominal=value, low=None, high=None, choices=())
    return out


def sample(
    unknowns: dict[str, Unknown], n: int, seed: int, method: str = "sobol", *, choices_apart: bool = False
) -> list[dict[str, Any]]:
    """``n`` sets of values (name → value) for the unknowns; fixed ones stay at their nominal.

    ``method``: ``sobol`` (scrambled Sobol' sequence; powers of 2 keep its balance), ``lhs``
    (Latin hypercube) or ``random`` (independent uniform draws). Each varying unknown takes
    one dimension of the unit hypercube, mapped by its distribution's inverse CDF
    (:mod:`scipy.stats`); a choice takes equal shares of it. Same seed, same samples.

    ``choices_apart`` (Sobol' only): a choice takes the next dimension of the sequence in which it
    splits the points differently from every choice before it (:func:`_apart_dimensions`), so that
    no two choices move together over the points (16 Sobol' points split into halves in only 8 ways,
    and in consecutive dimensions many two-choice unknowns share one). A sensitivity analysis needs
    this (aliased inputs cannot be told apart); an interval over the points does not.
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n: expected an integer >= 1, got {n!r}")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if choices_apart and method != "sobol":
        raise ValueError(f"choices_apart: works on the Sobol' sequence's dimensions, not on method {method!r}")
    varying = [u for u in unknowns.values() if u.kind != "fixed"]
    d = len(varying)
    if d == 0:
        points = np.zeros((n, 0))
    elif method == "sobol":
        width = d + _SPARE_DIMENSIONS if choices_apart else d
        with warnings.catch_warnings():  # n not a power of 2: still valid points, slightly less balanced
            warnings.filterwarnings("ignore", message=".*balance properties of Sobol.*", category=UserWarning)
            points = qmc.Sobol(width, scramble=True, seed=seed).random(n)
        if choices_apart:
            points = points[:, _apart_dimensions(varying, points)]
    elif method == "lhs":
        points = qmc.LatinHypercube(d, seed=seed).random(n)
    else:
        points = np.random.default_rng(seed).random((n, d))
    columns = {u.name: _from_unit(u, points[:, j]) for j, u in enumerate(varying)}
    return [
        {name: columns[name][i] if name in columns else u.nominal for name, u in unknowns.items()} for i in range(n)
    ]


_SPARE_DIMENSIONS = 64
"""Extra Sobol' dimensions drawn for ``choices_apart`` to pick the choices' dimensions from."""


def _apart_dimensions(varying: list[Unknown], points: np.ndarray) -> list[int]:
    """The dimension of ``points`` each unknown takes: the next unused one for a number, and for a choice
    the first unused one in which its shares split the points into groups no earlier choice's do (the
    next unused one when none does: then the split is unavoidable at this number of points)."""

    def split(u: Unknown, j: int) -> tuple[int, ...]:
        return groups_of(np.minimum((points[:, j] * len(u.choices)).astype(int), len(u.choices) - 1))

    unused = list(range(points.shape[1]))
    seen: set[tuple[int, ...]] = set()
    chosen = []
    for u in varying:
        j = unused[0]
        if u.kind == "choice":
            j = next((c for c in unused if split(u, c) not in seen), j)
            seen.add(split(u, j))
        unused.remove(j)
        chosen.append(j)
    return chosen


def groups_of(labels: np.ndarray | list) -> tuple[int, ...]:
    """The groups ``labels`` put the points in, numbered in order of first appearance, so that the same
    split under other labels reads the same.

    >>> groups_of(["b", "a", "b"]) == groups_of([0, 1, 0])
    True
    """
    labels = list(np.asarray(labels).tolist())
    rank = {c: k for k, c in enumerate(dict.fromkeys(labels))}
    return tuple(rank[c] for c in labels)


def _from_unit(u: Unknown, q: np.ndarray) -> list:
    """Values of ``u`` at unit-interval quantiles ``q`` (plain Python values)."""
    if u.kind == "choice":
        index = np.minimum((q * len(u.choices)).astype(int), len(u.choices) - 1)
        return [u.choices[i] for i in index]
    if u.kind == "uniform":
        x = uniform(loc=u.low, scale=u.high - u.low).ppf(q)
    else:
        x = loguniform(u.low, u.high).ppf(q)
    return [float(v) for v in np.clip(x, u.low, u.high)]


def apply(task: dict | FrameTask, values: dict[str, Any], unknowns: dict[str, Unknown] | None = None) -> dict:
    """A new frame task (see :mod:`studies.engine.frame`) with ``values`` (name → value) set.

    Scenario targets go into ``task["scenario"]``, camera targets into
    ``task["camera_overrides"]`` (``"lens.f_number"`` → value), data targets into
    ``task["scenario"]["data"]`` (``"leds.red.luminous_intensity_cd"`` → value) unless the value is
    the data file's own (then the task stays as a nominal one, with the key it had), tracker
    targets into ``task["thesis_morphology"]``. Unknowns scoped to other cameras than the task's,
    to ranges beyond the task's nominal range (``min_range_m``), and ``data.beacons.<name>.`` ones
    of another beacon, are skipped. ``task`` itself is left unchanged; the result is the task's plain form
    (:meth:`studies.engine.frame_task.FrameTask.coerce` reads it).
    """
    unknowns = load_unknowns() if unknowns is None else unknowns
    out = task.to_dict() if isinstance(task, FrameTask) else copy.deepcopy(task)
    scenario = out.setdefault("scenario", {})
    camera = scenario.get("camera", Scenario.__dataclass_fields__["camera"].default)
    beacon = scenario.get("beacon", Scenario.__dataclass_fields__["beacon"].default)
    overrides = dict(out.get("camera_overrides") or {})
    morphology = dict(out.get("thesis_morphology") or {})
    data = dict(scenario.get("data") or {})
    range_m = (out.get("nominal") or {}).get(
        "range_m", scenario.get("range_m", Scenario.__dataclass_fields__["range_m"].default)
    )
    for name, value in values.items():
        if name not in unknowns:
            raise ValueError(f"unknowns: no unknown {name!r} (expected one of {', '.join(unknowns)})")
        u = unknowns[name]
        if (u.cameras and camera not in u.cameras) or not u.applies_at(range_m):
            continue
        value = value.item() if isinstance(value, np.generic) else value
        if u.namespace == "scenario":
            scenario[u.path] = value
        elif u.namespace == "camera":
            overrides[u.path] = value
        elif u.namespace == "tracker":
            morphology[u.path.split(".", 1)[1]] = int(value)
        elif u.path.startswith("beacons.") and u.path.split(".")[1] != beacon:
            continue
        elif _same(value, data_file_value(u.target)):
            data.pop(u.path, None)
        else:
            data[u.path] = float(value)
    if overrides:
        out["camera_overrides"] = overrides
    if morphology:
        out["thesis_morphology"] = morphology
    if data:
        scenario["data"] = dict(sorted(data.items()))
    else:
        scenario.pop("data", None)
    return out
