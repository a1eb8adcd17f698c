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
    affinity = np.asarray(affinity, dtype=np.float64)
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    if affinity.size == 0:
        return empty
    clean = np.where(np.isfinite(affinity), affinity, -1.0)
    if not np.any(clean > 0):
        return empty
    # Non-positive entries are floored at 0 so they cannot pull the optimum; they are dropped after.
    rows, cols = linear_sum_assignment(np.maximum(clean, 0.0), maximize=True)
    keep = clean[rows, cols] > 0
    return rows[keep].astype(np.int64), cols[keep].astype(np.int64)
