"""The studies: each module a sweep over the engine's one frame path with its own report.

A study module has ``NAME``, ``default_options(quick) -> StudyOptions`` and
``run(out, options, execution) -> summary``. :data:`STUDIES` registers them by name,
:data:`SEQUENTIAL` those that can place their frames by a sequential design;
:mod:`studies.catalog.validate` (the source study's own tests) is run by its own command.
The main job runs :data:`MAIN_JOB` and :func:`studies.catalog.index.write_index` writes its
index page: the answers (which camera, what LED setting, how far) from their summaries.
"""

from __future__ import annotations

from types import ModuleType

from studies.catalog import brightness_diffuser, range_limit, replication, webcam_vs_dslr

STUDIES: dict[str, ModuleType] = {m.NAME: m for m in (webcam_vs_dslr, brightness_diffuser, range_limit, replication)}
"""Study name → module."""

MAIN_JOB = ("webcam-vs-dslr", "brightness-diffuser", "range-limit")
"""The studies the main job runs (quick forms)."""

SEQUENTIAL: dict[str, ModuleType] = {m.NAME: m for m in (webcam_vs_dslr, range_limit)}
"""Studies whose range limits a sequential design can decide
(:mod:`studies.engine.sequential`): they have ``default_design(quick)`` and take
``run(..., design=...)``."""

PHYSICS: dict[str, ModuleType] = {m.NAME: m for m in (range_limit, webcam_vs_dslr, brightness_diffuser)}
"""Studies that state noise + physics intervals beside their noise ones (``--uncertainty``,
:attr:`studies.engine.tasks.StudyOptions.physics`): range-limit and webcam-vs-dslr their far limits
(and webcam-vs-dslr the closest pair's colour separability), brightness-diffuser its recommended
settings' P(correct) and how often they stay in the window. ``replication`` is left out: it
re-runs the source study's own configurations (a reproduction, not a prediction), and its full
grid is already ~50 h of frames before N + 1 repeats."""

MAIN_JOB_DESIGNS = ("range-limit",)
"""The studies of :data:`MAIN_JOB` that place their frames by their quick sequential design:
``range-limit`` decides every camera's far limit at 0° and 30° (the index's "how far");
``webcam-vs-dslr`` runs its fixed quick grid there (colour separation and the webcam-DSLR
comparison at 0°; a sequential design of its eight camera × drive units doubled the main
job's frames for limits the index takes from ``range-limit``)."""
