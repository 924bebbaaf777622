"""Every JSON file a study writes is standard JSON; task records still give back their exact rows;
machine.csv counts each frame once; the README's column glossary is the results table's columns."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pandas as pd
import pytest

from studies.catalog import webcam_vs_dslr
from studies.engine.runner import MACHINE_LOG, ResultStore, _digest
from studies.engine.strict_json import decode_non_finite, dumps, encode_non_finite
from studies.engine.sweep import Execution

REPO = Path(__file__).resolve().parents[2]
TINY = {"spp": 2, "oversampling": 1, "crop": "target", "near_field_spp": 64}


def _refuse(name):
    raise ValueError(f"non-standard JSON constant {name}")


def strict_load(text: str):
    """``json.loads`` that refuses NaN, Infinity and -Infinity (RFC 8259)."""
    return json.loads(text, parse_constant=_refuse)


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory, mitsuba_variant) -> Path:
    out = tmp_path_factory.mktemp("webcam-vs-dslr")
    o = webcam_vs_dslr.default_options(True).with_overrides(
        cameras=("logitech-c270",), sides=("red", "green"), ranges_m=(4.0,), seeds=1, render=TINY
    )
    webcam_vs_dslr.run(out, o, Execution(workers=1))
    return out


def test_every_json_a_study_writes_is_standard_json(tiny_study):
    files = sorted(tiny_study.rglob("*.json"))
    assert any(f.parent.parent.name == "tasks" for f in files) and (tiny_study / "summary.json") in files
    for f in files:
        strict_load(f.read_text())  # raises on a bare NaN / Infinity
    rows = pd.read_csv(tiny_study / "results.csv")
    assert rows.isna().any().any()  # the rows do hold non-finite values: they were written as null


def test_task_records_round_trip_nan_with_the_old_digest(tmp_path):
    rows = [{"a": math.nan, "b": [1.0, math.inf], "c": "x"}, {"a": 2.0, "b": [-math.inf], "c": None}]
    store = ResultStore(tmp_path)
    store.put("k" * 64, rows)
    record = strict_load(store.path("k" * 64).read_text())
    assert record["rows"][0]["a"] is None and record["non_finite"]
    # the digest is that of the rows as Python's JSON writes them with NaN: records written before still resume
    assert record["sha256"] == _digest(rows)
    back = store.get("k" * 64)
    assert math.isnan(back[0]["a"]) and back[0]["b"] == [1.0, math.inf] and back[1]["b"] == [-math.inf]
    old = {"key": "j" * 64, "sha256": _digest(rows), "rows": rows}  # a record of the earlier format
    store.path("j" * 64).parent.mkdir(parents=True, exist_ok=True)
    store.path("j" * 64).write_text(json.dumps(old, allow_nan=True))
    assert math.isnan(store.get("j" * 64)[0]["a"])


def test_strict_dumps_and_its_places():
    value = {"x": [math.nan, 1.5, (math.inf,)]}
    assert strict_load(dumps(value)) == {"x": [None, 1.5, [None]]}
    clean, places = encode_non_finite(value)
    assert places == [["x", 0, "nan"], ["x", 2, 0, "inf"]]
    again = decode_non_finite(json.loads(json.dumps(clean)), places)
    assert math.isnan(again["x"][0]) and again["x"][2] == [math.inf]


def test_machine_csv_logs_each_frame_once(tiny_study):
    log = pd.read_csv(tiny_study / MACHINE_LOG, dtype={"task": str})
    frames = len(list((tiny_study / "tasks").rglob("*.json")))
    per_frame = log[log.field == "frame_s"]
    assert len(per_frame) == frames and per_frame.task.is_unique  # rows of a frame share its time: one line
    # summing the lines sums each frame once: at most the wall time of the frames, not 4 × it
    results = pd.read_csv(tiny_study / "results.csv")
    assert len(results) == 4 * frames  # 2 trackers × 2 estimators per frame


def _glossary_columns() -> set[str]:
    """The columns the README's "Columns of results.csv" paragraph names (expanding ``|`` and ``<i>``)."""
    text = (REPO / "README.md").read_text()
    para = text[text.index("Columns of `results.csv`") : text.index("Success is defined once")]
    names = set()
    for token in re.findall(r"`([^`]+)`", para):
        if token in ("results.csv", "pipeline.failures.Failure", "full", "crop") or " " in token:
            continue
        head, *alts = token.split("|")
        # each alternative replaces as many "_" parts of the first name's end as it has
        variants = [head, *("_".join([*head.split("_")[: -len(a.split("_"))], a]) for a in alts)]
        for v in variants:
            names |= {v.replace("<i>", str(i)) for i in range(1, 6)} if "<i>" in v else {v}
    return names


def test_readme_column_glossary_matches_the_results_table(tiny_study):
    columns = set(pd.read_csv(tiny_study / "results.csv").columns)
    glossary = _glossary_columns()
    study_tags = {"jitter"}  # tags a study adds to its own rows (not frame columns)
    assert glossary - columns == set()
    assert columns - glossary - study_tags == set()
