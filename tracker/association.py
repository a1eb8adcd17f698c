"""Target-to-detection association: the Hungarian algorithm on the (T, D) affinity, positive pairs only."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from core.jit import jit


def associate(affinity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximum-affinity one-to-one matching (Algorithm 1, Kuhn's Hungarian method), keeping A > 0 only.

    Args:
        affinity: (T, D) affinity matrix; non-finite entries never match.

    Returns:
        (rows, cols): int arrays of equal length, the matched target and detection indices.
    """
    affinity = np.ascontiguousarray(affinity, dtype=np.float64)
    if affinity.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    # Non-positive and non-finite entries are floored at 0 so they cannot pull the optimum; dropped after.
    floored = np.empty(affinity.shape)
    if not _positive_part(affinity, floored):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows, cols = linear_sum_assignment(floored, maximize=True)
    return _positive_pairs(floored, rows.astype(np.int64, copy=False), cols.astype(np.int64, copy=False))


@jit
def _positive_part(affinity, out):
    """out = affinity where it is finite and positive, 0 elsewhere; whether any entry is positive."""
    found = False
    for t in range(affinity.shape[0]):
        for d in range(affinity.shape[1]):
            a = affinity[t, d]
            positive = np.isfinite(a) and a > 0.0
            out[t, d] = a if positive else 0.0
            found = found or positive
    return found


@jit
def _positive_pairs(floored, rows, cols):
    """The (rows, cols) pairs of an assignment whose entry is positive."""
    keep = 0
    for i in range(rows.size):
        if floored[rows[i], cols[i]] > 0.0:
            rows[keep], cols[keep] = rows[i], cols[i]
            keep += 1
    return rows[:keep].copy(), cols[:keep].copy()
