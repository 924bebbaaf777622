"""Mitsuba shape dictionaries shared by the beacon-scale scene and the near-field marker
model: oriented disks, rectangles, cylinders, boxes and bars. Lengths in metres; every
shape is a plain dict (the scene spec), turned into Mitsuba objects later."""

from __future__ import annotations

import numpy as np

__all__ = ["beam_shape", "box_shape", "cylinder_shape", "disk_shape", "frame_with_z", "rect_shape", "to_world_matrix"]


def frame_with_z(z_axis: np.ndarray) -> np.ndarray:
    """A rotation matrix whose third column is ``z_axis``."""
    z = z_axis / np.linalg.norm(z_axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def to_world_matrix(rot: np.ndarray, centre: np.ndarray, scale=(1.0, 1.0, 1.0)) -> list[list[float]]:
    m = np.eye(4)
    m[:3, :3] = rot @ np.diag(scale)
    m[:3, 3] = centre
    return np.round(m, 12).tolist()


def disk_shape(centre, normal, radius, material, emitter=None) -> dict:
    shape = {
        "type": "disk",
        "matrix": to_world_matrix(frame_with_z(normal), centre, (radius, radius, 1.0)),
        "material": material,
    }
    if emitter is not None:
        shape["emitter"] = emitter
    return shape


def cylinder_shape(p0, p1, radius, material) -> dict:
    return {
        "type": "cylinder",
        "p0": list(map(float, p0)),
        "p1": list(map(float, p1)),
        "radius": float(radius),
        "material": material,
    }


def box_shape(centre, axes: np.ndarray, half_sizes, material) -> dict:
    """An oriented box; ``axes`` columns are its local x, y, z directions."""
    return {"type": "cube", "matrix": to_world_matrix(axes, centre, half_sizes), "material": material}


def beam_shape(p0, p1, width, material) -> dict:
    """A square bar of side ``width`` from ``p0`` to ``p1``."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axes = frame_with_z(p1 - p0)
    half = (width / 2, width / 2, np.linalg.norm(p1 - p0) / 2)
    return box_shape((p0 + p1) / 2, axes, half, material)


def rect_shape(centre, u, v, half_u, half_v, material, emitter=None) -> dict:
    """A rectangle spanning ±half_u along ``u`` and ±half_v along ``v``; normal u × v."""
    u, v = np.asarray(u, float), np.asarray(v, float)
    rot = np.stack([u, v, np.cross(u, v)], axis=1)
    shape = {"type": "rectangle", "matrix": to_world_matrix(rot, centre, (half_u, half_v, 1.0)), "material": material}
    if emitter is not None:
        shape["emitter"] = emitter
    return shape
