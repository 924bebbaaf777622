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
    draw = tr._TableDetections(t, ring, _Always(), {})
    rng = np.random.default_rng(0)
    beacons = np.array(
        [[3.0, 1.2, 0.0], [-3.0, -1.0, 0.0], [0.5, 4.0, 0.0], [1.0, -4.5, 0.0], [4.0, 3.0, 0.6], [-4.0, 2.0, -1.2]]
    )  # x, y and the way each faces (as in a bend)
    sides, cameras = set(), set()
    for heading in np.linspace(-math.pi, math.pi, 9):
        robot = np.array([0.2, -0.1, heading])
        for ((s, side, est, cov),) in draw(0, tr.sightings(t, ring.fov_rad, ring.d_t_m, robot, beacons), rng):
            pose = tr._robot_pose(t, beacons, ring.d_t_m, s.camera, s.beacon, side, est, cov)
            assert pose.vector[:2] == pytest.approx(robot[:2], abs=1e-9)
            assert math.remainder(pose.heading_rad - heading, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
            sides.add(side)
            cameras.add(s.camera)
    assert sides == set(tr.SIDE_ANGLES) and cameras == set(range(6))


def test_a_sightings_frame_task_is_the_same_pose():
    """The scenario a sighting renders (yaw mirrored into the target frame, the camera turned by the
    bearing) puts the camera where the traverse's geometry says, to 1e-6: the scenes' own pose code
    (:func:`pipeline.frames.pose_from_scenario`) read back in the traverse's planar frame."""
    from pipeline.frames import pose_from_scenario
    from scenes.scenario import Scenario

    t = tr.Traverse()
    ring = tr._ring(t)
    beacons = np.array([[3.0, 1.2, 0.0], [6.0, 1.2, 0.4]])
    seen = []
    for heading in (0.0, 0.4, -0.7, 2.0):
        seen += tr.sightings(t, ring.fov_rad, ring.d_t_m, np.array([0.0, -0.2, heading]), beacons)
    assert {round(math.degrees(s.bearing_rad)) > 0 for s in seen} == {True, False}  # both sides of the axis
    for s in seen:
        task = tr.frame_task(t, s, 0)
        sc = Scenario(**{k: v for k, v in task["scenario"].items()})
        u, v, psi = tr.planar_in_target(pose_from_scenario(sc))
        assert (u, v) == pytest.approx((s.u_m, s.v_m), abs=1e-3)  # the task rounds range to 0.1 mm
        assert math.remainder(psi - s.psi_rad, 2 * math.pi) == pytest.approx(0.0, abs=1e-4)


@pytest.mark.parametrize("slope_deg", [0.0, 8.0])
def test_a_sightings_frame_has_the_tubes_walls_and_slope_where_the_plan_has_them(slope_deg):
    """The walls of a sighting's render (in its beacon frame) stand where the traverse's floor plan has
    them: the camera's distance to the left wall (the plan's y = width / 2 for a straight tube along
    x) and its distance along the tube from the beacon; on a slope the camera stands that distance
    times tan(slope) above marker 1, and its axis, read back from the scenario's own pose, pitches
    with the floor along its heading."""
    from pipeline.frames import pose_from_scenario
    from scenes.scenario import Scenario

    t = tr.Traverse(slope_deg=slope_deg)
    ring = tr._ring(t)
    beacons = tr._beacons(t, 4.0)[:2]  # by the left wall, facing along the tube
    robot = np.array([1.0, -0.1, 0.3])
    seen = tr.sightings(t, ring.fov_rad, ring.d_t_m, robot, beacons)
    assert {s.side for s in seen} == {"blue", "yellow"}  # the robot comes from behind, right of the beacons
    grade = math.tan(math.radians(slope_deg))
    for s in seen:
        sc = Scenario(**tr.frame_task(t, s, 0)["scenario"])
        walls, rot = sc.tube_walls, sc.target_to_world()[0]
        cam_b = sc.render_pose().position_m
        heading = robot[2] + 2 * math.pi * s.camera / t.cameras_n
        cam = robot[:2] + t.radius_m * np.array([math.cos(heading), math.sin(heading)])
        across = walls.left_m + float(cam_b @ (rot @ walls.right()))
        assert across == pytest.approx(t.tube_width_m / 2 - cam[1], abs=2e-3)
        along = float(
            np.hypot(*(cam - beacons[s.beacon, :2])) * math.cos(math.atan2(*(cam - beacons[s.beacon, :2])[::-1]))
        )
        assert sc.camera_height_m == pytest.approx(along * grade, abs=2e-3)
        axis = pose_from_scenario(sc).cv_from_t.T @ np.array([0.0, 0.0, 1.0])  # optical axis in T (z down)
        pitch = math.degrees(math.asin(-axis[2]))
        assert pitch == pytest.approx(math.degrees(math.atan(grade * math.cos(heading))), abs=0.05)


def test_a_rendered_noise_free_sighting_gives_the_robots_pose():
    """One rendered whole frame (Spedal 920, V2 at ~2.5 m seen 24° off its side's normal and 36° off the
    camera's axis, no sensor noise), detected after the lens's rectification: the robot's pose from it
    within 5 cm and 1°. (At 29° off the normal the Spedal at 2 mA finds too few blobs, as its
    range-limit frames at 30° do.)"""
    t = tr.Traverse()
    ring = tr._ring(t)
    beacons = np.array([[2.5, 1.2, 0.0]])
    robot = np.array([0.0, 0.0, 0.0])
    seen = [
        s
        for s in tr.sightings(t, ring.fov_rad, ring.d_t_m, robot, beacons)
        if 20 < abs(math.degrees(s.bearing_rad)) < 40 and abs(s.yaw_deg) < 26
    ]
    assert seen
    s = seen[0]
    (row,) = tr.traverse_frame({**tr.frame_task(t, s, 0), "noise": False})
    assert row["side_detected"] == s.side
    est = np.array([row["u_m"], row["v_m"], row["psi_rad"]])
    pose = tr._robot_pose(t, beacons, ring.d_t_m, s.camera, s.beacon, s.side, est, np.eye(3))
    assert np.hypot(*(pose.vector[:2] - robot[:2])) < 0.05
    assert abs(math.degrees(math.remainder(pose.heading_rad - robot[2], 2 * math.pi))) < 1.0


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


def test_a_slip_that_wanders_is_recorded_per_step_and_the_filter_follows_it(tmp_path):
    """The slip column is each step's slip (its run mean in the summary); told the model's wander, the
    filter's scale state follows the true scale 1 − s closer than the drawn slip's prior spread does."""
    t = tr.Traverse(path_m=50.0, odometry={"slip_sd": 0.1, "slip_correlation_m": 5.0})
    table = tr.DetectionTable.from_summary(tr.DEFAULT_TABLE, t.camera)
    summary = tr.run(tmp_path, t, spacings_m=(5.0,), seeds=2, threshold_m=1.0, table=table)
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    for seed, run in steps.groupby("seed"):
        assert run.slip.std() > 0.03  # it wanders
        assert run.slip.mean() == pytest.approx(pd.DataFrame(summary["runs"]).set_index("seed").slip[seed])
        tail = run[run.distance_m > 10]  # after the first beacons have taught it
        assert np.sqrt(np.mean((tail.filter_scale - (1 - tail.slip)) ** 2)) < run.slip.std()
    with pytest.raises(ValueError, match=r"odometry: expected fields of pipeline.odometry.WheelOdometry, got \['sl"):
        tr.Traverse(odometry={"slipp": 0.1}).validate()


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
        (["--bend-deg", "190"], "bend_deg"),
        (["--bend-deg", "90", "--bend-radius-m", "1"], "bend_radius_m"),
        (["--dust-visibility-m", "10"], "dust-visibility-m"),
        (["--rendered", "--dust-visibility-m", "0"], "dust-visibility-m"),
        (["--slope-deg", "5"], "slope-deg"),
        (["--tube-height-m", "0"], "tube_height_m"),
        (["--tube-width-m", "0"], "tube_width_m"),
        (["--rendered", "--slope-deg", "50"], "slope_deg"),
        (["--rendered", "--scheduler", "tcp://127.0.0.1:1"], "scheduler"),
        (["--workers", "0"], "workers"),
        (["--wall-reflectance", "0.2"], "wall-reflectance"),
        (["--rendered", "--wall-reflectance", "1.5"], "wall_reflectance"),
        (["--rendered", "--no-tube-walls", "--wall-reflectance", "0.2"], "wall_reflectance"),
        (["--slip-sd", "-0.1"], "slip_sd"),
        (["--slip-sd", "0.1", "--slip-correlation-m", "0"], "slip_correlation_m"),
    ],
)
def test_bad_input_is_one_line_before_any_work(monkeypatch, tmp_path, args, field):
    from tests.helpers.cli import assert_one_line_error, invoke

    code, _, err = invoke(["traverse", "--out", str(tmp_path / "o"), *args])
    assert_one_line_error(code, err, field)
    assert not (tmp_path / "o").exists()


def test_error_covariances_are_the_planted_errors_second_moment():
    """Planted errors with a known covariance per band: the measured covariance recovers it (2000
    frames, 10 %) with 200 gross errors added to one band (trimmed and counted); frames that named
    another side do not count; a band without frames takes all."""
    rng = np.random.default_rng(3)
    near, far = np.diag([0.01, 0.02, 0.005]) ** 2, np.diag([0.05, 0.08, 0.01]) ** 2
    pairs = []
    for cov, r in ((near, 1.5), (far, 6.0)):
        for e in rng.multivariate_normal(np.zeros(3), cov, 2000):
            row = {"side_detected": "red", "u_m": r + e[0], "v_m": e[1], "psi_rad": math.pi + e[2]}
            pairs.append(
                ({"scenario": {"side": "red"}}, {**row, "true_u_m": r, "true_v_m": 0.0, "true_psi_rad": math.pi})
            )
    pairs.append(({"scenario": {"side": "red"}}, {**pairs[0][1], "side_detected": "yellow", "u_m": 99.0}))
    gross = [({"scenario": {"side": "red"}}, {**pairs[i][1], "v_m": 3.0 * (-1) ** i}) for i in range(0, 400, 2)]
    pairs += gross  # 10 % of the near band metres off on the right side: trimmed, counted
    bands = {b["low_m"]: b for b in tr.error_covariances(pairs)}
    np.testing.assert_allclose(np.diag(bands[1.0]["covariance"]), np.diag(near), rtol=0.1)
    np.testing.assert_allclose(np.diag(bands[4.0]["covariance"]), np.diag(far), rtol=0.1)
    assert bands[1.0]["frames"] == 2200 and bands[0.0]["frames"] == 0
    assert 200 <= bands[1.0]["outliers"] <= 210  # and ~0.1 % of the inliers, beyond the gate by chance
    pooled = np.diag(bands[0.0]["covariance"])  # both bands' inliers: a mixture, between the two
    assert np.all(np.diag(near) < pooled) and np.all(pooled < np.diag(far))
    # the far band's median position error: Rayleigh-like for its 2-D Gaussian, from its own planted errors
    planted = [math.hypot(r["u_m"] - r["true_u_m"], r["v_m"]) for _, r in pairs[2000:4000]]
    assert bands[4.0]["median_error_m"] == pytest.approx(float(np.median(planted)), rel=1e-12)
    # a band where every frame is 10 m off: nothing to trim against, the covariance is theirs, the median says so
    lost = [({"scenario": {"side": "red"}}, {**pairs[2000 + i][1], "v_m": 10.0 + 0.1 * i}) for i in range(20)]
    (far_band,) = [b for b in tr.error_covariances(lost) if b["low_m"] == 4.0]
    assert far_band["median_error_m"] == pytest.approx(10.95, abs=0.06)
    assert math.sqrt(far_band["covariance"][1][1]) > 10.0


def test_a_rendered_traverse_runs_and_resumes(tmp_path):
    """A 0.5 m rendered traverse (Spedal ring, beacon at the start): every frame stored, the filter's
    error small where the frames see the beacon, and the same command again renders nothing new and
    writes the same summary."""
    t = tr.Traverse(path_m=0.5, step_m=0.5)
    table = tr.DetectionTable.from_summary(tr.DEFAULT_TABLE, t.camera)
    first = tr.run(tmp_path, t, spacings_m=(10.0,), seeds=1, threshold_m=1.0, table=table, rendered=True, workers=1)
    stored = sorted(p.name for p in (tmp_path / "tasks").rglob("*.json"))
    assert first["detections"]["rendered"] and first["detections"]["frames"] == len(stored) > 0
    (run,) = first["runs"]
    assert run["fix_fraction"] > 0 and run["filter_max_error_m"] < 0.2
    again = tr.run(tmp_path, t, spacings_m=(10.0,), seeds=1, threshold_m=1.0, table=table, rendered=True, workers=1)
    assert sorted(p.name for p in (tmp_path / "tasks").rglob("*.json")) == stored
    assert {k: v for k, v in again.items() if k != "wall_s"} == {k: v for k, v in first.items() if k != "wall_s"}


def test_a_bends_inner_wall_hides_the_beacons_around_it(monkeypatch):
    """A 90° left bend (radius 6 m, tube 3 m wide): every sighting's line from camera to side stays
    clear of the inner wall, whose inside is the set within R − w/2 of the quadrant beyond the corner
    (an independent answer), some beacons seen along a straight sight line are hidden by it, and the
    beacons stand by the left wall facing along the tube where they are."""
    t = tr.Traverse(bend_deg=90.0, bend_at_m=20.0, bend_radius_m=6.0)
    ring = tr._ring(t)
    beacons = tr._beacons(t, 5.0)
    xy, facing = t.tube.centreline([5.0 * k for k in range(len(beacons))])
    assert np.hypot(*(beacons[:, :2] - xy).T) == pytest.approx(t.tube_width_m / 2 - t.wall_offset_m)
    assert beacons[:, 2] == pytest.approx(facing)

    def blocked(a, b):  # the segment comes within R - w/2 of the quadrant {x <= 20, y >= 6}
        p = a + np.linspace(0, 1, 4000)[:, None] * (b - a)
        return np.hypot(np.maximum(p[:, 0] - 20.0, 0.0), np.maximum(6.0 - p[:, 1], 0.0)).min() < 4.5

    truth = tr._truth(t)
    seen = [s for pose in truth[::4] for s in tr.sightings(t, ring.fov_rad, ring.d_t_m, pose, beacons)]
    monkeypatch.setattr(tr.Tube, "clear", lambda self, a, b, step_m=0.05: True)
    every = [s for pose in truth[::4] for s in tr.sightings(t, ring.fov_rad, ring.d_t_m, pose, beacons)]
    assert len(every) > len(seen) > 0
    hidden = {(s.camera, s.beacon, s.side, round(s.u_m, 9)) for s in every} - {
        (s.camera, s.beacon, s.side, round(s.u_m, 9)) for s in seen
    }
    for s in every:  # the camera from the sighting's pose in the side's frame, the side from the beacon's
        alpha = tr.SIDE_ANGLES[s.side] + beacons[s.beacon, 2]
        side = beacons[s.beacon, :2] + ring.d_t_m * np.array([math.cos(alpha), math.sin(alpha)])
        cam = side + tr._rot(alpha) @ np.array([s.u_m, s.v_m])
        assert blocked(cam, side) == ((s.camera, s.beacon, s.side, round(s.u_m, 9)) in hidden)


def test_one_frame_per_camera_holds_every_beacon_it_sees_nearest_first():
    t = tr.Traverse()
    ring = tr._ring(t)
    seen = tr.sightings(t, ring.fov_rad, ring.d_t_m, np.array([0.0, 0.0, 0.0]), tr._beacons(t, 4.0))
    frames = tr.camera_frames(seen, 9.0)
    assert sum(len(f) for f in frames) == sum(s.range_m <= 9.0 for s in seen) and max(map(len, frames)) > 1
    for f in frames:
        assert len({s.camera for s in f}) == 1 and [s.range_m for s in f] == sorted(s.range_m for s in f)
    nearest, *others = next(f for f in frames if len(f) > 1)
    task = tr.frame_task(t, nearest, 0, others)
    assert task["scenario"] == tr.frame_task(t, nearest, 0)["scenario"] and len(task["others"]) == len(others)


@pytest.mark.parametrize("order", [1, -1])
def test_a_detection_is_taken_for_the_beacon_in_view_whose_pose_fits(order):
    """Frames holding several beacons: each detection is exact for the nearest one, and every beacon in
    view is a candidate, listed in either order. The filter takes the one whose robot pose fits its
    prediction, so it tracks the truth as with the right beacon given (fixes exact, error < 2 cm)."""
    t = tr.Traverse(path_m=12.0)

    def frames(step, seen, rng):
        out = []
        for nearest, *others in tr.camera_frames(seen, 20.0):
            est = np.array([nearest.u_m, nearest.v_m, nearest.psi_rad])
            out.append([(s, nearest.side, est, 1e-6 * np.eye(3)) for s in (nearest, *others)][::order])
        return out

    steps = tr.simulate(t, _Always(), 4.0, 0, detections=frames)
    fixed = steps[steps.detections > 0]
    assert len(fixed) > 0.9 * len(steps) and fixed.fix_error_m.max() < 1e-6
    assert steps.filter_error_m.max() < 0.02 and steps.wrong_side.sum() == 0
