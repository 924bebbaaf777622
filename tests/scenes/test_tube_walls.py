"""The tube's walls around a beacon: where Mitsuba finds them, the floor's roughness statistics,
and the scenario's checks (scenes/tube_walls.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.assemble import environment_shapes, scene_spec, to_mitsuba
from scenes.mitsuba_variant import select_variant
from scenes.scenario import Scenario, ScenarioError
from scenes.tube_walls import TubeWalls, heightfield_mesh, rough_heights


def _hit(scenario: Scenario, origin, direction) -> tuple[float, float]:
    """Distance along a ray (beacon frame) to the first surface Mitsuba finds in the scene spec, and
    that surface's diffuse reflectance as Mitsuba's BSDF there gives it."""
    import mitsuba as mi

    select_variant("mono")
    spec = scene_spec(scenario)
    spec["shapes"] = environment_shapes(scenario)  # the tube alone, no beacon in the way
    scene = mi.load_dict(to_mitsuba(spec, 1))
    ray = mi.Ray3f(mi.Point3f(*map(float, origin)), mi.Vector3f(*map(float, direction)))
    si = scene.ray_intersect(ray)
    rho = si.bsdf().eval_diffuse_reflectance(si)
    return float(np.asarray(si.t)[0]), float(np.asarray(rho).ravel()[0])


def _hit_distance(scenario: Scenario, origin, direction) -> float:
    return _hit(scenario, origin, direction)[0]


def test_the_rough_floor_has_the_stated_height_and_correlation_length():
    # the target covariance sigma^2 exp(-r^2 / l^2): 1/e at the lag l, exp(-1/4) at l / 2; measured
    # over a 20 x 20 m patch of four floors (a floor's own modes put ~1/sqrt(1024) on each value)
    spacing, corr, rms = 0.1, 0.4, 0.05
    x, y = np.meshgrid(np.arange(200) * spacing, np.arange(200) * spacing, indexing="ij")
    lag = round(corr / spacing)
    got = {0: [], lag // 2: [], lag: []}
    for seed in range(4):
        h = rough_heights(x, y, rms_m=rms, correlation_m=corr, seed=seed)
        for k in got:
            got[k].append(
                0.5 * (np.mean(h[k:, :] * h[: h.shape[0] - k, :]) + np.mean(h[:, k:] * h[:, : h.shape[1] - k]))
            )
    variance = np.mean(got[0])
    assert math.sqrt(variance) == pytest.approx(rms, rel=0.05)
    for k, expected in ((lag // 2, math.exp(-0.25)), (lag, math.exp(-1.0))):
        assert np.mean(got[k]) / variance == pytest.approx(expected, abs=0.04), k
    # one floor: the same plan point has the same height whichever stretch asks for it
    a = rough_heights(np.array([3.2]), np.array([-1.1]), rms_m=rms, correlation_m=corr, seed=9)
    b = rough_heights(np.array([[0.0, 3.2]]), np.array([[5.0, -1.1]]), rms_m=rms, correlation_m=corr, seed=9)
    assert a[0] == pytest.approx(b[0, 1], rel=1e-12)


def test_a_stretch_of_floor_is_the_plans_field_where_it_lies():
    """The mesh of a stretch placed at (x0, y0) with heading 90 deg holds at its grid point (s, c) the
    plan's height at (x0 + c, y0 + s): c runs to the right of the heading."""
    spec = {
        "origin": [0.0, 0.0, 0.0],
        "e_s": [1.0, 0.0, 0.0],
        "e_c": [0.0, 1.0, 0.0],
        "normal": [0.0, 0.0, -1.0],
        "s": [0.0, 2.0],
        "c": [0.0, 1.0],
        "spacing_m": 1.0,
        "rms_m": 0.05,
        "correlation_m": 0.5,
        "seed": 4,
        "plan": [10.0, 20.0, 90.0],
    }
    vertices, _ = heightfield_mesh(spec)
    s, c = np.meshgrid([0.0, 1.0, 2.0], [0.0, 1.0], indexing="ij")
    expected = rough_heights(10.0 + c, 20.0 + s, rms_m=0.05, correlation_m=0.5, seed=4)
    np.testing.assert_allclose(-vertices[:, 2], expected.ravel(), atol=1e-6)


def test_the_floor_mesh_lies_on_its_sloped_plane():
    walls = TubeWalls(slope_deg=10.0, floor_rms_m=0.0)
    spec = {
        "origin": [0.0, 0.0, 1.0],
        "e_s": [math.cos(math.radians(10)), 0.0, -math.sin(math.radians(10))],
        "e_c": [0.0, 1.0, 0.0],
        "normal": [-math.sin(math.radians(10)), 0.0, -math.cos(math.radians(10))],
        "s": [-2.0, 8.0],
        "c": [-1.0, 3.0],
        "spacing_m": 0.5,
        "rms_m": walls.floor_rms_m,
        "correlation_m": walls.floor_correlation_m,
        "seed": 0,
        "plan": [0.0, 0.0, 0.0],
    }
    vertices, faces = heightfield_mesh(spec)
    assert len(vertices) == 21 * 9 and len(faces) == 2 * 20 * 8
    # every vertex on the plane z = 1 - x tan(10 deg) (z down: the floor rises along +x)
    np.testing.assert_allclose(vertices[:, 2], 1.0 - vertices[:, 0] * math.tan(math.radians(10)), atol=1e-5)


def test_mitsuba_finds_the_walls_ceiling_and_sloped_floor_where_stated():
    # red side: the target frame's x is the beacon frame's -x (SIDE_ANGLE_RAD red = 180 deg)
    walls = TubeWalls(axis_deg=-90.0, left_m=0.7, right_m=6.3, height_m=4.0, slope_deg=5.0)  # camera on the right
    sc = Scenario(side="red", range_m=4.0, tube_walls=walls)
    floor_z = sc.design.target_height_m
    rot = sc.target_to_world()[0]
    axis, right = rot @ walls.axis(), rot @ walls.right()
    foot = np.array([0.0, 0.0, floor_z - 0.5])  # half a metre above the floor at the beacon
    assert _hit_distance(sc, foot, right) == pytest.approx(6.3, abs=1e-3)
    assert _hit_distance(sc, foot, -right) == pytest.approx(0.7, abs=1e-3)
    # straight up from the beacon's foot the ceiling is height / cos(slope) away (height is perpendicular)
    assert _hit_distance(sc, foot, [0.0, 0.0, -1.0]) == pytest.approx(4.0 / math.cos(math.radians(5)) - 0.5, abs=1e-3)
    # 3 m along the axis, straight down: the floor has risen by 3 tan(5 deg)
    above = foot + 3.0 * axis
    assert _hit_distance(sc, above, [0.0, 0.0, 1.0]) == pytest.approx(0.5 - 3 * math.tan(math.radians(5)), abs=1e-3)


@pytest.mark.parametrize("reflectance", [None, 0.2])
def test_walls_ceiling_and_floor_reflect_the_tubes_own_reflectance_or_the_environments(reflectance):
    walls = TubeWalls(axis_deg=-90.0, left_m=0.7, right_m=6.3, floor_rms_m=0.05, reflectance=reflectance)
    sc = Scenario(side="red", range_m=4.0, tube_walls=walls)
    expected = 0.07 if reflectance is None else reflectance  # the dark environment's basalt (environments.toml)
    assert sc.env.wall_reflectance == sc.env.floor_reflectance == 0.07
    rot = sc.target_to_world()[0]
    foot = np.array([0.0, 0.0, sc.design.target_height_m - 0.5])
    for direction in (rot @ walls.right(), -(rot @ walls.right()), [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]):
        assert _hit(sc, foot, direction)[1] == pytest.approx(expected, rel=1e-6)
    assert ("reflectance" in walls.to_dict()) == (reflectance is not None)  # absent: the keys of before
    with pytest.raises(ScenarioError, match=r"^tube_walls.reflectance: expected a reflectance in \(0, 1\)"):
        Scenario(tube_walls={"reflectance": 1.2})


def test_a_camera_outside_the_walls_is_a_one_line_error():
    # yaw 90: the camera 4 m along the target's y, which is the axis's right at axis_deg 0
    with pytest.raises(ScenarioError, match=r"^tube_walls: the camera stands .* outside the walls"):
        Scenario(range_m=4.0, yaw_deg=89.0, tube_walls=TubeWalls(axis_deg=0.0, right_m=2.0))
    with pytest.raises(ScenarioError, match=r"^tube_walls: a tube's walls only in a cave"):
        Scenario(environment="lit-room", tube_walls=TubeWalls())
    with pytest.raises(ScenarioError, match=r"^tube_walls.height_m: expected a length > 0 m"):
        Scenario(tube_walls={"height_m": 0.0})
    with pytest.raises(ScenarioError, match=r"^tube_walls.width_m: unknown field"):
        Scenario(tube_walls={"width_m": 3.0})


def test_tube_walls_round_trip_and_leave_other_scenarios_keys_alone():
    sc = Scenario(tube_walls=TubeWalls(axis_deg=30.0, floor_rms_m=0.05, floor_seed=7))
    assert Scenario.from_dict(sc.to_dict()) == sc
    assert "tube_walls" not in Scenario().to_dict()
