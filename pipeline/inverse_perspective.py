"""Inverse perspective: ranges to three markers from their lines of sight (docs/source-study.md §6).

For a triad (i, j, k) with known marker distances l_ij and measured cos θ_ij = r_i·r_j,
the ranges solve the law of cosines three times::

    f_ij(R) = R_i² + R_j² − 2 R_i R_j cos θ_ij − l_ij² = 0

solved here by Newton–Raphson, vectorised over many triads at once. The system has up
to eight roots: ±R (all signs flipped) and, among the positive ones, the true ranges
and "mirror" solutions such as the centre marker reflected behind the plane of the
other two (the P3P ambiguity). Which one Newton reaches depends on the start:

* :func:`study_start`: the study's fixed (100, 500, 1000) mm, for any range.
* :func:`geometric_start` (the project's default): R_j = R_k = l_jk / (2 sin(θ_jk/2)),
  the distance at which the outer pair's baseline subtends its measured angle, and
  R_i = that minus the apex height h = √(l_ij² − (l_jk/2)²) (the centre marker is in
  front of the plane for a viewer in front of the target). It starts on the near side
  of the mirror root and at the right scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["STUDY_START_MM", "TriadSolution", "geometric_start", "solve_triads", "study_start"]

STUDY_START_MM = (100.0, 500.0, 1000.0)
"""The study's Newton start (R1, R2, R3), mm."""


@dataclass(frozen=True)
class TriadSolution:
    """Newton's answer for n triads.

    Attributes
    ----------
    ranges
        (n, 3) ranges (R_i, R_j, R_k), in the units of the distances given.
    converged
        (n,) True where the step fell below the tolerance within the iteration limit
        and the answer is finite.
    iterations
        (n,) iterations used.
    """

    ranges: NDArray[np.float64]
    converged: NDArray[np.bool_]
    iterations: NDArray[np.int64]


def _as_batch(cosines) -> NDArray[np.float64]:
    c = np.asarray(cosines, dtype=np.float64)
    if c.shape[-1] != 3:
        raise ValueError("cosines: expected (..., 3) values (cos θ_ij, cos θ_ik, cos θ_jk)")
    return c.reshape(-1, 3)


def study_start(cosines, distances) -> NDArray[np.float64]:
    """The study's start (100, 500, 1000) mm for every triad (distances must be in mm)."""
    return np.tile(np.array(STUDY_START_MM), (_as_batch(cosines).shape[0], 1))


def geometric_start(cosines, distances) -> NDArray[np.float64]:
    """The project's start: outer pair at the broadside range of their baseline, apex nearer by its height.

    Parameters
    ----------
    cosines
        (..., 3) cos θ_ij, cos θ_ik, cos θ_jk with i the apex (centre marker).
    distances
        (l_ij, l_ik, l_jk), any length unit.
    """
    c = _as_batch(cosines)
    l_ij, l_ik, l_jk = (float(x) for x in distances)
    half_angle_sin = np.sqrt(np.clip((1.0 - c[:, 2]) / 2.0, 1e-300, None))
    outer = l_jk / (2.0 * half_angle_sin)
    apex = np.sqrt(max(0.5 * (l_ij**2 + l_ik**2) - (l_jk / 2) ** 2, 0.0))
    return np.stack([outer - apex, outer, outer], axis=1)


def solve_triads(cosines, distances, start, tol: float = 1e-6, max_iter: int = 10000) -> TriadSolution:
    """Newton–Raphson on the three law-of-cosines equations, for many triads at once.

    Parameters
    ----------
    cosines
        (..., 3) cos θ_ij, cos θ_ik, cos θ_jk.
    distances
        (l_ij, l_ik, l_jk), the unit of the answer.
    start
        (n, 3) or (3,) starting ranges, same unit.
    tol
        Stop when every |ΔR| < tol (same unit).
    max_iter
        Iteration limit.
    """
    c = _as_batch(cosines)
    n = c.shape[0]
    l2 = np.asarray(distances, dtype=np.float64) ** 2
    r = np.broadcast_to(np.asarray(start, dtype=np.float64), (n, 3)).copy()
    iterations = np.zeros(n, dtype=np.int64)
    converged = np.zeros(n, dtype=bool)
    active = np.arange(n)
    # pairs: (0,1) uses c0, (0,2) uses c1, (1,2) uses c2
    for it in range(1, max_iter + 1):
        if active.size == 0:
            break
        ra, ca = r[active], c[active]
        r0, r1, r2 = ra[:, 0], ra[:, 1], ra[:, 2]
        f = np.stack(
            [
                r0**2 + r1**2 - 2 * r0 * r1 * ca[:, 0] - l2[0],
                r0**2 + r2**2 - 2 * r0 * r2 * ca[:, 1] - l2[1],
                r1**2 + r2**2 - 2 * r1 * r2 * ca[:, 2] - l2[2],
            ],
            axis=1,
        )
        jac = np.zeros((active.size, 3, 3))
        jac[:, 0, 0] = 2 * (r0 - r1 * ca[:, 0])
        jac[:, 0, 1] = 2 * (r1 - r0 * ca[:, 0])
        jac[:, 1, 0] = 2 * (r0 - r2 * ca[:, 1])
        jac[:, 1, 2] = 2 * (r2 - r0 * ca[:, 1])
        jac[:, 2, 1] = 2 * (r1 - r2 * ca[:, 2])
        jac[:, 2, 2] = 2 * (r2 - r1 * ca[:, 2])
        det = np.linalg.det(jac)
        ok = np.isfinite(det) & (np.abs(det) > 0)
        step = np.full((active.size, 3), np.nan)
        if ok.any():
            step[ok] = np.linalg.solve(jac[ok], f[ok][..., None])[..., 0]
        r[active] = ra - step
        iterations[active] = it
        done = np.all(np.abs(step) < tol, axis=1)
        bad = ~np.all(np.isfinite(r[active]), axis=1)
        converged[active[done]] = True
        active = active[~done & ~bad]
    return TriadSolution(r, converged & np.all(np.isfinite(r), axis=1), iterations)
