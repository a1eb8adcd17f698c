"""Multi-view triangulation: the standard DLT, the paper's time-weighted incremental DLT (eq. 6-11) and a
velocity-compensated variant for unsynchronised cameras."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from core.jit import jit, sort_prefix
from tracker.config import RowNorm, TrackerConfig

# How eq. (11) divides a row c of C (eq. 9), the `row_norm` code of the functions below.
UNIT_ROWS = 0
"""No division: Table 4's "w/o norm" and the conventional DLT (ablations)."""
WHOLE_ROW = 1
"""||c|| over its four entries: eq. (11) as printed. The fourth entry, x t3 - (K t)1 for P = K [R | t], grows
with the camera's distance from the world origin, so views of the same point weigh very differently by
where the origin happens to be: in the hypermarket (origin at a corner) up to 1,800 times."""
PLANE_ROW = 2
"""||c[:3]||, beyond the paper: c·X̃ / ||c[:3]|| is then the distance in metres from X to the plane through the
camera centre and the image line x = x_i (or y = y_i), whatever the world origin. With detector noise in
pixels proportional to the person's size in the image (the simulated detector's, docs/sensor-model.md), that
distance has about the same spread in every view, so equal weights are what least squares wants."""


class TriangulationParams(NamedTuple):
    """How the compiled triangulation (`triangulate_point`) weighs and filters a point's observations.

    Attributes:
        lambda_t_per_s: λt of eq. (11)'s time weights, 1/s (0: every observation weighs the same).
        use_velocity: also compute the velocity-compensated estimate.
        min_views: least number of views of a point.
        reject_factor: the robust second pass leaves out views whose reprojection error exceeds both
            `reject_floor_px` and this times the point's median error (0: no second pass).
        reject_floor_px: see reject_factor, pixels.
        row_norm: eq. (11)'s division of the rows (UNIT_ROWS, WHOLE_ROW or PLANE_ROW).
    """

    lambda_t_per_s: float
    use_velocity: bool
    min_views: int
    reject_factor: float
    reject_floor_px: float
    row_norm: int


class Observations(NamedTuple):
    """One point's observations, in arrays of which the first `num` count (the callers' work space, made once
    and refilled per point; `num` travels beside the tuple, so that the tuple is made once too).

    Attributes:
        cam: (>=num,) int64 camera of each observation.
        points_px: (>=num, 2) undistorted pixels.
        dts: (>=num,) t - t_i >= 0, s.
        decays: (>=num,) e^(-2 λt (t - t_i)), the squared time factors of the eq. (11) weights.
    """

    cam: np.ndarray
    points_px: np.ndarray
    dts: np.ndarray
    decays: np.ndarray


def row_norm_code(config: TrackerConfig, reconstruction: bool = False) -> int:
    """The `row_norm` code of a configuration: its triangulation mode and row norm.

    reconstruction: the code for a new target's reconstruction, whose rows are divided in every mode (the
    ablations of Table 4 leave the norm out of the update of eq. 6-11 only)."""
    if not (reconstruction or config.triangulation.normalizes_rows):
        return UNIT_ROWS
    return PLANE_ROW if config.row_norm is RowNorm.PLANE else WHOLE_ROW


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


def triangulate(P: np.ndarray, points_px: np.ndarray, min_views: int = 2, row_norm: int = WHOLE_ROW) -> np.ndarray:
    """Standard DLT (eq. 8-9), all points taken at one instant.

    Args:
        P: (C, 3, 4) projection matrices.
        points_px: (..., C, 2) undistorted pixels of the same point(s) in each camera, NaN missing.
        min_views: least number of views.
        row_norm: UNIT_ROWS, WHOLE_ROW or PLANE_ROW: how each row is divided (eq. 11 without the time term).

    Returns:
        (..., 3) world points, metres (NaN with fewer than `min_views` views).
    """
    rows = dlt_rows(P, points_px)
    if row_norm != UNIT_ROWS:
        with np.errstate(invalid="ignore", divide="ignore"):
            rows = rows / np.linalg.norm(rows if row_norm == WHOLE_ROW else rows[..., :3], axis=-1, keepdims=True)
    return solve_weighted(rows, np.ones(rows.shape[:-2]), min_views)


def triangulate_incremental(
    P: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None = None,
    min_views: int = 2,
    row_norm: int = WHOLE_ROW,
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
        row_norm: eq. (11)'s division of the rows (UNIT_ROWS, WHOLE_ROW or PLANE_ROW).

    Returns:
        (..., 3) world points at time t, metres (NaN with fewer than `min_views` views).
    """
    plain, compensated = triangulate_incremental_both(P, points_px, stamps_s, stamp_s, lambda_t_per_s,
                                                      velocities, min_views, row_norm)
    return plain if velocities is None else compensated


def triangulate_incremental_both(
    P: np.ndarray,
    points_px: np.ndarray,
    stamps_s: np.ndarray,
    stamp_s: float,
    lambda_t_per_s: float,
    velocities: np.ndarray | None,
    min_views: int = 2,
    row_norm: int = WHOLE_ROW,
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
                                                  lambda_t_per_s, vel, min_views, row_norm)
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
    row_norm: int = WHOLE_ROW,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Eq. (6)-(11) for many points at once, from a flat list of their observations (no missing entries).

    Each observation adds its two weighted rows' outer products to its point's 4x4 normal matrix (eq. 8, 10),
    accumulated by the compiled `triangulate_point`.

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
        row_norm: eq. (11)'s division of the rows (UNIT_ROWS, WHOLE_ROW or PLANE_ROW).

    Returns:
        (paper estimate (N, 3), velocity-compensated estimate (N, 3) or None without velocities); NaN for a
        point with fewer than `min_views` observations.
    """
    return triangulate_observations_robust(P, group, cam, points_px, stamps_s, num_groups, stamp_s, lambda_t_per_s,
                                           velocities, min_views, 0.0, 1.0, row_norm)


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
    reject_factor: float,
    reject_floor_px: float,
    row_norm: int = WHOLE_ROW,
) -> tuple[np.ndarray, np.ndarray | None]:
    """`triangulate_observations`, then once more without the views whose reprojection error exceeds both
    `reject_floor_px` and `reject_factor` times the median error of the point's views (beyond the paper).

    The error of an observation taken at t_i is measured against the estimate moved back to t_i with the
    velocity when velocities are given. A point keeps its first estimate if fewer than `min_views` views
    would remain. Arguments as `triangulate_observations`; reject_factor 0 disables the second pass;
    row_norm UNIT_ROWS leaves out eq. (11)'s division by the row norm (an ablation, Table 4), and λt = 0
    gives every point unit time weight (with it, the conventional DLT over the points).
    """
    P = np.ascontiguousarray(P, dtype=np.float64)
    group = np.asarray(group, dtype=np.int64)
    order = np.argsort(group, kind="stable")
    starts = np.zeros(num_groups + 1, dtype=np.int64)
    np.cumsum(np.bincount(group, minlength=num_groups), out=starts[1:])
    points = np.array(np.asarray(points_px, dtype=np.float64)[order], order="C")
    dts = np.maximum(stamp_s - np.asarray(stamps_s, dtype=np.float64)[order], 0.0)
    use_velocity = velocities is not None
    V = np.array(velocities, dtype=np.float64, order="C") if use_velocity else np.zeros((num_groups, 3))
    plain = np.empty((num_groups, 3))
    compensated = np.empty((num_groups, 3))
    params = TriangulationParams(float(lambda_t_per_s), use_velocity, int(min_views), float(reject_factor),
                                 float(reject_floor_px), int(row_norm))
    _triangulate_groups(P, starts, np.asarray(cam, dtype=np.int64)[order], points, dts, V, params, plain, compensated)
    return plain, compensated if use_velocity else None


@jit
def _triangulate_groups(P, starts, cam, points_px, dts, V, params, plain, compensated):
    """`triangulate_point` for each group of observations cam/points_px/dts[starts[n]:starts[n + 1]], with the
    velocity V[n] (N, 3), into plain and compensated (N, 3) (params: `TriangulationParams`)."""
    work = np.empty((3, 4, 4))
    size = 4
    for n in range(starts.size - 1):
        size = max(size, starts[n + 1] - starts[n])
    cam_n, points_n = np.empty(size, dtype=np.int64), np.empty((size, 2))
    dts_n, decays_n = np.empty(size), np.empty(size)
    scratch = np.empty((4, 8))
    V_n, plain_n, compensated_n = np.empty(3), np.empty(3), np.empty(3)
    observations = Observations(cam_n, points_n, dts_n, decays_n)
    for n in range(starts.size - 1):
        a, num = starts[n], starts[n + 1] - starts[n]
        for i in range(num):
            cam_n[i], points_n[i, 0], points_n[i, 1], dts_n[i] = cam[a + i], points_px[a + i, 0], \
                points_px[a + i, 1], dts[a + i]
            decays_n[i] = np.exp(-2.0 * params.lambda_t_per_s * dts[a + i])
        V_n[0], V_n[1], V_n[2] = V[n, 0], V[n, 1], V[n, 2]
        triangulate_point(P, observations, num, V_n, params, plain_n, compensated_n, work, scratch)
        for k in range(3):
            plain[n, k], compensated[n, k] = plain_n[k], compensated_n[k]


@jit
def triangulate_point(P, observations, num, V, params, plain, compensated, work, scratch):
    """Eq. (6)-(11) for one point from its observations, with the robust second pass (compiled kernel).

    Args:
        P: (C, 3, 4) projection matrices.
        observations: the point's `Observations` (its decays carry the time weights; params.lambda_t_per_s
            is not read); num: how many of them count.
        V: (3,) the point's velocity, m/s (read only when params.use_velocity).
        params: `TriangulationParams`.
        plain, compensated: (3,) outputs, NaN when not determined (compensated untouched without velocity).
        work: (3, 4, 4) and scratch: (4, 8) work space.
    """
    cam, points_px, dts, decays = observations.cam, observations.points_px, observations.dts, observations.decays
    use_velocity, min_views, reject_factor = params.use_velocity, params.min_views, params.reject_factor
    reject_floor_px = params.reject_floor_px
    solve_observations(P, observations, num, V, params, plain, compensated, work, scratch)
    if reject_factor <= 0.0 or num == 0:
        return
    X = compensated if use_velocity else plain
    if not (np.isfinite(X[0]) and np.isfinite(X[1]) and np.isfinite(X[2])):
        return  # no estimate: every error counts zero, nothing is dropped
    err = np.empty(num)
    for i in range(num):
        k = cam[i]
        Xi0, Xi1, Xi2 = X[0], X[1], X[2]
        if use_velocity:  # the estimate moved back to the observation's time t_i
            Xi0, Xi1, Xi2 = Xi0 - V[0] * dts[i], Xi1 - V[1] * dts[i], Xi2 - V[2] * dts[i]
        u = P[k, 0, 0] * Xi0 + P[k, 0, 1] * Xi1 + P[k, 0, 2] * Xi2 + P[k, 0, 3]
        v = P[k, 1, 0] * Xi0 + P[k, 1, 1] * Xi1 + P[k, 1, 2] * Xi2 + P[k, 1, 3]
        w = P[k, 2, 0] * Xi0 + P[k, 2, 1] * Xi1 + P[k, 2, 2] * Xi2 + P[k, 2, 3]
        du, dv = u / w - points_px[i, 0], v / w - points_px[i, 1]
        e = np.sqrt(du * du + dv * dv)
        err[i] = e if np.isfinite(e) else 0.0
    ordered = err.copy()
    sort_prefix(ordered, num)
    median = ordered[(num - 1) // 2]  # lower median
    keep = np.empty(num, dtype=np.int64)
    kept = 0
    for i in range(num):
        if not (err[i] > reject_floor_px and err[i] > reject_factor * median):
            keep[kept] = i
            kept += 1
    if kept == num or kept < min_views:
        return
    cam2, points2, dts2, decays2 = np.empty(kept, dtype=np.int64), np.empty((kept, 2)), np.empty(kept), np.empty(kept)
    for i in range(kept):
        cam2[i], points2[i, 0], points2[i, 1], dts2[i] = cam[keep[i]], points_px[keep[i], 0], points_px[keep[i], 1], \
            dts[keep[i]]
        decays2[i] = decays[keep[i]]
    plain2 = np.empty(3)
    compensated2 = np.empty(3)
    solve_observations(P, Observations(cam2, points2, dts2, decays2), kept, V, params, plain2, compensated2, work,
                        scratch)
    if np.isfinite(plain2[0]):
        plain[:] = plain2
        if use_velocity:
            compensated[:] = compensated2


@jit
def solve_observations(P, observations, num, V, params, plain, compensated, work, scratch):
    """The normal matrices of eq. (8), (10) with the weights of eq. (11) (without its row norms unless
    `params.row_norm`), and their smallest eigenvectors (arguments as `triangulate_point`)."""
    cam, points_px, dts, decays = observations.cam, observations.points_px, observations.dts, observations.decays
    use_velocity, min_views, row_norm = params.use_velocity, params.min_views, params.row_norm
    plain[0] = plain[1] = plain[2] = np.nan
    if use_velocity:
        compensated[0] = compensated[1] = compensated[2] = np.nan
    if num < min_views:
        return
    # The 10 upper-triangle entries of the normal matrix and its moments stay in registers (tuples).
    m0 = m1 = m2 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for i in range(num):
        k = cam[i]
        x0, x1 = points_px[i, 0], points_px[i, 1]
        # Eq. (9): the rows a = x p3 - p1 and b = y p3 - p2.
        a0, a1, a2, a3 = (x0 * P[k, 2, 0] - P[k, 0, 0], x0 * P[k, 2, 1] - P[k, 0, 1], x0 * P[k, 2, 2] - P[k, 0, 2],
                          x0 * P[k, 2, 3] - P[k, 0, 3])
        b0, b1, b2, b3 = (x1 * P[k, 2, 0] - P[k, 1, 0], x1 * P[k, 2, 1] - P[k, 1, 1], x1 * P[k, 2, 2] - P[k, 1, 2],
                          x1 * P[k, 2, 3] - P[k, 1, 3])
        # Eq. (11): squared row weight e^(-2 λt (t - t_i)) / ||r||² (the ablations: without the norm; PLANE_ROW:
        # the norm of the row's first three entries).
        decay = decays[i]
        w0, w1 = decay, decay
        if row_norm != UNIT_ROWS:
            norm_a, norm_b = a0 * a0 + a1 * a1 + a2 * a2, b0 * b0 + b1 * b1 + b2 * b2
            if row_norm == WHOLE_ROW:
                norm_a, norm_b = norm_a + a3 * a3, norm_b + b3 * b3
            w0, w1 = decay / norm_a, decay / norm_b
        # Eq. (8), (10): Σ w² r rᵀ, and with velocities its moments Σ dt_i (.) and Σ dt_i² (.).
        e = (w0 * a0 * a0 + w1 * b0 * b0, w0 * a0 * a1 + w1 * b0 * b1, w0 * a0 * a2 + w1 * b0 * b2,
             w0 * a0 * a3 + w1 * b0 * b3, w0 * a1 * a1 + w1 * b1 * b1, w0 * a1 * a2 + w1 * b1 * b2,
             w0 * a1 * a3 + w1 * b1 * b3, w0 * a2 * a2 + w1 * b2 * b2, w0 * a2 * a3 + w1 * b2 * b3,
             w0 * a3 * a3 + w1 * b3 * b3)
        m0 = _add_scaled(m0, e, 1.0)
        if use_velocity:
            m1 = _add_scaled(m1, e, dts[i])
            m2 = _add_scaled(m2, e, dts[i] * dts[i])
    _set_symmetric(work, 0, m0)
    _set_symmetric(work, 1, m1)
    _set_symmetric(work, 2, m2)
    if not use_velocity:
        smallest_eigenvector_point(work[0], plain, scratch)
        return
    # Beyond the paper: row·[X - V dt_i; 1] = 0, i.e. rows r T_i with T_i = [[I, -V dt_i], [0, 1]], so the
    # normal matrix Σ T_iᵀ A_i T_i follows from the moments Σ A_i, Σ dt_i A_i and Σ dt_i² A_i.
    M, M1, M2 = work[0], work[1], work[2]
    corner = M[3, 3]
    for r in range(3):
        corner -= 2.0 * M1[r, 3] * V[r]
        for s in range(3):
            corner += V[r] * M2[r, s] * V[s]
    for r in range(3):
        col = M[r, 3] - (M1[r, 0] * V[0] + M1[r, 1] * V[1] + M1[r, 2] * V[2])
        M1[r, 3] = col  # M1 is free now: it holds the compensated matrix
        M1[3, r] = col
        for s in range(3):
            M1[r, s] = M[r, s]
    M1[3, 3] = corner
    _smallest_eigenvector_pair(M, M1, plain, compensated, scratch)


@jit
def _add_scaled(s, e, f):
    """s + f e for 10-tuples."""
    return (s[0] + f * e[0], s[1] + f * e[1], s[2] + f * e[2], s[3] + f * e[3], s[4] + f * e[4], s[5] + f * e[5],
            s[6] + f * e[6], s[7] + f * e[7], s[8] + f * e[8], s[9] + f * e[9])


_UPPER_ROW = (0, 0, 0, 0, 1, 1, 1, 2, 2, 3)
_UPPER_COL = (0, 1, 2, 3, 1, 2, 3, 2, 3, 3)


@jit
def _set_symmetric(work, m, upper):
    """work[m] (4, 4) = the symmetric matrix of the 10 upper-triangle entries, row by row."""
    for i in range(10):
        work[m, _UPPER_ROW[i], _UPPER_COL[i]] = upper[i]
        work[m, _UPPER_COL[i], _UPPER_ROW[i]] = upper[i]


@jit
def smallest_eigenvector_point(M, out, scratch):
    """`_smallest_eigenvector` of one 4x4 normal matrix M into out (3,) (compiled kernel).

    Inverse iteration with the Cholesky factor of the regularised M (symmetric positive definite); should
    rounding make it indefinite, its inverse by Gauss-Jordan elimination with partial pivoting in scratch (4, 8).
    """
    out[0] = out[1] = out[2] = np.nan
    L = _regularised_cholesky(M)
    if L[0] > 0.0:
        v = _cholesky_solve(L, 0.0, 0.0, 0.0, 1.0)  # the last column of M⁻¹
        for _ in range(_INVERSE_ITERATIONS):
            v = _cholesky_solve(L, *_normalised(v))
    elif np.isfinite(M[0, 0] + M[1, 1] + M[2, 2] + M[3, 3]):
        v = _inverse_iteration_gauss_jordan(M, 1e-13 * (M[0, 0] + M[1, 1] + M[2, 2] + M[3, 3]), scratch)
    else:
        return
    _dehomogenise(_normalised(v), out)


@jit
def _smallest_eigenvector_pair(M, N, out_m, out_n, scratch):
    """`smallest_eigenvector_point` of M and of N, the two inverse iterations interleaved (two independent
    chains of dependent operations keep the processor busy)."""
    Lm, Ln = _regularised_cholesky(M), _regularised_cholesky(N)
    if not (Lm[0] > 0.0 and Ln[0] > 0.0):
        smallest_eigenvector_point(M, out_m, scratch)
        smallest_eigenvector_point(N, out_n, scratch)
        return
    a, b = _cholesky_solve(Lm, 0.0, 0.0, 0.0, 1.0), _cholesky_solve(Ln, 0.0, 0.0, 0.0, 1.0)
    for _ in range(_INVERSE_ITERATIONS):
        a, b = _cholesky_solve(Lm, *_normalised(a)), _cholesky_solve(Ln, *_normalised(b))
    out_m[0] = out_m[1] = out_m[2] = out_n[0] = out_n[1] = out_n[2] = np.nan
    _dehomogenise(_normalised(a), out_m)
    _dehomogenise(_normalised(b), out_n)


@jit
def _regularised_cholesky(M):
    """`_cholesky` of M + 1e-13 trace(M) I (failed for a non-finite M)."""
    scale = M[0, 0] + M[1, 1] + M[2, 2] + M[3, 3]
    if not np.isfinite(scale):
        return (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    eps = 1e-13 * scale
    return _cholesky(M[0, 0] + eps, M[1, 0], M[1, 1] + eps, M[2, 0], M[2, 1], M[2, 2] + eps, M[3, 0], M[3, 1],
                     M[3, 2], M[3, 3] + eps)


@jit
def _normalised(v):
    """v / ||v|| for a 4-tuple."""
    norm = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3])
    return v[0] / norm, v[1] / norm, v[2] / norm, v[3] / norm


@jit
def _dehomogenise(v, out):
    """out = v[:3] / v[3] unless v[3] ≈ 0 or the result is not finite (out untouched)."""
    if abs(v[3]) < 1e-12:
        return
    x0, x1, x2 = v[0] / v[3], v[1] / v[3], v[2] / v[3]
    if np.isfinite(x0) and np.isfinite(x1) and np.isfinite(x2):
        out[0], out[1], out[2] = x0, x1, x2


@jit
def _cholesky(a00, a10, a11, a20, a21, a22, a30, a31, a32, a33):
    """Lower Cholesky factor of a symmetric 4x4 matrix (lower triangle given row by row), its diagonal stored
    inverted; the first entry is not positive when the matrix is not (numerically) positive definite."""
    fail = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if not a00 > 0.0:
        return fail
    i00 = 1.0 / np.sqrt(a00)
    l10, l20, l30 = a10 * i00, a20 * i00, a30 * i00
    d = a11 - l10 * l10
    if not d > 0.0:
        return fail
    i11 = 1.0 / np.sqrt(d)
    l21, l31 = (a21 - l20 * l10) * i11, (a31 - l30 * l10) * i11
    d = a22 - l20 * l20 - l21 * l21
    if not d > 0.0:
        return fail
    i22 = 1.0 / np.sqrt(d)
    l32 = (a32 - l30 * l20 - l31 * l21) * i22
    d = a33 - l30 * l30 - l31 * l31 - l32 * l32
    if not d > 0.0:
        return fail
    return (i00, l10, i11, l20, l21, i22, l30, l31, l32, 1.0 / np.sqrt(d))


@jit
def _cholesky_solve(L, b0, b1, b2, b3):
    """x with L Lᵀ x = b for a `_cholesky` factor L."""
    i00, l10, i11, l20, l21, i22, l30, l31, l32, i33 = L
    y0 = b0 * i00
    y1 = (b1 - l10 * y0) * i11
    y2 = (b2 - l20 * y0 - l21 * y1) * i22
    y3 = (b3 - l30 * y0 - l31 * y1 - l32 * y2) * i33
    x3 = y3 * i33
    x2 = (y2 - l32 * x3) * i22
    x1 = (y1 - l21 * x2 - l31 * x3) * i11
    x0 = (y0 - l10 * x1 - l20 * x2 - l30 * x3) * i00
    return x0, x1, x2, x3


@jit
def _inverse_iteration_gauss_jordan(M, eps, a):
    """The unnormalised inverse-iteration vector of M + eps I by its explicit inverse (NaN if singular)."""
    for r in range(4):
        for s in range(4):
            a[r, s] = M[r, s]
            a[r, 4 + s] = 0.0
        a[r, r] += eps
        a[r, 4 + r] = 1.0
    for col in range(4):
        pivot = col
        for r in range(col + 1, 4):
            if abs(a[r, col]) > abs(a[pivot, col]):
                pivot = r
        if a[pivot, col] == 0.0:
            return np.nan, np.nan, np.nan, np.nan  # only for M = 0 (no weight)
        if pivot != col:
            for s in range(8):
                a[col, s], a[pivot, s] = a[pivot, s], a[col, s]
        inv_p = 1.0 / a[col, col]
        for s in range(8):
            a[col, s] *= inv_p
        for r in range(4):
            if r != col and a[r, col] != 0.0:
                f = a[r, col]
                for s in range(8):
                    a[r, s] -= f * a[col, s]
    v0, v1, v2, v3 = a[0, 7], a[1, 7], a[2, 7], a[3, 7]  # the last column of M⁻¹: the start [-a⁻¹b; 1] scaled
    for _ in range(_INVERSE_ITERATIONS):
        norm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3)
        v0, v1, v2, v3 = v0 / norm, v1 / norm, v2 / norm, v3 / norm
        v0, v1, v2, v3 = (a[0, 4] * v0 + a[0, 5] * v1 + a[0, 6] * v2 + a[0, 7] * v3,
                          a[1, 4] * v0 + a[1, 5] * v1 + a[1, 6] * v2 + a[1, 7] * v3,
                          a[2, 4] * v0 + a[2, 5] * v1 + a[2, 6] * v2 + a[2, 7] * v3,
                          a[3, 4] * v0 + a[3, 5] * v1 + a[3, 6] * v2 + a[3, 7] * v3)
    return v0, v1, v2, v3


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
