"""Target initialisation (supplement): cross-view clustering of unmatched detections by epipolar affinity
(eq. S1-S2) and graph partitioning with cycle consistency (eq. S3-S5), then a plausibility check.

Graph partitioning. The objective of eq. (S3) never gains from joining two groups of detections that share
no positive affinity, so the problem splits exactly into the connected components of the positive-affinity
graph. A component of at most `max_exact_nodes` detections is solved exactly as the binary integer program
(S3)-(S5) with `scipy.optimize.milp` (HiGHS). A larger component falls back to the greedy merge that
correlation-clustering solvers use as a start: begin with singletons and repeatedly join the two clusters
with the largest positive total affinity between them, never joining two detections of one camera (their
affinity is -inf, Algorithm S1). The greedy result is cycle-consistent by construction but may be suboptimal.
A component whose every pair has a positive affinity (two detections joined by one edge, most often) is
one cluster without a solver: joining all of it takes every term of (S3) and breaks no (S5). A component of
up to `ENUMERATE_MAX_NODES` detections is solved exactly by scoring every partition of it at once (203 for
six), which is what milp would return at a hundredth of its set-up cost (ties aside). A larger component
(up to `max_exact_nodes`) is solved exactly by a compiled branch and bound over its partitions, started from
the greedy merge's value and bounded by the positive affinities not yet placed; milp takes over only when
that search runs past `BRANCH_AND_BOUND_MAX_STEPS` (a crowd puts one person in ten or more views at once,
where milp's set-up alone cost more than the whole search).
"""

from __future__ import annotations

import functools
import itertools
import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_matrix

from core.jit import jit
from core.types import Skeleton
from tracker.triangulation import WHOLE_ROW, reprojection_error_px, triangulate_incremental

logger = logging.getLogger(__name__)

ENUMERATE_MAX_NODES = 6
"""Components up to this many detections are solved by enumerating their partitions instead of milp."""

BRANCH_AND_BOUND_MAX_STEPS = 200_000
"""Branching steps the exact search may take on one component before milp solves it instead."""


def partition_graph(affinity: np.ndarray, max_exact_nodes: int = 14) -> list[np.ndarray]:
    """Eq. (S3)-(S5): clusters of nodes maximising the total within-cluster affinity, cycle-consistent.

    Args:
        affinity: (n, n) symmetric affinity a_ij; -inf forbids i and j in one cluster (same camera).
        max_exact_nodes: components up to this size are solved exactly (milp), larger ones greedily.

    Returns:
        Clusters as sorted int arrays of node indices, singletons included, covering every node once.
    """
    a = np.asarray(affinity, dtype=np.float64)
    n = a.shape[0]
    if n == 0:
        return []
    positive = np.isfinite(a) & (a > 0)
    np.fill_diagonal(positive, False)
    labels = _component_labels(positive)
    clusters: list[np.ndarray] = []
    for comp in np.unique(labels):
        nodes = np.flatnonzero(labels == comp)
        if nodes.size == 1:
            clusters.append(nodes)
            continue
        sub = a[np.ix_(nodes, nodes)]
        if positive[np.ix_(nodes, nodes)].sum() == nodes.size * (nodes.size - 1):
            clusters.append(nodes)  # all pairs positive: the whole component is the optimum of (S3)-(S5)
            continue
        parts = None
        if nodes.size <= min(max_exact_nodes, ENUMERATE_MAX_NODES):
            parts = _partition_enumerated(sub)
        elif nodes.size <= max_exact_nodes:
            parts = _partition_branch_and_bound(sub)
            if parts is None:
                parts = _partition_milp(sub)
        if parts is None:
            parts = _partition_greedy(sub)
        clusters.extend(nodes[p] for p in parts)
    return clusters


def _component_labels(adjacency: np.ndarray) -> np.ndarray:
    """(n,) connected-component label of each node (the smallest node index in its component).

    Label propagation on the dense (n, n) bool adjacency: a few numpy steps for the tens of detections of a
    store, where building a sparse graph for scipy's `connected_components` costs more than the search.
    """
    labels = np.arange(adjacency.shape[0])
    while True:
        new = np.min(np.where(adjacency, labels[None, :], labels[:, None]), axis=1)
        new = new[new]  # jump along the chain: a node takes its new label's label
        if np.array_equal(new, labels):
            return labels
        labels = new


@functools.cache
def _partitions(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every partition of n nodes: ((P, n) cluster label per node, (P, n(n-1)/2) same-cluster mask per pair)."""
    labelings = [[0]]
    for _ in range(n - 1):  # restricted growth strings: node k joins a used cluster or opens the next one
        labelings = [lab + [c] for lab in labelings for c in range(max(lab) + 2)]
    labels = np.array(labelings, dtype=np.int64).reshape(-1, n)
    iu, ju = np.triu_indices(n, 1)
    return labels, labels[:, iu] == labels[:, ju]


def _partition_enumerated(a: np.ndarray) -> list[np.ndarray]:
    """Exact (S3)-(S5) on a small component: the best of all its partitions (cycle-consistent by definition)."""
    n = a.shape[0]
    labels, together = _partitions(n)
    iu, ju = np.triu_indices(n, 1)
    weights = a[iu, ju]
    forbidden = ~np.isfinite(weights)
    objective = together @ np.where(forbidden, 0.0, weights)  # (S3) of every partition
    objective[together[:, forbidden].any(axis=1)] = -np.inf  # one camera twice in a cluster
    best = labels[int(np.argmax(objective))]
    return [np.flatnonzero(best == c) for c in range(best.max() + 1)]


def _objective(a: np.ndarray, parts: list[np.ndarray]) -> float:
    """(S3): the total affinity within the clusters of a partition."""
    total = 0.0
    for p in parts:
        sub = a[np.ix_(p, p)]
        total += float(np.sum(np.triu(sub, 1)))
    return total


def _partition_branch_and_bound(a: np.ndarray) -> list[np.ndarray] | None:
    """Exact (S3)-(S5) on one component by branch and bound; None if it needs more than
    `BRANCH_AND_BOUND_MAX_STEPS` steps. Starts from the greedy merge, which it returns when nothing beats it."""
    greedy = _partition_greedy(a)
    n = a.shape[0]
    labels = np.empty(n, dtype=np.int64)
    for c, p in enumerate(greedy):
        labels[p] = c
    w = np.where(np.isfinite(a), a, -np.inf).astype(np.float64)
    solved = _branch_and_bound(np.ascontiguousarray(w), _objective(a, greedy), labels, BRANCH_AND_BOUND_MAX_STEPS)
    if not solved:
        return None
    return [np.flatnonzero(labels == c) for c in np.unique(labels)]


@jit
def _branch_and_bound(w, best_value, best_labels, max_steps):
    """Depth-first search over the partitions of n nodes (node k joins one of the clusters of nodes 0..k-1 or
    opens the next), pruning a branch whose value plus every positive affinity still to place cannot beat
    `best_value`; a cluster holding a -inf pair (one camera twice) is never formed. Writes the best labels
    found into `best_labels` (left alone when nothing beats `best_value`); returns whether the search ended
    within `max_steps`."""
    n = w.shape[0]
    bound = np.zeros(n + 1)  # bound[k]: the positive affinities between node j >= k and the nodes before it
    for j in range(n - 1, -1, -1):
        s = 0.0
        for i in range(j):
            if w[i, j] > 0.0:
                s += w[i, j]
        bound[j] = bound[j + 1] + s
    labels = np.full(n, -1, dtype=np.int64)
    value = np.zeros(n + 1)  # value[k]: (S3) of nodes 0..k-1 as labelled
    used = np.zeros(n + 1, dtype=np.int64)  # used[k]: clusters opened by nodes 0..k-1
    labels[0] = 0
    used[1] = 1
    k = 1
    steps = 0
    while k >= 1:
        if k == n:
            if value[n] > best_value:
                best_value = value[n]
                best_labels[:] = labels
            k -= 1
            continue
        c = labels[k] + 1
        advanced = False
        while c <= used[k]:
            steps += 1
            gain = 0.0
            allowed = True
            for i in range(k):
                if labels[i] == c:
                    if w[i, k] == -np.inf:
                        allowed = False
                        break
                    gain += w[i, k]
            if allowed and value[k] + gain + bound[k + 1] > best_value:
                labels[k] = c
                value[k + 1] = value[k] + gain
                used[k + 1] = max(used[k], c + 1)
                k += 1
                if k < n:
                    labels[k] = -1
                advanced = True
                break
            c += 1
        if not advanced:
            labels[k] = -1
            k -= 1
        if steps > max_steps:
            return False
    return True


def _partition_milp(a: np.ndarray) -> list[np.ndarray] | None:
    """Exact (S3)-(S5) on one component; None if the solver does not report an optimum."""
    n = a.shape[0]
    iu, ju = np.triu_indices(n, 1)
    index = -np.ones((n, n), dtype=np.int64)
    index[iu, ju] = np.arange(iu.size)
    index[ju, iu] = index[iu, ju]
    weights = a[iu, ju]
    forbidden = ~np.isfinite(weights)
    # (S3): maximise Σ a_ij y_ij  ->  minimise -Σ a_ij y_ij; forbidden pairs are fixed to 0 by their bound.
    cost = -np.where(forbidden, 0.0, weights)
    upper = np.where(forbidden, 0.0, 1.0)
    # (S5): y_ij + y_jk - y_ik <= 1 for every triple, in all three rotations.
    i, j, k = np.array(list(itertools.combinations(range(n), 3)), dtype=np.int64).reshape(-1, 3).T
    rows, cols, vals = [], [], []
    for r, (p, q, s) in enumerate([(i, j, k), (j, k, i), (k, i, j)]):
        base = r * i.size + np.arange(i.size)
        rows += [base, base, base]
        cols += [index[p, q], index[q, s], index[p, s]]
        vals += [np.ones(i.size), np.ones(i.size), -np.ones(i.size)]
    constraints = []
    if i.size:
        A = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(3 * i.size, iu.size)).tocsr()
        constraints.append(LinearConstraint(A, -np.inf, 1.0))
    result = milp(cost, constraints=constraints, integrality=np.ones(iu.size), bounds=Bounds(0.0, upper))
    if result.status != 0 or result.x is None:
        logger.warning("graph partitioning: milp did not solve a %d-node component (%s); using greedy",
                       n, result.message)
        return None
    y = result.x > 0.5
    together = np.zeros((n, n), dtype=bool)
    together[iu[y], ju[y]] = True
    labels = _component_labels(together | together.T)
    return [np.flatnonzero(labels == c) for c in np.unique(labels)]


def _partition_greedy(a: np.ndarray) -> list[np.ndarray]:
    """Greedy agglomeration: join the pair of clusters with the largest positive total affinity (the first
    such pair in row-major order on ties), until no pair has a positive one.

    Non-finite affinities (a shared camera) forbid the pair for good: -inf stays -inf under sums.
    """
    n = a.shape[0]
    S = np.where(np.isfinite(a), a, -np.inf).astype(np.float64)
    labels = np.arange(n, dtype=np.int64)
    _greedy_merge(S, labels)
    return [np.flatnonzero(labels == c) for c in np.unique(labels)]


@jit
def _greedy_merge(S, labels):
    """`_partition_greedy` in place: S (n, n) the affinities between the current clusters (-inf: never),
    labels (n,) each node's cluster, the smallest node index of it when done.

    Each row keeps its largest entry (and the first column holding it), so a merge costs one pass over the
    rows plus a rescan of the few rows whose largest entry was one of the two merged clusters.
    """
    n = S.shape[0]
    for i in range(n):
        S[i, i] = -np.inf
    best = np.empty(n)
    best_col = np.zeros(n, dtype=np.int64)
    alive = np.ones(n, dtype=np.bool_)
    for i in range(n):
        _row_best(S, i, best, best_col)
    while True:
        x = -1
        top = 0.0
        for i in range(n):
            if alive[i] and best[i] > top:  # strict: the first row holding the largest value
                top = best[i]
                x = i
        if x < 0:
            return
        y = best_col[x]  # x < y: S is symmetric and row x precedes row y
        for k in range(n):
            S[x, k] = S[x, k] + S[y, k]
            S[k, x] = S[x, k]
            S[y, k] = -np.inf
            S[k, y] = -np.inf
        S[x, x] = -np.inf
        alive[y] = False
        best[y] = -np.inf
        for k in range(n):
            if labels[k] == y:
                labels[k] = x
        _row_best(S, x, best, best_col)
        for i in range(n):
            if not alive[i] or i == x:
                continue
            if best_col[i] == x or best_col[i] == y:
                _row_best(S, i, best, best_col)
            elif S[i, x] > best[i] or (S[i, x] == best[i] and x < best_col[i]):
                best[i] = S[i, x]
                best_col[i] = x


@jit
def _row_best(S, i, best, best_col):
    """The largest entry of row i of S and the first column holding it."""
    best[i] = -np.inf
    best_col[i] = 0
    for k in range(S.shape[1]):
        if S[i, k] > best[i]:
            best[i] = S[i, k]
            best_col[i] = k


def consensus_views(origin: np.ndarray, rays: np.ndarray, origins: np.ndarray, candidate_rays: np.ndarray,
                    affinity: np.ndarray, min_common_joints: int, radius_m: float) -> np.ndarray:
    """Which candidate views of a new detection agree on where it is (beyond the paper).

    Each candidate is triangulated with the detection alone: per joint both hold, the midpoint of the two rays'
    closest points, in front of both cameras; their mean is where the pair places the person. True views of
    one person place it in one spot; a view of someone else who lies near the detection's epipolar line (in a
    crowd seen by hundreds of cameras, most of the positive epipolar matches) places it elsewhere along the
    detection's ray. The spot of most agreement wins (the largest summed epipolar affinity on ties), and the
    candidates within `radius_m` of it on the ground are kept.

    Args:
        origin: (3,) the detection's camera centre; rays: (J, 3) its joints' world ray directions, NaN missing.
        origins: (L, 3) the candidates' camera centres; candidate_rays: (L, J, 3) their joints' rays.
        affinity: (L,) their epipolar affinities to the detection (eq. S2).
        min_common_joints: a pair with fewer joints triangulated places nothing.
        radius_m: ground distance within which two placements agree.

    Returns:
        (L,) bool, the candidates kept.
    """
    spots = np.empty((candidate_rays.shape[0], 3))
    _pair_spots(np.ascontiguousarray(origin, dtype=np.float64), np.ascontiguousarray(rays, dtype=np.float64),
                np.ascontiguousarray(origins, dtype=np.float64), np.ascontiguousarray(candidate_rays, dtype=np.float64),
                int(min_common_joints), spots)
    placed = np.isfinite(spots[:, 0])
    keep = np.zeros(candidate_rays.shape[0], dtype=bool)
    if not placed.any():
        return keep
    ground = spots[:, :2]
    with np.errstate(invalid="ignore"):
        agree = np.linalg.norm(ground[:, None] - ground[None], axis=-1) <= radius_m  # (L, L), False for NaN
    support = agree.sum(axis=1)
    weight = np.where(agree, affinity[None, :], 0.0).sum(axis=1)
    best = np.lexsort((-weight, -support))[0]
    return agree[best] & placed


@jit
def _pair_spots(origin, rays, origins, candidate_rays, min_common_joints, out):
    """`consensus_views`' placements: out (L, 3) the mean over joints of the midpoints between the detection's
    ray and each candidate's, NaN where fewer than `min_common_joints` joints meet in front of both cameras."""
    L, J = candidate_rays.shape[0], candidate_rays.shape[1]
    for i in range(L):
        sx = sy = sz = 0.0
        count = 0
        wx, wy, wz = origin[0] - origins[i, 0], origin[1] - origins[i, 1], origin[2] - origins[i, 2]
        for j in range(J):
            d1x, d1y, d1z = rays[j, 0], rays[j, 1], rays[j, 2]
            d2x, d2y, d2z = candidate_rays[i, j, 0], candidate_rays[i, j, 1], candidate_rays[i, j, 2]
            if not (np.isfinite(d1x) and np.isfinite(d2x)):
                continue
            a = d1x * d1x + d1y * d1y + d1z * d1z
            b = d1x * d2x + d1y * d2y + d1z * d2z
            c = d2x * d2x + d2y * d2y + d2z * d2z
            d = d1x * wx + d1y * wy + d1z * wz
            e = d2x * wx + d2y * wy + d2z * wz
            den = a * c - b * b
            if den <= 1e-12 * a * c:  # (near) parallel rays meet nowhere in particular
                continue
            s = (b * e - c * d) / den  # closest point of ray 1: origin + s d1; of ray 2: origins[i] + t d2
            t = (a * e - b * d) / den
            if s <= 0.0 or t <= 0.0:
                continue
            sx += 0.5 * (origin[0] + s * d1x + origins[i, 0] + t * d2x)
            sy += 0.5 * (origin[1] + s * d1y + origins[i, 1] + t * d2y)
            sz += 0.5 * (origin[2] + s * d1z + origins[i, 2] + t * d2z)
            count += 1
        if count >= min_common_joints:
            out[i, 0], out[i, 1], out[i, 2] = sx / count, sy / count, sz / count
        else:
            out[i, 0] = out[i, 1] = out[i, 2] = np.nan


@dataclass(frozen=True)
class PlausibilityLimits:
    """Limits a new target must meet (see TrackerConfig.init_*)."""

    max_reprojection_px: float
    min_joints_3d: int
    max_bone_m: float
    min_top_m: float
    max_top_m: float
    min_bottom_m: float


def reconstruct(
    P: np.ndarray, points_px: np.ndarray, stamps_s: np.ndarray, stamp_s: float, lambda_t_per_s: float,
    min_views: int = 2, row_norm: int = WHOLE_ROW,
) -> np.ndarray:
    """3D reconstruction of a new target from a cluster (Algorithm 1): the eq. (10)-(11) DLT per joint.

    Args:
        P: (C, 3, 4) projection matrices of the cluster's cameras.
        points_px: (C, J, 2) undistorted joints of the cluster's detections, NaN missing.
        stamps_s: (C,) their frame stamps, s.
        stamp_s: the time of the estimate, s.

    Returns:
        (J, 3) pose, metres, NaN for joints seen in fewer than `min_views` views.
    """
    pts = np.swapaxes(points_px, 0, 1)  # (J, C, 2)
    stamps = np.broadcast_to(stamps_s, pts.shape[:2])
    return triangulate_incremental(P, pts, stamps, stamp_s, lambda_t_per_s, None, min_views, row_norm)


def check_plausible(
    pose: np.ndarray, P: np.ndarray, points_px: np.ndarray, skeleton: Skeleton, limits: PlausibilityLimits
) -> str | None:
    """Plausibility of a new target: reprojection error, bone lengths and height above the floor (z = 0).

    Args:
        pose: (J, 3) triangulated joints, metres.
        P: (C, 3, 4) projection matrices of the views it came from.
        points_px: (C, J, 2) those views' undistorted joints.

    Returns:
        None when plausible, else the reason it is not.
    """
    known = np.all(np.isfinite(pose), axis=-1)
    if known.sum() < limits.min_joints_3d:
        return f"only {int(known.sum())} joints triangulated"
    err = reprojection_error_px(P, pose, np.swapaxes(points_px, 0, 1))  # (J, C)
    median = float(np.nanmedian(err)) if np.any(np.isfinite(err)) else np.inf
    if median > limits.max_reprojection_px:
        return f"median reprojection error {median:.1f} px"
    bones = np.asarray(skeleton.bones, dtype=np.int64)
    if bones.size:
        lengths = np.linalg.norm(pose[bones[:, 0]] - pose[bones[:, 1]], axis=-1)
        longest = float(np.nanmax(lengths)) if np.any(np.isfinite(lengths)) else 0.0
        if longest > limits.max_bone_m:
            return f"bone of {longest:.2f} m"
    z = pose[known, 2]
    if not limits.min_top_m <= z.max() <= limits.max_top_m:
        return f"top joint at {z.max():.2f} m"
    if z.min() < limits.min_bottom_m:
        return f"lowest joint at {z.min():.2f} m"
    return None
