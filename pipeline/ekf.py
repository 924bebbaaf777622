"""A planar extended Kalman filter of the robot's pose: odometry between beacon fixes.

State x = (X, Y, θ) in the global frame (m, m, rad), covariance P. A reported step of length d̂
and heading change Δθ̂ (:class:`pipeline.odometry.WheelOdometry`, covariance Q of (d̂, Δθ̂)) moves
it along the mid-step heading (second-order in the turn):

    X' = X + d̂ cos(θ + Δθ̂/2),   Y' = Y + d̂ sin(θ + Δθ̂/2),   θ' = θ + Δθ̂,

and P' = F P Fᵀ + G Q Gᵀ with F = ∂x'/∂x and G = ∂x'/∂(d̂, Δθ̂). A fix from the beacons (the
fused pose of one instant, :func:`pipeline.ring.fuse`) observes the whole state, z = x + v,
v ~ N(0, R): the update is linear (H = I), K = P (P + R)⁻¹, with the heading's innovation wrapped
to (−π, π].

Example
-------
>>> import numpy as np
>>> x, p = predict(np.zeros(3), np.zeros((3, 3)), 2.0, 0.0, np.diag([0.01, 0.0]))
>>> x.round(3).tolist(), round(float(p[0, 0]), 3)
([2.0, 0.0, 0.0], 0.01)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["predict", "update"]


def predict(
    x: NDArray[np.float64], p: NDArray[np.float64], step_m: float, turn_rad: float, q: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The state and covariance after one reported step (module docstring)."""
    heading = x[2] + turn_rad / 2
    c, s = math.cos(heading), math.sin(heading)
    new = np.array([x[0] + step_m * c, x[1] + step_m * s, math.remainder(x[2] + turn_rad, 2 * math.pi)])
    f = np.array([[1.0, 0.0, -step_m * s], [0.0, 1.0, step_m * c], [0.0, 0.0, 1.0]])
    g = np.array([[c, -step_m * s / 2], [s, step_m * c / 2], [0.0, 1.0]])
    cov = f @ p @ f.T + g @ np.asarray(q, dtype=float) @ g.T
    return new, (cov + cov.T) / 2


def update(
    x: NDArray[np.float64], p: NDArray[np.float64], z: NDArray[np.float64], r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The state and covariance after a fix z of the whole pose with covariance r (module docstring)."""
    innovation = np.asarray(z, dtype=float) - x
    innovation[2] = math.remainder(innovation[2], 2 * math.pi)
    gain = p @ np.linalg.inv(p + r)
    new = x + gain @ innovation
    new[2] = math.remainder(new[2], 2 * math.pi)
    cov = (np.eye(3) - gain) @ p
    return new, (cov + cov.T) / 2
