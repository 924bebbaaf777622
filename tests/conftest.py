"""Shared fixtures: an isolated render cache per test session, quiet logging."""

from __future__ import annotations

import os

import pytest


@pytest.fixture(scope="session", autouse=True)
def _no_hugepage_advice():
    """As the command line does (studies.engine.runner.no_hugepage_advice): whole T6 frames
    otherwise spend most of their time in the kernel zeroing huge pages."""
    from studies.engine.runner import no_hugepage_advice

    no_hugepage_advice()


@pytest.fixture(scope="session", autouse=True)
def _isolated_cache(tmp_path_factory):
    """Keep the user's render cache out of the tests."""
    os.environ["BEACON_SIM_CACHE"] = str(tmp_path_factory.mktemp("render-cache"))
    yield


@pytest.fixture(scope="session")
def mitsuba_variant():
    """Activate the best Mitsuba variant once (mono)."""
    from scenes.mitsuba_variant import select_variant

    return select_variant("mono")


@pytest.fixture(autouse=True)
def _no_user_hardware():
    """Every test starts with the built-in hardware only and leaves none behind (``--camera-file``
    and ``add_hardware_file`` register the user's files in the process)."""
    from scenes.hardware import clear_user_hardware

    clear_user_hardware()
    yield
    clear_user_hardware()


@pytest.fixture
def work(monkeypatch, tmp_path):
    """The CLI's work functions patched to fast fakes; the current folder is an empty temporary
    one (tests/helpers/cli.py)."""
    from tests.helpers.cli import patch_work

    patch_work(monkeypatch)
    monkeypatch.chdir(tmp_path)
    return tmp_path
