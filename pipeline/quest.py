"""QUEST attitude from vector pairs: the study's Gibbs shortcut and the full algorithm.

Wahba's problem: find the rotation A minimising Σ a_i |w_i − A v_i|² for unit body
vectors w_i (here: the camera frame) and reference vectors v_i (the target frame).
Davenport's K matrix, with B = Σ a_i w_i v_iᵀ::

    S = B + Bᵀ,  σ = tr B,  z = Σ a_i w_i × v_i,  K = [[S − σI, z], [zᵀ, σ]]

The optimal quaternion is K's eigenvector of the largest eigenvalue λ_max. Quaternions
here are (x, y, z, w), scalar last, in Shuster's convention:
A(q) = (w² − |q_v|²) I + 2 q_v q_vᵀ − 2 w [q_v×], so that w_i ≈ A(q) v_i. (scipy's
``Rotation.from_quat(q).as_matrix()`` is A(q)ᵀ.)

* :func:`quest_shortcut` is what the study ran (docs/source-study.md §7): λ_max ≈ 1, Gibbs vector
  g = ((1 + σ)I − S)⁻¹ z, q = (g, 1)/√(1 + |g|²). With weights summing to 1 and
  noise-free vectors λ_max is exactly 1, so the shortcut is then exact up to rounding;
  with noise λ_max < 1 and it is approximate; at a 180° rotation (1 + σ)I − S is singular
  and near it the error grows as 1/(π − θ)².
* :func:`quest` is Shuster & Oh's QUEST: λ_max by Newton on K's characteristic equation
  (start Σ a_i), q from the adjugate form (no inverse), and Shuster's method of
  sequential rotations — the reference vectors are turned 180° about x, y or z when the
  scalar part would be small — so it is exact at and near 180°.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["QuestResult", "attitude_matrix", "quaternion_from_attitude", "quest", "quest_shortcut"]

_FLIPS = (np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]))


def attitude_matrix(q_xyzw) -> NDArray[np.float64]:
    """Shuster's attitude matrix A(q) of a unit quaternion (x, y, z, w); A maps reference to body."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    qv, w = q[:3], q[3]
    cross = np.array([[0.0, -qv[2], qv[1]], [qv[2], 0.0, -qv[0]], [-qv[1], qv[0], 0.0]])
    return (w * w - qv @ qv) * np.eye(3) + 2.0 * np.outer(qv, qv) - 2.0 * w * cross


def quaternion_from_attitude(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of :func:`attitude_matrix` (Shepperd's method, scalar ≥ 0), (x, y, z, w)."""
    a = np.asarray(a, dtype=np.float64)
    tr = np.trace(a)
    # pick the largest of 4w², 4x², 4y², 4z² to divide by (no cancellation)
    cands = np.array([1 + 2 * a[0, 0] - tr, 1 + 2 * a[1, 1] - tr, 1 + 2 * a[2, 2] - tr, 1 + tr])
    k = int(np.argmax(cands))
    q = np.empty(4)
    q[k] = 0.5 * np.sqrt(cands[k])
    d = 4.0 * q[k]
    if k == 3:
        q[0], q[1], q[2] = (a[1, 2] - a[2, 1]) / d, (a[2, 0] - a[0, 2]) / d, (a[0, 1] - a[1, 0]) / d
    elif k == 0:
        q[1], q[2], q[3] = (a[0, 1] + a[1, 0]) / d, (a[0, 2] + a[2, 0]) / d, (a[1, 2] - a[2, 1]) / d
    elif k == 1:
        q[0], q[2], q[3] = (a[0, 1] + a[1, 0]) / d, (a[1, 2] + a[2, 1]) / d, (a[2, 0] - a[0, 2]) / d
    else:
        q[0], q[1], q[3] = (a[0, 2] + a[2, 0]) / d, (a[1, 2] + a[2, 1]) / d, (a[0, 1] - a[1, 0]) / d
    return q if q[3] >= 0 else -q


def _profile(w, v, weights):
    w = np.asarray(w, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    a = np.asarray(weights, dtype=np.float64)
    if w.shape != v.shape or w.ndim != 2 or w.shape[1] != 3 or a.shape != (w.shape[0],):
        raise ValueError("quest: expected w, v of shape (n, 3) and n weights")
    b = np.einsum("i,ij,ik->jk", a, w, v)
    s = b + b.T
    sigma = np.trace(b)
    z = np.array([b[1, 2] - b[2, 1], b[2, 0] - b[0, 2], b[0, 1] - b[1, 0]])  # = Σ a_i w_i × v_i
    return s, sigma, z, float(a.sum())


def quest_shortcut(w, v, weights) -> NDArray[np.float64]:
    """The study's QUEST: Gibbs vector with λ_max ≈ 1, quaternion (x, y, z, w).

    Parameters
    ----------
    w, v
        Unit body (camera) and reference (target) vectors, shape (n, 3).
    weights
        a_i, shape (n,); the approximation λ_max ≈ 1 assumes Σ a_i = 1.

    Returns non-finite numbers at an exact 180° rotation, as the study's code would.
    """
    s, sigma, z, _ = _profile(w, v, weights)
    with np.errstate(all="ignore"):
        try:
            g = np.linalg.solve((1.0 + sigma) * np.eye(3) - s, z)
        except np.linalg.LinAlgError:
            g = np.full(3, np.inf)
        q = np.append(g, 1.0) / np.sqrt(1.0 + g @ g)
    return q


@dataclass(frozen=True)
class QuestResult:
    """Full QUEST solution.

    Attributes
    ----------
    q_xyzw
        Optimal quaternion (x, y, z, w), scalar ≥ 0.
    lambda_max
        Largest eigenvalue of K.
    loss
        Wahba loss Σ a_i − λ_max (0 for consistent vectors).
    iterations
        Newton iterations on the characteristic equation.
    flip_axis
        Sequential rotation used: None, or 0/1/2 for 180° about x/y/z.
    """

    q_xyzw: NDArray[np.float64]
    lambda_max: float
    loss: float
    iterations: int
    flip_axis: int | None


def _quest_once(s, sigma, z, lam0, tol, max_iter):
    kappa = _adj_trace(s)
    delta = np.linalg.det(s)
    a = sigma**2 - kappa
    b = sigma**2 + z @ z
    c = delta + z @ s @ z
    d = z @ s @ s @ z
    lam, it = lam0, 0
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is reported)
        f = lam**4 - (a + b) * lam**2 - c * lam + (a * b + c * sigma - d)
        fp = 4 * lam**3 - 2 * (a + b) * lam - c
        step = f / fp if fp != 0 else 0.0
        lam -= step
        if abs(step) <= tol * max(1.0, abs(lam)):
            break
    alpha = lam**2 - sigma**2 + kappa
    beta = lam - sigma
    gamma = (lam + sigma) * alpha - delta  # = det((λ + σ)I − S), 0 at a 180° rotation
    x = (alpha * np.eye(3) + beta * s + s @ s) @ z  # = adj((λ + σ)I − S) z, also 0 there
    return np.append(x, gamma), lam, it


def _adj_trace(s):
    # trace of the adjugate = sum of the principal 2×2 minors (valid for singular S too)
    minors = (s[1, 1] * s[2, 2] - s[1, 2] * s[2, 1], s[0, 0] * s[2, 2] - s[0, 2] * s[2, 0])
    return minors[0] + minors[1] + s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]


def quest(w, v, weights, tol: float = 1e-14, max_iter: int = 50) -> QuestResult:
    """Full QUEST with Newton on the characteristic equation and sequential rotations.

    Parameters
    ----------
    w, v
        Unit body (camera) and reference (target) vectors, shape (n, 3).
    weights
        a_i > 0, shape (n,); need not sum to 1.
    tol
        Relative Newton step tolerance on λ_max.
    max_iter
        Newton iteration limit.

    Notes
    -----
    The unnormalised solution (x, γ) vanishes at a 180° rotation (0/0), so the problem is
    solved in the original reference frame and in the frames turned 180° about x, y and
    z, and the one with the largest |γ| is kept (Shuster's method of sequential
    rotations, made unconditional because it costs three 3×3 solves); the turn is undone
    on the attitude matrix.
    """
    v = np.asarray(v, dtype=np.float64)
    total = float(np.sum(weights))
    best = None
    for k, flip_m in enumerate(_FLIPS):
        s, sigma, z, _ = _profile(w, v @ flip_m.T, weights)
        q_raw, lam, it = _quest_once(s, sigma, z, total, tol, max_iter)
        if best is None or abs(q_raw[3]) > abs(best[0][3]):
            best = (q_raw, lam, it, k)
    q_raw, lam, it, k = best
    q = q_raw / np.linalg.norm(q_raw)
    if k:  # w = A' (F v) = (A' F) v
        q = quaternion_from_attitude(attitude_matrix(q) @ _FLIPS[k])
    if q[3] < 0:
        q = -q
    return QuestResult(q, float(lam), float(total - lam), it, None if k == 0 else k - 1)
