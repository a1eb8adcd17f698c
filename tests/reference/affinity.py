"""The affinity terms of eq. (1)-(4) one by one, as plain vectorised numpy: the reference the tracker's compiled
`tracker.affinity.affinity_matrix` is tested against (matrices (T, D) with targets as rows, detections as
columns)."""

from __future__ import annotations

import numpy as np


def affinity_2d(
    prev_px: np.ndarray,
    prev_stamp_s: np.ndarray,
    det_px: np.ndarray,
    stamp_s: float,
    w_2d: float,
    alpha_2d_px_per_s: float,
    lambda_a_per_s: float,
    floor_px: float = 0.0,
) -> np.ndarray:
    """Eq. (2): per-joint 2D affinity within one camera.

    A2D = w2D (1 - ||x_t - x_t''|| / max(α2D (t - t''), floor)) e^(-λa (t - t''))

    α2D here is per second: Table S2's pixels per frame divided by the camera's frame period (the tracker does
    it per camera, `Tracker.frame_period_s`). With floor = 0 this is the paper's eq. (2). A positive floor
    (pixels, beyond the paper) keeps the detector's own noise, which does not shrink with t - t'', from making
    the term negative between close frames.

    Args:
        prev_px: (T, J, 2) each target's last matched joints in this camera, undistorted pixels (NaN: none).
        prev_stamp_s: (T, J) their stamps t'', s.
        det_px: (D, J, 2) the new detections' joints, undistorted pixels (NaN: missing or below threshold).
        stamp_s: the new frame's stamp t, s.
        alpha_2d_px_per_s: α2D per frame of this camera divided by its frame period, pixels per second.

    Returns:
        (T, D, J) affinities, NaN where either joint is missing.
    """
    # t > t'' for frames of one camera; a repeated stamp is treated as one microsecond apart.
    dt = np.maximum(stamp_s - prev_stamp_s, 1e-6)[:, None, :]
    dist = np.linalg.norm(det_px[None, :, :, :] - prev_px[:, None, :, :], axis=-1)
    threshold = np.maximum(alpha_2d_px_per_s * dt, floor_px)
    return w_2d * (1.0 - dist / threshold) * np.exp(-lambda_a_per_s * dt)


def affinity_3d(
    predicted: np.ndarray,
    joint_stamp_s: np.ndarray,
    center: np.ndarray,
    det_rays: np.ndarray,
    stamp_s: float,
    w_3d: float,
    alpha_3d_m: float,
    lambda_a_per_s: float,
) -> np.ndarray:
    """Eq. (3)-(4): per-joint 3D affinity between predicted joints and back-projected detection rays.

    A3D = w3D (1 - d_l(X̂_t, X_t(μ)) / α3D) e^(-λa (t - t'))

    Args:
        predicted: (T, J, 3) joints predicted to time t by eq. (5), metres (NaN: unknown).
        joint_stamp_s: (T, J) last update times t', s.
        center: (3,) camera centre X_c, metres.
        det_rays: (D, J, 3) unit ray directions through the detected joints (eq. 3).
        stamp_s: t, s.

    Returns:
        (T, D, J) affinities, NaN where either side is missing.
    """
    rel = predicted - center  # (T, J, 3)
    # |rel × d| = sqrt(|rel|² - (rel·d)²) for unit d: the point-to-line distance d_l of eq. (4).
    along = np.einsum("tjk,djk->tdj", rel, det_rays)
    sq = np.einsum("tjk,tjk->tj", rel, rel)[:, None, :] - along * along
    dist = np.sqrt(np.maximum(sq, 0.0))
    dt = np.maximum(stamp_s - joint_stamp_s, 0.0)[:, None, :]
    return w_3d * (1.0 - dist / alpha_3d_m) * np.exp(-lambda_a_per_s * dt)


def combine(a2d: np.ndarray | None, a3d: np.ndarray, normalize: bool) -> np.ndarray:
    """Eq. (1): sums the per-joint terms over joints; missing terms count zero.

    Args:
        a2d: (T, D, J) 2D terms or None (no target has a previous point in this camera).
        a3d: (T, D, J) 3D terms.
        normalize: divide by the number of joints with a 3D term (see TrackerConfig.normalize_affinity).

    Returns:
        (T, D) affinity matrix; a pair with no joint in common gets 0 (never matched).
    """
    total = np.nansum(a3d, axis=-1)
    if a2d is not None:
        total = total + np.nansum(a2d, axis=-1)
    if normalize:
        count = np.sum(np.isfinite(a3d), axis=-1)
        total = np.where(count > 0, total / np.maximum(count, 1), 0.0)
    return total
