"""Rendered marker centroids against the pinhole projection of their 3-D positions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes.assemble import scene_spec
from scenes.render import pixel_grid, render, render_unit_groups
from scenes.scenario import RenderSettings, Scenario
from scenes.view import project

pytestmark = pytest.mark.usefixtures("mitsuba_variant")

RANGES_M = (1.0, 5.0, 10.0)
YAWS_DEG = (0.0, 15.0, 30.0)


def _settings(range_m: float) -> RenderSettings:
    # enough sub-pixels across a 12 mm face (~50 px at 1 m, ~5 px at 10 m on the T6 + 18 mm)
    return RenderSettings(spp=16, oversampling=1 if range_m < 2 else 3, crop="target", seed=3)


def _centroids(image, grid, uv, radius_px):
    u, v = grid.subpixel_centres_px()
    out = []
    for pu, pv in uv:
        w = image * (((u[None, :] - pu) ** 2 + (v[:, None] - pv) ** 2) <= radius_px**2)
        out.append(((w * u[None, :]).sum() / w.sum(), (w * v[:, None]).sum() / w.sum()))
    return np.array(out)


def _window(uv):
    return 0.45 * min(np.hypot(*(uv[i] - uv[j])) for i in range(5) for j in range(i + 1, 5))


@pytest.mark.parametrize("beacon", ["v1", "v2"])
@pytest.mark.parametrize(
    "range_m", [pytest.param(r, marks=pytest.mark.slow) if r < 2.0 else r for r in RANGES_M]
)  # 1 m: 17-28 s per beacon, slow
def test_lambertian_marker_centroids_match_pinhole_projection(beacon, range_m):
    """Geometry alone: lit faces made Lambertian (what a thick diffuser approaches), so
    a face's radiance-weighted centre is its geometric centre; every marker whose face
    the camera sees from the front must image within 0.1 px of its projection."""
    for yaw in YAWS_DEG:
        scenario = Scenario(beacon=beacon, side="red", range_m=range_m, yaw_deg=yaw, render=_settings(range_m))
        spec = scene_spec(scenario)
        for shape in spec["shapes"]:
            if "emitter" in shape:
                shape["emitter"]["exponent"] = 0.0
        image = render_unit_groups(spec, 16, 3, ["led:red"])["led:red"].astype(np.float64)
        grid = pixel_grid(scenario)
        uv = project(scenario.geometry, scenario.camera_pose(), scenario.marker_positions_world_m())
        cam_t = scenario.camera_position_target_m()
        markers = scenario.design.markers
        facing = [m.id for m in markers if np.dot(cam_t - m.position_m, m.normal) > 1e-3]
        assert 1 in facing and (beacon == "v1" or len(facing) == 5)
        centroid = _centroids(image, grid, uv, _window(uv))
        err = np.hypot(*(centroid - uv).T)[[i - 1 for i in facing]]
        assert err.max() < 0.1, (beacon, range_m, yaw, facing, err)


def _emission_weighted_projection(scenario: Scenario, n_r: int = 40, n_phi: int = 96):
    """Independent reference: the image centroid of each lit face, by quadrature.

    centroid = ∫ u(x) L(θ_x) cos θ_x / r_x² dA / ∫ L(θ_x) cos θ_x / r_x² dA over the
    face, with L ∝ cos^(m−1) θ the bare-LED radiance and θ_x the angle between the
    face normal and the direction from x to the camera.
    """
    design, pose = scenario.design, scenario.camera_pose()
    rot, trans = scenario.target_to_world()
    m = scenario.led.cos_exponent
    r_face = design.lit_face_diameter_m / 2
    rr = (np.arange(n_r) + 0.5) / n_r * r_face
    pp = (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi
    R, P = np.meshgrid(rr, pp)
    out = []
    for marker in design.markers:
        n = rot @ marker.normal
        a = np.cross(n, [0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.cross(n, [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        centre = rot @ marker.position_m + trans
        pts = centre + (R * np.cos(P))[..., None] * a + (R * np.sin(P))[..., None] * b
        to_cam = pose.position_m - pts
        dist = np.linalg.norm(to_cam, axis=-1)
        cos_t = np.clip((to_cam @ n) / dist, 0.0, None)
        w = cos_t ** (m - 1) * cos_t / dist**2 * R  # R: polar area element
        uv = project(scenario.geometry, pose, pts)
        out.append(np.sum(w[..., None] * uv, axis=(0, 1)) / w.sum())
    return np.array(out)


@pytest.mark.parametrize(("range_m", "yaw"), [(1.0, 30.0), (5.0, 15.0), (10.0, 30.0)])
def test_bare_led_centroids_match_emission_weighted_projection(range_m, yaw):
    """With the bare LED's cos^(m−1) radiance the bright side of a tilted face pulls its
    centroid off the geometric centre (0.3 px at 1 m, 30°); the render must agree with
    an independent quadrature of that emission within 0.1 px."""
    scenario = Scenario(beacon="v2", side="red", range_m=range_m, yaw_deg=yaw, render=_settings(range_m))
    radiance = render(scenario, groups=["led:red"])
    uv = project(scenario.geometry, scenario.camera_pose(), scenario.marker_positions_world_m())
    image = radiance.component("led:red").image_W_m2_sr.astype(np.float64)
    centroid = _centroids(image, radiance.grid, uv, _window(uv))
    expected = _emission_weighted_projection(scenario)
    assert np.hypot(*(centroid - expected).T).max() < 0.1


def test_turned_camera_pose_projects_marker_one_off_centre():
    """Pan p and tilt t: marker 1 at (cx − f·tan p, cy + f·tan t / cos p) in the pinhole camera
    (the axis turned in azimuth, then in elevation); the render's pose is the unturned one."""
    from scenes.view import project

    sc = Scenario(camera="logitech-c270", range_m=4.0, yaw_deg=10.0, pan_deg=20.0, tilt_deg=8.0)
    plain = Scenario(camera="logitech-c270", range_m=4.0, yaw_deg=10.0)
    g = sc.geometry
    cx, cy = g.principal_point_px
    f = g.focal_length_px
    uv = project(g, sc.camera_pose(), sc.marker_positions_world_m()[:1])[0]
    p, t = math.radians(20.0), math.radians(8.0)
    # direction to marker 1 in the turned camera: azimuth −p from the new axis' heading, elevation −t
    d = np.array([-math.sin(p) * math.cos(0.0), 0.0, math.cos(p)])
    d = np.array([d[0], d[2] * math.sin(t), d[2] * math.cos(t)])
    assert uv == pytest.approx([cx + f * d[0] / d[2], cy + f * d[1] / d[2]], abs=1e-6)
    np.testing.assert_allclose(sc.render_pose().rotation, plain.camera_pose().rotation)
    assert "pan_deg" not in plain.to_dict() and sc.to_dict()["pan_deg"] == 20.0
    assert Scenario.from_dict(sc.to_dict()) == sc
