"""OpenCV's camera model as a plain vectorised numpy formula: the reference `core.projection.in_image_many_kernel`
is tested against, bit for bit (and this against `cv2.projectPoints`); also the lens model applied to pinhole
pixels (the inverse of `tracker.geometry.undistort_points`)."""

from __future__ import annotations

import numpy as np

from core.projection import MIN_DEPTH_M, monotonic_radius
from core.types import Camera


def _distort(xn: np.ndarray, yn: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's radial-tangential distortion of normalised image coordinates."""
    k1, k2, p1, p2, k3 = dist
    r2 = xn * xn + yn * yn
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


def project(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projects world points to distorted pixels with OpenCV's camera model.

    Args:
        camera: the camera.
        points_world: (..., 3) points in the world frame, metres.

    Returns:
        (..., 2) distorted pixel coordinates (NaN for points not in front of the camera) and
        (...,) bool mask of the points in front of the camera.
    """
    px, in_front, _ = _project(camera, points_world)
    return px, in_front


def _project(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`project` plus (...,) the undistorted normalised radius of each point (NaN behind)."""
    points = np.asarray(points_world, dtype=np.float64)
    if points.shape[-1:] != (3,):
        raise ValueError(f"points_world: expected shape (..., 3), got {points.shape}")
    cam = points @ camera.R_cam_from_world.T + camera.t_cam_from_world
    z = cam[..., 2]
    in_front = z > MIN_DEPTH_M
    inv_z = np.divide(1.0, z, out=np.full(z.shape, np.nan), where=in_front)
    xn, yn = cam[..., 0] * inv_z, cam[..., 1] * inv_z
    xd, yd = _distort(xn, yn, camera.dist)
    K = camera.K
    px = np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=-1)
    return px, in_front, np.sqrt(xn * xn + yn * yn)


def distort_pixels(camera: Camera, points_px: np.ndarray) -> np.ndarray:
    """Undistorted pinhole pixels (..., 2) to distorted pixels (..., 2) with OpenCV's lens model; NaN stays NaN."""
    points = np.asarray(points_px, dtype=np.float64)
    K = camera.K
    yn = (points[..., 1] - K[1, 2]) / K[1, 1]
    xn = (points[..., 0] - K[0, 2] - K[0, 1] * yn) / K[0, 0]
    xd, yd = _distort(xn, yn, camera.dist)
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=-1)


def in_image(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`core.projection.in_image` as numpy: pixels, and in front, within the monotonic radius and inside the image."""
    px, in_front, r = _project(camera, points_world)
    with np.errstate(invalid="ignore"):
        inside = (
            in_front
            & (r <= monotonic_radius(camera.dist))
            & (px[..., 0] >= -0.5) & (px[..., 0] <= camera.width_px - 0.5)
            & (px[..., 1] >= -0.5) & (px[..., 1] <= camera.height_px - 0.5)
        )
    return px, inside
