"""Scenario → scene description → Mitsuba scene dictionary.

The scene is first written as a *spec*: plain JSON-able data (shapes as 4×4 matrices,
materials as reflectances, emitters as groups). The spec is what the render cache
hashes, so anything that changes the image changes the key. :func:`to_mitsuba`
turns it into the dictionary ``mitsuba.load_dict`` takes.

Emitter groups: every lit face belongs to the group of its side (``led:red`` …) and the
luminous ceiling of a room to ``ambient``. The renderer renders one group at a time
(light transport is linear), so each group's image can be scaled and coloured by its
own spectrum afterwards. A lit face emits ``1 / A`` W·m⁻²·sr⁻¹ along its normal: one
W·sr⁻¹ of on-axis LED intensity spread over the face, times cos^(m−1)θ (plus the LED's
Lambertian wide share, :mod:`scenes.led`). A housing whose printed wall transmits light
(``housing_transmittance`` in ``scenes/data/beacons/*.toml``) also glows: its cylinder carries
a Lambertian emitter of the side's group with the near-field model's leak radiance
(:func:`scenes.near_field.housing_leak`), which is how V1's sideways-pointing in-plane LEDs
are seen from the front.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenes.beacon import SIDE_ANGLE_RAD, BeaconDesign, target_to_beacon
from scenes.near_field import NearFieldSettings, housing_leak, marker_emission
from scenes.scenario import Scenario, ScenarioError
from scenes.shapes import beam_shape, box_shape, cylinder_shape, disk_shape, rect_shape
from scenes.tube_walls import heightfield_mesh
from scenes.view import project

__all__ = [
    "FACE_STANDOFF_M",
    "CropBox",
    "bare_face_emitter",
    "beacon_shapes",
    "ceiling_radiance_W_m2_sr",
    "crop_box",
    "emitter_groups",
    "environment_shapes",
    "face_emitter",
    "leak_emitter",
    "room_extent",
    "room_spec",
    "scene_spec",
    "sensor_spec",
    "surface_reflectance",
    "target_shapes",
    "to_mitsuba",
]

FACE_STANDOFF_M = 2e-4
"""A housing's front plate sits 0.2 mm behind its lit face so the two never coincide; the
lit face itself is exactly at the marker position."""


@dataclass(frozen=True)
class CropBox:
    """Region of the full frame that is rendered, in camera pixels (OpenCV convention:
    pixel (x0, y0) is the crop's top-left pixel)."""

    x0: int
    y0: int
    width: int
    height: int


def bare_face_emitter(design: BeaconDesign, side: str) -> dict:
    """The lit-face emitter of a bare LED: radiance (1/A)[(1 − s) cos^(m−1)θ + s] per W·sr⁻¹."""
    led = design.led(side)
    emitter = {
        "type": "marker_face",
        "group": f"led:{side}",
        "radiance": 1.0 / design.lit_face_area_m2,
        "exponent": led.cos_exponent - 1.0,
    }
    if led.wide_fraction > 0:
        emitter["wide"] = led.wide_fraction
    return emitter


def leak_emitter(scenario: Scenario, side: str) -> dict | None:
    """The Lambertian emitter on a side's housing walls (per W·sr⁻¹ of LED intensity), or
    ``None`` where the wall is opaque."""
    leak = housing_leak(
        scenario.design,
        scenario.led_for(side),
        scenario.housing,
        scenario.diffuser,
        side,
        settings=NearFieldSettings(spp=scenario.render.near_field_spp),
    )
    if leak <= 0.0:
        return None
    return {"type": "marker_face", "group": f"led:{side}", "radiance": float(np.round(leak, 9)), "exponent": 0.0}


def face_emitter(scenario: Scenario, side: str) -> tuple[dict, float]:
    """The lit-face emitter of a side's markers and the face's reflectance.

    Bare LEDs: radiance 1/A along the normal × cos^(m−1)θ (one W·sr⁻¹ on axis). With
    diffusers: the near-field exit radiance L(r, θ) per W·sr⁻¹ as a texture.
    """
    design, led, config = scenario.design, scenario.led_for(side), scenario.diffuser
    group = f"led:{side}"
    if config.is_bare:
        return bare_face_emitter(design, side), design.lit_face_reflectance
    emission = marker_emission(
        design, led, scenario.housing, config, side, settings=NearFieldSettings(spp=scenario.render.near_field_spp)
    )
    emitter = {
        "type": "marker_face",
        "group": group,
        "radiance": 1.0,
        "exponent": 0.0,
        "profile": np.round(emission.profile_per_m2, 9).tolist(),
    }
    if config.paper_sheets:
        reflectance = float(config.sheet(side).at(emission.reference_wavelength_nm)[0])
    else:
        reflectance = 0.8  # foam face: white polyethylene (assumed, as the foam's albedo suggests)
    return emitter, reflectance


def target_shapes(
    design: BeaconDesign,
    side: str,
    housing: str,
    emitter: dict | None = None,
    face_material: str = "lit_face",
    wall_emitter: dict | None = None,
) -> list[dict]:
    """Shapes of one side's target (housings, arms, stalk, lit faces), beacon frame;
    ``wall_emitter`` (if any) makes each housing's cylinder glow (light leaking out)."""
    rot, trans = target_to_beacon(side, design.d_t_m)
    world = lambda p: rot @ np.asarray(p, float) + trans  # noqa: E731
    wdir = lambda d: rot @ np.asarray(d, float)  # noqa: E731
    mat = f"housing_{housing}"
    r_face, r_house = design.lit_face_diameter_m / 2, design.housing_radius_m
    depth, w = design.housing_depth_m, design.arm_width_m
    centre = np.array([-design.out_of_plane_m, 0.0, 0.0])  # centre of the in-plane cross
    shapes: list[dict] = []
    if emitter is None:  # bare LED faces
        emitter = bare_face_emitter(design, side)
    for marker in design.markers:
        p, n = marker.position_m, marker.normal
        back = p - depth * n
        shapes.append(disk_shape(world(p), wdir(n), r_face, face_material, emitter))
        shapes.append(disk_shape(world(p - FACE_STANDOFF_M * n), wdir(n), r_house, mat))
        wall = cylinder_shape(world(back), world(p), r_house, mat)
        if wall_emitter is not None:
            wall["emitter"] = dict(wall_emitter)
        shapes.append(wall)
        shapes.append(disk_shape(world(back), wdir(-n), r_house, mat))
        if marker.id == 1:
            shapes.append(beam_shape(world(centre), world(back), w, mat))
            continue
        radial = (p - centre) * np.array([0.0, 1.0, 1.0])
        radial /= np.linalg.norm(radial)
        if np.allclose(n, radial):  # V1: housing along the arm, arm ends at its back
            shapes.append(beam_shape(world(centre), world(back), w, mat))
        else:  # V2: arm behind the plane, elbow forward into the housing's back
            elbow = back - (w / 2) * n
            root = centre - (depth + w / 2) * np.array([1.0, 0.0, 0.0])
            shapes.append(beam_shape(world(root), world(elbow), w, mat))
            shapes.append(beam_shape(world(elbow), world(back), w, mat))
    hub = centre - (depth + w / 2) * np.array([1.0, 0.0, 0.0])
    shapes.append(box_shape(world(hub), rot, (w, w, w), mat))
    # stalk from the cross's hub back to the node's surface
    stalk_end = np.array([-(design.d_t_m - design.node_radius_m) + 1e-3, 0.0, 0.0])
    shapes.append(beam_shape(world(hub), world(stalk_end), w, mat))
    return shapes


def beacon_shapes(scenario: Scenario) -> tuple[list[dict], dict[str, float]]:
    """The node body and all four targets (beacon frame), and the lit faces' materials."""
    design, housing = scenario.design, scenario.housing
    mat = f"housing_{housing}"
    floor_z = design.target_height_m
    top_z = floor_z - design.node_height_m
    r = design.node_radius_m
    shapes = [
        cylinder_shape((0, 0, floor_z), (0, 0, top_z), r, mat),
        disk_shape(np.array([0.0, 0.0, top_z]), np.array([0.0, 0.0, -1.0]), r, mat),
    ]
    face_materials: dict[str, float] = {}
    for side in SIDE_ANGLE_RAD:
        emitter, reflectance = face_emitter(scenario, side)
        face_materials[f"face_{side}"] = reflectance
        shapes += target_shapes(design, side, housing, emitter, f"face_{side}", leak_emitter(scenario, side))
    return shapes, face_materials


def room_extent(scenario: Scenario) -> tuple[np.ndarray, float, float]:
    """Unit vector from the beacon toward the camera (horizontal) and the box's extent
    along it: (along, s_back, s_front), with s measured from the beacon axis, m."""
    cam = scenario.camera_pose().position_m
    along = np.array([cam[0], cam[1], 0.0])
    dist = float(np.linalg.norm(along))
    along = along / dist if dist > 0 else np.array([1.0, 0.0, 0.0])
    env = scenario.env
    return along, -env.back_wall_m, dist + env.front_wall_m


def environment_shapes(scenario: Scenario) -> list[dict]:
    """Floor, ceiling and walls of the box around the camera-beacon line, or the tube's around the
    beacon where the scenario has :attr:`~scenes.scenario.Scenario.tube_walls`
    (:func:`scenes.tube_walls.tube_wall_shapes`)."""
    env, design = scenario.env, scenario.design
    if scenario.tube_walls is not None:
        return scenario.tube_shapes()
    along, s0, s1 = room_extent(scenario)
    down = np.array([0.0, 0.0, 1.0])
    across = np.cross(down, along)
    floor_z = design.target_height_m
    ceil_z = floor_z - env.height_m
    half_l, mid_s = 0.5 * (s1 - s0), 0.5 * (s0 + s1)
    half_w, half_h, mid_z = env.width_m / 2, env.height_m / 2, 0.5 * (floor_z + ceil_z)
    mid = mid_s * along + mid_z * down
    ceiling_emitter = None
    if env.kind == "room":  # luminous ceiling, unit radiance, scaled after rendering
        ceiling_emitter = {"type": "area", "group": "ambient", "radiance": 1.0}
    return [
        rect_shape(mid + half_h * down, along, across, half_l, half_w, "floor"),
        rect_shape(mid - half_h * down, along, across, half_l, half_w, "wall", ceiling_emitter),
        rect_shape(mid + (s0 - mid_s) * along, across, down, half_w, half_h, "wall"),
        rect_shape(mid + (s1 - mid_s) * along, across, down, half_w, half_h, "wall"),
        rect_shape(mid + half_w * across, along, down, half_l, half_h, "wall"),
        rect_shape(mid - half_w * across, along, down, half_l, half_h, "wall"),
    ]


def ceiling_radiance_W_m2_sr(scenario: Scenario) -> float:
    """Radiance of the room's luminous ceiling giving the environment's illuminance, W·m⁻²·sr⁻¹."""
    _, s0, s1 = room_extent(scenario)
    return scenario.env.ceiling_radiance_W_m2_sr(scenario.design.target_height_m, s0, s1)


def crop_box(scenario: Scenario) -> CropBox:
    """The full-frame pixels covering the beacon (all four targets) plus the margin."""

    design, geom = scenario.design, scenario.geometry
    if scenario.render.crop == "target":
        rot, trans = scenario.target_to_world()
        corners = design.bounding_points_m() @ rot.T + trans
    else:
        reach = design.arm_length_m + design.housing_radius_m + design.housing_depth_m
        ext = design.d_t_m + 0.01
        corners = np.array([[x, y, z] for x in (-ext, ext) for y in (-ext, ext) for z in (-reach, reach)])
    pose = scenario.render_pose()
    if np.any(pose.world_to_camera(corners)[:, 2] <= 0.05):
        raise ScenarioError(f"range_m: the camera at {scenario.range_m} m is inside or too close to the beacon")
    uv = project(geom, pose, corners)
    m = scenario.render.margin_px
    x0 = max(0, math.floor(uv[:, 0].min()) - m)
    y0 = max(0, math.floor(uv[:, 1].min()) - m)
    x1 = min(geom.width_px, math.ceil(uv[:, 0].max()) + m + 1)
    y1 = min(geom.height_px, math.ceil(uv[:, 1].max()) + m + 1)
    if x1 <= x0 or y1 <= y0:
        raise ScenarioError("camera: the beacon is outside the camera's field of view")
    return CropBox(x0, y0, x1 - x0, y1 - y0)


def sensor_spec(scenario: Scenario, *, turned: bool = False) -> dict:
    """The camera of a scene spec: pose, field of view, oversampled film and the crop. The pose is
    the render's (:meth:`scenes.scenario.Scenario.render_pose`), or with ``turned`` the camera's
    own (a whole-frame view of the room)."""
    geom, s = scenario.geometry, scenario.render.oversampling
    pose = scenario.camera_pose() if turned else scenario.render_pose()
    crop = crop_box(scenario)
    return {
        "position": pose.position_m.tolist(),
        "target": (pose.position_m + pose.rotation[2]).tolist(),
        "up": (-pose.rotation[1]).tolist(),
        "fov_x_deg": math.degrees(2 * math.atan(geom.width_px / (2 * geom.focal_length_px))),
        "film": [geom.width_px * s, geom.height_px * s],
        "crop": [crop.x0 * s, crop.y0 * s, crop.width * s, crop.height * s],
    }


def surface_reflectance(scenario: Scenario) -> dict[str, float]:
    """Diffuse reflectance of the surroundings' ``wall`` and ``floor`` materials: the environment's,
    or the tube's own where :attr:`~scenes.scenario.Scenario.tube_walls` states one."""
    walls = scenario.tube_walls
    if walls is not None and walls.reflectance is not None:
        return {"wall": walls.reflectance, "floor": walls.reflectance}
    return {"wall": scenario.env.wall_reflectance, "floor": scenario.env.floor_reflectance}


def room_spec(scenario: Scenario) -> dict:
    """The scene of :func:`scene_spec` without the beacon: the room (and its luminous
    ceiling) seen by the same camera; path length that of the ambient light."""
    return {
        "sensor": sensor_spec(scenario, turned=True),
        "materials": surface_reflectance(scenario),
        "shapes": environment_shapes(scenario),
        "max_depth": scenario.render.ambient_max_depth,
    }


def scene_spec(scenario: Scenario) -> dict:
    """Plain-data description of everything Mitsuba renders for ``scenario``."""
    design, env, settings = scenario.design, scenario.env, scenario.render
    shapes, face_materials = beacon_shapes(scenario)
    return {
        "sensor": sensor_spec(scenario),
        "materials": {
            "housing_white": design.housing_reflectance["white"],
            "housing_black": design.housing_reflectance["black"],
            **face_materials,
            **surface_reflectance(scenario),
        },
        "shapes": shapes + environment_shapes(scenario),
        "max_depth": max(settings.led_max_depth, settings.ambient_max_depth if env.has_ambient else 0),
    }


def emitter_groups(spec: dict) -> list[str]:
    """Names of the emitter groups in a spec, sorted."""
    return sorted({sh["emitter"]["group"] for sh in spec["shapes"] if "emitter" in sh})


def to_mitsuba(spec: dict, spp: int) -> dict:
    """The ``mitsuba.load_dict`` dictionary for a spec (active variant)."""
    import mitsuba as mi

    def xf(matrix):
        return mi.ScalarTransform4f(np.asarray(matrix, dtype=np.float64))

    sensor = spec["sensor"]
    w, h = sensor["film"]
    cx, cy, cw, ch = sensor["crop"]
    pixel_format = "luminance" if mi.variant().endswith("mono") else "rgb"
    scene: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(spec["max_depth"]), "hide_emitters": False},
        "sensor": {
            "type": "perspective",
            "fov": sensor["fov_x_deg"],
            "fov_axis": "x",
            "near_clip": 1e-3,
            "far_clip": 1e4,
            "to_world": mi.ScalarTransform4f().look_at(sensor["position"], sensor["target"], sensor["up"]),
            "film": {
                "type": "hdrfilm",
                "width": w,
                "height": h,
                "crop_offset_x": cx,
                "crop_offset_y": cy,
                "crop_width": cw,
                "crop_height": ch,
                "pixel_format": pixel_format,
                "component_format": "float32",
                "rfilter": {"type": "box"},
                "sample_border": False,
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    for name, rho in spec["materials"].items():
        scene[f"mat_{name}"] = {
            "type": "twosided",
            "id": f"mat_{name}",
            "bsdf": {"type": "diffuse", "reflectance": float(rho)},
        }
    for i, sh in enumerate(spec["shapes"]):
        if sh["type"] == "heightfield":
            scene[f"shape_{i:04d}"] = _heightfield(sh, spec["materials"][sh["material"]], f"shape_{i:04d}")
            continue
        d: dict = {"type": sh["type"], "bsdf": {"type": "ref", "id": f"mat_{sh['material']}"}}
        if "matrix" in sh:
            d["to_world"] = xf(sh["matrix"])
        if sh["type"] == "cylinder":
            d.update(p0=sh["p0"], p1=sh["p1"], radius=sh["radius"])
        if "emitter" in sh:
            e = sh["emitter"]
            d["emitter"] = {k: v for k, v in e.items() if k not in ("group", "profile")}
            if "profile" in e:
                table = np.asarray(e["profile"], dtype=np.float32)[..., None]
                d["emitter"]["profile"] = {
                    "type": "bitmap",
                    "data": mi.TensorXf(table),
                    "raw": True,
                    "filter_type": "bilinear",
                    "wrap_mode": "clamp",
                }
            if e["type"] == "marker_face":
                # distinct values: Mitsuba's parser merges identical nested emitter dicts
                d["emitter"]["instance"] = i
        scene[f"shape_{i:04d}"] = d
    return scene


def _heightfield(shape: dict, reflectance: float, name: str):
    """A ``heightfield`` shape (:func:`scenes.tube_walls.heightfield_mesh`) as a Mitsuba mesh with a
    two-sided diffuse BSDF of ``reflectance``."""
    import mitsuba as mi

    vertices, faces = heightfield_mesh(shape)
    props = mi.Properties()
    props.set_id(name)
    props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": float(reflectance)}})
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(vertices.reshape(-1))
    params["faces"] = mi.UInt32(faces.reshape(-1))
    params.update()
    return mesh
