"""History matching of the simulator to observations with Gaussian-process emulators (issue 25).

One concept per module: the inputs (:mod:`.inputs`), the observations (:mod:`.observations`), the
emulators and their diagnostics (:mod:`.emulator`), implausibility (:mod:`.implausibility`),
space-filling designs (:mod:`.design`), the waves and their strict-JSON record (:mod:`.waves`),
and the figures (:mod:`.plots`, kept apart from the numerics). The names below are the package's
public interface.
"""

from studies.engine.calibration.emulator import Diagnostics, Emulator, diagnose, fit_emulator, loo, predict
from studies.engine.calibration.implausibility import CUTOFF, combine, implausibility, required_discrepancy_var
from studies.engine.calibration.inputs import Input, InputSpace
from studies.engine.calibration.observations import KINDS, Observation
from studies.engine.calibration.plots import write_figures
from studies.engine.calibration.waves import (
    DiscrepancyNeed,
    HistoryMatch,
    Settings,
    Wave,
    closest_points,
    discrepancy_needs,
    from_json,
    history_match,
    nroy_mask,
    nroy_sample,
    observation_shares,
    reference_implausibility,
    to_json,
)

__all__ = [
    "CUTOFF",
    "KINDS",
    "Diagnostics",
    "DiscrepancyNeed",
    "Emulator",
    "HistoryMatch",
    "Input",
    "InputSpace",
    "Observation",
    "Settings",
    "Wave",
    "closest_points",
    "combine",
    "diagnose",
    "discrepancy_needs",
    "fit_emulator",
    "from_json",
    "history_match",
    "implausibility",
    "loo",
    "nroy_mask",
    "nroy_sample",
    "observation_shares",
    "predict",
    "reference_implausibility",
    "required_discrepancy_var",
    "to_json",
    "write_figures",
]
