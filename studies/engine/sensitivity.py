"""Global sensitivity of one simulator output to the unknowns: Morris screening and Sobol' indices.

The estimators are SALib's (Herman & Usher 2017, "SALib: an open-source Python library for
sensitivity analysis"; Iwanaga, Usher & Herman 2022), not written here: Morris' elementary effects
(Morris 1991; μ* of Campolongo, Cariboni & Saltelli 2007) from :mod:`SALib.sample.morris` and
:mod:`SALib.analyze.morris`, and Sobol' first-order and total indices with Saltelli's sampling
(Saltelli 2002; Saltelli et al. 2010) from :mod:`SALib.sample.sobol` and :mod:`SALib.analyze.sobol`,
their 95 % confidence intervals by SALib's bootstrap.

The inputs are the calibration's (:class:`~studies.engine.calibration.inputs.InputSpace`, e.g.
``InputSpace.from_unknowns(load_unknowns())``): SALib's "problem" is the unit cube of the space, and a
point of the cube becomes the unknowns' values through the space exactly as
:func:`studies.engine.unknowns.sample` maps its Sobol' points (log-uniform on the log scale, a choice
in equal shares of its dimension). So the indices are of the output's variance under the registry's
own distributions, a choice's included (each choice equally likely).

``model`` is a callable taking ``(n, space.dim)`` unit-cube points of the **whole** space (columns in
the space's order; ``space.values(q)`` turns them into name → value dicts) and returning ``(n,)``
outputs; it is called once per analysis with every point, so it can evaluate them as a batch (in
parallel, on a cluster, or on an emulator). When :func:`sobol` analyses a subset of the inputs the
other columns hold, in every row, the coordinate of their nominal value.

Where direct runs are too dear, :func:`emulate` fits the calibration's Gaussian-process emulator
(:func:`~studies.engine.calibration.emulator.fit_emulator`) to a set of direct runs and returns its
mean as a model, with its leave-one-out diagnostics, so a report can say how far to trust indices
computed on it. :func:`explain` says what the indices mean in words.

Every function is pure: the same seed gives the same numbers, bit for bit (the seed goes to SALib's
samplers and, derived, to its bootstrap).

Example
-------
>>> import numpy as np
>>> from studies.engine.calibration.inputs import Input, InputSpace
>>> space = InputSpace((Input("a", 0.0, 1.0), Input("b", 0.0, 1.0), Input("c", 0.0, 1.0)))
>>> result = sobol(lambda q: 4 * q[:, 0] + q[:, 1], space, n=1024, seed=1)
>>> [round(s, 2) for s in result.s1]
[0.94, 0.06, 0.0]
>>> print(explain(result, output="the toy")[0])
measure a: it explains 94 % of the toy's variance (total effect 94 %)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from SALib.analyze import morris as morris_analyze
from SALib.analyze import sobol as sobol_analyze
from SALib.sample import morris as morris_sample
from SALib.sample import sobol as sobol_sample

from studies.engine.calibration.emulator import Diagnostics, Emulator, diagnose, fit_emulator, predict
from studies.engine.calibration.inputs import InputSpace
from studies.engine.report import join_words
from studies.engine.unknowns import Unknown, groups_of

__all__ = [
    "CONF_LEVEL",
    "INTERACTION_SUM",
    "NEGLIGIBLE",
    "UNRELIABLE",
    "EmulatedModel",
    "Model",
    "Morris",
    "Sobol",
    "aliased_inputs",
    "emulate",
    "explain",
    "morris",
    "sobol",
]

Model = Callable[[np.ndarray], np.ndarray]
"""``(n, d)`` unit-cube points of the whole space → ``(n,)`` outputs (in the output's unit)."""

CONF_LEVEL = 0.95
"""Confidence level of the bootstrap intervals SALib gives (half-widths)."""
INTERACTION_SUM = 0.9
"""Σ S1 below this is "well under 1": at least a tenth of the variance comes from inputs acting
together (an additive model has Σ S1 = 1)."""
NEGLIGIBLE = 0.01
"""A total effect (fraction of the variance) or a μ* (fraction of the largest μ*) under this is
negligible: the input can be held at its nominal."""
_PREDICT_BLOCK = 8192
"""Points per emulator prediction (bounds the cross-covariance matrix's memory)."""


def _derived_seed(seed: int, stream: int) -> int:
    """An independent, non-zero seed for one use of ``seed`` (SALib's Sobol' bootstrap treats 0 as
    "no seed" and would draw from numpy's global state)."""
    return int(np.random.SeedSequence([seed, stream]).generate_state(1)[0]) or 1


def _check_int(name: str, value: Any, minimum: int) -> int:
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_space(space: Any) -> InputSpace:
    if not isinstance(space, InputSpace):
        raise ValueError(f"space: expected an InputSpace, got {type(space).__name__}")
    return space


def _problem(names: Sequence[str]) -> dict:
    """SALib's problem: the unit cube of the named inputs."""
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


def _evaluate(model: Model, points: np.ndarray) -> np.ndarray:
    """The model's outputs at ``points`` (n, d), checked: (n,) finite numbers."""
    if not callable(model):
        raise ValueError(f"model: expected a callable on (n, d) unit-cube points, got {type(model).__name__}")
    n = len(points)
    y = np.asarray(model(points.copy()), dtype=float)
    if y.shape == (n, 1):
        y = y[:, 0]
    if y.shape != (n,):
        raise ValueError(f"model: expected outputs of shape ({n},), got shape {y.shape}")
    bad = int(np.sum(~np.isfinite(y)))
    if bad:
        raise ValueError(
            f"model: {bad} of {n} outputs are not finite (failed runs?); the indices need every run: "
            "rerun them, or fit an emulator to the finished ones (emulate)"
        )
    return y


def _finite_or_none(values: Sequence[float]) -> list[float | None]:
    return [float(v) if math.isfinite(v) else None for v in values]


@dataclass(frozen=True)
class Morris:
    """Morris screening of one output: elementary effects over trajectories of the unit cube.

    An elementary effect of input ``i`` is the output's change when that input alone moves by
    Δ = levels / (2 (levels − 1)) of its unit interval, divided by Δ: the output's change per the
    input's whole range (output unit), from one point of a ``levels``-level grid.

    Attributes
    ----------
    inputs
        The inputs' names, in the space's order (every field below follows it).
    mu_star
        Mean absolute elementary effect μ* (output unit per input range): how much the input moves
        the output, in either direction (Campolongo, Cariboni & Saltelli 2007).
    mu_star_conf
        Half-width of μ*'s 95 % bootstrap interval (output unit).
    mu
        Mean signed elementary effect (output unit); ``|mu| < mu_star``: effects of both signs.
    sigma
        Standard deviation of the elementary effects (output unit): large against μ*, the effect
        depends on where the other inputs are (non-linear or interacting).
    runs
        Model runs used: ``trajectories × (d + 1)``.
    trajectories, levels, seed
        The design's settings.
    """

    inputs: tuple[str, ...]
    mu_star: tuple[float, ...]
    mu_star_conf: tuple[float, ...]
    mu: tuple[float, ...]
    sigma: tuple[float, ...]
    runs: int
    trajectories: int
    levels: int
    seed: int

    def ranked(self) -> tuple[str, ...]:
        """The inputs, the one with the largest μ* first (ties in the space's order)."""
        order = sorted(range(len(self.inputs)), key=lambda i: -self.mu_star[i])
        return tuple(self.inputs[i] for i in order)

    def to_json(self) -> dict:
        """The record as strict-JSON values (null for a non-finite number)."""
        return {
            "method": "morris",
            "inputs": list(self.inputs),
            "mu_star": _finite_or_none(self.mu_star),
            "mu_star_conf": _finite_or_none(self.mu_star_conf),
            "mu": _finite_or_none(self.mu),
            "sigma": _finite_or_none(self.sigma),
            "runs": self.runs,
            "trajectories": self.trajectories,
            "levels": self.levels,
            "seed": self.seed,
        }


def morris(model: Model, space: InputSpace, *, trajectories: int = 20, levels: int = 4, seed: int = 0) -> Morris:
    """Screen every input of ``space`` by Morris' elementary effects (SALib).

    Parameters
    ----------
    model
        ``(n, space.dim)`` unit-cube points → ``(n,)`` outputs; called once, with every point.
    space
        The inputs (their unit cube is SALib's problem).
    trajectories
        Random one-at-a-time trajectories (>= 2), each of ``d + 1`` runs.
    levels
        Grid levels per input (even, >= 2; SALib's ``num_levels``). A choice input's levels fall in
        its equal shares (4 levels of a 3-way choice: the first, second, third and third choice).
    seed
        Seed of the trajectories and of the bootstrap of μ*'s interval.

    Returns
    -------
    Morris
        μ*, its interval, μ and σ per input (output unit per input range), and the runs used.
    """
    space = _check_space(space)
    trajectories = _check_int("trajectories", trajectories, 2)
    levels = _check_int("levels", levels, 2)
    if levels % 2:
        raise ValueError(f"levels: expected an even integer >= 2, got {levels!r}")
    seed = _check_int("seed", seed, 0)
    problem = _problem(space.names)
    points = morris_sample.sample(problem, trajectories, num_levels=levels, seed=seed)
    y = _evaluate(model, points)
    si = morris_analyze.analyze(
        problem, points, y, num_levels=levels, conf_level=CONF_LEVEL, seed=_derived_seed(seed, 1)
    )
    return Morris(
        inputs=space.names,
        mu_star=tuple(float(v) for v in si["mu_star"]),
        mu_star_conf=tuple(float(v) for v in si["mu_star_conf"]),
        mu=tuple(float(v) for v in si["mu"]),
        sigma=tuple(float(v) for v in si["sigma"]),
        runs=len(points),
        trajectories=trajectories,
        levels=levels,
        seed=seed,
    )


@dataclass(frozen=True)
class Sobol:
    """Sobol' indices of one output over some inputs, the others held.

    Indices are fractions of the output's variance over the analysed inputs (dimensionless):
    ``S1`` the share input ``i`` explains alone (the expected fall of the variance if it were known
    exactly: Saltelli et al. 2008's factor prioritisation), ``ST`` the share it takes part in, its
    interactions included (``ST`` ≈ 0: it can be held at any value: factor fixing).

    Attributes
    ----------
    inputs
        The analysed inputs' names, in the space's order (every per-input field follows it).
    s1, s1_conf
        First-order indices and the half-widths of their 95 % bootstrap intervals.
    st, st_conf
        Total indices and their half-widths.
    s2
        With ``second_order``: ``(name_i, name_j, S2, S2_conf)`` per pair ``i < j``; else empty.
    held
        ``(name, unit coordinate)`` of each input of the space held, in every run, at its nominal.
    n
        Base sample size (a power of 2).
    runs
        Model runs used: ``n (d + 2)``, or ``n (2d + 2)`` with second-order indices.
    mean, variance
        The outputs' mean (output unit) and variance (unit squared) over the runs.
    seed
        The sample's seed.
    """

    inputs: tuple[str, ...]
    s1: tuple[float, ...]
    s1_conf: tuple[float, ...]
    st: tuple[float, ...]
    st_conf: tuple[float, ...]
    s2: tuple[tuple[str, str, float, float], ...]
    held: tuple[tuple[str, float], ...]
    n: int
    runs: int
    mean: float
    variance: float
    seed: int

    def ranked(self, by: Literal["s1", "st"] = "s1") -> tuple[str, ...]:
        """The inputs by ``S1`` (ties by ``ST``) or by ``ST`` (ties by ``S1``), largest first."""
        if by not in ("s1", "st"):
            raise ValueError(f"by: expected 's1' or 'st', got {by!r}")
        first, second = (self.s1, self.st) if by == "s1" else (self.st, self.s1)
        order = sorted(range(len(self.inputs)), key=lambda i: (-first[i], -second[i]))
        return tuple(self.inputs[i] for i in order)

    def to_json(self) -> dict:
        """The record as strict-JSON values (null for a non-finite number)."""
        return {
            "method": "sobol",
            "inputs": list(self.inputs),
            "s1": _finite_or_none(self.s1),
            "s1_conf": _finite_or_none(self.s1_conf),
            "st": _finite_or_none(self.st),
            "st_conf": _finite_or_none(self.st_conf),
            "s2": [[a, b, *_finite_or_none((v, c))] for a, b, v, c in self.s2],
            "held": [[name, q] for name, q in self.held],
            "n": self.n,
            "runs": self.runs,
            "mean": self.mean,
            "variance": self.variance,
            "seed": self.seed,
        }


def _chosen(space: InputSpace, inputs: Sequence[str] | None) -> tuple[str, ...]:
    if inputs is None:
        return space.names
    if isinstance(inputs, str) or not isinstance(inputs, Sequence | set | frozenset):
        raise ValueError(f"inputs: expected a list of input names, got {inputs!r}")
    inputs = list(inputs)
    if not inputs:
        raise ValueError("inputs: expected at least one input name")
    for name in inputs:
        if name not in space.names:
            raise ValueError(f"inputs: no unknown {name!r} in the space (expected some of {', '.join(space.names)})")
    if len(set(inputs)) != len(inputs):
        twice = next(name for name in inputs if inputs.count(name) > 1)
        raise ValueError(f"inputs: {twice!r} named twice")
    return tuple(name for name in space.names if name in inputs)  # the space's order


def _held(
    space: InputSpace, chosen: tuple[str, ...], nominal: Mapping[str, Any] | None
) -> tuple[tuple[str, float], ...]:
    """Unit coordinates of the inputs not analysed: their nominal values, or the cube's centre."""
    if nominal is not None and not isinstance(nominal, Mapping):
        raise ValueError(f"nominal: expected a mapping of input name to value, got {type(nominal).__name__}")
    held = []
    for inp in space.inputs:
        if inp.name in chosen:
            continue
        if nominal is None:
            held.append((inp.name, 0.5))
            continue
        if inp.name not in nominal:
            raise ValueError(f"nominal: no value for {inp.name!r} (held at nominal: it is not among the inputs)")
        value = nominal[inp.name]
        try:
            q = float(inp.to_unit([value])[0])
        except (ValueError, TypeError):
            q = math.nan
        if not 0.0 <= q <= 1.0:
            where = " | ".join(map(str, inp.choices)) if inp.categorical else f"[{inp.low:g}, {inp.high:g}]"
            raise ValueError(f"nominal: {inp.name}={value!r} is outside {where}")
        held.append((inp.name, q))
    return tuple(held)


def sobol(
    model: Model,
    space: InputSpace,
    *,
    inputs: Sequence[str] | None = None,
    n: int = 1024,
    seed: int = 0,
    second_order: bool = False,
    nominal: Mapping[str, Any] | None = None,
) -> Sobol:
    """Sobol' first-order and total indices (SALib: Saltelli's sampling, Saltelli et al. 2010's estimators).

    Parameters
    ----------
    model
        ``(n, space.dim)`` unit-cube points → ``(n,)`` outputs; called once, with every point.
    space
        The inputs.
    inputs
        Names of the inputs to analyse (None: all); the others are held at ``nominal``.
    n
        Base sample size, a power of 2 >= 8 (the estimates' error falls as ~1/√n).
    seed
        Seed of the scrambled Sobol' sample and of the bootstrap of the intervals.
    second_order
        Also estimate the pairs' second-order indices (n (2d + 2) runs instead of n (d + 2)).
    nominal
        Name → value (e.g. :func:`studies.engine.unknowns.nominal` of the registry; names not in the
        space are ignored) of each input held; None holds them at the centre of their unit interval.

    Returns
    -------
    Sobol
        ``S1``, ``ST`` and their 95 % half-widths per analysed input (fractions of the variance).
    """
    space = _check_space(space)
    chosen = _chosen(space, inputs)
    if not isinstance(n, int | np.integer) or isinstance(n, bool) or n < 8 or n & (n - 1):
        raise ValueError(f"n: expected a power of 2 >= 8, got {n!r}")
    seed = _check_int("seed", seed, 0)
    if not isinstance(second_order, bool):
        raise ValueError(f"second_order: expected True or False, got {second_order!r}")
    held = _held(space, chosen, nominal)
    problem = _problem(chosen)
    sample = sobol_sample.sample(problem, int(n), calc_second_order=second_order, seed=seed)
    points = np.empty((len(sample), space.dim))
    columns = {name: j for j, name in enumerate(chosen)}
    coordinates = dict(held)
    for j, name in enumerate(space.names):
        points[:, j] = sample[:, columns[name]] if name in columns else coordinates[name]
    y = _evaluate(model, points)
    if not np.ptp(y) > 0:
        raise ValueError(f"model: every output is {float(y[0])!r}; a constant output has no variance to share out")
    si = sobol_analyze.analyze(
        problem, y, calc_second_order=second_order, conf_level=CONF_LEVEL, seed=_derived_seed(seed, 1)
    )
    s2 = ()
    if second_order:
        s2 = tuple(
            (chosen[i], chosen[k], float(si["S2"][i, k]), float(si["S2_conf"][i, k]))
            for i in range(len(chosen))
            for k in range(i + 1, len(chosen))
        )
    return Sobol(
        inputs=chosen,
        s1=tuple(float(v) for v in si["S1"]),
        s1_conf=tuple(float(v) for v in si["S1_conf"]),
        st=tuple(float(v) for v in si["ST"]),
        st_conf=tuple(float(v) for v in si["ST_conf"]),
        s2=s2,
        held=held,
        n=int(n),
        runs=len(points),
        mean=float(np.mean(y)),
        variance=float(np.var(y)),
        seed=seed,
    )


@dataclass(frozen=True, eq=False)
class EmulatedModel:
    """A Gaussian-process emulator's mean as a :data:`Model`, with how well it predicts left-out runs.

    Call it like a model: ``(n, space.dim)`` unit-cube points → ``(n,)`` emulator means (the
    simulator's run-to-run noise left out: the indices are of the smooth response).

    Attributes
    ----------
    space
        The inputs the emulator was fitted on (its features: :meth:`InputSpace.features`).
    emulator
        The fitted emulator (:func:`~studies.engine.calibration.emulator.fit_emulator`).
    loo
        Its exact leave-one-out :class:`~studies.engine.calibration.emulator.Diagnostics`
        (standardised errors, 68 %/95 % coverage, RMSE in the output's unit).
    output_sd
        Standard deviation of the finished runs' outputs (output unit).
    aliases
        Groups of choice inputs the runs cannot tell apart (:func:`aliased_inputs` of the runs'
        design): the emulator splits their shared effect by its prior, not by the runs.
    """

    space: InputSpace
    emulator: Emulator
    loo: Diagnostics
    output_sd: float
    aliases: tuple[tuple[str, ...], ...] = ()

    @property
    def runs(self) -> int:
        """Direct runs the emulator was fitted to (failed ones left out)."""
        return len(self.emulator.y)

    @property
    def relative_error(self) -> float:
        """LOO RMSE relative to the outputs' spread (dimensionless; NaN for a constant output)."""
        return self.loo.rmse / self.output_sd if self.output_sd > 0 else math.nan

    def __call__(self, points: np.ndarray) -> np.ndarray:
        points = np.atleast_2d(np.asarray(points, dtype=float))
        features = self.space.features(points)
        return np.concatenate(
            [
                predict(self.emulator, features[i : i + _PREDICT_BLOCK], include_noise=False)[0]
                for i in range(0, len(features), _PREDICT_BLOCK)
            ]
            or [np.empty(0)]
        )

    def describe(self) -> str:
        """The sentence a report states beside indices computed on it."""
        coverage = self.loo.coverage_95
        return (
            f"on an emulator of {self.runs} runs, LOO relative error {100 * self.relative_error:.1f} % "
            f"(RMSE / the runs' sd; {100 * coverage:.0f} % of runs inside their 95 % LOO intervals)"
        )


def emulate(
    space: InputSpace,
    design: np.ndarray,
    outputs: np.ndarray,
    *,
    output: str = "",
    kernel: Literal["matern52", "rbf"] = "matern52",
    n_restarts: int = 4,
    seed: int = 0,
) -> EmulatedModel:
    """Fit the calibration's emulator to direct runs; its mean becomes the model of an analysis.

    Parameters
    ----------
    space
        The inputs of the runs.
    design
        ``(n, space.dim)`` unit-cube points of the runs (e.g.
        :func:`studies.engine.calibration.design.sobol`).
    outputs
        ``(n,)`` the output of each run, in its unit; NaN (a failed run) is left out.
    output
        The output's name.
    kernel, n_restarts, seed
        As :func:`~studies.engine.calibration.emulator.fit_emulator` (same seed, same emulator).

    Returns
    -------
    EmulatedModel
        Callable on unit-cube points, with the emulator's leave-one-out diagnostics.
    """
    space = _check_space(space)
    design = np.asarray(design, dtype=float)
    outputs = np.asarray(outputs, dtype=float)
    if design.ndim != 2 or design.shape[1] != space.dim:
        raise ValueError(f"design: expected points of shape (n, {space.dim}), got shape {design.shape}")
    if not np.all((design >= 0.0) & (design <= 1.0)):
        raise ValueError("design: expected unit-cube points (every coordinate in [0, 1])")
    if outputs.shape != (len(design),):
        raise ValueError(f"outputs: expected shape ({len(design)},), one per design point, got {outputs.shape}")
    n_restarts = _check_int("n_restarts", n_restarts, 0)
    seed = _check_int("seed", seed, 0)
    emulator = fit_emulator(
        space.features(design), outputs, output=output, kernel=kernel, n_restarts=n_restarts, seed=seed
    )
    return EmulatedModel(
        space=space,
        emulator=emulator,
        loo=diagnose(emulator),
        output_sd=float(np.std(emulator.y)),
        aliases=aliased_inputs(space, design[np.isfinite(outputs)]),
    )


def aliased_inputs(space: InputSpace, design: np.ndarray) -> tuple[tuple[str, ...], ...]:
    """Groups of choice inputs that a set of runs cannot tell apart.

    Two choice inputs are aliased in a design when they split its runs into the same groups: at
    every run one's choice comes with the same choice of the other (housing white exactly where
    the paper is matched, say), so any effect of the one could as well be the other's. A
    scrambled Sobol' design of few points aliases many two-choice inputs: its coordinates' first
    bits are linear functions of the point's index bits that all hold the lowest one (the first
    direction number is ½ in every dimension), so 16 points split into halves in only 8 ways
    whatever the dimension (31 dimensions: 51 of their 465 pairs aliased), 32 points in 16.
    Inputs that take one choice at every run are left out (no run varies them).

    Parameters
    ----------
    space
        The inputs of the runs.
    design
        ``(n, space.dim)`` unit-cube points of the runs.

    Returns
    -------
    tuple of tuple of str
        Each group of two or more aliased inputs, in the space's order.

    Examples
    --------
    >>> from studies.engine.calibration.inputs import Input, InputSpace
    >>> space = InputSpace((Input("housing", choices=("white", "black")),
    ...                     Input("paper", choices=("matched", "white")), Input("x", 0.0, 1.0)))
    >>> aliased_inputs(space, np.array([[0.2, 0.1, 0.5], [0.7, 0.9, 0.1], [0.3, 0.4, 0.9]]))
    (('housing', 'paper'),)
    """
    design = np.atleast_2d(np.asarray(design, dtype=float))
    groups: dict[tuple[int, ...], list[str]] = {}
    for j, item in enumerate(space.inputs):
        if not item.categorical:
            continue
        split = groups_of(item.choice_index(design[:, j]))
        if max(split) > 0:
            groups.setdefault(split, []).append(item.name)
    return tuple(tuple(names) for names in groups.values() if len(names) > 1)


def _percent(x: float) -> str:
    return f"{100 * max(x, 0.0):.0f} %"


def _label(name: str, unknowns: Mapping[str, Unknown] | None, descriptions: Mapping[str, str] | None) -> str:
    text = (descriptions or {}).get(name)
    if text is None and unknowns is not None and name in unknowns:
        text = unknowns[name].target
    return f"{name} ({text})" if text else name


UNRELIABLE = 0.5
"""LOO relative error of an emulator above which its indices are said not to be acted on (its
held-out predictions miss by half the outputs' spread or more)."""


def explain(
    result: Sobol | Morris,
    output: str = "the output",
    *,
    unknowns: Mapping[str, Unknown] | None = None,
    descriptions: Mapping[str, str] | None = None,
    emulated: EmulatedModel | None = None,
) -> tuple[str, ...]:
    """What the indices say, in sentences, the most important input first.

    Sobol' indices: inputs ranked by their first-order share (what measuring one would remove of
    the variance), each with its total effect; an input acting only through interactions, or with a
    negligible total effect (under :data:`NEGLIGIBLE`), is said so; Σ S1 under
    :data:`INTERACTION_SUM` is stated as interactions. Morris: inputs ranked by μ*.

    Parameters
    ----------
    result
        From :func:`sobol` or :func:`morris`.
    output
        The output's name as it reads in a sentence (``"the far limit"``).
    unknowns
        The registry (:func:`studies.engine.unknowns.load_unknowns`): names its inputs by their target.
    descriptions
        Name → words (``"the LED's luminous intensity bin"``), before the registry's target.
    emulated
        The emulator the indices were computed on: its accuracy is stated.

    Returns
    -------
    tuple of str
    """
    if isinstance(result, Sobol):
        lines = _explain_sobol(result, output, unknowns, descriptions)
    elif isinstance(result, Morris):
        lines = _explain_morris(result, output, unknowns, descriptions)
    else:
        raise ValueError(f"result: expected a Sobol or Morris record, got {type(result).__name__}")
    if emulated is not None:
        if not isinstance(emulated, EmulatedModel):
            raise ValueError(f"emulated: expected an EmulatedModel, got {type(emulated).__name__}")
        lines.append(emulated.describe())
        analysed = set(result.inputs)
        for group in emulated.aliases:
            if analysed.intersection(group):
                names = [_label(name, unknowns, descriptions) for name in group]
                lines.insert(
                    0,
                    f"the {emulated.runs} runs cannot tell {join_words(names)} apart: at every run one's value came "
                    "with the same value of the other, so how their effect splits between them is the "
                    "emulator's guess; more points (--points) would separate them",
                )
        if not emulated.relative_error <= UNRELIABLE:  # (NaN: a constant output, nothing to rank)
            lines.insert(
                0,
                f"do not act on this ranking yet: the emulator misses the runs it leaves out by "
                f"{100 * emulated.relative_error:.0f} % of their spread ({emulated.runs} runs of "
                f"{len(emulated.space.names)} inputs); more points (--points) would decide it",
            )
    return tuple(lines)


def _explain_sobol(r: Sobol, output: str, unknowns, descriptions) -> list[str]:
    lines = []
    for name in r.ranked("s1"):
        i = r.inputs.index(name)
        label = _label(name, unknowns, descriptions)
        s1, st = r.s1[i], r.st[i]
        if st < NEGLIGIBLE:
            lines.append(f"hold {label} at its nominal: its total effect is {_percent(st)} of {output}'s variance")
        elif s1 < NEGLIGIBLE:
            lines.append(
                f"{label} acts only with other inputs: it explains {_percent(s1)} of {output}'s variance alone "
                f"(total effect {_percent(st)})"
            )
        else:
            lines.append(
                f"measure {label}: it explains {_percent(s1)} of {output}'s variance (total effect {_percent(st)})"
            )
    total = sum(r.s1)
    if total < INTERACTION_SUM:
        lines.append(
            f"the indices do not sum to 1: interactions (Σ S1 = {_percent(total)}; the rest of {output}'s "
            "variance comes from inputs acting together)"
        )
    if r.held:
        others = ", ".join(name for name, _ in r.held) if len(r.held) <= 4 else f"the other {len(r.held)}"
        lines.append(f"over {len(r.inputs)} of {len(r.inputs) + len(r.held)} inputs; {others} held at nominal")
    return lines


def _explain_morris(r: Morris, output: str, unknowns, descriptions) -> list[str]:
    lines = []
    largest = max(r.mu_star)
    for name in r.ranked():
        i = r.inputs.index(name)
        label = _label(name, unknowns, descriptions)
        mu_star, sigma = r.mu_star[i], r.sigma[i]
        if not mu_star > NEGLIGIBLE * largest:
            lines.append(f"{label} barely moves {output} (μ* = {mu_star:.3g}): hold it at its nominal")
            continue
        text = (
            f"{label} moves {output} by μ* = {mu_star:.3g} ± {r.mu_star_conf[i]:.2g} over its range (σ = {sigma:.3g})"
        )
        if sigma > mu_star:
            text += ": its effect depends on where the others are (non-linear or interacting)"
        lines.append(text)
    return lines
