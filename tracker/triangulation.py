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
    valid = np.isfinite(rows).all(axis=(-1, -2)) & (weights > 0)
    r = np.where(valid[..., None, None], rows * np.where(valid, weights, 0.0)[..., None, None], 0.0)
    return _smallest_solution(r, valid.sum(axis=-1), min_views)


_INVERSE_ITERATIONS = 2  # each multiplies the start's error by λ_min / λ_2, tiny for a posed triangulation


def _smallest_solution(r: np.ndarray, num_views: np.ndarray, min_views: int) -> np.ndarray:
    """The unit X̃ minimising ||r X̃|| for rows r (..., C, 2, 4) (zero rows for missing views), dehomogenised.

    That is the right singular vector of the smallest singular value of r (eq. 8, "solved via SVD"), i.e. the
    eigenvector of M = rᵀr with the smallest eigenvalue (see `_smallest_eigenvector`).
    """
    batch = r.shape[:-3]
    flat = r.reshape((-1, r.shape[-3] * 2, 4))
    ok = num_views.reshape(-1) >= min_views
    X = np.full((flat.shape[0], 3), np.nan)
    if ok.any():
        sel = flat[ok]
        X[ok] = _smallest_eigenvector(np.einsum("nki,nkj->nij", sel, sel))
    return X.reshape(batch + (3,))


def _smallest_eigenvector(M: np.ndarray) -> np.ndarray:
    """Dehomogenised eigenvector of the smallest eigenvalue of each symmetric PSD 4x4 normal matrix.

    Found by inverse iteration on M started from the inhomogeneous solution (X̃4 = 1), which for 4x4 matrices
    in a batch is several times faster than a batched eigendecomposition and agrees with it to rounding (tests
    compare with an SVD). That start, [-a⁻¹b; 1] for M = [[a, b], [bᵀ, d]], is the last column of M⁻¹ up to
    a scale, so start plus `_INVERSE_ITERATIONS` steps is M⁻¹ applied to e4 1 + `_INVERSE_ITERATIONS` times:
    one batched inverse and a few 4x4 products.

    Args:
        M: (N, 4, 4) normal matrices rᵀr (eq. 8).

    Returns:
        (N, 3) points; NaN for a degenerate solution (X̃4 ≈ 0 or non-finite).
    """
    scale = np.trace(M, axis1=1, axis2=2)[:, None, None]
    regular = M + 1e-13 * scale * np.eye(4)
    try:
        inv = np.linalg.inv(regular)
        v = inv[:, :, 3]
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
        for _ in range(_INVERSE_ITERATIONS):
            v = np.einsum("nij,nj->ni", inv, v)
            v /= np.linalg.norm(v, axis=1, keepdims=True)
    except np.linalg.LinAlgError:
        v = np.linalg.eigh(M)[1][:, :, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        sol = v[:, :3] / v[:, 3:4]
    sol[(np.abs(v[:, 3]) < 1e-12) | ~np.isfinite(sol).all(axis=1)] = np.nan
    return sol


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
    plain, compensated = triangulate_incremental_both(P, points_px, stamps_s, stamp_s, lambda_t_per_s,
                                                      velocities, min_views)
    return plain if velocities is None else compensated


def triangulate_incremental_both(
    P: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None,
    min_views: int = 2,
) -> tuple[np.ndarray, np.ndarray | None]:
    """`triangulate_incremental` without and with velocity compensation, sharing one batched solve.

    Returns:
        (paper estimate (..., 3), velocity-compensated estimate (..., 3) or None without velocities).
    """
    batch = points_px.shape[:-2]
    C = points_px.shape[-2]
    valid = np.isfinite(points_px).all(axis=-1).reshape(-1, C)  # (N, C)
    group, cam = np.nonzero(valid)
    px = points_px.reshape(-1, C, 2)[group, cam]
    stamps = np.broadcast_to(stamps_s, batch + (C,)).reshape(-1, C)[group, cam]
    vel = None if velocities is None else np.broadcast_to(velocities, batch + (3,)).reshape(-1, 3)
    plain, compensated = triangulate_observations(P, group, cam, px, stamps, valid.shape[0], stamp_s,
                                                  lambda_t_per_s, vel, min_views)
    return plain.reshape(batch + (3,)), None if compensated is None else compensated.reshape(batch + (3,))


def triangulate_observations(
    P: np.ndarray,
    group: np.ndarray,
    cam: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    num_groups: int,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None,
    min_views: int = 2,
    quadrics: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Eq. (6)-(11) for many points at once, from a flat list of their observations (no missing entries).

    Each observation adds its two weighted rows' outer products to its point's 4x4 normal matrix (eq. 8, 10),
    written as a weighted sum of per-camera constant matrices (`camera_quadrics`).

    Args:
        P: (C, 3, 4) projection matrices.
        group: (K,) point index of each observation, in [0, num_groups).
        cam: (K,) camera index of each observation (at most one observation per point and camera).
        points_px: (K, 2) undistorted pixels.
        stamps_s: (K,) their stamps t_i, s.
        num_groups: number of points N.
        stamp_s: the time t of the estimate, s.
        lambda_t_per_s: λt, 1/s.
        velocities: None, or (N, 3) joint velocities, m/s (see `triangulate_incremental`).
        min_views: least number of views.
        quadrics: `camera_quadrics(P)` if already computed (a tracker keeps it), else None.

    Returns:
        (paper estimate (N, 3), velocity-compensated estimate (N, 3) or None without velocities); NaN for a
        point with fewer than `min_views` observations.
    """
    plain = np.full((num_groups, 3), np.nan)
    compensated = None if velocities is None else np.full((num_groups, 3), np.nan)
    counts = np.bincount(group, minlength=num_groups)
    ok = counts >= min_views
    if not ok.any():
        return plain, compensated
    keep = ok[group]
    if not keep.all():
        group, cam, points_px, stamps_s = group[keep], cam[keep], points_px[keep], stamps_s[keep]
    targets = np.flatnonzero(ok)
    slot = (np.cumsum(ok) - 1)[group]  # (K,) row of each observation's point among `targets`
    Q = camera_quadrics(P) if quadrics is None else quadrics  # (C, 5, 4, 4)
    C = Q.shape[0]
    dt = np.maximum(stamp_s - stamps_s, 0.0)  # (K,)
    x0, x1 = points_px[:, 0], points_px[:, 1]
    # Eq. (9) row r = x_r p3 - p_r, so rᵀr = x_r² p3ᵀp3 - 2 x_r sym(p_rᵀp3) + p_rᵀp_r and ||r||² is the same
    # combination of the quadrics' traces. Eq. (11): squared row weight e^(-2 λt (t - t_i)) / ||r||².
    tr = np.trace(Q, axis1=2, axis2=3)[cam]  # (K, 5)
    decay = np.exp(-2.0 * lambda_t_per_s * dt)
    w0 = decay / (x0 * x0 * tr[:, 0] - 2.0 * x0 * tr[:, 1] + tr[:, 3])
    w1 = decay / (x1 * x1 * tr[:, 0] - 2.0 * x1 * tr[:, 2] + tr[:, 4])
    coef = np.stack([w0 * x0 * x0 + w1 * x1 * x1, -2.0 * w0 * x0, -2.0 * w1 * x1, w0, w1], axis=-1)  # (K, 5)
    # Sum over each point's observations (eq. 8, 10): one dense product (points, cameras x 5) @ (cameras x 5, 16).
    moments = 1 if velocities is None else 3
    table = np.zeros((moments, targets.size, C, 5))
    table[0, slot, cam] = coef
    if velocities is not None:
        table[1, slot, cam] = coef * dt[:, None]
        table[2, slot, cam] = coef * (dt * dt)[:, None]
    sums = (table.reshape(moments * targets.size, C * 5) @ Q.reshape(C * 5, 16)).reshape(moments, -1, 4, 4)
    M = sums[0]
    if velocities is None:
        plain[targets] = _smallest_eigenvector(M)
        return plain, None
    # Beyond the paper: row·[X - V dt_i; 1] = 0, i.e. rows r T_i with T_i = [[I, -V dt_i], [0, 1]], so the
    # normal matrix Σ T_iᵀ A_i T_i follows from the moments Σ A_i, Σ dt_i A_i and Σ dt_i² A_i.
    V = velocities[targets]  # (N', 3)
    M1, M2 = sums[1], sums[2]
    Mv = M.copy()
    col = M[:, :3, 3] - np.einsum("nij,nj->ni", M1[:, :3, :3], V)
    Mv[:, :3, 3] = col
    Mv[:, 3, :3] = col
    Mv[:, 3, 3] = (M[:, 3, 3] - 2.0 * np.einsum("ni,ni->n", M1[:, :3, 3], V)
                   + np.einsum("ni,nij,nj->n", V, M2[:, :3, :3], V))
    both = _smallest_eigenvector(np.concatenate([M, Mv]))
    plain[targets] = both[: targets.size]
    compensated[targets] = both[targets.size:]
    return plain, compensated


def triangulate_observations_robust(
    P: np.ndarray,
    group: np.ndarray,
    cam: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    num_groups: int,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None,
    min_views: int,
    quadrics: np.ndarray | None,
    reject_factor: float,
    reject_floor_px: float,
) -> tuple[np.ndarray, np.ndarray | None]:
    """`triangulate_observations`, then once more without the views whose reprojection error exceeds both
    `reject_floor_px` and `reject_factor` times the median error of the point's views (beyond the paper).

    The error of an observation taken at t_i is measured against the estimate moved back to t_i with the
    velocity when velocities are given. A point keeps its first estimate if fewer than `min_views` views
    would remain. Arguments as `triangulate_observations`; reject_factor 0 disables the second pass.
    """
    args = (num_groups, stamp_s, lambda_t_per_s, velocities, min_views, quadrics)
    plain, compensated = triangulate_observations(P, group, cam, points_px, stamps_s, *args)
    if reject_factor <= 0 or group.size == 0:
        return plain, compensated
    X = (plain if compensated is None else compensated)[group]  # (K, 3)
    if velocities is not None:
        X = X - velocities[group] * np.maximum(stamp_s - stamps_s, 0.0)[:, None]
    Pc = P[cam]  # (K, 3, 4)
    proj = np.einsum("kij,kj->ki", Pc[:, :, :3], X) + Pc[:, :, 3]  # (K, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        err = np.linalg.norm(proj[:, :2] / proj[:, 2:3] - points_px, axis=-1)  # (K,) pixels
    err = np.where(np.isfinite(err), err, 0.0)
    order = np.lexsort((err, group))  # by point, then error
    counts = np.bincount(group, minlength=num_groups)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    median = np.zeros(num_groups)
    has = counts > 0
    median[has] = err[order][starts[has] + (counts[has] - 1) // 2]  # lower median
    drop = (err > reject_floor_px) & (err > reject_factor * median[group])
    if not drop.any():
        return plain, compensated
    keep = ~drop
    plain2, compensated2 = triangulate_observations(P, group[keep], cam[keep], points_px[keep], stamps_s[keep],
                                                    *args)
    redo = np.zeros(num_groups, dtype=bool)
    redo[group[drop]] = True
    redo &= np.isfinite(plain2[:, 0])
    plain[redo] = plain2[redo]
    if compensated is not None:
        compensated[redo] = compensated2[redo]
    return plain, compensated


def camera_quadrics(P: np.ndarray) -> np.ndarray:
    """Per-camera constants of the eq. (9) normal matrices: p3ᵀp3, sym(p1ᵀp3), sym(p2ᵀp3), p1ᵀp1, p2ᵀp2.

    Args:
        P: (C, 3, 4) projection matrices (rows p1, p2, p3).

    Returns:
        (C, 5, 4, 4) symmetric matrices.
    """
    p1, p2, p3 = P[:, 0], P[:, 1], P[:, 2]

    def outer(u, v):
        return u[:, :, None] * v[:, None, :]

    return np.stack([outer(p3, p3), 0.5 * (outer(p1, p3) + outer(p3, p1)), 0.5 * (outer(p2, p3) + outer(p3, p2)),
                     outer(p1, p1), outer(p2, p2)], axis=1)


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
