"""Affinity terms with hand-computed values: eq. (1), (2), (4), (5), (S2); the compiled (T, D) kernel against them."""

import numpy as np
import pytest

from tests.reference.affinity import affinity_2d, affinity_3d, combine
from tests.reference.plain import plain_python
from tests.tracker.synthetic import look_at_camera
from tracker.affinity import (
    AffinityParams,
    affinity_matrix,
    epipolar_affinity,
    epipolar_affinity_between,
    epipolar_affinity_matrix,
    predict_positions,
)
from tracker.geometry import fundamental_matrix, project, ray_directions, world_from_pixel_matrix
from tracker.target_rows import TargetRows


def test_2d_affinity_by_hand():
    # Eq. (2): moved 5 px in 1 s with α2D = 10 px/s: 0.4 (1 - 5/10) e^(-0.5 · 1).
    a = affinity_2d(np.zeros((1, 1, 2)), np.zeros((1, 1)), np.array([[[3.0, 4.0]]]), 1.0, 0.4, 10.0, 0.5)
    assert a.shape == (1, 1, 1)
    assert a[0, 0, 0] == pytest.approx(0.4 * 0.5 * np.exp(-0.5))


def test_2d_affinity_is_negative_beyond_the_velocity_threshold_and_floor_limits_it():
    prev, stamp, det = np.zeros((1, 1, 2)), np.zeros((1, 1)), np.array([[[0.0, 6.0]]])
    # 6 px in 0.2 s at α2D = 10 px/s: threshold 2 px -> 0.4 (1 - 3) = -0.8.
    assert affinity_2d(prev, stamp, det, 0.2, 0.4, 10.0, 0.0)[0, 0, 0] == pytest.approx(-0.8)
    # A 12 px floor on the threshold: 0.4 (1 - 6/12) = 0.2.
    assert affinity_2d(prev, stamp, det, 0.2, 0.4, 10.0, 0.0, floor_px=12.0)[0, 0, 0] == pytest.approx(0.2)


def test_prediction_is_linear_motion_with_a_clipped_horizon():
    # Eq. (5): X + V (t - t'), horizon clipped to max_predict_s.
    X, V = np.array([[1.0, 2.0, 0.0]]), np.array([[1.0, 0.0, -1.0]])
    np.testing.assert_allclose(predict_positions(X, V, np.array([1.0]), 1.5, 2.0), [[1.5, 2.0, -0.5]])
    np.testing.assert_allclose(predict_positions(X, V, np.array([1.0]), 9.0, 0.25), [[1.25, 2.0, -0.25]])


def test_3d_affinity_by_hand():
    # Eq. (4): the predicted joint is 0.05 m from the ray along z; α3D = 0.1 m: 0.6 (1 - 0.5) e^(-2 · 0.5).
    predicted = np.array([[[0.05, 0.0, 2.0]]])
    rays = np.array([[[0.0, 0.0, 1.0]]])
    a = affinity_3d(predicted, np.array([[0.5]]), np.zeros(3), rays, 1.0, 0.6, 0.1, 2.0)
    assert a[0, 0, 0] == pytest.approx(0.6 * 0.5 * np.exp(-1.0))


def test_3d_affinity_shapes_are_targets_by_detections_by_joints():
    rng = np.random.default_rng(0)
    T, D, J = 3, 4, 5
    rays = rng.normal(size=(D, J, 3))
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    a = affinity_3d(rng.normal(size=(T, J, 3)), np.zeros((T, J)), np.zeros(3), rays, 0.0, 0.6, 0.2, 3.0)
    assert a.shape == (T, D, J)
    # Against a direct loop with the cross-product distance.
    t, d, j = 2, 1, 3
    X = rng.normal(size=(T, J, 3))
    a = affinity_3d(X, np.zeros((T, J)), np.zeros(3), rays, 0.0, 0.6, 0.2, 3.0)
    dist = np.linalg.norm(np.cross(X[t, j], rays[d, j]))
    assert a[t, d, j] == pytest.approx(0.6 * (1 - dist / 0.2))


def test_combine_sums_over_joints_and_ignores_missing():
    # Eq. (1): Σ_k A2D + A3D; a missing term counts zero.
    a3d = np.array([[[0.5, np.nan, 0.25]]])
    a2d = np.array([[[0.1, 0.2, np.nan]]])
    assert combine(a2d, a3d, normalize=False)[0, 0] == pytest.approx(1.05)
    assert combine(None, a3d, normalize=True)[0, 0] == pytest.approx(0.375)


def test_epipolar_affinity_by_hand_on_a_rectified_pair():
    # Two cameras side by side looking along y: epipolar lines are image rows, so a point shifted δ px
    # vertically is δ px from its line in both images, and (S2) gives 1 - 2δ / (2α).
    a = look_at_camera("a", [0.0, 0.0, 1.0], [0.0, 5.0, 1.0])
    b = look_at_camera("b", [1.0, 0.0, 1.0], [1.0, 5.0, 1.0])
    X = np.array([[0.3, 4.0, 1.2], [0.6, 5.0, 0.7], [0.1, 3.0, 1.5]])
    xa, xb = project(a.P, X)[None], project(b.P, X)[None]
    F = fundamental_matrix(a, b)
    assert epipolar_affinity(xa, xb, F, 20.0, 1)[0, 0] == pytest.approx(1.0)
    shifted = xb + np.array([0.0, 5.0])
    assert epipolar_affinity(xa, shifted, F, 20.0, 1)[0, 0] == pytest.approx(1.0 - 5.0 / 20.0)
    # Too few shared joints: -inf.
    xa_missing = xa.copy()
    xa_missing[0, 1:] = np.nan
    assert epipolar_affinity(xa_missing, xb, F, 20.0, 2)[0, 0] == -np.inf


def _target_arrays(rng, T, C, J, D, camera):
    """Random target arrays as the tracker holds them, with unknown joints, never-seen joints and no 2D point."""
    pos = rng.uniform([0.0, 0.0, 0.2], [4.0, 3.0, 1.8], (T, J, 3))
    pos[rng.random((T, J)) < 0.15] = np.nan
    vel = rng.normal(0.0, 0.5, (T, J, 3))
    joint_s = 2.0 - rng.uniform(0.0, 0.8, (T, J))
    seen_s = joint_s - rng.uniform(0.0, 0.3, (T, J))
    seen_s[rng.random((T, J)) < 0.1] = -np.inf
    prev_px = rng.uniform(0.0, 1000.0, (T, C, J, 2))
    prev_s = 2.0 - rng.uniform(0.0, 0.5, (T, C, J))
    prev_s[rng.random((T, C, J)) < 0.3] = np.nan
    prev_px[np.isnan(prev_s)] = np.nan
    det = prev_px[:D, camera] + rng.normal(0.0, 20.0, (D, J, 2)) if D <= T else rng.uniform(0, 1000, (D, J, 2))
    det[rng.random((D, J)) < 0.2] = np.nan
    return pos, vel, joint_s, seen_s, prev_px, prev_s, det


@pytest.mark.parametrize("normalize", [False, True])
def test_compiled_affinity_matrix_equals_the_per_equation_functions(normalize):
    rng = np.random.default_rng(3)
    T, C, J, D, c = 5, 3, 7, 4, 1
    pos, vel, joint_s, seen_s, prev_px, prev_s, det = _target_arrays(rng, T, C, J, D, c)
    cam = look_at_camera("a", [2.0, -3.0, 3.0], [2.0, 1.5, 1.0])
    M = world_from_pixel_matrix(cam)
    t, w2, a2, floor, w3, a3, lam, horizon = 2.0, 0.4, 200.0, 30.0, 0.6, 0.3, 3.0, 0.5
    # Reference: eq. (5), (3), (4), (2), (1) one by one.
    predicted = predict_positions(pos, vel, joint_s, t, horizon)
    a3d = affinity_3d(predicted, seen_s, cam.center_world, ray_directions(cam, det, M), t, w3, a3, lam)
    a2d = affinity_2d(prev_px[:, c], prev_s[:, c], det, t, w2, a2, lam, floor)
    expected = combine(a2d, a3d, normalize)
    targets = TargetRows.empty(T, C, J, 1)._replace(pos=pos, vel=vel, joint_s=joint_s, seen_s=seen_s, obs_px=prev_px,
                                                    obs_s=prev_s)
    params = AffinityParams(w_2d=w2, alpha_2d_floor_px=floor, w_3d=w3, alpha_3d_m=a3, lambda_a_per_s=lam,
                            max_predict_s=horizon, normalize=normalize)
    for kernel in (affinity_matrix, plain_python(affinity_matrix)):
        out = np.full((T, D), np.nan)
        kernel(targets, c, det, M, cam.center_world, t, a2, params, np.arange(T), out)
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)
        some = np.array([3, 1])
        part = np.full((2, D), np.nan)
        kernel(targets, c, det, M, cam.center_world, t, a2, params, some, part)
        np.testing.assert_allclose(part, expected[some], rtol=1e-12, atol=1e-12)


def test_pool_affinity_matrix_equals_the_pairwise_epipolar_affinity():
    rng = np.random.default_rng(5)
    cams = [look_at_camera(f"c{k}", [4.0 * np.cos(k), 4.0 * np.sin(k), 3.0], [0.0, 0.0, 1.0]) for k in range(3)]
    X = rng.uniform([-1.0, -1.0, 0.0], [1.0, 1.0, 1.8], (2, 6, 3))  # 2 people, 6 joints
    cameras = np.array([0, 0, 1, 1, 2])
    people = np.array([0, 1, 0, 1, 1])
    points = np.stack([project(cams[k].P, X[p]) for k, p in zip(cameras, people)]) + rng.normal(0, 2.0, (5, 6, 2))
    points[rng.random((5, 6)) < 0.25] = np.nan
    F = np.zeros((3, 3, 3, 3))
    for a in range(3):
        for b in range(3):
            if a != b:
                F[a, b] = fundamental_matrix(cams[a], cams[b])
    A = epipolar_affinity_matrix(points, cameras, F, 30.0, 2)
    for a in range(5):
        for b in range(5):
            if cameras[a] == cameras[b]:
                assert A[a, b] == -np.inf
            else:
                pair = epipolar_affinity(points[a:a + 1], points[b:b + 1], F[cameras[a], cameras[b]], 30.0, 2)[0, 0]
                assert A[a, b] == pytest.approx(pair, rel=1e-12, abs=1e-12)
    assert np.isfinite(A).sum() >= 8
    # one set against another: the rows and columns of the pool's matrix, unlinked cameras at 0
    B = epipolar_affinity_between(points[:2], cameras[:2], points[1:], cameras[1:], F, 30.0, 2)
    np.testing.assert_array_equal(B, A[:2, 1:])
    linked = np.ones((3, 3), dtype=bool)
    linked[0, 2] = linked[2, 0] = False
    B = epipolar_affinity_between(points[:2], cameras[:2], points[1:], cameras[1:], F, 30.0, 2, linked)
    np.testing.assert_array_equal(B, np.where(cameras[1:][None, :] == 2, 0.0, A[:2, 1:]))
