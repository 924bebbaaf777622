"""The command line run in this process without starting work: :func:`invoke` runs
``beacon-sim`` through :func:`studies.cli.app.main`; :func:`patch_work` replaces every function
that would start work (render, capture, sweep, experiment) by one raising :class:`WorkStarted`,
so a test sees whether a command got past its validation; :func:`assert_one_line_error`
checks the one-line error every bad input must give.
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

import pytest

__all__ = ["REPO", "WORK_FUNCTIONS", "WorkStarted", "assert_one_line_error", "invoke", "patch_work"]

REPO = Path(__file__).parents[2]
"""The repository's root."""


class WorkStarted(BaseException):
    """Raised by every patched work function: the command got past its validation.

    A BaseException, so no ``except Exception`` in a command can swallow it."""


def _work(*args, **kwargs):
    raise WorkStarted()


WORK_FUNCTIONS = {
    "scenes.render": ["render"],
    "scenes.background": ["render_background"],
    "camera_models.capture": ["capture"],
    "camera_models.emva": ["write_dataset"],
    "pipeline.detect": ["detect"],
    "pipeline.calibration": ["calibrate"],
    "studies.engine.runner": ["run_tasks"],
    "studies.engine.sweep": ["sweep", "sweep_in_chunks", "run_frames"],
    "studies.engine.sequential": ["run_design"],
    "studies.engine.colour_reach": ["reach_table"],
    "studies.catalog.validate": ["run"],
    "studies.catalog.unknowns_search": ["run"],
    "studies.catalog.calibration": ["run"],
    "studies.catalog.sensitivity": ["run"],
    "studies.catalog.design": ["run"],
    "studies.catalog.traverse": ["run"],
    "studies.catalog.webcam_vs_dslr": ["run"],
    "studies.catalog.brightness_diffuser": ["run"],
    "studies.catalog.range_limit": ["run"],
    "studies.catalog.replication": ["run"],
    "studies.experiments.e2e_detection": ["run"],
    "studies.experiments.crop_vs_full": ["run"],
    "studies.experiments.tracker_pruning": ["run"],
    "studies.experiments.saturation_table": ["saturation_rows"],
    "studies.experiments.diffuser_mosaic": ["diffuser_mosaic"],
    "studies.experiments.two_stage_check": ["compare"],
    "studies.experiments.lens_calibration": ["calibrate"],
    "studies.experiments.estimator_montecarlo": ["pose_error_trials"],
    "studies.experiments.bench": [
        "two_stage_vs_brute_force",
        "reuse_vs_rerender",
        "frame_vs_memcpy",
        "hugepage_advice",
        "workers_and_dask",
        "full_grid_estimate",
        "variant_ratio",
        "replication_tables",
        "grid_sample",
    ],
}
"""Functions that start real work (render, capture, sweep, experiment), by module."""


def patch_work(mp: pytest.MonkeyPatch) -> None:
    """Replace every work function, wherever it was imported by name, with one raising :class:`WorkStarted`."""
    import importlib

    import studies.cli.app  # noqa: F401  (imports every command module)

    originals = set()
    for module_name, names in WORK_FUNCTIONS.items():
        module = importlib.import_module(module_name)
        for name in names:
            originals.add(id(getattr(module, name)))
    for module_name, module in list(sys.modules.items()):
        if module is None or not module_name.startswith(("studies", "scenes", "camera_models", "pipeline")):
            continue
        for attr, value in list(vars(module).items()):
            if callable(value) and id(value) in originals:
                mp.setattr(module, attr, _work)


def invoke(args: list[str]) -> tuple[int | str, str, str]:
    """Run ``beacon-sim args`` in this process: (exit code or ``"work"``, stdout, stderr)."""
    from studies.cli.app import main

    out, err = io.StringIO(), io.StringIO()
    saved = sys.argv
    sys.argv = ["beacon-sim", *args]
    code: int | str = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except WorkStarted:
        code = "work"
    finally:
        sys.argv = saved
    return code, out.getvalue(), err.getvalue()


def assert_one_line_error(code, err: str, field: str | None = None) -> str:
    """Exit code 2 and exactly one stderr line ``beacon-sim: error: <field>: ...``."""
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("beacon-sim: error: "), (code, err)
    if field is not None:
        assert lines[0].startswith(f"beacon-sim: error: {field}:"), lines[0]
    return lines[0]
