"""A planar extended Kalman filter of the robot's pose: odometry between beacon fixes.

State x = (X, Y, θ) in the global frame (m, m, rad), or (X, Y, θ, k) with k the odometer's scale
(true length per reported length: 1 − s for a slip ratio s, which a filter cannot know in advance
but can learn from the fixes), covariance P. A reported step of length d̂ and heading change Δθ̂
(:class:`pipeline.odometry.WheelOdometry`, covariance Q of (d̂, Δθ̂)) moves it along the mid-step
heading (second-order in the turn), with k = 1 in the three-state filter:

    X' = X + k d̂ cos(θ + Δθ̂/2),   Y' = Y + k d̂ sin(θ + Δθ̂/2),   θ' = θ + Δθ̂,   k' = k,

and P' = F P Fᵀ + G Q Gᵀ with F = ∂x'/∂x and G = ∂x'/∂(d̂, Δθ̂). A fix from the beacons (the
fused pose of one instant, :func:`pipeline.ring.fuse`) observes the pose, z = (X, Y, θ) + v,
v ~ N(0, R): the update is linear (H = [I₃ 0]), K = P Hᵀ (H P Hᵀ + R)⁻¹, with the heading's
innovation wrapped to (−π, π]. :func:`mahalanobis2` is the fix's squared distance from the
prediction, for gating outliers.

Example
-------
>>> import numpy as np
>>> x, p = predict(np.zeros(3), np.zeros((3, 3)), 2.0, 0.0, np.diag([0.01, 0.0]))
>>> x.round(3).tolist(), round(float(p[0, 0]), 3)
([2.0, 0.0, 0.0], 0.01)
>>> x, p = predict(np.array([0.0, 0.0, 0.0, 0.8]), np.diag([0, 0, 0, 0.01]), 2.0, 0.0, np.zeros((2, 2)))
>>> x.round(3).tolist(), round(float(p[0, 0]), 3)  # 0.8 × 2 m; the scale's sd 0.1 × 2 m
([1.6, 0.0, 0.0, 0.8], 0.04)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["mahalanobis2", "predict", "update"]


def predict(
    x: NDArray[np.float64],
    p: NDArray[np.float64],
    step_m: float,
    turn_rad: float,
    q: NDArray[np.float64],
    *,
    scale_walk: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The state and covariance after one reported step (module docstring); ``scale_walk``: the
    four-state filter's scale drifts as a random walk of this variance per reported metre (1/m)."""
    n = len(x)
    k = float(x[3]) if n == 4 else 1.0
    heading = x[2] + turn_rad / 2
    c, s = math.cos(heading), math.sin(heading)
    new = np.array(x, dtype=float)
    new[:3] = [x[0] + k * step_m * c, x[1] + k * step_m * s, math.remainder(x[2] + turn_rad, 2 * math.pi)]
    f = np.eye(n)
    f[0, 2], f[1, 2] = -k * step_m * s, k * step_m * c
    g = np.zeros((n, 2))
    g[:3] = [[k * c, -k * step_m * s / 2], [k * s, k * step_m * c / 2], [0.0, 1.0]]
    if n == 4:
        f[0, 3], f[1, 3] = step_m * c, step_m * s
    cov = f @ p @ f.T + g @ np.asarray(q, dtype=float) @ g.T
    if n == 4:
        cov[3, 3] += scale_walk * abs(step_m)
    return new, (cov + cov.T) / 2


def _innovation(x: NDArray[np.float64], z: NDArray[np.float64]) -> NDArray[np.float64]:
    y = np.asarray(z, dtype=float) - x[:3]
    y[2] = math.remainder(y[2], 2 * math.pi)
    return y


def mahalanobis2(
    x: NDArray[np.float64], p: NDArray[np.float64], z: NDArray[np.float64], r: NDArray[np.float64]
) -> float:
    """Squared Mahalanobis distance of a pose fix z (covariance r) from the state's pose: yᵀ(HPHᵀ + R)⁻¹y;
    χ² with 3 degrees of freedom when the fix and the filter are consistent."""
    y = _innovation(x, z)
    return float(y @ np.linalg.solve(p[:3, :3] + r, y))


def update(
    x: NDArray[np.float64], p: NDArray[np.float64], z: NDArray[np.float64], r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The state and covariance after a fix z of the pose with covariance r (module docstring)."""
    n = len(x)
    gain = p[:, :3] @ np.linalg.inv(p[:3, :3] + r)
    new = x + gain @ _innovation(x, z)
    new[2] = math.remainder(new[2], 2 * math.pi)
    h = np.zeros((3, n))
    h[:, :3] = np.eye(3)
    cov = (np.eye(n) - gain @ h) @ p
    return new, (cov + cov.T) / 2
