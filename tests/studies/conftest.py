"""Fixtures shared by the CLI tests of tests/studies."""

from __future__ import annotations

import pytest

from tests.studies.test_cli_edges import patch_work


@pytest.fixture
def work(monkeypatch, tmp_path):
    """Work functions patched; the current folder is an empty temporary one."""
    patch_work(monkeypatch)
    monkeypatch.chdir(tmp_path)
    return tmp_path
