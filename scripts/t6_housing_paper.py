"""Housing and paper colour apart, for V2 + Canon T6 18 mm (README, "Predicting before you build").

The 16 Sobol' points of ``beacon-sim sensitivity --camera canon-t6-18mm --points 16 --quick`` aliased
two unknowns: white housing came with matched paper at every point, black housing with white paper
(``studies.engine.sensitivity.aliased_inputs``). This runs the other corners: every unknown at its
registry nominal except housing and/or paper colour (the nominal itself, matched paper and black
housing, is the sensitivity run's own nominal unit), V2 red side at 0°, 2 mA, with the same options
and sequential design as the sensitivity study's quick form. Writes ``points.csv`` (each point's far
limit and P(correct pose) at 5 m) and ``bands.csv`` (correct poses nearer and farther than 8 m, and
the failures' causes) into OUT; the frames are stored by content, so a second run reads them.

Usage: ``python scripts/t6_housing_paper.py OUT`` (about 20 min on 2 cores; copy a finished
sensitivity run's ``range-limit/tasks`` into OUT first to reuse its nominal frames).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from studies.catalog import prediction_set, range_limit
from studies.catalog.sensitivity import UNIT_BUDGET_GRIDS, Setting, point_outputs, study_options
from studies.engine.scoring import failure_cause, pose_success
from studies.engine.sequential import SequentialDesign
from studies.engine.sweep import Execution
from studies.engine.unknowns import load_unknowns

CORNERS = (("black", "matched"), ("white", "matched"), ("black", "white"), ("white", "white"))
"""(housing, paper colour); the first is the registry's nominal, run as the study's nominal unit."""
BAND_M = 8.0
"""Where the close-range failures of the white housing end (m)."""


def main(out: Path) -> None:
    keys = list(prediction_set.physics_points(1, seed=0, calibration=None)[0][0])
    registry = load_unknowns()
    base = {k: registry[k].nominal for k in keys}
    physics = tuple({**base, "housing": h, "paper_colour": p} for h, p in CORNERS[1:])
    options = study_options(Setting(camera="canon-t6-18mm"), physics, "registry nominal, housing and paper set", True)
    options.validate()
    coarse = len(options.ranges_m) * options.seeds
    design = SequentialDesign(target_relative=0.2, max_range_m=20.0, unit_budget_frames=UNIT_BUDGET_GRIDS * coarse)
    range_limit.run(out, options, Execution(), design=design)
    frame = pd.read_parquet(out / "results.parquet")
    table = point_outputs(frame, len(physics))
    table.insert(1, "housing", [p["housing"] for p in physics])
    table.insert(2, "paper_colour", [p["paper_colour"] for p in physics])
    table.to_csv(out / "points.csv", index=False)
    best = frame[frame.tracker == "best"].copy()
    best["point"] = best["point"].fillna(-1).astype(int)  # -1: the nominal
    records = best.to_dict("records")
    best["correct"] = [pose_success(r) for r in records]
    best["cause"] = [failure_cause(r) if not ok else "" for r, ok in zip(records, best["correct"], strict=True)]
    best["band"] = np.where(best.nominal_range_m < BAND_M, f"< {BAND_M:g} m", f">= {BAND_M:g} m")
    corner = dict(enumerate(CORNERS, start=-1))
    bands = (
        best.groupby(["point", "band"])
        .agg(
            frames=("correct", "size"),
            correct=("correct", "sum"),
            causes=("cause", lambda c: dict(c[c != ""].value_counts())),
        )
        .reset_index()
    )
    bands.insert(1, "housing", [corner[p][0] for p in bands.point])
    bands.insert(2, "paper_colour", [corner[p][1] for p in bands.point])
    bands.to_csv(out / "bands.csv", index=False)
    print(table.to_string(index=False))
    print(bands.to_string(index=False))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
