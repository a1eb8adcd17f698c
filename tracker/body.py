"""A target's joints that no camera has triangulated yet, inferred from its own body: a mean body model fitted
to the joints it has (translation, heading and the scale of its known bones), and the per-joint state codes
of the output (observed, predicted, inferred)."""

from __future__ import annotations

import numpy as np

from core.types import Skeleton
from tracker.types import JointState

# A standing adult in the body frame (x forward, y left, z up), metres, by joint name: the mean body the
# unseen joints are taken from (COCO-17 names, and the Campus/Shelf head joints).
MEAN_BODY_M = {
    "nose": (0.10, 0.00, 1.62), "left_eye": (0.08, 0.03, 1.66), "right_eye": (0.08, -0.03, 1.66),
    "left_ear": (0.02, 0.07, 1.64), "right_ear": (0.02, -0.07, 1.64),
    "left_shoulder": (0.00, 0.19, 1.42), "right_shoulder": (0.00, -0.19, 1.42),
    "left_elbow": (0.00, 0.23, 1.13), "right_elbow": (0.00, -0.23, 1.13),
    "left_wrist": (0.02, 0.24, 0.87), "right_wrist": (0.02, -0.24, 0.87),
    "left_hip": (0.00, 0.11, 0.93), "right_hip": (0.00, -0.11, 0.93),
    "left_knee": (0.02, 0.11, 0.50), "right_knee": (0.02, -0.11, 0.50),
    "left_ankle": (0.00, 0.11, 0.07), "right_ankle": (0.00, -0.11, 0.07),
    "bottom_head": (0.02, 0.00, 1.52), "top_head": (0.02, 0.00, 1.78),
}

SCALE_RANGE = (0.8, 1.25)
"""The fitted body scale is clipped to this range of the mean body's."""


def mean_body(skeleton: Skeleton) -> np.ndarray:
    """(J, 3) the mean body in the skeleton's joint order, metres; a joint the model lacks sits at the hips'
    height on the body axis."""
    return np.array([MEAN_BODY_M.get(name, (0.0, 0.0, 0.93)) for name in skeleton.joints], dtype=np.float64)


def fill_unknown(pose: np.ndarray, model: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """The pose with its unknown (NaN) joints taken from the mean body fitted to its known joints.

    The fit: scale = median ratio of the known bones to the model's (clipped to SCALE_RANGE, 1 without a known
    bone); heading = the rotation about z that best aligns the model's known joints with the pose's in the
    floor plane (2D Procrustes; none with fewer than two known joints); translation = the difference of the
    means of the known joints. Known joints are returned unchanged.

    Args:
        pose: (J, 3) metres, NaN unknown; at least one joint known.
        model: (J, 3) `mean_body`; bones: (B, 2) joint pairs.

    Returns:
        (J, 3) pose without NaN.
    """
    known = np.all(np.isfinite(pose), axis=-1)
    if known.all() or not known.any():
        return pose
    a, b = bones[:, 0], bones[:, 1]
    both = known[a] & known[b]
    scale = 1.0
    if both.any():
        ratio = np.linalg.norm(pose[a[both]] - pose[b[both]], axis=-1) / np.maximum(
            np.linalg.norm(model[a[both]] - model[b[both]], axis=-1), 1e-6)
        scale = float(np.clip(np.median(ratio), *SCALE_RANGE))
    src = model[known] * scale
    dst = pose[known]
    src_mean, dst_mean = src.mean(axis=0), dst.mean(axis=0)
    yaw = 0.0
    if known.sum() >= 2:
        s, d = src[:, :2] - src_mean[:2], dst[:, :2] - dst_mean[:2]
        cross, dot = np.sum(s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]), np.sum(s[:, 0] * d[:, 0] + s[:, 1] * d[:, 1])
        yaw = float(np.arctan2(cross, dot))
    c, sn = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    out = pose.copy()
    out[~known] = (model[~known] * scale - src_mean) @ R.T + dst_mean
    return out


def joint_states(seen_s: np.ndarray, known: np.ndarray, stamp_s: float, stale_after_s: float) -> np.ndarray:
    """(T, J) `JointState` codes: OBSERVED when triangulated within `stale_after_s` of `stamp_s`, PREDICTED when
    triangulated earlier (carried with the body since), INFERRED when never triangulated (`fill_unknown`).

    Args:
        seen_s: (T, J) last time each joint was triangulated from observations (-inf never); known: (T, J) whether
            the tracker holds an estimate of the joint.
    """
    codes = np.full(seen_s.shape, JointState.PREDICTED.value, dtype=np.uint8)
    codes[stamp_s - seen_s <= stale_after_s] = JointState.OBSERVED.value
    codes[~known] = JointState.INFERRED.value
    return codes
