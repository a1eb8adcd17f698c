"""Detector statistics: each figure checked on hand-made frames whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest

from core.types import COCO17, Camera, Frame
from crossview.detector_stats import body25_joint_count, detector_stats, format_detector_stats
from sim.types import CameraFrame, DetectionEffect, DetectionTruth, PoseTruth

J = COCO17.num_joints


def _person_px(height_px=100.0, x0=100.0):
    """(17, 2) a person 100 px tall: every joint on a vertical line from y = 0 to y = height."""
    return np.column_stack([np.full(J, x0), np.linspace(0, height_px, J)])


def _frame(detected, true, ids, effects=None, in_image=None, occluded=None, camera="c0", poses=None):
    D = len(ids)
    in_image = np.ones((D, J), bool) if in_image is None else in_image
    occluded = np.zeros((D, J), bool) if occluded is None else occluded
    truth = DetectionTruth(0.0, 0.05, np.array(ids, dtype=np.int64), np.array(true, dtype=float).reshape(D, J, 2),
                           in_image, occluded, np.zeros((D, J), bool),
                           np.zeros(D, np.int64) if effects is None else np.array(effects, dtype=np.int64))
    kp = np.array(detected, dtype=float).reshape(D, J, 2)
    scores = np.where(np.isnan(kp[..., 0]), 0.0, 0.9)
    poses = poses or PoseTruth(0.0, np.zeros(0, np.int64), np.zeros((0, J, 3)))
    return CameraFrame(Frame(camera, 0.0, kp, scores), truth, poses)


def test_errors_are_normalised_by_the_person_size_on_limb_joints():
    true = _person_px()
    detected = true.copy()
    detected[:, 0] += np.arange(J) * 0.1  # joint j is off by 0.1 j px, i.e. 0.001 j of the 100 px height
    stats = detector_stats([_frame([detected], [true], [0])])
    limb = np.array([5, 6, 7, 8, 9, 10, 13, 14, 15, 16]) * 0.001
    assert stats["error_median"] == pytest.approx(np.median(limb))
    assert stats["error_p95"] == pytest.approx(np.percentile(limb, 95))
    assert stats["gross_error_rate"] == 0.0


def test_fragments_false_positives_swaps_and_occlusion_are_counted():
    true = _person_px()
    fragment = np.full((J, 2), np.nan)
    fragment[[5, 7, 9]] = true[[5, 7, 9]]  # an arm: 3 joints plus the neck = 4 of 15
    occluded = np.zeros((4, J), bool)
    occluded[0, :4] = True
    frames = [_frame([true, fragment, true, true], [true] * 4, [0, 1, 2, -1],
                     effects=[DetectionEffect.LEFT_RIGHT_SWAP, DetectionEffect.FRAGMENT, DetectionEffect.DUPLICATE,
                              DetectionEffect.PHANTOM], occluded=occluded)]
    stats = detector_stats(frames)
    assert stats["fragment_rate"] == pytest.approx(1 / 2)  # of the two real detections
    assert stats["false_positive_rate"] == pytest.approx(2 / 4)
    assert stats["swap_rate"] == pytest.approx(1 / 2)
    assert stats["occluded_share"] == pytest.approx(4 / (2 * J))
    assert stats["per_camera"]["c0"]["detections"] == 4
    assert stats["miss_rate"] is None  # no cameras given


def test_body25_count_adds_neck_and_mid_hip():
    detected = np.zeros((2, J), bool)
    detected[0, [5, 11]] = True  # a shoulder and a hip: + neck + mid-hip
    detected[1, :] = True
    assert body25_joint_count(detected).tolist() == [4, 15]


def test_miss_rate_counts_people_at_least_half_in_view_without_a_detection():
    camera = Camera("c0", [[500, 0, 320], [0, 500, 240], [0, 0, 1]], np.zeros(5), np.eye(3), [0, 0, 0], 640, 480)
    standing = np.column_stack([np.zeros(J), np.linspace(-0.8, 0.8, J), np.full(J, 4.0)])
    poses = PoseTruth(0.0, np.array([0, 1, 2]), np.stack([standing, standing + [1, 0, 0], standing + [50, 0, 0]]))
    true = _person_px()
    # Person 0 detected, person 1 in view but missed, person 2 out of view.
    stats = detector_stats([_frame([true], [true], [0], poses=poses)], [camera])
    assert stats["person_views"] == 2 and stats["miss_rate"] == pytest.approx(0.5)
    text = format_detector_stats(stats)
    assert "missed person-views" in text and "50.00 %" in text
