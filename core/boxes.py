"""Axis-aligned image boxes: the box around a pose's 2D joints and the IoU of two sets of boxes.

A box is (x0, y0, x1, y1) in pixels, x0 <= x1 and y0 <= y1; a box that cannot be formed is all NaN.
The single-view tracker (`tracker.single_view`) and the per-camera 2D scores (`crossview.scoring`) use
the same two functions, so a tracker's box and the box it is scored by are the same thing.
"""

from __future__ import annotations

import numpy as np

MIN_BOX_JOINTS = 2
"""Fewest joints a box is made of: one joint has no extent."""


def keypoint_boxes(keypoints_px: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """The bounding box of each pose's known joints.

    Args:
        keypoints_px: (N, J, 2) pixel coordinates; NaN for a joint not known.
        valid: optional (N, J) bool; joints where it is False are left out too.

    Returns:
        (N, 4) boxes (x0, y0, x1, y1), pixels; all NaN for a pose with fewer than `MIN_BOX_JOINTS` joints.
    """
    kp = np.asarray(keypoints_px, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[2] != 2:
        raise ValueError(f"keypoint_boxes: keypoints_px expected (N, J, 2), got {kp.shape}")
    ok = np.isfinite(kp).all(axis=-1)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool).reshape(ok.shape)
    lo = np.where(ok[..., None], kp, np.inf).min(axis=1, initial=np.inf)
    hi = np.where(ok[..., None], kp, -np.inf).max(axis=1, initial=-np.inf)
    boxes = np.hstack([lo, hi])
    boxes[ok.sum(axis=1) < MIN_BOX_JOINTS] = np.nan
    return boxes


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of every pair of boxes.

    Args:
        a: (N, 4) boxes (x0, y0, x1, y1), pixels.
        b: (M, 4) boxes.

    Returns:
        (N, M) IoU in [0, 1]; 0 where the union is empty or a box is NaN.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0, None), axis=-1)
    area_a = np.prod(a[:, 2:] - a[:, :2], axis=-1)
    area_b = np.prod(b[:, 2:] - b[:, :2], axis=-1)
    union = area_a[:, None] + area_b[None, :] - inter
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(inter) & (union > 0)
    return np.divide(inter, union, out=np.zeros_like(inter), where=usable)
