"""History matching in waves: rule out the inputs whose emulated outputs cannot match the observations.

Wave k (Vernon, Goldstein & Bower 2010, "Galaxy formation: a Bayesian uncertainty analysis";
Andrianakis et al. 2015, "Bayesian history matching of complex infectious disease models using
emulation: a tutorial and a case study on HIV in Uganda"):

1. a space-filling design (scrambled Sobol', seeded, greedy maximin subset) inside the region
   not ruled out by waves 1 … k−1 (:mod:`~studies.engine.calibration.design`);
2. the simulator at those points, through the caller's ``simulate(values) -> outputs`` (a list
   of name → value dicts in, an (n, m) array out in the order of the observations, NaN for a
   failed run), so the real simulator can run them in parallel, on Dask, or resume;
3. one emulator per output (:mod:`~studies.engine.calibration.emulator`), fitted on this wave's
   runs and the earlier runs inside this wave's region, with leave-one-out (and, if asked,
   held-out) diagnostics;
4. the implausibility of every point of a fixed large Sobol' sample of the whole space
   (:mod:`~studies.engine.calibration.implausibility`): a point is not ruled out yet (NROY) when
   every wave so far finds its combined implausibility at most the cut-off; their share is the
   NROY fraction of the original space.

Waves go on until ``max_waves``, or once ``min_waves`` are done, until the NROY fraction shrinks
by less than ``shrink_tol`` of itself; they stop at once if nothing is left. The result says, for
each observation, the smallest model-discrepancy standard deviation under which some point is
not ruled out by that observation alone, and at the point that matches all of them best.

The result is strict JSON (:func:`to_json`: no NaN or Infinity, null instead), and
``history_match(..., resume=from_json(text))`` continues after its last wave: a long run can be
written after each wave (``on_wave``) and picked up where it stopped.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from studies.engine.calibration.design import maximin_subset, sample_region, sobol
from studies.engine.calibration.emulator import Diagnostics, Emulator, diagnose, fit_emulator, predict
from studies.engine.calibration.implausibility import CUTOFF, combine, implausibility, required_discrepancy_var
from studies.engine.calibration.inputs import InputSpace
from studies.engine.calibration.observations import Observation

__all__ = [
    "FORMAT",
    "DiscrepancyNeed",
    "HistoryMatch",
    "Settings",
    "Wave",
    "closest_points",
    "discrepancy_needs",
    "from_json",
    "history_match",
    "nroy_mask",
    "nroy_sample",
    "observation_shares",
    "reference_implausibility",
    "to_json",
    "wave_implausibility",
]

FORMAT = "beacon-sim history match 1"
Simulate = Callable[[list[dict[str, Any]]], Any]


@dataclass(frozen=True)
class Settings:
    """Options of a history match.

    Attributes
    ----------
    n_per_wave
        Simulator runs per wave that train the emulators.
    n_validation
        Further runs per wave held out to validate them (0: leave-one-out only).
    min_waves, max_waves
        Waves run at least (unless NROY is empty) and at most.
    shrink_tol
        After ``min_waves``: stop when a wave shrinks the NROY fraction by less than this share of it.
    seed
        Seed of every random choice (designs, reference sample, optimiser restarts).
    cutoff
        Implausibility cut-off (3: Pukelsheim's rule).
    order
        Combine outputs by the largest (1), second (2) or third (3) largest implausibility.
    n_reference
        Size of the fixed Sobol' sample of the whole space the NROY fraction is estimated on (a power of 2).
    kernel
        ``matern52`` or ``rbf``.
    n_restarts
        Optimiser restarts per emulator.
    include_simulator_noise
        Count the simulator's run-to-run variance (the emulators' white-noise term) in the
        implausibility's emulator variance: the observation is one noisy realisation, as a run is.
    reuse_runs
        Train a wave's emulators also on earlier waves' runs inside its region.
    max_candidates
        Most Sobol' points drawn to find a wave's design in the current region.
    pool_factor
        The design is a maximin subset of ``pool_factor × runs`` candidates inside the region.
    """

    n_per_wave: int = 40
    n_validation: int = 0
    min_waves: int = 3
    max_waves: int = 5
    shrink_tol: float = 0.05
    seed: int = 0
    cutoff: float = CUTOFF
    order: int = 1
    n_reference: int = 2**14
    kernel: str = "matern52"
    n_restarts: int = 4
    include_simulator_noise: bool = True
    reuse_runs: bool = True
    max_candidates: int = 2**18
    pool_factor: int = 8

    def __post_init__(self) -> None:
        if self.n_per_wave < 3 or self.n_validation < 0:
            raise ValueError("Settings: n_per_wave >= 3 and n_validation >= 0")
        if not 1 <= self.min_waves <= self.max_waves:
            raise ValueError("Settings: 1 <= min_waves <= max_waves")
        if self.order not in (1, 2, 3):
            raise ValueError(f"Settings.order: expected 1, 2 or 3, got {self.order!r}")
        if self.n_reference < 1 or self.n_reference & (self.n_reference - 1):
            raise ValueError(f"Settings.n_reference: expected a power of 2, got {self.n_reference!r}")
        if not self.cutoff > 0:
            raise ValueError("Settings.cutoff: expected > 0")


@dataclass(frozen=True, eq=False)
class Wave:
    """One wave.

    Attributes
    ----------
    index
        1, 2, …
    design
        (n, d) the wave's runs as unit-cube points.
    outputs
        (n, m) what the simulator returned (NaN: a failed run), in the observations' order.
    held_out
        (n,) True for the runs held out to validate the emulators.
    emulators
        One per output.
    loo, validation
        Each emulator's leave-one-out and held-out diagnostics (``validation`` empty without held-out runs).
    region_fraction
        Share of the Sobol' candidates inside the wave's region (waves before it): a second,
        independent estimate of the previous wave's NROY fraction.
    nroy_fraction
        Share of the reference sample not ruled out by this wave and every earlier one.
    """

    index: int
    design: np.ndarray
    outputs: np.ndarray
    held_out: np.ndarray
    emulators: tuple[Emulator, ...]
    loo: tuple[Diagnostics, ...]
    validation: tuple[Diagnostics, ...]
    region_fraction: float
    nroy_fraction: float


@dataclass(frozen=True)
class DiscrepancyNeed:
    """How much model discrepancy one observation needs before some point matches it.

    Attributes
    ----------
    observation
        Its name.
    stated_sd
        The stated discrepancy standard deviation √disc_var, output unit.
    alone_sd
        Smallest discrepancy sd under which some point is not ruled out by this observation alone.
    joint_sd
        The discrepancy sd it needs at the point that matches all observations best (the least
        combined implausibility).
    rules_out_alone
        Whether this observation alone rules out every point at the stated discrepancy.
    """

    observation: str
    stated_sd: float
    alone_sd: float
    joint_sd: float
    rules_out_alone: bool


@dataclass(frozen=True, eq=False)
class HistoryMatch:
    """A history match, wave by wave.

    Attributes
    ----------
    space, observations, settings
        What was matched, and how.
    waves
        The waves run.
    stopped
        Why it stopped: ``nroy empty``, ``max waves``, ``stopped shrinking``, ``region too small``.
    nroy_points
        (k, d) unit-cube points of the reference sample not ruled out by any wave.
    discrepancy
        One :class:`DiscrepancyNeed` per observation (from the last wave's emulators, over its region).
    """

    space: InputSpace
    observations: tuple[Observation, ...]
    settings: Settings
    waves: tuple[Wave, ...]
    stopped: str
    nroy_points: np.ndarray
    discrepancy: tuple[DiscrepancyNeed, ...]

    @property
    def nroy_fraction(self) -> float:
        """The last wave's NROY fraction of the original space."""
        return self.waves[-1].nroy_fraction if self.waves else 1.0

    def nroy_values(self) -> list[dict[str, Any]]:
        """The NROY points as name → value dicts."""
        return self.space.values(self.nroy_points) if len(self.nroy_points) else []


def _seed(*path: int) -> int:
    return int(np.random.SeedSequence(list(path)).generate_state(1)[0])


def reference_points(space: InputSpace, settings: Settings) -> np.ndarray:
    """The fixed Sobol' sample (n_reference, d) of the whole space the NROY fraction is estimated on."""
    return sobol(settings.n_reference, space.dim, seed=_seed(settings.seed, 0))


def wave_implausibility(
    wave: Wave, space: InputSpace, observations: Sequence[Observation], settings: Settings, q: np.ndarray
) -> np.ndarray:
    """(n, m) per-output implausibility of unit points ``q`` under one wave's emulators."""
    features = space.features(q)
    means, variances = zip(
        *(predict(e, features, include_noise=settings.include_simulator_noise) for e in wave.emulators), strict=True
    )
    return implausibility(np.column_stack(means), np.column_stack(variances), observations)


def _ruled_out_by(wave: Wave, space: InputSpace, obs: Sequence[Observation], settings: Settings, q) -> np.ndarray:
    return combine(wave_implausibility(wave, space, obs, settings, q), order=settings.order) > settings.cutoff


def _inside(waves: Sequence[Wave], space, obs, settings, q: np.ndarray) -> np.ndarray:
    keep = np.ones(len(q), dtype=bool)
    for wave in waves:
        if keep.any():
            keep[keep] = ~_ruled_out_by(wave, space, obs, settings, q[keep])
    return keep


def nroy_mask(result: HistoryMatch, q: np.ndarray) -> np.ndarray:
    """(n,) True where unit points ``q`` are not ruled out by any of the result's waves."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return _inside(result.waves, result.space, result.observations, result.settings, q)


def nroy_sample(result: HistoryMatch, n: int, *, max_points: int | None = None) -> tuple[np.ndarray, int]:
    """Up to ``n`` points of the whole space not ruled out by any wave: scrambled Sobol' points (seeded
    by the match's seed) drawn in blocks until ``n`` pass or ``max_points`` (default 4 ×
    ``Settings.max_candidates``) were drawn, in Sobol' order.

    The reference sample estimates the NROY fraction; when that fraction is small it holds only a
    handful of survivors, too few to predict from (:mod:`studies.catalog.prediction_set` takes 20);
    this draws the set a prediction is made from.

    Returns
    -------
    points, drawn
        (k ≤ n, d) unit points and how many were drawn to find them (k / drawn estimates the NROY
        fraction again).
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n: expected an integer >= 1, got {n!r}")
    limit = 4 * result.settings.max_candidates if max_points is None else max_points
    if not result.waves or result.nroy_fraction == 0:  # empty on the reference sample: the match says so
        return np.empty((0, result.space.dim)), 0
    region = sample_region(
        lambda q: nroy_mask(result, q),
        result.space.dim,
        n_wanted=n,
        seed=_seed(result.settings.seed, 4),
        max_points=limit,
    )
    return region.points[:n], region.n_drawn


def observation_shares(result: HistoryMatch) -> tuple[np.ndarray, np.ndarray]:
    """What each observation does to the whole space under the first wave's emulators (the only ones
    trained over all of it), on the reference sample.

    Returns
    -------
    alone
        (m,) share of the space observation j rules out by itself (its implausibility above the cut-off).
    without
        (m,) share not ruled out by the other observations (combined as the match combines them, at most
        the order their number allows): how much room there would be without observation j.
    """
    m = len(result.observations)
    if not result.waves:
        return np.zeros(m), np.ones(m)
    q = reference_points(result.space, result.settings)
    per = wave_implausibility(result.waves[0], result.space, result.observations, result.settings, q)
    alone = (per > result.settings.cutoff).mean(axis=0)
    without = np.ones(m)
    for j in range(m):
        rest = np.delete(per, j, axis=1)
        if rest.shape[1]:
            order = min(result.settings.order, rest.shape[1])
            without[j] = float((combine(rest, order=order) <= result.settings.cutoff).mean())
    return alone, without


def reference_implausibility(result: HistoryMatch) -> tuple[np.ndarray, np.ndarray]:
    """The reference sample and each point's implausibility over the waves.

    Returns
    -------
    q
        (n_reference, d) unit points.
    implausibility
        (n_reference,) the largest over waves of each wave's combined implausibility (a point is
        NROY where it is at most the cut-off); the quantity of minimum-implausibility plots.
    """
    q = reference_points(result.space, result.settings)
    worst = np.zeros(len(q))
    for wave in result.waves:
        c = combine(
            wave_implausibility(wave, result.space, result.observations, result.settings, q),
            order=result.settings.order,
        )
        worst = np.maximum(worst, c)
    return q, worst


def closest_points(result: HistoryMatch, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` reference points with the lowest implausibility over the waves
    (:func:`reference_implausibility`), lowest first: what a prediction can be made from, *said so*,
    when nothing survives the cut-off (each point's implausibility is returned beside it).

    Returns
    -------
    points, implausibility
        (k ≤ n, d) unit points and their (k,) implausibility.
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n: expected an integer >= 1, got {n!r}")
    q, worst = reference_implausibility(result)
    order = np.argsort(worst, kind="stable")[:n]
    return q[order], worst[order]


def discrepancy_needs(
    waves: Sequence[Wave], space: InputSpace, observations: Sequence[Observation], settings: Settings
) -> tuple[DiscrepancyNeed, ...]:
    """The discrepancy each observation needs, from the last wave's emulators over its region.

    The region is the reference sample's points not ruled out by the waves before the last (the
    last wave's emulators were trained there; the whole space for a single wave). At each point
    the emulator mean and variance give the smallest discrepancy variance that brings that
    output's implausibility down to the cut-off (:func:`required_discrepancy_var`); ``alone_sd``
    is its minimum over the region, ``joint_sd`` its value at the point of least combined
    implausibility under the stated variances.
    """
    if not waves:
        return ()
    q = reference_points(space, settings)
    q = q[_inside(waves[:-1], space, observations, settings, q)]
    if not len(q):
        nan = float("nan")
        return tuple(DiscrepancyNeed(o.name, math.sqrt(o.disc_var), nan, nan, True) for o in observations)
    features = space.features(q)
    means, variances = zip(
        *(predict(e, features, include_noise=settings.include_simulator_noise) for e in waves[-1].emulators),
        strict=True,
    )
    mean, var = np.column_stack(means), np.column_stack(variances)
    need = required_discrepancy_var(mean, var, observations, cutoff=settings.cutoff)
    per_output = implausibility(mean, var, observations)
    best = int(np.argmin(combine(per_output, order=settings.order)))
    return tuple(
        DiscrepancyNeed(
            observation=o.name,
            stated_sd=math.sqrt(o.disc_var),
            alone_sd=float(np.sqrt(need[:, j].min())),
            joint_sd=float(np.sqrt(need[best, j])),
            rules_out_alone=bool(np.all(per_output[:, j] > settings.cutoff)),
        )
        for j, o in enumerate(observations)
    )


def _run(simulate: Simulate, space: InputSpace, q: np.ndarray, m: int) -> np.ndarray:
    out = np.asarray(simulate(space.values(q)), dtype=float)
    if out.shape != (len(q), m):
        raise ValueError(f"simulate: expected outputs of shape {(len(q), m)}, got {out.shape}")
    return out


def _wave(
    k: int, simulate: Simulate, space: InputSpace, obs: tuple[Observation, ...], settings: Settings, earlier
) -> Wave | None:
    """Run wave ``k`` (None if its region is too small to design in)."""
    n_total = settings.n_per_wave + settings.n_validation
    region = sample_region(
        lambda q: _inside(earlier, space, obs, settings, q),
        space.dim,
        n_wanted=settings.pool_factor * n_total,
        seed=_seed(settings.seed, 1, k),
        max_points=settings.max_candidates,
    )
    if len(region.points) < n_total:
        return None
    design = region.points[maximin_subset(region.points, n_total)]
    outputs = _run(simulate, space, design, len(obs))
    held_out = np.zeros(n_total, dtype=bool)
    if settings.n_validation:
        rng = np.random.default_rng(_seed(settings.seed, 3, k))
        held_out[rng.choice(n_total, settings.n_validation, replace=False)] = True
    train_q, train_y = [design[~held_out]], [outputs[~held_out]]
    if settings.reuse_runs and earlier:
        for w in earlier:
            q_w, y_w = w.design[~w.held_out], w.outputs[~w.held_out]
            inside = _inside(earlier, space, obs, settings, q_w)
            train_q.append(q_w[inside])
            train_y.append(y_w[inside])
    x, y = space.features(np.vstack(train_q)), np.vstack(train_y)
    emulators = tuple(
        fit_emulator(
            x,
            y[:, j],
            output=o.name,
            kernel=settings.kernel,
            n_restarts=settings.n_restarts,
            seed=_seed(settings.seed, 2, k, j),
        )
        for j, o in enumerate(obs)
    )
    validation = ()
    if settings.n_validation:
        xv = space.features(design[held_out])
        validation = tuple(diagnose(e, xv, outputs[held_out, j]) for j, e in enumerate(emulators))
    return Wave(
        index=k,
        design=design,
        outputs=outputs,
        held_out=held_out,
        emulators=emulators,
        loo=tuple(diagnose(e) for e in emulators),
        validation=validation,
        region_fraction=len(region.points) / region.n_drawn,
        nroy_fraction=float("nan"),
    )


def _stop(waves: Sequence[Wave], settings: Settings) -> str:
    if not waves:
        return ""
    k, frac = len(waves), waves[-1].nroy_fraction
    if frac == 0:
        return "nroy empty"
    if k >= settings.max_waves:
        return "max waves"
    previous = waves[-2].nroy_fraction if k > 1 else 1.0
    if k >= settings.min_waves and frac >= (1 - settings.shrink_tol) * previous:
        return "stopped shrinking"
    return ""


def history_match(
    simulate: Simulate,
    space: InputSpace,
    observations: Sequence[Observation],
    *,
    settings: Settings | None = None,
    resume: HistoryMatch | None = None,
    on_wave: Callable[[HistoryMatch], None] | None = None,
) -> HistoryMatch:
    """History-match ``simulate`` to ``observations`` over ``space``, in waves.

    Parameters
    ----------
    simulate
        ``simulate(values) -> outputs``: a list of n name → value dicts (:meth:`InputSpace.values`)
        in, an (n, m) array-like out, column j the output ``observations[j].name`` (NaN: a failed run).
    space
        The inputs.
    observations
        The m observed outputs.
    settings
        Options (:class:`Settings`; defaults if None).
    resume
        An earlier result of the same space, observations and settings (``min_waves`` and
        ``max_waves`` may differ): its waves are kept and the match goes on after them.
    on_wave
        Called with the result so far after each wave (e.g. to write :func:`to_json`).

    Returns
    -------
    HistoryMatch
    """
    settings = Settings() if settings is None else settings
    obs = tuple(observations)
    if len({o.name for o in obs}) != len(obs) or not obs:
        raise ValueError("observations: expected at least one, with distinct names")
    if settings.order > len(obs):
        raise ValueError(f"Settings.order={settings.order} needs at least that many observations, got {len(obs)}")
    waves: list[Wave] = []
    if resume is not None:
        same = dataclasses.replace(resume.settings, min_waves=settings.min_waves, max_waves=settings.max_waves)
        if resume.space != space or resume.observations != obs or same != settings:
            raise ValueError("resume: the earlier result was made with another space, observations or settings")
        waves = list(resume.waves)
    q_ref = reference_points(space, settings)
    mask = _inside(waves, space, obs, settings, q_ref)
    stopped = _stop(waves, settings) if resume is None or resume.stopped != "region too small" else resume.stopped
    while not stopped:
        wave = _wave(len(waves) + 1, simulate, space, obs, settings, tuple(waves))
        if wave is None:
            stopped = "region too small"
            break
        if mask.any():
            mask[mask] = ~_ruled_out_by(wave, space, obs, settings, q_ref[mask])
        waves.append(dataclasses.replace(wave, nroy_fraction=float(mask.mean())))
        stopped = _stop(waves, settings)
        if on_wave is not None:
            on_wave(_result(space, obs, settings, waves, stopped or "running", q_ref[mask]))
    return _result(space, obs, settings, waves, stopped, q_ref[mask])


def _result(space, obs, settings, waves, stopped, nroy_points) -> HistoryMatch:
    return HistoryMatch(
        space=space,
        observations=obs,
        settings=settings,
        waves=tuple(waves),
        stopped=stopped,
        nroy_points=nroy_points,
        discrepancy=discrepancy_needs(waves, space, obs, settings),
    )


# --- strict JSON ---------------------------------------------------------------------------


def _strict(x: Any) -> Any:
    """JSON-able values with NaN and ±Infinity as None."""
    if isinstance(x, dict):
        return {k: _strict(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_strict(v) for v in x]
    if isinstance(x, np.ndarray):
        return _strict(x.tolist())
    if isinstance(x, np.generic):
        return _strict(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _array(x: Any, columns: int) -> np.ndarray:
    a = np.array([[np.nan if v is None else v for v in row] for row in x], dtype=float)
    return a.reshape(len(x), columns)


def to_json(result: HistoryMatch) -> str:
    """The result as strict JSON text (sorted keys; NaN and Infinity written as null)."""
    doc = {
        "format": FORMAT,
        "space": result.space.to_json(),
        "observations": [o.to_json() for o in result.observations],
        "settings": dataclasses.asdict(result.settings),
        "stopped": result.stopped,
        "nroy_fraction": result.nroy_fraction,
        "waves": [
            {
                "index": w.index,
                "design": w.design,
                "design_values": result.space.values(w.design),
                "outputs": w.outputs,
                "held_out": w.held_out.tolist(),
                "emulators": [e.to_json() for e in w.emulators],
                "loo": [d.to_json() for d in w.loo],
                "validation": [d.to_json() for d in w.validation],
                "region_fraction": w.region_fraction,
                "nroy_fraction": w.nroy_fraction,
            }
            for w in result.waves
        ],
        "nroy_points": result.nroy_points,
        "nroy_values": result.nroy_values(),
        "discrepancy": [dataclasses.asdict(d) for d in result.discrepancy],
    }
    return json.dumps(_strict(doc), sort_keys=True, allow_nan=False, indent=1) + "\n"


def from_json(text: str) -> HistoryMatch:
    """A result from :func:`to_json`'s text (its emulators rebuilt: they predict as before)."""
    doc = json.loads(text)
    if doc.get("format") != FORMAT:
        raise ValueError(f"from_json: not a history match ({FORMAT!r}), got format {doc.get('format')!r}")
    space = InputSpace.from_json(doc["space"])
    obs = tuple(Observation.from_json(o) for o in doc["observations"])
    m = len(obs)
    waves = tuple(
        Wave(
            index=w["index"],
            design=_array(w["design"], space.dim),
            outputs=_array(w["outputs"], m),
            held_out=np.array(w["held_out"], dtype=bool),
            emulators=tuple(Emulator.from_json(e) for e in w["emulators"]),
            loo=tuple(Diagnostics.from_json(d) for d in w["loo"]),
            validation=tuple(Diagnostics.from_json(d) for d in w["validation"]),
            region_fraction=float(w["region_fraction"]),
            nroy_fraction=float(w["nroy_fraction"]),
        )
        for w in doc["waves"]
    )
    nan = float("nan")
    return HistoryMatch(
        space=space,
        observations=obs,
        settings=Settings(**doc["settings"]),
        waves=waves,
        stopped=doc["stopped"],
        nroy_points=_array(doc["nroy_points"], space.dim),
        discrepancy=tuple(
            DiscrepancyNeed(**{k: nan if v is None else v for k, v in d.items()}) for d in doc["discrepancy"]
        ),
    )
