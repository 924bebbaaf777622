"""QUEST, both forms, against scipy's Wahba solver (Rotation.align_vectors) with known truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.quest import attitude_matrix, quaternion_from_attitude, quest, quest_shortcut

STUDY_WEIGHTS = np.array([0.05, 0.05, 0.45, 0.45])


def _vectors(rng, n=4):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _angle_between(a, b) -> float:
    return float(Rotation.from_matrix(a @ b.T).magnitude())


def test_attitude_matrix_is_scipys_transpose_and_round_trips():
    rng = np.random.default_rng(1)
    for q in Rotation.random(20, rng=rng).as_quat():
        assert np.allclose(attitude_matrix(q), Rotation.from_quat(q).as_matrix().T, atol=1e-14)
        back = quaternion_from_attitude(attitude_matrix(q))
        assert np.allclose(back, q if q[3] >= 0 else -q, atol=1e-12)


def test_full_quest_matches_align_vectors_to_1e9_rad_noise_free():
    rng = np.random.default_rng(2)
    worst = 0.0
    for k in range(300):
        v = _vectors(rng, 4)
        truth = Rotation.random(rng=rng).as_matrix()
        w = v @ truth.T
        weights = STUDY_WEIGHTS if k % 2 else rng.uniform(0.1, 1.0, 4)
        ref, _ = Rotation.align_vectors(w, v, weights=weights)
        got = attitude_matrix(quest(w, v, weights).q_xyzw)
        worst = max(worst, _angle_between(got, ref.as_matrix()), _angle_between(got, truth))
    assert worst < 1e-9, worst


def test_full_quest_matches_align_vectors_with_noise():
    """Noisy vectors: both solve Wahba's problem, so they must agree (not with the truth)."""
    rng = np.random.default_rng(3)
    for _ in range(100):
        v = _vectors(rng, 4)
        w = v @ Rotation.random(rng=rng).as_matrix().T + rng.normal(scale=0.02, size=(4, 3))
        w /= np.linalg.norm(w, axis=1, keepdims=True)
        ref, _ = Rotation.align_vectors(w, v, weights=STUDY_WEIGHTS)
        res = quest(w, v, STUDY_WEIGHTS)
        assert _angle_between(attitude_matrix(res.q_xyzw), ref.as_matrix()) < 1e-9
        assert 0 < res.loss < 0.01


@pytest.mark.parametrize("gap_rad", [0.0, 1e-9, 1e-6, 1e-3, 0.1])
def test_full_quest_at_and_near_180_degrees(gap_rad):
    rng = np.random.default_rng(4)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        truth = Rotation.from_rotvec((np.pi - gap_rad) * axis).as_matrix()
        v = _vectors(rng)
        res = quest(v @ truth.T, v, STUDY_WEIGHTS)
        assert _angle_between(attitude_matrix(res.q_xyzw), truth) < 1e-9
        assert res.flip_axis is not None  # solved in a turned frame


def test_shortcut_error_is_reported_and_grows_toward_180_degrees():
    """The study's Gibbs shortcut: exact (rounding) without noise away from 180°, singular at 180°.

    Prints the shortcut's worst error per distance from 180° and, with noise, its error
    relative to full QUEST (the λ_max ≈ 1 approximation).
    """
    rng = np.random.default_rng(5)
    rows = []
    for gap in (np.pi, 1.0, 1e-2, 1e-4, 1e-6, 0.0):
        errs = []
        for _ in range(50):
            axis = rng.normal(size=3)
            truth = Rotation.from_rotvec((np.pi - gap) * axis / np.linalg.norm(axis)).as_matrix()
            v = _vectors(rng)
            q = quest_shortcut(v @ truth.T, v, STUDY_WEIGHTS)
            errs.append(_angle_between(attitude_matrix(q), truth) if np.all(np.isfinite(q)) else np.pi)
        rows.append((gap, max(errs)))
    print("\nshortcut, noise free: pi - angle [rad] -> worst error [rad]")
    for gap, err in rows:
        print(f"  {gap:9.1e} -> {err:.2e}")
    errs = dict(rows)
    assert errs[np.pi] < 1e-12 and errs[1.0] < 1e-12  # exact away from 180°: λ_max = Σa = 1
    assert errs[1e-4] > 10 * errs[1.0]  # conditioning of ((1 + σ)I − S) degrades near 180°
    assert errs[0.0] > 0.1  # at 180° the shortcut fails outright

    noisy = []
    for _ in range(200):
        v = _vectors(rng)
        truth = Rotation.random(rng=rng).as_matrix()
        if Rotation.from_matrix(truth).magnitude() > 2.5:
            continue
        w = v @ truth.T + rng.normal(scale=0.01, size=(4, 3))
        w /= np.linalg.norm(w, axis=1, keepdims=True)
        full = attitude_matrix(quest(w, v, STUDY_WEIGHTS).q_xyzw)
        noisy.append(_angle_between(attitude_matrix(quest_shortcut(w, v, STUDY_WEIGHTS)), full))
    noisy = np.array(noisy)
    med, worst = np.median(noisy), noisy.max()
    print(f"shortcut vs full QUEST, 0.01 rad vector noise: median {med:.2e} rad, max {worst:.2e} rad")
    assert 0 < np.median(noisy) < 1e-3
