"""numpy's huge-page advice is switched off for this process and the ones it starts, unless the
user chose otherwise (studies.engine.runner.no_hugepage_advice)."""

from __future__ import annotations

import subprocess
import sys

from studies.engine import runner

CHILD = "import numpy._core.multiarray as m; print(m._get_madvise_hugepage())"


def test_the_advice_is_off_here_and_in_a_started_process(monkeypatch):
    monkeypatch.delenv(runner.HUGEPAGE_ENV, raising=False)
    from numpy._core.multiarray import _get_madvise_hugepage, _set_madvise_hugepage

    before = _set_madvise_hugepage(True)  # as numpy starts on Linux ≥ 4.6
    try:
        assert runner.no_hugepage_advice() is True
        assert _get_madvise_hugepage() is False
        child = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, check=True)
        assert child.stdout.strip() == "False"  # read from the environment at import
    finally:
        _set_madvise_hugepage(before)


def test_the_users_own_setting_stands(monkeypatch):
    monkeypatch.setenv(runner.HUGEPAGE_ENV, "1")
    from numpy._core.multiarray import _get_madvise_hugepage, _set_madvise_hugepage

    before = _set_madvise_hugepage(True)
    try:
        assert runner.no_hugepage_advice() is False
        assert _get_madvise_hugepage() is True
        child = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, check=True)
        assert child.stdout.strip() == "True"
    finally:
        _set_madvise_hugepage(before)
