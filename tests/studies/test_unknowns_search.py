"""The close-range search over the unknowns: its space, tasks, scoring, summary and calibrated set."""

from __future__ import annotations

import pandas as pd
import pytest

from scenes.led import SIDE_COLOURS
from studies.catalog import unknowns_search
from studies.engine.sweep import Execution
from studies.engine.unknowns import load_unknowns, sample


def test_search_space_has_a_drive_per_beacon_side_and_the_tuning_webcam():
    space = unknowns_search.search_space()
    drives = {f"led_drive_{b}_{s}" for b in ("v1", "v2") for s in SIDE_COLOURS}
    assert drives <= set(space) and "led_drive" not in space
    assert {"tuning_webcam", "webcam_max_exposure", "focus_distance", "housing", "paper_colour"} <= set(space)
    assert "veiling_glare_10mm" not in space  # the 10 mm lens is in no close-range condition
    # the data-file unknowns (LED bins, foam, paper, lit faces) vary too: they decide blob size and colour
    assert {"led_intensity_red", "foam_optical_depth", "paper_transmittance", "lit_face_diameter"} <= set(space)
    assert all(u.kind != "fixed" for u in space.values())


def test_tasks_take_their_own_sides_drive_and_the_point_s_webcam():
    space = unknowns_search.search_space()
    point = {n: u.nominal for n, u in space.items()}
    point |= {f"led_drive_v1_{s}": 0.1 * (i + 1) for i, s in enumerate(SIDE_COLOURS)}
    point |= {f"led_drive_v2_{s}": 1.0 * (i + 1) for i, s in enumerate(SIDE_COLOURS)}
    point["tuning_webcam"] = "spedal-920"
    tasks = unknowns_search.tasks([point], space, seeds=2)
    assert len(tasks) == len(unknowns_search.CONDITIONS) * len(SIDE_COLOURS) * 2
    for t in tasks:
        sc = t["scenario"]
        i = SIDE_COLOURS.index(sc["side"])
        assert sc["led_current_mA"] == pytest.approx((0.1 if sc["beacon"] == "v1" else 1.0) * (i + 1))
        if t["tags"]["condition"] == "webcam-150mm":
            assert sc["camera"] == "spedal-920" and t["full_frame"] and sc["range_m"] == 0.15
        else:
            assert sc["camera"] == "canon-t6-18mm" and t["align_px"] == 16 and "lens.f_number" in t["camera_overrides"]


def _samples_csv(path, consistent_tuning, consistent_all, agree=None):
    space = unknowns_search.search_space()
    table = pd.DataFrame(sample(space, len(consistent_tuning), seed=3))
    for i, (c, s) in enumerate((c, s) for c in unknowns_search.CONDITIONS for s in SIDE_COLOURS):
        table[f"{c}_{s}"] = [i < a for a in (agree or [0] * len(table))]
    table["consistent_webcam-150mm"] = consistent_tuning
    table["consistent"] = consistent_all
    table.to_csv(path, index=False)
    return table


def test_calibrated_set_prefers_every_condition_then_the_tuning_one(tmp_path):
    csv = tmp_path / "samples.csv"
    table = _samples_csv(csv, [True, False, True, True], [False, False, True, False])
    points, which = unknowns_search.calibrated_set(csv)
    assert len(points) == 1 and points[0]["focus_distance"] == pytest.approx(table.focus_distance[2])
    assert "every close-range condition" in which
    table = _samples_csv(csv, [True, False, True, True], [False] * 4)
    points, which = unknowns_search.calibrated_set(csv, limit=2)
    assert [p["focus_distance"] for p in points] == pytest.approx(list(table.focus_distance[[0, 3]]))
    assert which.startswith("2 of 3 points consistent at webcam-150mm")
    assert isinstance(points[0]["glare_on"], bool)
    task = unknowns_search.apply_point(
        {"scenario": {"beacon": "v2", "side": "blue", "camera": "canon-t6-18mm"}, "seed": 0}, points[0]
    )
    assert task["scenario"]["led_current_mA"] == pytest.approx(points[0]["led_drive_v2_blue"])
    table = _samples_csv(csv, [False] * 4, [False] * 4, agree=[2, 5, 0, 5])  # no whole condition anywhere
    points, which = unknowns_search.calibrated_set(csv)
    assert [p["focus_distance"] for p in points] == pytest.approx(list(table.focus_distance[[1, 3]]))
    assert "5 of 8 (condition × side)" in which and "not a calibration" in which


def test_the_kept_search_serves_validate_with_later_unknowns_at_nominal():
    """validate's default set (results/unknowns-search) predates some registry entries: they are held at
    nominal and named, not an error (validate's default run had stopped on it)."""
    header = set(pd.read_csv(unknowns_search.REFERENCE_SEARCH, nrows=0).columns)
    space = unknowns_search.search_space()
    later = [n for n in space if n not in header]
    points, which = unknowns_search.calibrated_set(unknowns_search.REFERENCE_SEARCH, limit=2)
    assert len(points) == 2 and set(points[0]) == set(space)
    for name in later:
        assert points[0][name] == space[name].nominal and name in which
    shared = sorted(set(space) - set(later))
    assert shared and all(n in header for n in shared)


def test_calibrated_set_refuses_what_it_cannot_use(tmp_path):
    csv = tmp_path / "samples.csv"
    _samples_csv(csv, [False, False], [False, False])
    with pytest.raises(ValueError, match="no point agrees with any close-range observation"):
        unknowns_search.calibrated_set(csv)
    pd.DataFrame({"x": [1]}).to_csv(csv, index=False)
    with pytest.raises(ValueError, match="missing column 'consistent'"):
        unknowns_search.calibrated_set(csv)
    csv.write_text("a,b\n1\n1,2,3\n")
    with pytest.raises(ValueError, match=r"samples.csv: expected an unknowns-search samples.csv, cannot read it"):
        unknowns_search.calibrated_set(csv)


@pytest.mark.slow  # 95 s; the default run's budget is 10 min on 2 cores
def test_tiny_search_scores_every_point_on_every_condition_and_side(tmp_path, monkeypatch, mitsuba_variant):
    monkeypatch.setattr(
        unknowns_search, "RENDER", {"spp": 1, "oversampling": 1, "crop": "target", "near_field_spp": 16}
    )
    crops = {n: {**c, "task": {}} for n, c in unknowns_search.CONDITIONS.items()}  # crops: whole frames cost more
    monkeypatch.setattr(unknowns_search, "CONDITIONS", crops)
    monkeypatch.setattr(unknowns_search, "HELD", ("paper_colour", "housing", "tuning_webcam"))  # renders shared
    summary = unknowns_search.run(tmp_path, samples=2, seeds=1, execution=Execution(workers=1))
    table = pd.read_csv(tmp_path / "samples.csv")
    assert len(table) == 2
    for name in unknowns_search.CONDITIONS:
        expected = table[[f"{name}_{s}" for s in SIDE_COLOURS]].all(axis=1)
        assert list(table[f"consistent_{name}"]) == list(expected)
        got = summary["conditions"][name]
        assert got["consistent_points"] == int(expected.sum())
        assert got["per_side_detected"] == {s: int(table[f"{name}_{s}"].sum()) for s in SIDE_COLOURS}
    both = table[[f"consistent_{n}" for n in unknowns_search.CONDITIONS]].all(axis=1)
    assert list(table.consistent) == list(both) and summary["consistent_points"] == int(both.sum())
    t6 = summary["conditions"]["t6-1m"]["unknowns"]
    assert "led_drive_v2_red" in t6 and "led_drive_v1_red" not in t6 and "tuning_webcam" not in t6
    assert t6["led_drive_v2_red"]["prior"] == pytest.approx([0.05, 20.0])
    assert t6["housing"] == {"held_at": "black"}
    assert load_unknowns()["led_drive"].low == 0.05
