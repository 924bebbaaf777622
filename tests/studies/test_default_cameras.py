"""Adding a camera file changes no default: every study's grid and the experiments that ran every
camera keep the source study's four cameras (issue 27: the Raspberry Pi HQ lenses and the
mvBlueFOX3-2016C are built in, and run only where named)."""

from __future__ import annotations

import pytest

from scenes.view import camera_names
from studies.catalog import MAIN_JOB, STUDIES
from studies.engine.tasks import STUDY_CAMERAS
from tests.helpers.cli import WorkStarted, invoke

NEW = ("mvbluefox3-2016c-8mm", "raspberry-pi-hq-16mm", "raspberry-pi-hq-6mm")


def test_the_study_cameras_are_the_first_four_built_ins():
    names = camera_names()
    assert set(NEW) <= set(names) and set(STUDY_CAMERAS) | set(NEW) == set(names)
    assert list(STUDY_CAMERAS) == [n for n in names if n in STUDY_CAMERAS]  # the order the listing had


@pytest.mark.parametrize("quick", [True, False])
@pytest.mark.parametrize("study", sorted(STUDIES))
def test_study_defaults_and_the_main_job_keep_the_four_cameras(study, quick):
    cameras = STUDIES[study].default_options(quick).cameras
    assert set(cameras) <= set(STUDY_CAMERAS), cameras
    assert set(MAIN_JOB) <= set(STUDIES)


@pytest.mark.parametrize(
    ("command", "module", "function"),
    [
        (["colour-reach", "--out", "o"], "studies.engine.colour_reach", "reach_table"),
        (["crop-vs-full", "--out", "o"], "studies.experiments.crop_vs_full", "run"),
    ],
)
def test_experiments_that_ran_every_camera_default_to_the_four(work, monkeypatch, command, module, function):
    """``colour-reach`` and ``crop-vs-full`` took every camera of ``beacon-sim cameras`` by default;
    their default is now the four cameras they were run with, named (``--cameras`` runs others)."""
    import importlib

    seen = []

    def record(*args, **kwargs):
        cameras = args[1] if function == "run" else args[0]
        seen.append(tuple(cameras))
        raise WorkStarted()

    monkeypatch.setattr(importlib.import_module(module), function, record)
    code, _out, err = invoke(command)
    assert code == "work", err
    assert seen == [STUDY_CAMERAS]
    code, _out, err = invoke([*command, "--cameras", "mvbluefox3-2016c-8mm"])
    assert code == "work", err
    assert seen[-1] == ("mvbluefox3-2016c-8mm",)
