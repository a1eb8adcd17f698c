"""Where a camera sees a world point: distorted pixels by OpenCV's camera model, and whether the point is in
front of the camera, inside the lens's well-behaved radius and inside the image. The simulator's detector,
the scores and the pictures all project with it.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import numpy as np

from core.jit import intrinsic, jit, llvm_ir, types
from core.types import Camera

# Points closer than this in front of the camera plane count as behind it (their projection blows up).
MIN_DEPTH_M = 1e-6


def monotonic_radius(dist: np.ndarray) -> float:
    """Largest undistorted normalised radius up to which the radial distortion keeps growing.

    Beyond it a strong barrel lens folds far-away points back into the image, so projections there
    are not where a real lens would put them.
    """
    return _monotonic_radius(tuple(float(d) for d in dist))


@functools.lru_cache(maxsize=256)
def _monotonic_radius(dist: tuple[float, ...]) -> float:
    k1, k2, _, _, k3 = dist
    r = np.linspace(0.0, 10.0, 20001)
    r2 = r * r
    derivative = 1 + 3 * k1 * r2 + 5 * k2 * r2 * r2 + 7 * k3 * r2 * r2 * r2
    bad = np.nonzero(derivative <= 0)[0]
    return float(r[bad[0] - 1]) if bad.size else math.inf


def in_image(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distorted pixels (OpenCV's camera model) and whether each point is in front of the camera, within the
    lens's monotonic radius (`monotonic_radius`) and inside its image.

    Args:
        camera: the camera.
        points_world: (..., 3) world points, metres.

    Returns:
        (..., 2) distorted pixels (NaN behind the camera) and (...,) bool visible-in-image mask.
    """
    points = np.asarray(points_world, dtype=np.float64)
    if points.shape[-1:] != (3,):
        raise ValueError(f"points_world: expected shape (..., 3), got {points.shape}")
    px, inside = in_image_many(camera.R_cam_from_world[None], camera.t_cam_from_world[None], camera.K[None],
                               camera.dist[None], np.array([[camera.width_px, camera.height_px]], dtype=float),
                               np.array([monotonic_radius(camera.dist)]), points.reshape(1, -1, 3),
                               np.zeros(1, dtype=np.int64))
    return px.reshape(points.shape[:-1] + (2,)), inside.reshape(points.shape[:-1])


def in_image_many(R: np.ndarray, t: np.ndarray, K: np.ndarray, dist: np.ndarray, size: np.ndarray,
                  max_radius: np.ndarray, points_world: np.ndarray, cameras: np.ndarray):
    """`in_image` of several point sets, each seen by its own camera of a rig, in one compiled pass.

    Args:
        R (C, 3, 3), t (C, 3), K (C, 3, 3), dist (C, 5): the rig's extrinsics, intrinsics and distortion.
        size (C, 2): width and height in pixels; max_radius (C,): `monotonic_radius` of each camera.
        points_world: (S, N, 3) world points, metres (NaN rows are never in the image).
        cameras: (S,) index of the camera of each point set.

    Returns:
        (S, N, 2) distorted pixels (NaN behind the camera) and (S, N) bool visible-in-image mask.
    """
    points = np.ascontiguousarray(points_world, dtype=np.float64)
    cameras = np.ascontiguousarray(cameras, dtype=np.int64)
    px = np.empty(points.shape[:2] + (2,))
    inside = np.empty(points.shape[:2], dtype=bool)
    # The tangential and skew terms are added only when some camera of the batch has them (adding exact
    # zeros could only turn a -0.0 into +0.0, but the results stay those of the vectorised formula).
    tangential = np.full(len(cameras), dist[cameras][:, 2:4].any())
    skew = np.full(len(cameras), K[cameras][:, 0, 1].any())
    in_image_many_kernel(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(t, dtype=np.float64),
                     np.ascontiguousarray(K, dtype=np.float64), np.ascontiguousarray(dist, dtype=np.float64),
                     np.ascontiguousarray(size, dtype=np.float64), np.ascontiguousarray(max_radius, dtype=np.float64),
                     points, cameras, tangential, skew, px, inside)
    return px, inside


def _plain_fma(a, b, c):
    """a * b + c rounded once, in Python: exact rational arithmetic, then one rounding."""
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return a * b + c
    return float(Fraction(a) * Fraction(b) + Fraction(c))


@intrinsic(plain=_plain_fma)
def _fma(typingctx, a, b, c):
    """a * b + c rounded once (LLVM's fma intrinsic), as the BLAS kernels behind numpy's matmul compute."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, sig, args):
        double = llvm_ir.DoubleType()
        fma = builder.module.declare_intrinsic("llvm.fma", [double], llvm_ir.FunctionType(double, [double] * 3))
        return builder.call(fma, args)

    return signature, codegen


@jit
def in_image_many_kernel(R, t, K, dist, size, max_radius, points, cameras, tangential, skew, px, inside):
    """The loops of `in_image_many` (its arguments, C-contiguous, then `tangential` and `skew` (S,): whether
    a camera of each set's batch has those terms, and the outputs px (S, N, 2) and inside (S, N)), for
    callers that keep the rig's arrays ready. Written out in the order of the vectorised numpy formula of
    `tests/reference/cameras.py`, so that every pixel is the same bit for bit (which keeps the recordings'
    bytes): numpy's matmul (OpenBLAS) rotates as fma(z, R2, fma(y, R1, x R0)), fused multiply-adds rounded
    once, and so does this loop."""
    for s in range(points.shape[0]):
        c = cameras[s]
        k1, k2, p1, p2, k3 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3], dist[c, 4]
        r2_max = max_radius[c] * max_radius[c]
        w, h = size[c, 0] - 0.5, size[c, 1] - 0.5
        for n in range(points.shape[1]):
            x, y, z = points[s, n, 0], points[s, n, 1], points[s, n, 2]
            cx = _fma(z, R[c, 0, 2], _fma(y, R[c, 0, 1], x * R[c, 0, 0])) + t[c, 0]
            cy = _fma(z, R[c, 1, 2], _fma(y, R[c, 1, 1], x * R[c, 1, 0])) + t[c, 1]
            cz = _fma(z, R[c, 2, 2], _fma(y, R[c, 2, 1], x * R[c, 2, 0])) + t[c, 2]
            in_front = cz > MIN_DEPTH_M
            inv_z = 1.0 / cz if in_front else np.nan
            xn, yn = cx * inv_z, cy * inv_z
            r2 = xn * xn + yn * yn
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd, yd = xn * radial, yn * radial
            if tangential[s]:
                xd, yd = (xd + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn),
                          yd + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn)
            u = K[c, 0, 0] * xd
            if skew[s]:
                u += K[c, 0, 1] * yd
            u += K[c, 0, 2]
            v = K[c, 1, 1] * yd + K[c, 1, 2]
            px[s, n, 0], px[s, n, 1] = u, v
            inside[s, n] = in_front and r2 <= r2_max and u >= -0.5 and u <= w and v >= -0.5 and v <= h
