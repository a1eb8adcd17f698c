"""Inferred joints: the mean body fitted to a target's known joints, and the per-joint state codes."""

import numpy as np
import pytest

from core.types import CAMPUS14, COCO17
from tracker.body import fill_poses, fill_unknown, joint_states, mean_body
from tracker.types import JointState

BONES = np.asarray(COCO17.bones, dtype=np.int64)


def _placed(scale, yaw, shift):
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return mean_body(COCO17) * scale @ R.T + shift


def test_a_body_of_the_model_shape_is_completed_exactly():
    truth = _placed(1.1, 2.0, [3.0, -1.0, 0.02])
    pose = truth.copy()
    pose[[0, 1, 2, 3, 4, 9, 15]] = np.nan  # head, a wrist and an ankle never seen
    filled = fill_unknown(pose, mean_body(COCO17), BONES)
    np.testing.assert_allclose(filled, truth, atol=1e-9)
    known = np.isfinite(pose[:, 0])
    assert np.array_equal(filled[known], pose[known])  # known joints untouched


def test_the_fit_stays_near_a_real_body_and_never_leaves_nan():
    rng = np.random.default_rng(0)
    truth = _placed(0.95, -0.7, [1.0, 2.0, 0.0]) + rng.normal(0, 0.03, (17, 3))
    pose = truth.copy()
    pose[[5, 7, 9]] = np.nan  # a whole left arm
    filled = fill_unknown(pose, mean_body(COCO17), BONES)
    assert np.isfinite(filled).all()
    assert np.linalg.norm(filled[[5, 7, 9]] - truth[[5, 7, 9]], axis=-1).max() < 0.15
    only_hips = np.full((17, 3), np.nan)
    only_hips[[11, 12]] = truth[[11, 12]]  # the least a confirmed target has
    assert np.isfinite(fill_unknown(only_hips, mean_body(COCO17), BONES)).all()


def test_the_model_covers_both_skeletons():
    for skeleton in (COCO17, CAMPUS14):
        body = mean_body(skeleton)
        assert body.shape == (skeleton.num_joints, 3) and np.isfinite(body).all()
        assert 1.5 < body[:, 2].max() < 1.9


@pytest.mark.parametrize("compiled", [True, False])
def test_joint_states(compiled):
    seen = np.array([[9.9, 9.0, -np.inf, 9.75]])
    known = np.array([[True, True, False, True]])
    codes = (joint_states if compiled else joint_states.py_func)(seen, known, 10.0, 0.3)
    assert codes.dtype == np.uint8
    assert codes.tolist() == [[JointState.OBSERVED.value, JointState.PREDICTED.value, JointState.INFERRED.value,
                               JointState.OBSERVED.value]]


def test_compiled_fill_runs_the_same_as_plain_python():
    rng = np.random.default_rng(3)
    poses = _placed(1.05, 0.4, [1.0, 1.0, 0.0])[None] + rng.normal(0, 0.05, (6, 17, 3))
    poses[rng.random((6, 17)) < 0.4] = np.nan
    poses[0] = np.nan  # nothing known: left alone
    compiled, plain = poses.copy(), poses.copy()
    fill_poses(compiled, mean_body(COCO17), BONES)
    fill_poses.py_func(plain, mean_body(COCO17), BONES)
    np.testing.assert_allclose(compiled, plain, rtol=0, atol=1e-12)
    assert np.isnan(compiled[0]).all() and np.isfinite(compiled[1:]).all()
