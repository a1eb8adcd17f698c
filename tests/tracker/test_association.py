"""Hungarian association keeping positive affinities only."""

import itertools

import numpy as np
import pytest

from tracker.association import associate


def test_hungarian_maximises_total_affinity():
    # Greedy would take (0, 0) = 0.9 and leave (1, 1) = 0.1; the optimum pairs (0, 1) and (1, 0).
    A = np.array([[0.9, 0.8], [0.85, 0.1]])
    rows, cols = associate(A)
    assert sorted(zip(rows.tolist(), cols.tolist())) == [(0, 1), (1, 0)]


def test_non_positive_and_non_finite_affinities_never_match():
    A = np.array([[-0.5, 0.0, np.nan], [2.0, -np.inf, 0.3]])
    rows, cols = associate(A)
    assert list(zip(rows.tolist(), cols.tolist())) == [(1, 0)]


def test_empty_matrices():
    for shape in [(0, 0), (0, 3), (2, 0)]:
        rows, cols = associate(np.zeros(shape))
        assert rows.size == cols.size == 0


def test_matching_maximises_the_positive_total_against_brute_force():
    rng = np.random.default_rng(2)
    for _ in range(30):
        T, D = (int(n) for n in rng.integers(1, 5, size=2))
        A = rng.uniform(-1.0, 1.0, (T, D))
        A[rng.random((T, D)) < 0.1] = np.nan
        rows, cols = associate(A)
        assert np.all(A[rows, cols] > 0) and len(set(rows)) == rows.size and len(set(cols)) == cols.size
        # Brute force: the best total of positive entries over every one-to-one assignment.
        gain = np.where(np.isfinite(A) & (A > 0), A, 0.0)
        k = min(T, D)
        best = max(sum(gain[t, d] for t, d in zip(targets, detections))
                   for targets in itertools.combinations(range(T), k)
                   for detections in itertools.permutations(range(D), k))
        assert A[rows, cols].sum() == pytest.approx(best)
