"""The study's pose estimator, kept as it was (docs/source-study.md §6–8), in one consistent frame set.

Steps, for unit vectors r_1..r_5 in the study camera frame Cs (X back, Y right, Z up):

1. Inverse perspective (:mod:`pipeline.inverse_perspective`) on the horizontal triad
   (1, 2, 3) and the vertical triad (1, 4, 5), l_ij from the beacon geometry, Newton
   from (100, 500, 1000) mm, tolerance 1e-6 mm, at most 10 000 iterations. R1 is the
   mean of the two triads' R1; R2, R3 come from the first triad, R4, R5 from the second.
2. QUEST with the Gibbs shortcut (:func:`pipeline.quest.quest_shortcut`) on
   w_i = (R1 r1 − R_i r_i)/|…| and the reference vectors v_i = p1 − p_i (normalised),
   weights a = (0.05, 0.05, 0.45, 0.45) for i = 2..5.
3. The frame chain T1·T2·T3 is in :mod:`pipeline.frames`.

Frame mapping (``pipeline/CONVENTIONS.md``): the reference vectors are expressed in the
right-handed study target frame S (x toward the viewer, y the viewer's right, z up), so
v2 = (46, −70, 0) and v3 = (46, 70, 0) mm as in the study, and v4 = (46, 0, −70),
v5 = (46, 0, 70) mm with 4 the top marker. The study's text gives v4 = (46, 0, 70): that
is the same pair set if its "greatest elevation" (β positive down) is read literally,
i.e. its marker 4 is the lowest in the image; the QUEST input, and so the answer, is the
same either way. QUEST's A maps S into Cs; a camera facing the target squarely has A = I.

Known weaknesses (kept; quantified in the tests and CONVENTIONS.md):

* The fixed start ignores the measured angles: at 1–10 m Newton from (100, 500, 1000) mm
  may reach the mirror root, a root with negative ranges, or not converge.
* The two triads' R1 are averaged even when one failed; failure is not detected.
* The Gibbs shortcut assumes λ_max = 1 (exact only without noise) and is singular at
  a 180° rotation.
* The horizontal pairs get weight 0.05 each, so yaw rests mostly on the vertical pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.angles import study_unit_vectors
from pipeline.failures import Failure
from pipeline.frames import CS_FROM_CV, S_FROM_T, Pose
from pipeline.inverse_perspective import geometric_start, solve_triads, study_start
from pipeline.messages import BotPositionQuat, LEDPoints
from pipeline.quest import attitude_matrix, quest, quest_shortcut
from scenes.beacon import BeaconDesign

__all__ = [
    "EQUAL_WEIGHTS",
    "HORIZONTAL",
    "QUEST_WEIGHTS",
    "STUDY_WEIGHTS",
    "VERTICAL",
    "ThesisPoseResult",
    "ThesisRanges",
    "attitude_and_pose",
    "measured_vectors",
    "pose_from_study",
    "reference_vectors_s",
    "thesis_pose",
    "thesis_pose_from_vectors",
    "thesis_ranges",
    "triad_distances_mm",
]

STUDY_WEIGHTS = (0.05, 0.05, 0.45, 0.45)
"""QUEST weights for w2..w5 after the study's tuning (docs/source-study.md §7)."""
EQUAL_WEIGHTS = (0.25, 0.25, 0.25, 0.25)
"""The study's starting point before tuning: equal QUEST weights (docs/source-study.md §7)."""
QUEST_WEIGHTS = {"tuned": STUDY_WEIGHTS, "equal": EQUAL_WEIGHTS}
"""The two weight sets of the study's weight experiment, by label."""

HORIZONTAL = (0, 1, 2)
VERTICAL = (0, 3, 4)
"""Marker indices (0-based) of the triads (1, 2, 3) and (1, 4, 5)."""


def triad_distances_mm(design: BeaconDesign, triad: tuple[int, int, int]) -> tuple[float, float, float]:
    """(l_ij, l_ik, l_jk) of a triad from the design's marker positions, mm."""
    p = design.marker_positions_m() * 1e3
    i, j, k = triad
    return (
        float(np.linalg.norm(p[i] - p[j])),
        float(np.linalg.norm(p[i] - p[k])),
        float(np.linalg.norm(p[j] - p[k])),
    )


def reference_vectors_s(design: BeaconDesign) -> NDArray[np.float64]:
    """Unit reference vectors v_2..v_5 = (p1 − p_i)/|…| in the study target frame S, shape (4, 3)."""
    p = design.marker_positions_m()
    v = (p[0] - p[1:]) @ S_FROM_T.T
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@dataclass(frozen=True)
class ThesisRanges:
    """Inverse-perspective ranges for n pose samples.

    Attributes
    ----------
    ranges_m
        (n, 5) R1..R5, m; R1 is the mean of the two triads' R1.
    r1_triads_m
        (n, 2) R1 from the horizontal and the vertical triad, m.
    converged
        (n, 2) Newton's convergence flag per triad.
    iterations
        (n, 2) Newton iterations per triad.
    """

    ranges_m: NDArray[np.float64]
    r1_triads_m: NDArray[np.float64]
    converged: NDArray[np.bool_]
    iterations: NDArray[np.int64]


def _cosines(r: NDArray[np.float64], triad) -> NDArray[np.float64]:
    i, j, k = triad
    dot = lambda a, b: np.sum(r[:, a] * r[:, b], axis=-1)  # noqa: E731
    return np.stack([dot(i, j), dot(i, k), dot(j, k)], axis=1)


def thesis_ranges(
    r_cs, design: BeaconDesign, start: str = "study", tol_mm: float = 1e-6, max_iter: int = 10000
) -> ThesisRanges:
    """Inverse-perspective ranges of markers 1..5 (docs/source-study.md §6), vectorised.

    Parameters
    ----------
    r_cs
        (5, 3) or (n, 5, 3) unit lines of sight of markers 1..5 (any right-handed
        camera frame; only their dot products matter).
    design
        Beacon design (the l_ij).
    start
        ``study`` for the study's (100, 500, 1000) mm, ``geometric`` for the project's
        :func:`pipeline.inverse_perspective.geometric_start`.
    tol_mm, max_iter
        Newton's step tolerance (mm) and iteration limit.
    """
    r = np.asarray(r_cs, dtype=np.float64).reshape(-1, 5, 3)
    starts = {"study": study_start, "geometric": geometric_start}
    if start not in starts:
        raise ValueError(f"start: expected 'study' or 'geometric', got {start!r}")
    out = []
    for triad in (HORIZONTAL, VERTICAL):
        cos = _cosines(r, triad)
        dist = triad_distances_mm(design, triad)
        out.append(solve_triads(cos, dist, starts[start](cos, dist), tol=tol_mm, max_iter=max_iter))
    h, v = out
    r1 = 0.5 * (h.ranges[:, 0] + v.ranges[:, 0])
    ranges = np.stack([r1, h.ranges[:, 1], h.ranges[:, 2], v.ranges[:, 1], v.ranges[:, 2]], axis=1) * 1e-3
    return ThesisRanges(
        ranges,
        np.stack([h.ranges[:, 0], v.ranges[:, 0]], axis=1) * 1e-3,
        np.stack([h.converged, v.converged], axis=1),
        np.stack([h.iterations, v.iterations], axis=1),
    )


def measured_vectors(r_cs: NDArray[np.float64], ranges_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """w_i = (R1 r1 − R_i r_i)/|…| for i = 2..5, shape (4, 3), in the frame of ``r_cs``."""
    r = np.asarray(r_cs, dtype=np.float64)
    w = ranges_m[0] * r[0] - ranges_m[1:, None] * r[1:]
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def pose_from_study(q_xyzw, range_m: float, r1_cs) -> Pose:
    """Our :class:`~pipeline.frames.Pose` from the study's quaternion (A: S → Cs), R1 and r1 (in Cs)."""
    a = attitude_matrix(q_xyzw)
    cv_from_t = CS_FROM_CV.T @ a @ S_FROM_T
    return Pose(cv_from_t, CS_FROM_CV.T @ (range_m * np.asarray(r1_cs, dtype=np.float64)))


@dataclass(frozen=True)
class ThesisPoseResult:
    """The study's pose for one frame.

    Attributes
    ----------
    message
        The study's BotPositionQuat, or None when the answer is not finite.
    pose
        The same pose in our frames, or None.
    ranges_m
        R1..R5, m.
    converged
        Newton's flags for the two triads.
    reason
        Why there is no pose, else None.
    failure
        The code of ``reason``, else None.
    """

    message: BotPositionQuat | None
    pose: Pose | None
    ranges_m: NDArray[np.float64]
    converged: tuple[bool, bool]
    reason: str | None
    failure: Failure | None


def thesis_pose_from_vectors(
    r_cs, design: BeaconDesign, start: str = "study", weights=STUDY_WEIGHTS, full_quest: bool = False
) -> ThesisPoseResult:
    """The study's range + QUEST from five unit vectors in its camera frame Cs.

    ``full_quest`` swaps the Gibbs shortcut for :func:`pipeline.quest.quest` (an
    ablation, not the study's method).
    """
    r = np.asarray(r_cs, dtype=np.float64).reshape(5, 3)
    rng = thesis_ranges(r, design, start=start)
    ranges = rng.ranges_m[0]
    converged = (bool(rng.converged[0, 0]), bool(rng.converged[0, 1]))
    if not np.all(np.isfinite(ranges)) or ranges[0] <= 0:
        return ThesisPoseResult(
            None, None, ranges, converged, "inverse perspective: no finite positive range", Failure.RANGE
        )
    q = _attitude(r, ranges, design, weights, full_quest)
    if q is None:
        return ThesisPoseResult(None, None, ranges, converged, "QUEST: no finite attitude", Failure.ATTITUDE)
    msg = BotPositionQuat(float(ranges[0]), tuple(q), tuple(r[0]))
    return ThesisPoseResult(msg, pose_from_study(q, ranges[0], r[0]), ranges, converged, None, None)


def _attitude(r, ranges, design, weights, full_quest) -> NDArray[np.float64] | None:
    with np.errstate(all="ignore"):
        w = measured_vectors(r, ranges)
    if not np.all(np.isfinite(w)):
        return None
    v = reference_vectors_s(design)
    q = quest(w, v, weights).q_xyzw if full_quest else quest_shortcut(w, v, weights)
    return q if np.all(np.isfinite(q)) else None


def attitude_and_pose(r_cs, ranges_m, design: BeaconDesign, weights=STUDY_WEIGHTS, full_quest=False) -> Pose | None:
    """Step 2 alone: QUEST on given ranges (from a batched :func:`thesis_ranges`) → our Pose, or None."""
    r = np.asarray(r_cs, dtype=np.float64).reshape(5, 3)
    if not np.all(np.isfinite(ranges_m)) or ranges_m[0] <= 0:
        return None
    q = _attitude(r, ranges_m, design, weights, full_quest)
    return None if q is None else pose_from_study(q, ranges_m[0], r[0])


def thesis_pose(points: LEDPoints, design: BeaconDesign, start: str = "study") -> ThesisPoseResult:
    """The study's pose program: LEDPoints in, BotPositionQuat (and our Pose) out."""
    r = study_unit_vectors(np.array(points.azimuth_rad), np.array(points.elevation_rad))
    return thesis_pose_from_vectors(r, design, start=start)
