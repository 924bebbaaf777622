"""What was observed, as records: the value, its measurement uncertainty and the model discrepancy.

The history-matching variance budget (Craig, Goldstein, Seheult & Smith 1997, "Pressure matching
for hydrocarbon reservoirs: a case study in the use of Bayes linear strategies for large computer
experiments"; Vernon, Goldstein & Bower 2010, "Galaxy formation: a Bayesian uncertainty analysis")
separates the observation error (how well ``z`` measures the real system) from the model
discrepancy (how far the simulator at its best input can be from the real system). Each comes
with its reason, so a report can print the budget it was matched under.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["Observation"]


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
    """

    name: str
    z: float
    obs_var: float
    disc_var: float
    obs_reason: str = ""
    disc_reason: str = ""
    unit: str = ""

    def __post_init__(self) -> None:
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
        }

    @staticmethod
    def from_json(d: Mapping) -> Observation:
        """The record from :meth:`to_json`'s values."""
        return Observation(**d)
