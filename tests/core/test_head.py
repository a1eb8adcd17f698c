"""The head frame of nose and ears, and points of a rigid head expressed in it."""

import numpy as np
import pytest

from core.head import LEFT_EAR, NOSE, RIGHT_EAR, HeadPoints, head_frame
from core.types import COCO17


@pytest.fixture
def rng():
    return np.random.default_rng(34)


def _rotation(rng) -> np.ndarray:
    """A random proper rotation (3, 3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# A head in its own frame (x forward, y left, z up), metres: nose, left ear, right ear.
NOSE_M, LEFT_EAR_M, RIGHT_EAR_M = np.array([0.1, 0.0, 0.06]), np.array([0.0, 0.08, 0.08]), np.array([0.0, -0.08, 0.08])


def test_the_joint_indices_are_the_coco_layouts():
    assert (NOSE, LEFT_EAR, RIGHT_EAR) == tuple(COCO17.index(n) for n in ("nose", "left_ear", "right_ear"))


def test_the_frame_is_right_handed_orthonormal_and_points_forward_left_and_up():
    origin, axes, scale = head_frame(NOSE_M, LEFT_EAR_M, RIGHT_EAR_M)
    np.testing.assert_allclose(axes.T @ axes, np.eye(3), atol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0)
    np.testing.assert_allclose(origin, [0.0, 0.0, 0.08])
    assert scale == pytest.approx(0.16)
    # Forward is the nose's direction with nothing sideways; lateral is +y; up leans back as forward leans down.
    forward, lateral, up = axes.T
    np.testing.assert_allclose(forward, np.array([0.1, 0.0, -0.02]) / np.hypot(0.1, 0.02))
    np.testing.assert_allclose(lateral, [0.0, 1.0, 0.0])
    assert up[2] > 0.9 and up[0] > 0


def test_points_of_a_head_follow_it_through_any_rigid_motion_and_scaling(rng):
    # Two points of the head, expressed once in its frame ...
    bottom, top = np.array([0.0, 0.0, 0.0]), np.array([0.01, 0.0, 0.21])
    head = HeadPoints.of(bottom, top, NOSE_M, LEFT_EAR_M, RIGHT_EAR_M)
    for _ in range(5):
        # ... are found again from the nose and ears after the head is turned, moved and scaled.
        R, t, s = _rotation(rng), rng.normal(size=3), rng.uniform(0.8, 1.2)
        nose, left_ear, right_ear, bottom_now, top_now = (s * R @ p + t for p in
                                                          (NOSE_M, LEFT_EAR_M, RIGHT_EAR_M, bottom, top))
        pose = np.full((17, 3), 7.0)  # the other joints play no part
        pose[[NOSE, LEFT_EAR, RIGHT_EAR]] = [nose, left_ear, right_ear]
        np.testing.assert_allclose(head.locate(pose), [bottom_now, top_now], atol=1e-12)  # m


def test_many_poses_at_once_and_a_missing_ear_gives_nan(rng):
    head = HeadPoints((0.1, 0.0, -0.5), (0.0, 0.0, 0.8))
    poses = rng.normal(size=(4, 2, 17, 3))
    located = head.locate(poses)
    assert located.shape == (4, 2, 2, 3)
    np.testing.assert_allclose(located[2, 1], head.locate(poses[2, 1]))
    poses[1, 0, LEFT_EAR] = np.nan
    assert np.isnan(head.locate(poses)[1, 0]).all() and np.isfinite(head.locate(poses)[0]).all()


@pytest.mark.parametrize("bad", [(0.0, 1.0), (0.0, np.nan, 1.0), (0.0, 0.0, np.inf)])
def test_coefficients_must_be_three_finite_numbers(bad):
    with pytest.raises(ValueError, match="top_head"):
        HeadPoints((0.0, 0.0, 0.0), bad)
