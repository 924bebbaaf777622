"""Wheel odometry of a robot on loose sand: what it reports for a path, and how wrong it may be.

A step of true length d and heading change Δθ is reported as

    d̂ = d (1 + b) + σ_d √d n₁,     Δθ̂ = Δθ + σ_θ √d n₂,     n₁, n₂ ~ N(0, 1),

with b the systematic over-count (wheels that slip turn more than the ground they cover, so a
slipping robot believes it went farther: b = s / (1 − s) for a slip ratio s), σ_d
(``scale_sd``, m per √m) a random length error whose variance grows with distance, and σ_θ
(``heading_sd_rad``, rad per √m) a heading error from unequal slip of the two sides. The
numbers are unknowns with ranges (:data:`LOOSE_SAND`): the source study's robots met fine sand in
a lava tube where wheel odometry failed, and laser-based relative localisation there drifted ~2 %
of distance (0.63 m over a 79.6 m loop); Mars rovers saw slip up to 125 % in loose material (both
as issue 28 reports them). The model is first-order (no wheel-sinkage dynamics) and draws every
step's noise independently.

The slip is the run's ``slip`` s̄, or, with ``slip_sd`` σ_s > 0, changes along the run as the sand
does: s(x) = clip(s̄ + σ_s z(x), 0, 0.95) with z a unit Ornstein-Uhlenbeck process in the distance
driven x, correlation exp(−|Δx| / ℓ) (``slip_correlation_m`` ℓ), started from its stationary law.
Over a short distance Δx the slip (and the scale 1 − s a filter learns) then wanders with variance
2 σ_s² Δx / ℓ (:attr:`WheelOdometry.scale_walk_per_m`).

Example
-------
>>> odo = WheelOdometry(slip=0.2, scale_sd=0.0, heading_sd_rad=0.0)
>>> d, dtheta = odo.report([1.0, 1.0], [0.0, 0.1], seed=0)
>>> [round(float(x), 3) for x in d], [round(float(x), 3) for x in dtheta]
([1.25, 1.25], [0.0, 0.1])
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LOOSE_SAND", "WheelOdometry", "scale_prior"]


@dataclass(frozen=True)
class WheelOdometry:
    """A wheel-odometry error model (module docstring).

    Attributes
    ----------
    slip
        Slip ratio s of the traverse (0 ≤ s < 1): the odometer over-counts by s / (1 − s).
    scale_sd
        σ_d, random length error, m per √m of travel.
    heading_sd_rad
        σ_θ, random heading error, rad per √m of travel.
    slip_sd
        σ_s, standard deviation of the slip about ``slip`` along the run (0: constant slip).
    slip_correlation_m
        ℓ, distance over which the slip's changes are correlated by 1/e, m.
    """

    slip: float = 0.2
    scale_sd: float = 0.05
    heading_sd_rad: float = 0.02
    slip_sd: float = 0.0
    slip_correlation_m: float = 10.0

    def __post_init__(self) -> None:
        if not 0 <= self.slip < 1:
            raise ValueError(f"slip: expected a slip ratio in [0, 1), got {self.slip!r}")
        for name in ("scale_sd", "heading_sd_rad", "slip_sd"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: expected a standard deviation >= 0, got {value!r}")
        if not (math.isfinite(self.slip_correlation_m) and self.slip_correlation_m > 0):
            raise ValueError(f"slip_correlation_m: expected a length > 0 m, got {self.slip_correlation_m!r}")

    @property
    def bias(self) -> float:
        """The systematic over-count b = s / (1 − s) at the run's mean slip."""
        return self.slip / (1 - self.slip)

    @property
    def scale_walk_per_m(self) -> float:
        """Variance per metre (1/m) with which the slip, and the scale 1 − s, wander over short
        distances: 2 σ_s² / ℓ (0 for a constant slip)."""
        return 2 * self.slip_sd**2 / self.slip_correlation_m

    def slip_along(self, steps_m: Sequence[float], *, seed: int) -> NDArray[np.float64]:
        """The slip ratio of each step (module docstring): ``slip`` everywhere when ``slip_sd`` is 0.

        ``seed`` is the one :meth:`report` takes, so both see the same slip.

        >>> odo = WheelOdometry(slip=0.3, slip_sd=0.1, slip_correlation_m=5.0)
        >>> s = odo.slip_along([0.25] * 4000, seed=1)
        >>> bool(0.0 <= s.min() and s.max() <= 0.95), round(float(s.std()), 1)
        (True, 0.1)
        """
        d = np.asarray(steps_m, dtype=float)
        if not self.slip_sd or d.size == 0:
            return np.full(d.shape, self.slip)
        rng = np.random.default_rng([seed, 1])  # a stream of its own: report's noise stays as it was
        n = rng.standard_normal(d.shape)
        rho = np.exp(-np.concatenate([[0.0], d[:-1]]) / self.slip_correlation_m)  # from step i-1's start to i's
        z = np.empty(d.shape)
        z[0] = n[0]
        for i in range(1, d.size):
            z[i] = rho[i] * z[i - 1] + math.sqrt(1 - rho[i] ** 2) * n[i]
        return np.clip(self.slip + self.slip_sd * z, 0.0, 0.95)

    def report(
        self, steps_m: Sequence[float], turns_rad: Sequence[float], *, seed: int
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """What the odometer reports for true steps (m) and heading changes (rad): (d̂, Δθ̂)."""
        d = np.asarray(steps_m, dtype=float)
        turns = np.asarray(turns_rad, dtype=float)
        if d.shape != turns.shape or (d < 0).any():
            raise ValueError("steps_m: expected lengths >= 0 m, one per turn")
        rng = np.random.default_rng(seed)
        root = np.sqrt(d)
        noise = rng.standard_normal((2, *d.shape))
        slip = self.slip_along(d, seed=seed)
        reported = d / (1 - slip) if self.slip_sd else d * (1 + self.bias)
        return reported + self.scale_sd * root * noise[0], turns + self.heading_sd_rad * root * noise[1]

    def step_covariance(self, step_m: float, *, bias: bool = True) -> NDArray[np.float64]:
        """Covariance of one reported step (length m², heading rad²) as a filter assumes it: the noise
        terms plus, with ``bias``, the bias, which a three-state filter cannot know, taken as a
        zero-mean error of sd b·d (a filter with the scale as a state, :mod:`pipeline.ekf`, leaves it out)."""
        d = float(step_m)
        return np.diag([self.scale_sd**2 * d + (self.bias * d * bias) ** 2, self.heading_sd_rad**2 * d])


def scale_prior(slip: tuple[float, float] = (0.05, 0.5)) -> tuple[float, float]:
    """Mean and sd of the odometer's scale k = 1 − s (true length per reported length) for a slip s
    uniform on ``slip`` (default :data:`LOOSE_SAND`'s): the prior of :mod:`pipeline.ekf`'s scale state.

    >>> [round(v, 4) for v in scale_prior((0.05, 0.5))]
    [0.725, 0.1299]
    """
    low, high = slip
    return 1.0 - (low + high) / 2, (high - low) / math.sqrt(12.0)


LOOSE_SAND = {
    "slip": (0.05, 0.5),
    "scale_sd": (0.02, 0.1),
    "heading_sd_rad": (0.005, 0.05),
    "slip_sd": (0.0, 0.15),
    "slip_correlation_m": (2.0, 20.0),
}
"""Ranges of the model's unknowns on loose sand (assumed): slip from a few per cent on firm sand to
half on the fine sand where the study's wheel odometry failed (Mars rovers reached 125 % on slopes,
beyond the model); scale noise and heading noise per √m spanning well-behaved to poor odometry (a
laser-based relative localisation drifted ~2 % of distance in the same tube, a bound odometry on
sand does not beat); the slip's change along a run from none (one kind of sand throughout) to a
standard deviation of 0.15 (a third of the slip range: firm and loose patches alternating), over
2-20 m (sand patches a tube-width or two to a few tube-widths long). The traverse draws the slip per
run from the first range and keeps it constant unless told the slip's sd and correlation."""
