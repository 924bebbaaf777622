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
``run(..., design=...)``; the main job runs them with their quick design."""
