"""beacon-sim traverse: the geometry of a detection is exact without noise, the CRLB's planar part is
the bound's own, the filter beats odometry alone, and the spacing answer reads its runs right."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from studies.catalog import traverse as tr


class _Always:
    """A detection table that sees every side in view (P = 1)."""

    camera, source = "spedal-920", "test"

    def probability(self, range_m: float, yaw_deg: float) -> float:
        return 1.0


def test_without_noise_every_detection_gives_the_robots_exact_pose(monkeypatch):
    """Every ring camera and every side in view: the robot's global pose from the detection (camera pose
    in the side's target frame, through the beacon's pose and the camera's mount) is the true one."""
    monkeypatch.setattr(tr, "CENTROID_SD_PX", 1e-12)
    t = tr.Traverse()
    ring = tr._ring(t)
    rng = np.random.default_rng(0)
    beacons = np.array([[3.0, 1.2], [-3.0, -1.0], [0.5, 4.0], [1.0, -4.5]])
    sides, cameras = set(), set()
    for heading in np.linspace(-math.pi, math.pi, 9):
        robot = np.array([0.2, -0.1, heading])
        for _, _, side, pose in tr._detections(t, ring, _Always(), robot, beacons, rng, {}):
            assert pose.vector[:2] == pytest.approx(robot[:2], abs=1e-9)
            assert math.remainder(pose.heading_rad - heading, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
            sides.add(side)
        cameras |= {k for k, *_ in tr._detections(t, ring, _Always(), robot, beacons, rng, {})}
    assert sides == set(tr.SIDE_ANGLES) and cameras == set(range(6))


def test_the_planar_covariance_is_the_bounds_position_and_yaw():
    from pipeline.crlb import bound_from_covariance, planar_covariance, pose_covariance
    from pipeline.frames import pose_from_scenario
    from scenes.scenario import Scenario

    t = tr.Traverse()
    ring = tr._ring(t)
    pose = pose_from_scenario(Scenario(camera=t.camera, beacon="v2", range_m=5.0, yaw_deg=20.0))
    cov = pose_covariance(ring.points_t_m, pose, ring.intrinsics, 0.5)
    bound = bound_from_covariance(cov, pose)
    planar = planar_covariance(cov, pose)
    assert np.sqrt(np.diag(planar)) == pytest.approx([*bound.position_t_m[:2], bound.attitude_axes_rad[2]], rel=1e-9)


def test_a_traverse_corrects_odometry_at_every_fix(tmp_path):
    t = tr.Traverse(path_m=20.0)
    table = tr.DetectionTable.from_summary(tr.DEFAULT_TABLE, t.camera)
    summary = tr.run(tmp_path, t, spacings_m=(5.0, 20.0), seeds=2, threshold_m=1.0, table=table)
    runs = pd.DataFrame(summary["runs"])
    assert (runs.filter_max_error_m < runs.odometry_max_error_m).all()
    near, far = runs[runs.spacing_m == 5.0], runs[runs.spacing_m == 20.0]
    assert (near.fix_fraction.to_numpy() > far.fix_fraction.to_numpy()).all()  # paired by seed: same slip
    assert (near.slip.to_numpy() == far.slip.to_numpy()).all()
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    assert len(steps) == 2 * 2 * 81 and (tmp_path / "report.html").is_file()
    again = tr.run(tmp_path / "again", t, spacings_m=(5.0, 20.0), seeds=2, threshold_m=1.0, table=table)
    assert again["runs"] == summary["runs"]  # same seeds, same numbers


def test_the_spacing_answer_is_the_largest_spacing_under_the_threshold_per_seed():
    runs = pd.DataFrame(
        {"spacing_m": [5, 10, 20] * 2, "seed": [0] * 3 + [1] * 3, "filter_max_error_m": [0.2, 0.8, 1.5, 0.3, 1.2, 0.9]}
    )
    answer = tr.largest_spacing(runs, 1.0)
    # seed 1 passes at 20 m after failing at 10 m: luck of where the beacons fell, not counted
    assert answer["per_seed"] == {0: 10, 1: 5} and (answer["low_m"], answer["high_m"]) == (5, 10)
    assert not answer["at_least"] and tr.spacing_text(answer) == "5 to 10 m over 2 seeds (error under 1 m)"
    assert tr.spacing_text(tr.largest_spacing(runs, 2.0)) == "≥ 20 m at each of 2 seeds (error under 2 m)"
    same = tr.largest_spacing(runs[runs.spacing_m < 20], 1.3)
    assert tr.spacing_text(same) == "≥ 10 m at each of 2 seeds (error under 1.3 m)"
    lucky = pd.DataFrame({"spacing_m": [5, 10, 20], "seed": [0] * 3, "filter_max_error_m": [0.2, 1.4, 0.9]})
    assert tr.largest_spacing(lucky, 1.0)["per_seed"] == {0: 5}  # 20 m passing after 10 m failed is luck
    none = tr.largest_spacing(runs, 0.1)
    assert none["high_m"] is None and tr.spacing_text(none).startswith("no spacing tried")


def test_a_table_interpolates_the_measured_fractions():
    table = tr.DetectionTable("c", "t", ((0.0, (2.0, 4.0), (1.0, 0.5)), (10.0, (2.0, 4.0), (0.0, 0.0))))
    assert table.probability(3.0, 0.0) == pytest.approx(0.75)
    assert table.probability(3.0, -5.0) == pytest.approx(0.375)
    assert table.probability(1.0, 0.0) == 1.0 and table.probability(4.5, 0.0) == 0.0
    assert table.probability(3.0, 11.0) == 0.0


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--spacing-m", "5,-1"], "spacing-m"),
        (["--seeds", "0"], "seeds"),
        (["--threshold-m", "0"], "threshold-m"),
        (["--camera", "canon-t6-18mm", "--detections", "nope.json"], "detections"),
        (["--camera", "mvbluefox3-2016c-8mm"], "camera"),
        (["--cameras-n", "1"], "cameras_n"),
    ],
)
def test_bad_input_is_one_line_before_any_work(monkeypatch, tmp_path, args, field):
    from tests.helpers.cli import assert_one_line_error, invoke

    code, _, err = invoke(["traverse", "--out", str(tmp_path / "o"), *args])
    assert_one_line_error(code, err, field)
    assert not (tmp_path / "o").exists()
