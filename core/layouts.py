"""COCO-17 poses as the 14-joint Campus/Shelf layout and back, exactly as the datasets' published evaluate.py
maps them (Chen et al., CVPR 2020; longcw/crossview_3d_pose_tracking): scoring brings poses to Campus-14
with it, and the dataset reader writes a published 14-joint truth as COCO-17 with its inverse.
"""

from __future__ import annotations

import numpy as np

from core.head import HeadPoints

COCO_TO_CAMPUS12 = np.array([16, 14, 12, 11, 13, 15, 10, 8, 6, 5, 7, 9])
"""(12,) the COCO-17 joints that give the first 12 Campus-14 joints, in Campus order (evaluate.py's coco2shelf)."""

BOTTOM_HEAD_FACTORS = np.array([0.3, 0.4, 0.6])
"""(3,) per-axis (x, y, z) factors that place bottom-head on the ray from the mid-shoulders to the nose
(evaluate.py's coco2shelf3D; they are the protocol, not a choice of ours)."""

TOP_HEAD_FACTORS = np.array([0.78, 0.5, 1.5])
"""(3,) per-axis factors that place top-head on that ray, as `BOTTOM_HEAD_FACTORS`."""


def coco17_to_campus14(poses: np.ndarray, head: HeadPoints | None = None) -> np.ndarray:
    """Maps COCO-17 poses to the 14-joint Campus/Shelf layout exactly as the dataset's evaluate.py does, or
    with the head joints on the head itself.

    The head joints do not exist in COCO-17: evaluate.py places bottom-head and top-head on the line from the
    mid-shoulders to the nose with fixed per-axis factors (z up in the Campus world frame). With `head`, they
    are its points of the rigid head of the nose and ears instead. A NaN input joint gives NaN in every output
    joint built from it.

    Args:
        poses: (..., 17, 3) joint positions.
        head: None: evaluate.py's head joints (the protocol's, for estimates); else the bottom and the top of
            the head in the nose-ear frame (a simulated truth scored as the datasets annotate theirs).

    Returns:
        (..., 14, 3) joint positions in the Campus order.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.shape[-2:] != (17, 3):
        raise ValueError(f"coco17_to_campus14: expected (..., 17, 3), got {poses.shape}")
    out = np.empty(poses.shape[:-2] + (14, 3))
    out[..., :12, :] = poses[..., COCO_TO_CAMPUS12, :]
    if head is not None:
        out[..., 12:, :] = head.locate(poses)
        return out
    mid_shoulder = (out[..., 8, :] + out[..., 9, :]) / 2
    to_nose = poses[..., 0, :] - mid_shoulder
    out[..., 13, :] = mid_shoulder + to_nose * TOP_HEAD_FACTORS
    out[..., 12, :] = mid_shoulder + to_nose * BOTTOM_HEAD_FACTORS
    return out


def campus14_to_coco17(poses: np.ndarray) -> np.ndarray:
    """Writes 14-joint Campus poses (..., 14, 3) as COCO-17 (..., 17, 3) so that the published evaluate.py
    mapping (`coco17_to_campus14`) gives the same limbs back and a head on the
    mid-shoulder-to-head line: the nose is placed where that mapping puts the top of the head's direction.
    Face joints other than the nose are NaN."""
    poses = np.asarray(poses, dtype=np.float64)
    out = np.full(poses.shape[:-2] + (17, 3), np.nan)
    out[..., COCO_TO_CAMPUS12, :] = poses[..., :12, :]
    mid_shoulder = (poses[..., 8, :] + poses[..., 9, :]) / 2
    # evaluate.py: top = mid + (nose - mid) * f_top, bottom = mid + (nose - mid) * f_bottom, per axis.
    # Least squares for the nose offset d from both head joints, per axis: d = Σ f h / Σ f².
    top, bottom = poses[..., 13, :] - mid_shoulder, poses[..., 12, :] - mid_shoulder
    d = (top * TOP_HEAD_FACTORS + bottom * BOTTOM_HEAD_FACTORS) / (TOP_HEAD_FACTORS ** 2 + BOTTOM_HEAD_FACTORS ** 2)
    out[..., 0, :] = mid_shoulder + d
    return out
