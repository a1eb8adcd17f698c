"""Geometric affinities: target-to-detection (eq. 1-5) and detection-to-detection across views (eq. S1-S2).

All functions are pure and vectorised; matrices are (T, D) with targets as rows and detections as columns.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.jit import jit


def predict_positions(
    positions: np.ndarray, velocities: np.ndarray, joint_stamp_s: np.ndarray, stamp_s: float, max_predict_s: float
) -> np.ndarray:
    """Eq. (5): linear motion X̂_t = X_t' + V_t' (t - t'), the horizon clipped to [0, max_predict_s].

    Args:
        positions: (..., J, 3) last estimated joints X_t', metres.
        velocities: (..., J, 3) joint velocities V_t', m/s.
        joint_stamp_s: (..., J) last update times t', s.
        stamp_s: the time t to predict to, s.

    Returns:
        (..., J, 3) predicted joints, metres.
    """
    dt = np.clip(stamp_s - joint_stamp_s, 0.0, max_predict_s)
    return positions + velocities * dt[..., None]


class AffinityParams(NamedTuple):
    """The weights and thresholds of eq. (1)-(5) that do not change from frame to frame (`affinity_matrix`).

    Attributes:
        w_2d: eq. (2)'s weight.
        alpha_2d_floor_px: the least threshold of eq. (2), pixels (0: the paper's eq. 2).
        w_3d: eq. (4)'s weight.
        alpha_3d_m: eq. (4)'s threshold, m.
        lambda_a_per_s: λa of eq. (2), (4), 1/s.
        max_predict_s: the longest horizon of eq. (5)'s prediction, s.
        normalize: eq. (1)'s sum divided by the number of joints with a 3D term (TrackerConfig.normalize_affinity).
    """

    w_2d: float
    alpha_2d_floor_px: float
    w_3d: float
    alpha_3d_m: float
    lambda_a_per_s: float
    max_predict_s: float
    normalize: bool


@jit
def affinity_matrix(targets, camera, det_px, world_from_pixel, center, stamp_s, alpha_2d_px_per_s, params, rows, out):
    """Eq. (1)-(5) in one pass from the tracker's target arrays: eq. (1)'s sum of the per-joint terms of eq. (2)
    and (4) after `predict_positions` and `geometry.ray_directions` (compiled kernel, no intermediate (T, D, J)
    arrays; the terms one by one, as plain numpy, are the tests' reference: tests/reference/affinity.py).

    Args:
        targets: the `TargetRows`, read: pos, vel (T, J, 3) X_t' (NaN unknown) and V_t'; joint_s (T, J) t' of
            X_t', s; seen_s (T, J) last observation of each joint, from which eq. (4)'s time penalty counts, s;
            obs_px (T, C, J, 2) last matched undistorted joints per camera and obs_s (T, C, J) their stamps
            (NaN none), of camera `camera` only (eq. 2).
        det_px: (D, J, 2) the frame's undistorted joints (NaN missing).
        world_from_pixel: (3, 3) R^T K^-1 of the camera; center: (3,) its centre (eq. 3).
        stamp_s: t, s.
        alpha_2d_px_per_s: eq. (2)'s α2D in pixels per second (converted with the camera's frame period).
        params: `AffinityParams`.
        rows: (R,) the target rows to score (those in the camera's view, `visibility.targets_in_view`).
        out: (R, D) the affinity matrix of those rows, written.
    """
    positions, velocities, joint_stamp_s, seen_stamp_s = targets.pos, targets.vel, targets.joint_s, targets.seen_s
    prev_px, prev_stamp_s = targets.obs_px, targets.obs_s
    w_2d, alpha_2d_floor_px, w_3d, alpha_3d_m = params.w_2d, params.alpha_2d_floor_px, params.w_3d, params.alpha_3d_m
    lambda_a_per_s, max_predict_s, normalize = params.lambda_a_per_s, params.max_predict_s, params.normalize
    J = positions.shape[1]
    D = det_px.shape[0]
    rays = np.empty((D, J, 3))
    for d in range(D):
        for j in range(J):
            x, y = det_px[d, j, 0], det_px[d, j, 1]
            for k in range(3):  # eq. (3): direction R^T K^-1 x̃, normalised
                rays[d, j, k] = x * world_from_pixel[k, 0] + y * world_from_pixel[k, 1] + world_from_pixel[k, 2]
            norm = np.sqrt(rays[d, j, 0] ** 2 + rays[d, j, 1] ** 2 + rays[d, j, 2] ** 2)
            for k in range(3):
                rays[d, j, k] /= norm
    sum_3d = np.empty(D)
    sum_2d = np.empty(D)
    count = np.empty(D)
    for i in range(rows.size):
        t = rows[i]
        sum_3d[:] = 0.0
        sum_2d[:] = 0.0
        count[:] = 0.0
        for j in range(J):
            # Eq. (5): X̂_t = X_t' + V_t' (t - t'), the horizon clipped to [0, max_predict_s].
            horizon = min(max(stamp_s - joint_stamp_s[t, j], 0.0), max_predict_s)
            r0 = positions[t, j, 0] + velocities[t, j, 0] * horizon - center[0]
            r1 = positions[t, j, 1] + velocities[t, j, 1] * horizon - center[1]
            r2 = positions[t, j, 2] + velocities[t, j, 2] * horizon - center[2]
            if np.isfinite(r0 + r1 + r2):
                rel_sq = r0 * r0 + r1 * r1 + r2 * r2
                decay_3d = np.exp(-lambda_a_per_s * max(stamp_s - seen_stamp_s[t, j], 0.0))
                for d in range(D):
                    # Eq. (4): d_l = |rel × d| = sqrt(|rel|² - (rel·d)²) for the unit ray direction d.
                    along = r0 * rays[d, j, 0] + r1 * rays[d, j, 1] + r2 * rays[d, j, 2]
                    a = w_3d * (1.0 - np.sqrt(max(rel_sq - along * along, 0.0)) / alpha_3d_m) * decay_3d
                    if not np.isnan(a):
                        sum_3d[d] += a
                        count[d] += 1.0
            prev_s = prev_stamp_s[t, camera, j]
            if not np.isnan(prev_s):
                # Eq. (2); t > t'' for frames of one camera, a repeated stamp counts as one microsecond apart.
                dt = max(stamp_s - prev_s, 1e-6)
                threshold = max(alpha_2d_px_per_s * dt, alpha_2d_floor_px)
                decay_2d = np.exp(-lambda_a_per_s * dt)
                px, py = prev_px[t, camera, j, 0], prev_px[t, camera, j, 1]
                for d in range(D):
                    dx, dy = det_px[d, j, 0] - px, det_px[d, j, 1] - py
                    a = w_2d * (1.0 - np.sqrt(dx * dx + dy * dy) / threshold) * decay_2d
                    if not np.isnan(a):
                        sum_2d[d] += a
        for d in range(D):  # eq. (1)
            total = sum_3d[d] + sum_2d[d]
            if normalize:
                total = total / count[d] if count[d] > 0 else 0.0
            out[i, d] = total


def epipolar_affinity(
    points_a: np.ndarray, points_b: np.ndarray, F_ab: np.ndarray, alpha_px: float, min_common_joints: int
) -> np.ndarray:
    """Eq. (S1)-(S2): epipolar affinity between the detections of two cameras, averaged over shared joints.

    Ae = 1 - (d_l(x_a, l_a) + d_l(x_b, l_b)) / (2 α), with l_b = F x_a and l_a = F^T x_b.

    Args:
        points_a: (Da, J, 2) undistorted pixels in camera a (NaN: missing).
        points_b: (Db, J, 2) undistorted pixels in camera b.
        F_ab: (3, 3) fundamental matrix with x_b^T F x_a = 0.
        alpha_px: threshold α, pixels.
        min_common_joints: pairs sharing fewer joints get -inf.

    Returns:
        (Da, Db) affinities.
    """
    ha = np.concatenate([points_a, np.ones(points_a.shape[:-1] + (1,))], axis=-1)
    hb = np.concatenate([points_b, np.ones(points_b.shape[:-1] + (1,))], axis=-1)
    lines_b = ha @ F_ab.T  # (Da, J, 3): l_b = F x_a
    lines_a = hb @ F_ab  # (Db, J, 3): l_a = F^T x_b
    # Distance of x_b to l_b and of x_a to l_a for every pair: |l·x| / ||l[:2]||.
    num_b = np.abs(np.einsum("ajk,bjk->abj", lines_b, hb))
    d_b = num_b / np.hypot(lines_b[..., 0], lines_b[..., 1])[:, None, :]
    num_a = np.abs(np.einsum("bjk,ajk->abj", lines_a, ha))
    d_a = num_a / np.hypot(lines_a[..., 0], lines_a[..., 1])[None, :, :]
    per_joint = 1.0 - (d_a + d_b) / (2.0 * alpha_px)
    common = np.sum(np.isfinite(per_joint), axis=-1)
    with np.errstate(invalid="ignore"):
        mean = np.nansum(per_joint, axis=-1) / np.maximum(common, 1)
    return np.where(common >= min_common_joints, mean, -np.inf)


def epipolar_affinity_matrix(
    points: np.ndarray, cameras: np.ndarray, F: np.ndarray, alpha_px: float, min_common_joints: int,
    linked: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. (S2) between every two detections of a pool, -inf within one camera (Algorithm S1).

    Args:
        points: (n, J, 2) undistorted pixels of the pooled detections (NaN missing).
        cameras: (n,) camera index of each detection.
        F, alpha_px, min_common_joints, linked: as in `epipolar_affinity_between`.

    Returns:
        (n, n) symmetric affinity matrix.
    """
    return epipolar_affinity_between(points, cameras, points, cameras, F, alpha_px, min_common_joints, linked)


def epipolar_affinity_between(
    points_a: np.ndarray, cameras_a: np.ndarray, points_b: np.ndarray, cameras_b: np.ndarray, F: np.ndarray,
    alpha_px: float, min_common_joints: int, linked: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. (S2) between every detection of one set and every detection of another, -inf within one camera.

    Two cameras whose views share no part of the space people occupy (`linked` False, from
    `visibility.overlapping_views`) cannot see one person: their detections get 0, no edge of the graph
    (an epipolar line of one crosses the other's image anyway, so eq. S2 alone would link them by chance).

    Args:
        points_a: (n, J, 2) undistorted pixels (NaN missing); cameras_a: (n,) camera index of each.
        points_b: (m, J, 2) and cameras_b: (m,) the same for the other set.
        F: (C, C, 3, 3) fundamental matrices, F[a, b] with x_b^T F[a, b] x_a = 0 (any value on the diagonal).
        alpha_px: threshold α, pixels.
        min_common_joints: pairs sharing fewer joints get -inf.
        linked: (C, C) bool, whether two cameras' views overlap; None: all do.

    Returns:
        (n, m) affinities.
    """
    if linked is None:
        linked = np.ones(F.shape[:2], dtype=bool)
    A = np.empty((points_a.shape[0], points_b.shape[0]))
    _epipolar_matrix(np.ascontiguousarray(points_a, dtype=np.float64), np.asarray(cameras_a, dtype=np.int64),
                     np.ascontiguousarray(points_b, dtype=np.float64), np.asarray(cameras_b, dtype=np.int64),
                     np.ascontiguousarray(F, dtype=np.float64), float(alpha_px), int(min_common_joints),
                     np.ascontiguousarray(linked, dtype=np.bool_), A)
    return A


@jit
def _epipolar_matrix(points_a, cameras_a, points_b, cameras_b, F, alpha_px, min_common_joints, linked, out):
    """`epipolar_affinity_between` into out (n, m) (compiled kernel; `epipolar_affinity` per pair)."""
    J = points_a.shape[1]
    for a in range(points_a.shape[0]):
        for b in range(points_b.shape[0]):
            ka, kb = cameras_a[a], cameras_b[b]
            out[a, b] = -np.inf
            if ka == kb:
                continue
            if not linked[ka, kb]:
                out[a, b] = 0.0
                continue
            total = 0.0
            common = 0
            for j in range(J):
                xa, ya, xb, yb = points_a[a, j, 0], points_a[a, j, 1], points_b[b, j, 0], points_b[b, j, 1]
                # l_b = F x_a and l_a = F^T x_b (eq. S1), and each point's distance to the other's line.
                lb0 = F[ka, kb, 0, 0] * xa + F[ka, kb, 0, 1] * ya + F[ka, kb, 0, 2]
                lb1 = F[ka, kb, 1, 0] * xa + F[ka, kb, 1, 1] * ya + F[ka, kb, 1, 2]
                lb2 = F[ka, kb, 2, 0] * xa + F[ka, kb, 2, 1] * ya + F[ka, kb, 2, 2]
                la0 = F[ka, kb, 0, 0] * xb + F[ka, kb, 1, 0] * yb + F[ka, kb, 2, 0]
                la1 = F[ka, kb, 0, 1] * xb + F[ka, kb, 1, 1] * yb + F[ka, kb, 2, 1]
                la2 = F[ka, kb, 0, 2] * xb + F[ka, kb, 1, 2] * yb + F[ka, kb, 2, 2]
                d_b = abs(lb0 * xb + lb1 * yb + lb2) / np.sqrt(lb0 * lb0 + lb1 * lb1)
                d_a = abs(la0 * xa + la1 * ya + la2) / np.sqrt(la0 * la0 + la1 * la1)
                a_j = 1.0 - (d_a + d_b) / (2.0 * alpha_px)  # eq. (S2) per joint
                if not np.isnan(a_j):
                    total += a_j
                    common += np.isfinite(a_j)
            if common >= min_common_joints:
                out[a, b] = total / max(common, 1)
