"""Camera geometry for the tracker: undistortion, projection, back-projected rays and epipolar lines.

Shapes: C cameras, J joints, D detections, N points; coordinates on the last axis, float64, NaN missing.
Pixels here are *undistorted* pixels of the pinhole model P = K [R | t] unless a name says `distorted`.
"""

from __future__ import annotations

import cv2
import numpy as np

from core.jit import jit
from core.types import Camera


def undistort_points(camera: Camera, points_px: np.ndarray) -> np.ndarray:
    """Maps distorted pixels to the pixels of the undistorted pinhole model (cv2.undistortPoints with P=K).

    Args:
        camera: the camera that took the points.
        points_px: (..., 2) distorted pixel coordinates; non-finite entries stay NaN.

    Returns:
        (..., 2) undistorted pixel coordinates, NaN where the input was not finite.
    """
    def undistort(finite_px: np.ndarray) -> np.ndarray:
        flat = np.ascontiguousarray(finite_px.reshape(-1, 1, 2))
        return cv2.undistortPoints(flat, camera.K, camera.dist, P=camera.K).reshape(-1, 2)

    return _map_finite_pixels(camera, points_px, undistort)


@jit
def undistort_detections(keypoints_px, scores, score_threshold, K, dist, out):
    """Undistorts the usable joints of one frame (compiled kernel for the tracker; `undistort_points` per joint).

    A joint is usable when both coordinates are finite and its score, NaN read as 0 and clipped to [0, 1], is
    positive and at least `score_threshold`. The lens model is inverted as cv2.undistortPoints does it with its
    default criteria (five fixed-point iterations) and P = K, so the pixels agree with it (tests compare).

    Args:
        keypoints_px: (D, J, 2) distorted pixels; scores: (D, J) detector scores.
        K: (3, 3) intrinsics; dist: (5,) OpenCV k1, k2, p1, p2, k3.
        out: (D, J, 2) undistorted pixels, NaN for unusable joints (written).

    Returns:
        (D,) number of usable joints of each detection.
    """
    D, J = scores.shape
    usable = np.zeros(D, dtype=np.int64)
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    lens = k1 != 0.0 or k2 != 0.0 or p1 != 0.0 or p2 != 0.0 or k3 != 0.0
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    for d in range(D):
        for j in range(J):
            u, v, score = keypoints_px[d, j, 0], keypoints_px[d, j, 1], scores[d, j]
            score = 0.0 if np.isnan(score) else min(max(score, 0.0), 1.0)
            if not (np.isfinite(u) and np.isfinite(v) and score >= score_threshold and score > 0.0):
                out[d, j, 0] = np.nan
                out[d, j, 1] = np.nan
                continue
            usable[d] += 1
            if not lens:
                out[d, j, 0] = u
                out[d, j, 1] = v
                continue
            x0 = x = (u - cx) * (1.0 / fx)
            y0 = y = (v - cy) * (1.0 / fy)
            for _ in range(5):
                r2 = x * x + y * y
                icdist = 1.0 / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
                if icdist < 0.0:  # beyond the model's valid radius: OpenCV keeps the distorted normalised point
                    x = (u - cx) * (1.0 / fx)
                    y = (v - cy) * (1.0 / fy)
                    break
                delta_x = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
                delta_y = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
                x = (x0 - delta_x) * icdist
                y = (y0 - delta_y) * icdist
            w = 1.0 / (K[2, 0] * x + K[2, 1] * y + K[2, 2])
            out[d, j, 0] = (K[0, 0] * x + K[0, 1] * y + K[0, 2]) * w
            out[d, j, 1] = (K[1, 0] * x + K[1, 1] * y + K[1, 2]) * w
    return usable


def _map_finite_pixels(camera: Camera, points_px: np.ndarray, lens_map) -> np.ndarray:
    """Applies `lens_map` ((N, 2) -> (N, 2) pixels) to the finite points of (..., 2); NaN elsewhere.

    A camera without distortion maps pixels to themselves, so `lens_map` is skipped.
    """
    points = np.asarray(points_px, dtype=np.float64)
    out = np.full(points.shape, np.nan)
    finite = np.all(np.isfinite(points), axis=-1)
    if not finite.any():
        return out
    out[finite] = lens_map(points[finite]) if np.any(camera.dist) else points[finite]
    return out


def project(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Eq. (7): pinhole projection of world points.

    Args:
        P: (3, 4) projection matrix, or (C, 3, 4) for several cameras.
        X: (..., 3) world points, metres.

    Returns:
        (..., 2) undistorted pixels for one camera, or (C, ..., 2) for several; NaN behind the camera.
    """
    P = np.asarray(P, dtype=np.float64)
    X = np.asarray(X, dtype=np.float64)
    Xh = np.concatenate([X, np.ones(X.shape[:-1] + (1,))], axis=-1)
    if P.ndim == 2:
        x = Xh @ P.T
    else:
        x = np.einsum("cij,...j->c...i", P, Xh)
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = x[..., :2] / x[..., 2:3]
    uv[x[..., 2] <= 0] = np.nan
    return uv


def ray_directions(camera: Camera | None, points_px: np.ndarray, world_from_pixel: np.ndarray | None = None
                   ) -> np.ndarray:
    """Eq. (3): unit world directions of the rays from the camera centre through undistorted pixels.

    The ray P⁺x̃ + μX̃_c of eq. (3) is the line through the centre X_c with direction R^T K^-1 x̃.

    Args:
        camera: the camera (None when `world_from_pixel` is given).
        points_px: (..., 2) undistorted pixels.
        world_from_pixel: R^T K^-1 of the camera if already computed (`world_from_pixel_matrix(camera)`), (3, 3);
            or one per leading index of points_px, (..., 3, 3), for pixels of several cameras.

    Returns:
        (..., 3) unit directions in the world frame (NaN where the pixel is NaN).
    """
    points = np.asarray(points_px, dtype=np.float64)
    M = world_from_pixel_matrix(camera) if world_from_pixel is None else np.asarray(world_from_pixel)
    if M.ndim == 2:
        d = points @ M[:, :2].T + M[:, 2]
    else:
        d = np.einsum("...ab,...b->...a", M[..., :, :2], points) + M[..., :, 2]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def world_from_pixel_matrix(camera: Camera) -> np.ndarray:
    """(3, 3) R^T K^-1: the world direction of the ray through an undistorted homogeneous pixel (eq. 3)."""
    return camera.R_cam_from_world.T @ np.linalg.inv(camera.K)


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix [v]_x."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_matrix(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """(3, 3) fundamental matrix F with x_b^T F x_a = 0 (undistorted pixels), so that l_b = F x_a (eq. S1)."""
    R = cam_b.R_cam_from_world @ cam_a.R_cam_from_world.T
    t = cam_b.t_cam_from_world - R @ cam_a.t_cam_from_world
    E = skew(t) @ R
    F = np.linalg.inv(cam_b.K).T @ E @ np.linalg.inv(cam_a.K)
    return F / np.linalg.norm(F)


def point_line_distance_px(points_px: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Distance in pixels between points (..., 2) and homogeneous lines (..., 3) (a x + b y + c = 0)."""
    num = np.abs(lines[..., 0] * points_px[..., 0] + lines[..., 1] * points_px[..., 1] + lines[..., 2])
    return num / np.hypot(lines[..., 0], lines[..., 1])
