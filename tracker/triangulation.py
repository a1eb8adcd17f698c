"""Multi-view triangulation: the standard DLT, the paper's time-weighted incremental DLT (eq. 6-11) and a
velocity-compensated variant for unsynchronised cameras."""

from __future__ import annotations

import numpy as np


def dlt_rows(P: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Eq. (9): the two rows x p3ᵀ - p1ᵀ and y p3ᵀ - p2ᵀ of each view.

    Args:
        P: (C, 3, 4) projection matrices.
        points_px: (..., C, 2) undistorted pixels.

    Returns:
        (..., C, 2, 4) coefficient rows (NaN where the point is NaN).
    """
    return points_px[..., :, :, None] * P[:, 2:3, :] - P[:, 0:2, :]


def solve_weighted(rows: np.ndarray, weights: np.ndarray, min_views: int = 2) -> np.ndarray:
    """Eq. (8), (10): least-squares solution of (w ∘ C) X̃ = 0 with ||X̃|| = 1, batched.

    Args:
        rows: (..., C, 2, 4) rows of C (any NaN row counts as missing).
        weights: (..., C) per-view weights w_i (applied to both rows of the view); 0 drops a view.
        min_views: joints seen in fewer views get NaN.

    Returns:
        (..., 3) points, metres; NaN with too few views or a degenerate solution.
    """
    valid = np.all(np.isfinite(rows), axis=(-1, -2)) & (weights > 0)
    w = np.where(valid, weights, 0.0)
    r = np.where(valid[..., None, None], rows, 0.0) * w[..., None, None]
    r = r.reshape(r.shape[:-3] + (-1, 4))
    # The right singular vector of the smallest singular value = eigenvector of CᵀC for the smallest eigenvalue.
    M = np.einsum("...ri,...rj->...ij", r, r)
    _, vecs = np.linalg.eigh(M)
    Xh = vecs[..., :, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        X = Xh[..., :3] / Xh[..., 3:4]
    bad = (np.sum(valid, axis=-1) < min_views) | (np.abs(Xh[..., 3]) < 1e-12) | ~np.all(np.isfinite(X), axis=-1)
    X[bad] = np.nan
    return X


def triangulate(P: np.ndarray, points_px: np.ndarray, min_views: int = 2, normalize_rows: bool = True) -> np.ndarray:
    """Standard DLT (eq. 8-9), all points taken at one instant.

    Args:
        P: (C, 3, 4) projection matrices.
        points_px: (..., C, 2) undistorted pixels of the same point(s) in each camera, NaN missing.
        min_views: least number of views.
        normalize_rows: divide each row by its norm (eq. 11 without the time term); False: unit weights.

    Returns:
        (..., 3) world points, metres (NaN with fewer than `min_views` views).
    """
    rows = dlt_rows(P, points_px)
    if normalize_rows:
        with np.errstate(invalid="ignore", divide="ignore"):
            rows = rows / np.linalg.norm(rows, axis=-1, keepdims=True)
    return solve_weighted(rows, np.ones(rows.shape[:-2]), min_views)


def time_weights(
    rows: np.ndarray, stamps_s: np.ndarray, stamp_s: float, lambda_t_per_s: float
) -> np.ndarray:
    """Eq. (11): w_i = e^(-λt (t - t_i)) / ||c_i|| for each row.

    Args:
        rows: (..., C, 2, 4) rows of C.
        stamps_s: (..., C) stamps t_i of the points, s.
        stamp_s: the target time t, s.

    Returns:
        (..., C, 2) row weights (NaN propagates for missing rows).
    """
    decay = np.exp(-lambda_t_per_s * np.maximum(stamp_s - stamps_s, 0.0))
    norm = np.linalg.norm(rows, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return decay[..., None] / norm


def triangulate_incremental(
    P: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None = None,
    min_views: int = 2,
) -> np.ndarray:
    """Eq. (6)-(11): the time-weighted DLT over the latest point of each camera.

    With `velocities` (beyond the paper) an older point x_i constrains X(t) - V (t - t_i) instead of X(t):
    row·[X - V dt_i; 1] = 0, i.e. the row's constant term becomes c4 - c[:3]·V dt_i.

    Args:
        P: (C, 3, 4) projection matrices.
        points_px: (..., C, 2) latest undistorted pixels of each camera, NaN missing.
        stamps_s: (..., C) their stamps t_i, s.
        stamp_s: the time t of the estimate, s.
        lambda_t_per_s: λt, 1/s.
        velocities: None, or (..., 3) joint velocities, m/s.
        min_views: least number of views.

    Returns:
        (..., 3) world points at time t, metres (NaN with fewer than `min_views` views).
    """
    rows = dlt_rows(P, points_px)  # (..., C, 2, 4)
    # Eq. (11) normalises by the norm of the row of C itself (before any velocity shift).
    w = time_weights(rows, stamps_s, stamp_s, lambda_t_per_s)
    if velocities is not None:
        dt = np.maximum(stamp_s - stamps_s, 0.0)  # (..., C)
        shift = np.einsum("...crk,...ck->...cr", rows[..., :3], velocities[..., None, :] * dt[..., None])
        rows = rows.copy()
        rows[..., 3] -= shift
    r = rows * w[..., None]
    valid_view = np.all(np.isfinite(r), axis=(-1, -2))
    return solve_weighted(np.where(valid_view[..., None, None], r, np.nan), valid_view.astype(np.float64), min_views)


def reprojection_error_px(P: np.ndarray, X: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Pixel distance between projected points and observed points.

    Args:
        P: (C, 3, 4); X: (..., 3) world points; points_px: (..., C, 2) observations.

    Returns:
        (..., C) errors, NaN where either side is missing.
    """
    Xh = np.concatenate([X, np.ones(X.shape[:-1] + (1,))], axis=-1)
    x = np.einsum("cij,...j->...ci", P, Xh)
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = x[..., :2] / x[..., 2:3]
    return np.linalg.norm(uv - points_px, axis=-1)
