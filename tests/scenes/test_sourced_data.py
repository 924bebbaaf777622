"""Every number in a data file carries a source or an 'assumed' note."""

from __future__ import annotations

from pathlib import Path

import pytest

from scenes.sourced import DATA_DIR, DataFileError, load_sourced
from scenes.view import CAMERA_DATA_DIR


@pytest.mark.parametrize(
    "path",
    sorted(DATA_DIR.rglob("*.toml"))
    + sorted(CAMERA_DATA_DIR.rglob("*.toml"))
    + sorted((Path(__file__).resolve().parents[2] / "docs" / "examples").glob("*.toml")),
    ids=lambda p: p.name,
)
def test_data_files_load_with_provenance(path):
    values, provenance = load_sourced(path)
    assert values and provenance
    assert all(v.startswith(("source: ", "assumed: ")) and len(v) > 20 for v in provenance.values())


def test_number_without_provenance_is_rejected(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[led]\nwavelength_nm = 625\n")
    with pytest.raises(DataFileError, match=r"led\.wavelength_nm: number 625 has no 'source'"):
        load_sourced(f)


def test_both_source_and_assumed_is_rejected(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('x = { value = 1, source = "a", assumed = "b" }\n')
    with pytest.raises(DataFileError, match="exactly one"):
        load_sourced(f)
