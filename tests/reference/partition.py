"""Plain numpy greedy agglomeration of a graph's nodes, the reference of tracker.initialization's compiled one."""

import numpy as np


def greedy_partition(a: np.ndarray) -> list[np.ndarray]:
    """Joins the pair of clusters with the largest positive total affinity (np.argmax's first in row-major order),
    until none is positive; -inf (and any non-finite affinity) forbids a pair for good."""
    n = a.shape[0]
    S = np.where(np.isfinite(a), a, -np.inf).astype(np.float64)
    np.fill_diagonal(S, -np.inf)
    members = [[i] for i in range(n)]
    alive = np.ones(n, dtype=bool)
    while True:
        x, y = divmod(int(np.argmax(S)), n)
        if not S[x, y] > 0:
            break
        S[x] = S[x] + S[y]
        S[:, x] = S[x]
        S[x, x] = -np.inf
        S[y] = -np.inf
        S[:, y] = -np.inf
        members[x] += members[y]
        alive[y] = False
    return [np.asarray(sorted(members[i])) for i in range(n) if alive[i]]
