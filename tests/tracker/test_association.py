"""Hungarian association keeping positive affinities only."""

import numpy as np

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
