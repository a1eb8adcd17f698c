"""Triangulation: DLT round trip, eq. (11) weights by hand, incremental = standard when stamps agree,
and the velocity-compensated variant."""

import numpy as np
import pytest

from tests.reference.plain import plain_python
from tests.tracker.synthetic import ceiling_rig
from tracker.geometry import project
from tracker.triangulation import (
    PLANE_ROW,
    UNIT_ROWS,
    WHOLE_ROW,
    TriangulationParams,
    _inverse_iteration_gauss_jordan,
    _triangulate_groups,
    dlt_rows,
    smallest_eigenvector_point,
    triangulate,
    triangulate_incremental,
    triangulate_observations,
    triangulate_observations_robust,
)


@pytest.fixture(scope="module")
def rig():
    cams = ceiling_rig(6, 5.0, 4.0)
    return np.stack([c.P for c in cams])


def _reference_dlt(P, x, weights=None, normalize=True):
    """Independent per-point DLT: stack the two rows of eq. (9) per view (each divided by its norm unless
    `normalize` is False; by the norm of its first three entries when it is "plane"), SVD, dehomogenise."""
    rows = []
    for c in range(len(P)):
        if np.isnan(x[c]).any():
            continue
        r1 = x[c, 0] * P[c, 2] - P[c, 0]
        r2 = x[c, 1] * P[c, 2] - P[c, 1]
        w = 1.0 if weights is None else weights[c]
        n1, n2 = (np.linalg.norm(r1), np.linalg.norm(r2)) if normalize else (1.0, 1.0)
        if normalize == "plane":
            n1, n2 = np.linalg.norm(r1[:3]), np.linalg.norm(r2[:3])
        rows += [w * r1 / n1, w * r2 / n2]
    _, _, vt = np.linalg.svd(np.array(rows))
    return vt[-1, :3] / vt[-1, 3]


def test_triangulate_inverts_projection(rig):
    X = np.random.default_rng(1).uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (20, 3))
    x = np.moveaxis(project(rig, X), 0, 1)  # (N, C, 2)
    np.testing.assert_allclose(triangulate(rig, x), X, atol=1e-7)  # m
    np.testing.assert_allclose(triangulate(rig, x, row_norm=UNIT_ROWS), X, atol=1e-7)  # m
    np.testing.assert_allclose(triangulate(rig, x, row_norm=PLANE_ROW), X, atol=1e-7)  # m


def test_triangulate_matches_an_independent_svd_with_noise_and_missing_views(rig):
    rng = np.random.default_rng(2)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (10, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0, 3.0, (10, len(rig), 2))
    x[0, :3] = np.nan
    got = triangulate(rig, x)
    for i in range(len(X)):
        np.testing.assert_allclose(got[i], _reference_dlt(rig, x[i]), atol=1e-8)  # m


def test_fewer_than_two_views_give_nan(rig):
    x = np.moveaxis(project(rig, np.array([[2.0, 2.0, 1.0]])), 0, 1)
    x[0, 1:] = np.nan
    assert np.isnan(triangulate(rig, x)).all()


def test_incremental_equals_standard_dlt_when_all_stamps_are_equal(rig):
    rng = np.random.default_rng(3)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (10, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0, 2.0, (10, len(rig), 2))
    stamps = np.full((10, len(rig)), 7.5)
    np.testing.assert_allclose(triangulate_incremental(rig, x, stamps, 7.5, 10.0), triangulate(rig, x), atol=1e-9)


def test_incremental_weights_match_an_independent_weighted_svd(rig):
    rng = np.random.default_rng(4)
    X = np.array([2.0, 1.5, 1.0])
    x = project(rig, X) + rng.normal(0, 2.0, (len(rig), 2))
    stamps = 1.0 - rng.uniform(0, 0.3, len(rig))
    got = triangulate_incremental(rig, x, stamps, 1.0, 10.0)
    np.testing.assert_allclose(got, _reference_dlt(rig, x, np.exp(-10.0 * (1.0 - stamps))), atol=1e-8)


_CODE = {False: UNIT_ROWS, True: WHOLE_ROW, "plane": PLANE_ROW}


@pytest.mark.parametrize("lambda_t, normalize", [(10.0, False), (0.0, False), (0.0, True), (10.0, "plane"),
                                                 (0.0, "plane")])
def test_the_ablations_weights_match_an_independent_svd(rig, lambda_t, normalize):
    # Table 4's "w/o norm" (λt, no row norms), the conventional DLT (unit weights, λt = 0) and the plane norm,
    # point by point.
    rng = np.random.default_rng(9)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (5, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0.0, 2.0, (5, len(rig), 2))
    stamps = 1.0 - rng.uniform(0.0, 0.3, (5, len(rig)))
    got, _ = triangulate_observations_robust(rig, *_flat(x, stamps), 5, 1.0, lambda_t, None, 2, 0.0, 10.0,
                                             row_norm=_CODE[normalize])
    for n in range(5):
        expected = _reference_dlt(rig, x[n], np.exp(-lambda_t * (1.0 - stamps[n])), normalize=normalize)
        np.testing.assert_allclose(got[n], expected, atol=1e-7)  # m
    if lambda_t == 0.0:
        np.testing.assert_allclose(got, triangulate(rig, x, row_norm=_CODE[normalize]), atol=1e-7)  # m


def test_the_plane_norm_does_not_depend_on_where_the_world_origin_is(rig):
    # The same rig and noisy points with the world origin moved 40 m away (a corner of a large store): with
    # the plane norm the estimates move with the origin (within a millimetre: the solve's unit-norm constraint
    # on X̃ is not quite free of the origin); with eq. (11)'s whole-row norm they move 5 cm more, because the
    # rows' constant terms, and so their weights, change with the cameras' distance from the origin.
    rng = np.random.default_rng(11)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (20, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0.0, 3.0, (20, len(rig), 2))
    shift = np.array([-40.0, 25.0, 0.0])  # world' = world + shift
    moved = rig.copy()
    moved[:, :, 3] -= rig[:, :, :3] @ shift  # P' [X + shift; 1] = P [X; 1]
    moved_by = {}
    for code in (PLANE_ROW, WHOLE_ROW):
        here, there = triangulate(rig, x, row_norm=code), triangulate(moved, x, row_norm=code)
        moved_by[code] = np.abs(there - shift - here).max()
    assert moved_by[PLANE_ROW] < 0.001 and moved_by[WHOLE_ROW] > 0.02, moved_by  # m


def test_stale_views_pull_the_paper_estimate_back_and_velocity_compensation_removes_it(rig):
    # A point moving at 1.4 m/s: the newest view at t = 1, the others up to 0.1 s older.
    V = np.array([1.4, 0.0, 0.0])
    X1 = np.array([2.0, 2.0, 1.0])
    stamps = 1.0 - np.linspace(0.0, 0.1, len(rig))
    x = np.stack([project(rig[c], X1 - V * (1.0 - stamps[c])) for c in range(len(rig))])
    paper = triangulate_incremental(rig, x, stamps, 1.0, 5.0)
    compensated = triangulate_incremental(rig, x, stamps, 1.0, 5.0, velocities=V)
    assert np.linalg.norm(paper - X1) > 0.02  # m: the stale points lag
    np.testing.assert_allclose(compensated, X1, atol=1e-7)  # m: exact with the true velocity


def test_rows_are_those_of_eq_9(rig):
    x = np.array([[10.0, 20.0]])
    rows = dlt_rows(rig[:1], x)
    np.testing.assert_allclose(rows[0, 0], 10.0 * rig[0, 2] - rig[0, 0])
    np.testing.assert_allclose(rows[0, 1], 20.0 * rig[0, 2] - rig[0, 1])


def _flat(x, stamps):
    """Flat observation list (group, cam, px, stamps) of (N, C, 2) points, NaN missing."""
    group, cam = np.nonzero(np.isfinite(x[..., 0]))
    return group, cam, x[group, cam], stamps[group, cam]


def test_flat_observations_match_the_padded_incremental_dlt_with_velocities(rig):
    rng = np.random.default_rng(5)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (12, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0.0, 1.0, (12, len(rig), 2))
    x[rng.random((12, len(rig))) < 0.3] = np.nan
    stamps = 2.0 - rng.uniform(0.0, 0.2, (12, len(rig)))
    V = rng.normal(0.0, 1.0, (12, 3))
    plain, compensated = triangulate_observations(rig, *_flat(x, stamps), 12, 2.0, 5.0, V)
    np.testing.assert_allclose(plain, triangulate_incremental(rig, x, stamps, 2.0, 5.0), atol=1e-8)  # m
    np.testing.assert_allclose(compensated, triangulate_incremental(rig, x, stamps, 2.0, 5.0, velocities=V),
                               atol=1e-8)  # m


def test_robust_pass_is_the_dlt_of_the_views_within_the_rejection_rule(rig):
    rng = np.random.default_rng(6)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (8, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0.0, 0.5, (8, len(rig), 2))
    x[:, 2] += 30.0  # one view 30 px off for every point
    stamps = np.full((8, len(rig)), 1.0)
    got, _ = triangulate_observations_robust(rig, *_flat(x, stamps), 8, 1.0, 5.0, None, 2, 3.0, 10.0)
    first = np.stack([_reference_dlt(rig, p) for p in x])
    errors = np.stack([np.linalg.norm(project(rig, p)[:, :2] - xp, axis=-1) for p, xp in zip(first, x)])  # (N, C)
    median = np.sort(errors, axis=1)[:, (len(rig) - 1) // 2]  # lower median
    drop = (errors > 10.0) & (errors > 3.0 * median[:, None])
    assert drop[:, 2].sum() >= 2 and drop.any(axis=1).sum() < 8  # the rule bites on some points only
    kept = np.where(drop[..., None], np.nan, x)
    np.testing.assert_allclose(got, np.stack([_reference_dlt(rig, p) for p in kept]), atol=1e-7)  # m
    off, _ = triangulate_observations_robust(rig, *_flat(x, stamps), 8, 1.0, 5.0, None, 2, 0.0, 10.0)
    np.testing.assert_allclose(off, first, atol=1e-8)  # m


def test_a_stale_point_is_judged_against_its_prediction_not_against_the_present(rig):
    # A joint walking at 1.5 m/s seen by six cameras, each at its own time up to 0.2 s before t: their points
    # lie up to 0.3 m (tens of pixels) from the joint's place at t, but each where X(t) - V (t - t_i) projects.
    rng = np.random.default_rng(9)
    X = np.array([2.5, 2.0, 1.2])  # m, at t = 1
    V = np.array([1.5, 0.0, 0.0])  # m/s
    dts = np.array([0.0, 0.05, 0.1, 0.15, 0.2, 0.0])  # s
    at_capture = X - V * dts[:, None]
    x = np.stack([project(rig[c:c + 1], at_capture[c])[0, :2] for c in range(len(rig))])
    x = x + rng.normal(0.0, 0.5, x.shape)
    group, cam, stamps = np.zeros(len(rig), dtype=np.int64), np.arange(len(rig)), 1.0 - dts

    def robust(points, factor):
        return triangulate_observations_robust(rig, group, cam, points, stamps, 1, 1.0, 5.0, V[None], 2, factor,
                                               10.0, PLANE_ROW)[1][0]

    # Every point agrees with its prediction: the rejection drops none of them, stale or not.
    np.testing.assert_array_equal(robust(x, 3.0), robust(x, 0.0))
    np.testing.assert_allclose(robust(x, 3.0), X, atol=0.02)  # m
    # The stalest point 100 px beyond its prediction is dropped: the estimate is the other five views'.
    off = x.copy()
    off[4] += [100.0, 0.0]
    np.testing.assert_allclose(robust(off, 3.0), _without_view(rig, x, stamps, V, 4), atol=1e-9)  # m
    assert np.linalg.norm(robust(off, 0.0) - X) > 2 * np.linalg.norm(robust(off, 3.0) - X)


def _without_view(rig, x, stamps, V, dropped):
    """The velocity-compensated estimate of one point from every view but `dropped`, without rejection."""
    keep = np.arange(len(rig)) != dropped
    return triangulate_observations_robust(rig, np.zeros(keep.sum(), dtype=np.int64), np.arange(len(rig))[keep],
                                           x[keep], stamps[keep], 1, 1.0, 5.0, V[None], 2, 0.0, 10.0,
                                           PLANE_ROW)[1][0]


def test_compiled_smallest_eigenvector_matches_an_eigendecomposition_on_either_path():
    rng = np.random.default_rng(7)
    for _ in range(20):
        X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9])
        rows = rng.normal(size=(8, 4))
        rows -= np.outer(rows @ np.append(X, 1.0), np.append(X, 1.0)) / (np.sum(X * X) + 1.0)  # rows ⟂ [X; 1]
        rows += rng.normal(0.0, 1e-4, rows.shape)  # noise
        M = rows.T @ rows
        v = np.linalg.eigh(M)[1][:, 0]
        expected = v[:3] / v[3]
        out = np.empty(3)
        smallest_eigenvector_point(M, out, np.empty((4, 8)))
        np.testing.assert_allclose(out, expected, atol=1e-9)  # m
        # The Gauss-Jordan fallback (used when rounding makes the Cholesky factor fail) agrees.
        fallback = np.array(_inverse_iteration_gauss_jordan(M, 1e-13 * np.trace(M), np.empty((4, 8))))
        np.testing.assert_allclose(fallback[:3] / fallback[3], expected, atol=1e-9)  # m
    # No weight at all: no point.
    smallest_eigenvector_point(np.zeros((4, 4)), out, np.empty((4, 8)))
    assert np.isnan(out).all()


@pytest.mark.parametrize("velocity", [False, True])
def test_compiled_triangulation_runs_the_same_as_plain_python(rig, velocity):
    rng = np.random.default_rng(8)
    X = rng.uniform([0.5, 0.5, 0.1], [4.5, 3.5, 1.9], (6, 3))
    x = np.moveaxis(project(rig, X), 0, 1) + rng.normal(0.0, 1.0, (6, len(rig), 2))
    x[:, 1] += 40.0  # one view far off, so that the robust pass drops it
    x[rng.random((6, len(rig))) < 0.2] = np.nan
    group, cam, px, stamps = _flat(x, 1.0 - rng.uniform(0.0, 0.2, (6, len(rig))))
    order = np.argsort(group, kind="stable")
    starts = np.concatenate([[0], np.cumsum(np.bincount(group, minlength=6))])
    V = rng.normal(0.0, 1.0, (6, 3))
    outputs = []
    for kernel in (_triangulate_groups, plain_python(_triangulate_groups)):
        plain, compensated = np.empty((6, 3)), np.empty((6, 3))
        params = TriangulationParams(lambda_t_per_s=5.0, use_velocity=velocity, min_views=2, reject_factor=3.0,
                                     reject_floor_px=10.0, row_norm=PLANE_ROW if velocity else WHOLE_ROW)
        kernel(rig, starts, cam[order], px[order], np.maximum(1.0 - stamps[order], 0.0), V, params, plain,
               compensated)
        outputs.append(plain if not velocity else compensated)
    np.testing.assert_allclose(outputs[0], outputs[1], atol=1e-12)  # m
    assert np.isfinite(outputs[0]).all()
