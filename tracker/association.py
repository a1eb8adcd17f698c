"""Target-to-detection association: the Hungarian algorithm on the (T, D) affinity, positive pairs only."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


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
    floored = np.where(np.isfinite(affinity) & (affinity > 0.0), affinity, 0.0)
    if not floored.any():
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rows, cols = linear_sum_assignment(floored, maximize=True)
    keep = floored[rows, cols] > 0.0
    return rows[keep].astype(np.int64), cols[keep].astype(np.int64)
