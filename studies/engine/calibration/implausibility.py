"""Implausibility: how far an emulated output is from its observation, in standard deviations.

For output j at input x (Craig, Goldstein, Seheult & Smith 1997; Vernon, Goldstein & Bower 2010,
"Galaxy formation: a Bayesian uncertainty analysis")

    I_j(x) = |E[f_j(x)] − z_j| / sqrt(Var_emulator,j(x) + Var_discrepancy,j + Var_observation,j)

(for a bound, ``at_least`` or ``at_most`` z, only the shortfall counts: :meth:`Observation.shortfall`)
and over outputs the largest, second- or third-largest I_j (the second and third tolerate one or two
outputs the model cannot match without ruling out everything on them alone). A point is ruled out
when the combined value exceeds the cut-off, 3 by default: Pukelsheim 1994, "The three sigma rule"
(The American Statistician 48:88-91), shows that for any unimodal distribution at least 95 % of the
probability lies within 3 standard deviations of the mean.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from studies.engine.calibration.observations import Observation

__all__ = ["CUTOFF", "combine", "implausibility", "required_discrepancy_var"]

CUTOFF = 3.0
"""Pukelsheim's 3σ rule."""


def implausibility(mean: np.ndarray, var_emulator: np.ndarray, observations: Sequence[Observation]) -> np.ndarray:
    """Per-output implausibility.

    Parameters
    ----------
    mean, var_emulator
        (n, m): emulator means and variances of the m outputs at n points, in the outputs' units.
    observations
        The m observations, in the same order as the columns.

    Returns
    -------
    (n, m) implausibilities (dimensionless).
    """
    gap = _shortfall(mean, observations)
    other = np.array([o.disc_var + o.obs_var for o in observations])
    total = np.atleast_2d(var_emulator) + other
    with np.errstate(divide="ignore", invalid="ignore"):
        out = gap / np.sqrt(total)
    return np.where((total == 0) & (gap == 0), 0.0, out)


def _shortfall(mean: np.ndarray, observations: Sequence[Observation]) -> np.ndarray:
    """(n, m) distance of each mean from satisfying its observation, the outputs' units."""
    mean = np.atleast_2d(np.asarray(mean, dtype=np.float64))
    return np.column_stack([o.shortfall(mean[:, j]) for j, o in enumerate(observations)])


def combine(per_output: np.ndarray, *, order: int = 1) -> np.ndarray:
    """The ``order``-th largest implausibility over outputs (1: maximum, 2: second largest, ...).

    Parameters
    ----------
    per_output
        (n, m) implausibilities.
    order
        1, 2 or 3, at most m.

    Returns
    -------
    (n,) combined implausibility.
    """
    per_output = np.atleast_2d(per_output)
    m = per_output.shape[1]
    if not 1 <= order <= m:
        raise ValueError(f"order: expected 1..{m} (the number of outputs), got {order!r}")
    return -np.partition(-per_output, order - 1, axis=1)[:, order - 1]


def required_discrepancy_var(
    mean: np.ndarray, var_emulator: np.ndarray, observations: Sequence[Observation], *, cutoff: float = CUTOFF
) -> np.ndarray:
    """The smallest model-discrepancy variance under which each output is not ruled out at each point.

    Solves ``g / sqrt(var_emulator + d + obs_var) = cutoff`` for ``d``, g the shortfall (``|mean − z|``
    for an equality): ``d = g² / cutoff² − var_emulator − obs_var``, clipped at 0.

    Returns
    -------
    (n, m) variances in the outputs' units squared.
    """
    obs = np.array([o.obs_var for o in observations])
    gap = _shortfall(mean, observations)
    return np.maximum(gap**2 / cutoff**2 - np.atleast_2d(var_emulator) - obs, 0.0)
