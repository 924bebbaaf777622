"""What was observed, as records: the value, its measurement uncertainty and the model discrepancy.

The history-matching variance budget (Craig, Goldstein, Seheult & Smith 1997, "Pressure matching
for hydrocarbon reservoirs: a case study in the use of Bayes linear strategies for large computer
experiments"; Vernon, Goldstein & Bower 2010, "Galaxy formation: a Bayesian uncertainty analysis")
separates the observation error (how well ``z`` measures the real system) from the model
discrepancy (how far the simulator at its best input can be from the real system). Each comes
with its reason, so a report can print the budget it was matched under.

An observation is an equality (the output was measured to be ``z``) or a bound (``at_least`` /
``at_most`` ``z``: what a yes-or-no observation implies of a continuous output, e.g. "the blobs were
found" implies "the closed region was at least as tall as the erosion needs"); a bound is matched
by every value on its side, and its implausibility counts only the shortfall (Vernon, Goldstein &
Bower 2010 treat such one-sided constraints the same way).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["KINDS", "Observation"]

KINDS = ("equal", "at_least", "at_most")
"""How an observation constrains its output."""


@dataclass(frozen=True)
class Observation:
    """One observed output.

    Attributes
    ----------
    name
        Name of the simulator output it observes (the column of ``simulate``'s result).
    z
        The observed value, in the output's unit.
    obs_var
        Observation-error variance, in the output's unit squared (>= 0).
    disc_var
        Model-discrepancy variance, in the output's unit squared (>= 0).
    obs_reason, disc_reason
        Why these variances (the measurement, the model's known gaps).
    unit
        Unit of ``z`` (empty if dimensionless).
    kind
        ``equal`` (default), ``at_least`` or ``at_most`` (:data:`KINDS`).
    """

    name: str
    z: float
    obs_var: float
    disc_var: float
    obs_reason: str = ""
    disc_reason: str = ""
    unit: str = ""
    kind: str = "equal"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"{self.name}.kind: expected one of {', '.join(KINDS)}, got {self.kind!r}")
        for field in ("z", "obs_var", "disc_var"):
            if not math.isfinite(getattr(self, field)):
                raise ValueError(f"{self.name}.{field}: must be finite, got {getattr(self, field)!r}")
        if self.obs_var < 0 or self.disc_var < 0:
            raise ValueError(f"{self.name}: variances must be >= 0")

    def to_json(self) -> dict:
        """The record as JSON-able values."""
        return {
            "name": self.name,
            "z": self.z,
            "obs_var": self.obs_var,
            "disc_var": self.disc_var,
            "obs_reason": self.obs_reason,
            "disc_reason": self.disc_reason,
            "unit": self.unit,
            "kind": self.kind,
        }

    @staticmethod
    def from_json(d: Mapping) -> Observation:
        """The record from :meth:`to_json`'s values (records written before ``kind`` are equalities)."""
        return Observation(**d)

    def shortfall(self, value):
        """How far ``value`` (a number or array, the output's unit) is from satisfying the observation:
        ``|value − z|`` for an equality, the part below ``z`` for ``at_least``, above it for ``at_most``."""
        diff = np.asarray(value, dtype=np.float64) - self.z
        if self.kind == "at_least":
            return np.maximum(-diff, 0.0)
        if self.kind == "at_most":
            return np.maximum(diff, 0.0)
        return np.abs(diff)
