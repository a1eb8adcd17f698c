"""Initialisation: graph partitioning (S3-S5) against brute force, cycle consistency, plausibility."""

import itertools

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from core.types import COCO17
from tests.reference.partition import greedy_partition
from tests.tracker.synthetic import look_at_camera
from tracker.initialization import (
    PlausibilityLimits,
    _branch_and_bound,
    _component_labels,
    _partition_branch_and_bound,
    _partition_greedy,
    _partition_milp,
    check_plausible,
    consensus_views,
    partition_graph,
)


def _set_partitions(items):
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for part in _set_partitions(rest):
        for i in range(len(part)):
            yield part[:i] + [[first] + part[i]] + part[i + 1:]
        yield [[first]] + part


def _objective(A, clusters):
    total = 0.0
    for c in clusters:
        for i, j in itertools.combinations(sorted(c), 2):
            total += A[i, j]
    return total


def _random_problem(rng, n, cams):
    camera = rng.integers(0, cams, n)
    A = rng.normal(0.0, 1.0, (n, n))
    A = (A + A.T) / 2
    A[camera[:, None] == camera[None, :]] = -np.inf
    return A


def test_exact_partition_matches_brute_force_optimum():
    rng = np.random.default_rng(0)
    for _ in range(20):
        A = _random_problem(rng, 6, 3)
        best = max(_objective(A, p) for p in _set_partitions(list(range(6))))
        got = partition_graph(A, max_exact_nodes=10)  # connected parts enumerated
        assert _objective(A, got) == pytest.approx(best)
        assert _objective(A, _partition_milp(A)) == pytest.approx(best)  # the solver used above six nodes


def test_branch_and_bound_matches_brute_force_and_milp():
    rng = np.random.default_rng(7)
    for n, cams, shift in ((7, 4, 0.0), (8, 5, 0.8), (8, 8, 0.3)):
        for _ in range(4):
            A = _random_problem(rng, n, cams) + shift
            best = max(_objective(A, p) for p in _set_partitions(list(range(n))))
            assert _objective(A, _partition_branch_and_bound(A)) == pytest.approx(best)
    for _ in range(5):  # beyond brute force: against milp
        A = _random_problem(rng, 12, 6) + 0.5
        assert _objective(A, _partition_branch_and_bound(A)) == pytest.approx(_objective(A, _partition_milp(A)))
        assert _objective(A, partition_graph(A, max_exact_nodes=14)) == pytest.approx(_objective(A, _partition_milp(A)))


def test_branch_and_bound_plain_python_agrees_and_gives_up_past_its_budget():
    rng = np.random.default_rng(8)
    A = _random_problem(rng, 9, 9) + 0.2
    w = np.where(np.isfinite(A), A, -np.inf)
    labels_c, labels_p = np.zeros(9, dtype=np.int64), np.zeros(9, dtype=np.int64)
    assert _branch_and_bound(w, -np.inf, labels_c, 10**7) and _branch_and_bound.py_func(w, -np.inf, labels_p, 10**7)
    np.testing.assert_array_equal(labels_c, labels_p)
    assert not _branch_and_bound(w, -np.inf, labels_c, 5)


def test_mostly_positive_problems_and_their_all_positive_components_stay_exact():
    rng = np.random.default_rng(1)
    for _ in range(30):
        A = _random_problem(rng, 6, 4) + 1.2  # most pairs positive: many components are all-positive cliques
        best = max(_objective(A, p) for p in _set_partitions(list(range(6))))
        assert _objective(A, partition_graph(A, max_exact_nodes=10)) == pytest.approx(best)


def test_component_labels_agree_with_scipy():
    rng = np.random.default_rng(2)
    for n in (1, 2, 5, 12, 30):
        for density in (0.0, 0.05, 0.2):
            upper = np.triu(rng.random((n, n)) < density, 1)
            adjacency = upper | upper.T
            count, expected = connected_components(adjacency.astype(int), directed=False)
            got = _component_labels(adjacency)
            assert np.unique(got).size == count
            # Same partition: the labels map one to one.
            assert len({(int(a), int(b)) for a, b in zip(got, expected)}) == count


def test_greedy_fallback_is_feasible_and_never_better_than_exact():
    rng = np.random.default_rng(1)
    for _ in range(10):
        A = _random_problem(rng, 7, 4)
        exact = partition_graph(A, max_exact_nodes=10)
        greedy = partition_graph(A, max_exact_nodes=2)
        assert np.isfinite(_objective(A, greedy))
        assert _objective(A, greedy) <= _objective(A, exact) + 1e-9


def test_cycle_consistency_beats_pairwise_matching():
    # i-j and j-k are good matches but i and k are incompatible: the best consistent answer keeps
    # one pair (eq. S5 forbids y_ij = y_jk = 1 with y_ik = 0).
    A = np.array([[0.0, 1.0, -5.0], [1.0, 0.0, 0.8], [-5.0, 0.8, 0.0]])
    clusters = sorted(sorted(c.tolist()) for c in partition_graph(A))
    assert clusters == [[0, 1], [2]]


def test_partition_covers_every_node_once_and_never_joins_one_camera():
    rng = np.random.default_rng(2)
    A = _random_problem(rng, 9, 3)
    for clusters in (partition_graph(A), [np.asarray(c) for c in _partition_greedy(A)]):
        nodes = np.sort(np.concatenate(clusters))
        np.testing.assert_array_equal(nodes, np.arange(9))
        for c in clusters:
            for i, j in itertools.combinations(c, 2):
                assert np.isfinite(A[i, j])


def test_two_clear_people_in_three_cameras():
    # Nodes 0-2: person a in cameras 0, 1, 2; nodes 3-5: person b in the same cameras.
    cam = np.array([0, 1, 2, 0, 1, 2])
    same = np.array([0, 0, 0, 1, 1, 1])
    A = np.where(same[:, None] == same[None, :], 0.8, -0.7)
    A[cam[:, None] == cam[None, :]] = -np.inf
    clusters = sorted(sorted(c.tolist()) for c in partition_graph(A))
    assert clusters == [[0, 1, 2], [3, 4, 5]]


LIMITS = PlausibilityLimits(max_reprojection_px=10.0, min_joints_3d=6, max_bone_m=1.0, min_top_m=0.4,
                            max_top_m=2.6, min_bottom_m=-0.5)


def _standing():
    from tests.tracker.synthetic import _REST

    return _REST + np.array([2.0, 2.0, 0.0])


def _views(pose):
    from tests.tracker.synthetic import ceiling_rig
    from tracker.geometry import project

    P = np.stack([c.P for c in ceiling_rig(3, 4.0, 4.0)])
    return P, project(P, pose)


def test_plausible_person_passes():
    pose = _standing()
    P, x = _views(pose)
    assert check_plausible(pose, P, x, COCO17, LIMITS) is None


@pytest.mark.parametrize("change, reason", [
    (lambda p: p + np.array([0.0, 0.0, 3.0]), "top joint"),
    (lambda p: np.concatenate([p[:15], p[15:] - np.array([0.0, 0.0, 1.5])]), "bone"),
    (lambda p: p * np.array([1.0, 1.0, 0.1]), "top joint"),
])
def test_implausible_people_are_rejected(change, reason):
    pose = change(_standing())
    P, x = _views(pose)
    assert reason in check_plausible(pose, P, x, COCO17, LIMITS)


def test_reprojection_error_is_checked():
    pose = _standing()
    P, x = _views(pose)
    assert "reprojection" in check_plausible(pose + np.array([0.3, 0.0, 0.0]), P, x, COCO17, LIMITS)


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_greedy_merge_equals_the_plain_one(seed):
    """The same clusters as numpy's argmax loop, ties and forbidden pairs included, at sizes up to a crowd's."""
    rng = np.random.default_rng(seed)
    n = [5, 17, 40, 120, 250, 400][seed]
    A = np.round(rng.normal(0.0, 1.0, (n, n)), 1)  # rounded: many equal totals, so ties are exercised
    A = (A + A.T) / 2
    cams = rng.integers(0, max(2, n // 3), n)
    A[cams[:, None] == cams[None, :]] = -np.inf
    got = _partition_greedy(A)
    want = greedy_partition(A)
    assert [c.tolist() for c in got] == [c.tolist() for c in want]


def test_consensus_keeps_the_views_that_agree_on_where_the_person_is():
    """A detection's true views from four cameras place it in one spot; views of two other people who lie on
    its ray (in front of and behind it) place it elsewhere along the ray: only the true ones are kept."""
    person = np.array([1.0, 0.5, 1.0])
    cams = [look_at_camera(f"c{k}", [5.0 * np.cos(k), 5.0 * np.sin(k), 3.0], [0.0, 0.0, 1.0]) for k in range(7)]
    J = 6
    offsets = np.linspace(-0.4, 0.4, J)[:, None] * np.array([0.0, 0.0, 1.0])
    origin = cams[0].center_world
    rays = person + offsets - origin
    # others on the detection's rays, 1.5 m nearer and 2 m farther along them
    others = [origin + 0.55 * (person - origin) + offsets, origin + 1.6 * (person - origin) + offsets]
    bodies = [person + offsets] * 4 + others
    origins = np.stack([cams[k].center_world for k in range(1, 7)])
    candidate_rays = np.stack([body - o for body, o in zip(bodies, origins)])
    candidate_rays[1, :2] = np.nan  # a view missing two joints still places the person
    affinity = np.array([0.6, 0.5, 0.7, 0.4, 0.95, 0.9])  # the other people match the epipolar lines best
    keep = consensus_views(origin, rays, origins, candidate_rays, affinity, 3, 0.5)
    assert keep.tolist() == [True, True, True, True, False, False]
    candidate_rays[1, 3:] = np.nan  # now it shares only three joints... then two: it places nothing
    keep = consensus_views(origin, rays, origins, candidate_rays, affinity, 3, 0.5)
    assert keep.tolist() == [True, False, True, True, False, False]
